"""The nuPlan-shaped episode score: each term on cases with known answers, and the braking
lead the recorded driver drives into (``log`` scores 0, ACC + AEB more than 0.5)."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest

from vid2sim.adas.campaign import CampaignOptions, run_campaign
from vid2sim.adas.episode import run_episode
from vid2sim.adas.registry import parse_policy
from vid2sim.adas.score import (
    SCORE_COLUMNS,
    ComfortBounds,
    EpisodeTrace,
    ScoreConfig,
    against_flow_m,
    collision_at_fault,
    comfortable,
    episode_score,
    progress_ratio,
    speed_limit_term,
)
from vid2sim.core.lanelayout import CrossSection, LaneSpec
from vid2sim.core.scenario import Road, Trajectory, save
from vid2sim.samples.scenarios import RUN_INTO_LEAD, braking_lead_scenario


def _trace(speed, t=None, y=0.0, heading=0.0, ttc=math.inf, offroad=False, fault=False):
    speed = np.asarray(speed, float)
    t = np.arange(len(speed)) * 0.1 if t is None else np.asarray(t, float)
    x = np.r_[0.0, np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))]
    n = len(t)
    return EpisodeTrace(t, x, np.full(n, y), np.full(n, heading), speed, np.full(n, ttc),
                        np.full(n, offroad), fault)


def _log(speed_mps=10.0, n=101):
    t = np.arange(n) * 0.1
    return Trajectory(t, speed_mps * t, np.zeros(n), np.zeros(n), np.full(n, speed_mps))


def test_at_fault_classes():
    # 4.5 m ego, 4.4 m lead: end to end at 4.45 m centre distance
    assert collision_at_fault(4.45, 10.0, True, 4.5, 4.4)  # rear-ending the lead
    assert not collision_at_fault(-4.45, 10.0, True, 4.5, 4.4)  # hit from behind
    assert not collision_at_fault(4.45, 0.0, True, 4.5, 4.4)  # hit while standing
    assert not collision_at_fault(0.5, 10.0, True, 4.5, 4.4)  # side swipe, ego in its lane
    assert collision_at_fault(0.5, 10.0, False, 4.5, 4.4)  # side swipe while changing lanes


def test_progress_is_the_share_of_the_recorded_route():
    log = _log()  # 100 m in 10 s
    assert progress_ratio(_trace(np.full(101, 10.0)), log, 0.1) == pytest.approx(1.0)
    assert progress_ratio(_trace(np.full(101, 4.0)), log, 0.1) == pytest.approx(0.4)
    assert progress_ratio(_trace(np.full(101, 14.0)), log, 0.1) == 1.0  # capped
    assert progress_ratio(_trace(np.zeros(101)), _log(0.0), 0.1) == 1.0  # expert stood


def test_driving_against_the_lane_direction():
    """An ego in the oncoming lane of a two-way road at 10 m/s moves 10 m against the flow
    per second; in its own lane nothing."""
    section = CrossSection(-3.5, (LaneSpec("driving", "forward", 3.5),
                                  LaneSpec("driving", "backward", 3.5)))
    road = Road("r", "", "primary", "osm", [], 2, 3.5, np.array([[-10.0, 0.0], [200.0, 0.0]]),
                cross_section=section)
    assert against_flow_m(_trace(np.full(31, 10.0), y=-1.75), [road], 1.0) == 0.0
    assert against_flow_m(_trace(np.full(31, 10.0), y=1.75), [road], 1.0) == pytest.approx(10.0)
    cfg = ScoreConfig()
    oncoming = episode_score(_trace(np.full(31, 10.0), y=1.75), _log(10.0, 31), [road],
                             config=cfg)
    assert oncoming.direction == 0.0 and oncoming.score == 0.0
    slow = episode_score(_trace(np.full(31, 0.4), y=1.75), _log(0.4, 31), [road])
    assert slow.direction == 1.0  # 0.4 m against the flow per second: within 2 m


def test_comfort_bounds():
    """Steady 1 m/s^2 braking is comfortable; full braking (8 m/s^2) is not, nor a step from
    cruising into 3 m/s^2 (a jerk of tens of m/s^3 over a 0.5 s window)."""
    b = ComfortBounds()
    t = np.arange(101) * 0.1
    assert comfortable(_trace(15.0 - 1.0 * t, t), b, 0.5)
    assert not comfortable(_trace(np.maximum(15.0 - 8.0 * t, 0.0), t), b, 0.5)
    assert not comfortable(_trace(np.where(t < 5.0, 15.0, 15.0 - 3.0 * (t - 5.0)), t), b, 0.5)


def test_speed_limit_term_is_nuplans():
    """2.23 m/s over the limit for the whole episode gives 0, for a tenth of it 0.9."""
    t = np.arange(101) * 0.1
    assert math.isnan(speed_limit_term(_trace(np.full(101, 15.0), t), None, 2.23))
    assert speed_limit_term(_trace(np.full(101, 15.0), t), 15.0, 2.23) == 1.0
    over = np.where(t < 1.0, 15.0 + 2.23, 15.0)  # 10 of 101 samples, 10 s long
    assert speed_limit_term(_trace(over, t), 15.0, 2.23) == pytest.approx(0.9, abs=1e-9)
    assert speed_limit_term(_trace(np.full(101, 20.0), t), 15.0, 2.23) == 0.0


def test_weighted_average_with_and_without_a_limit():
    log = _log()
    ok = episode_score(_trace(np.full(101, 10.0)), log, [])
    assert ok.score == 1.0 and math.isnan(ok.speed_limit)
    close = episode_score(_trace(np.full(101, 10.0), ttc=0.9), log, [])
    assert close.ttc == 0.0 and close.score == pytest.approx(7.0 / 12.0)  # (5 + 2) / 12
    with_limit = episode_score(_trace(np.full(101, 10.0), ttc=0.9), log, [],
                               speed_limit_mps=20.0)
    assert with_limit.score == pytest.approx(11.0 / 16.0)  # (5 + 4 + 2) / 16
    assert episode_score(_trace(np.full(101, 10.0), fault=True), log, []).score == 0.0
    assert episode_score(_trace(np.full(101, 10.0), offroad=True), log, []).score == 0.0
    stuck = episode_score(_trace(np.full(101, 1.5)), log, [])  # 15 % of the route
    assert stuck.making_progress == 0.0 and stuck.score == 0.0


def test_the_recorded_driver_who_drives_into_the_lead_scores_zero():
    sc = braking_lead_scenario(**RUN_INTO_LEAD)
    log = run_episode(sc, parse_policy("log"))
    assert log.metrics.collision and log.score.no_at_fault == 0.0 and log.score.score == 0.0
    aeb = run_episode(sc, parse_policy("acc+aeb"))
    assert not aeb.metrics.collision
    assert aeb.score.score > 0.5
    assert aeb.score.progress < 1.0  # it follows the lead down to 4 m/s


def test_results_csv_has_the_score(tmp_path):
    path = tmp_path / "s" / "scenario.json"
    path.parent.mkdir()
    save(braking_lead_scenario(**RUN_INTO_LEAD), path)
    for policy, check in (("log", lambda s: s == 0.0), ("acc+aeb", lambda s: s > 0.5)):
        run_campaign(CampaignOptions(inputs=(path,), policy=policy, out_dir=tmp_path / policy))
        with open(tmp_path / policy / "results.csv", newline="") as f:
            rows = list(csv.DictReader(f))
        assert set(SCORE_COLUMNS) <= set(rows[0])
        score = float(rows[0]["score"])
        assert 0.0 <= score <= 1.0 and check(score)
        assert rows[0]["score_speed_limit"] == ""  # the scenario's map has no limit
        assert "score" in (tmp_path / policy / "summary.html").read_text()
