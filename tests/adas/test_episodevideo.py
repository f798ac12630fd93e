"""test-policy --render: episode videos that show what the policy did."""

from __future__ import annotations

import csv
import re

import numpy as np
import pytest

from tests.videoframes import decoded_frames
from vid2sim.adas.episodevideo import EPISODE_VIEW_PX, RenderChoice, parse_render, pick
from vid2sim.base.errors import ImpossibleValueError
from vid2sim.cli.main import main
from vid2sim.core.scenario import save
from vid2sim.samples.scenarios import braking_lead_scenario

_frames = decoded_frames


def _red_banner(img) -> int:
    """Pixels of the collision banner's red in the band where the banner is written."""
    h = EPISODE_VIEW_PX[1]
    band = img[h - 70:h - 25].astype(int)
    return int((np.abs(band - np.array([60, 60, 255])).sum(axis=2) < 90).sum())


def test_the_log_policy_s_collision_is_in_its_video(tmp_path):
    # the recorded driver brakes 4 s after the lead does: the log drives into the lead
    path = tmp_path / "late" / "scenario.json"
    save(braking_lead_scenario(reaction_s=4.0), path)
    out = tmp_path / "out"
    assert main(["-q", "test-policy", str(path), "--policy", "log", "--render", "worst",
                 "--out", str(out)]) == 0
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert rows[0]["collision"] == "1"
    frames = _frames(out / "episodes" / "0000.mp4")
    assert len(frames) == 121  # the reset and 120 steps of 0.1 s
    assert frames[0].shape == (EPISODE_VIEW_PX[1] + 220, EPISODE_VIEW_PX[0], 3)
    # the banner appears at the collision (6.9 s) and stays
    assert _red_banner(frames[60]) == 0
    assert _red_banner(frames[75]) > 100 and _red_banner(frames[120]) > 100
    summary = (out / "summary.html").read_text()
    assert re.search(r"<video controls[^>]* src='episodes/0000\.mp4'", summary)
    assert "collision at 6.9 s" in summary


def test_a_policy_that_brakes_leaves_its_ghost_behind(tmp_path):
    path = tmp_path / "late" / "scenario.json"
    save(braking_lead_scenario(reaction_s=4.0), path)
    out = tmp_path / "out"
    assert main(["-q", "test-policy", str(path), "--policy", "acc+aeb", "--render", "all",
                 "--out", str(out)]) == 0
    frames = _frames(out / "episodes" / "0000.mp4")
    assert len(frames) == 121
    assert all(_red_banner(f) == 0 for f in frames[::10])  # no collision
    # the recorded ego (white outline) runs ahead of the braking policy's: at 9 s the white
    # ghost lies above the ego's fixed point in the picture
    view = frames[90][:EPISODE_VIEW_PX[1]]
    white = np.argwhere((view > 235).all(axis=2))
    ego_row = EPISODE_VIEW_PX[1] * 0.96 - 15.0 * (EPISODE_VIEW_PX[1] * 0.92 / 75.0)
    ghost = white[(white[:, 0] > 60) & (white[:, 0] < ego_row - 20)]
    assert len(ghost) > 150  # labels and markings alone: ~30 (the log policy's video)


def test_render_choice_and_pick():
    assert parse_render("worst") == RenderChoice(worst=1)
    assert parse_render("3") == RenderChoice(worst=3)
    assert parse_render("ALL") == RenderChoice(all=True)
    for bad in ("0", "-1", "most", "1.5", ""):
        with pytest.raises(ImpossibleValueError):
            parse_render(bad)


def test_pick_orders_collision_then_ttc_then_gap():
    from vid2sim.adas.episode import EpisodeResult
    from vid2sim.adas.episode_metrics import EpisodeMetrics

    def result(collision, ttc, gap):
        return EpisodeResult(EpisodeMetrics(collision, ttc, 1.0, gap, 1.0, 1.0, 0, 10.0))

    results = [result(False, 2.0, 5.0), None, result(True, 3.0, -1.0), result(False, 2.0, 1.0),
               EpisodeResult(None, skip_reason="x")]
    assert pick(results, RenderChoice(worst=1)) == [2]
    assert pick(results, RenderChoice(worst=2)) == [2, 3]
    assert pick(results, RenderChoice(all=True)) == [2, 3, 0]


def test_a_bad_render_choice_fails_before_any_episode(tmp_path, capsys):
    path = tmp_path / "s" / "scenario.json"
    save(braking_lead_scenario(), path)
    assert main(["test-policy", str(path), "--policy", "log", "--render", "lots", "--out",
                 str(tmp_path / "out")]) == 2
    assert capsys.readouterr().err.startswith("error: --render")
    assert not (tmp_path / "out").exists()
