"""The application layer: one GPS time base for every stage, one set of detector options."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import DetectorSettings, Settings, tracker_for_score
from vid2sim.base.errors import ImpossibleValueError, MissingInputError
from vid2sim.cli import main
from vid2sim.detect.tracking.tracker import TrackerConfig


@pytest.fixture(scope="module")
def sample(tmp_path_factory) -> Path:
    from vid2sim.samples.demo_sample import generate_demo_sample

    folder = tmp_path_factory.mktemp("app_sample")
    generate_demo_sample(folder, seed=3, duration_s=6.0)
    return folder


def _video(sample: Path) -> Path:
    return sample / "demo.mp4" if (sample / "demo.mp4").exists() else sample / "demo.avi"


def test_build_and_road_share_the_gps_time_base(sample, tmp_path):
    """`build --gps-offset S` reaches map matching exactly as `road --gps-offset S` does."""
    from vid2sim.samples.demo_sample import helsinki_pbf_path

    pbf = str(helsinki_pbf_path())
    roads = {}
    for offset in ("0", "1.5"):
        road_out = tmp_path / f"road_{offset}.json"
        assert main(["-q", "road", str(sample / "demo.gpx"), "--map", pbf, "--gps-offset",
                     offset, "--out", str(road_out)]) == 0
        build_out = tmp_path / f"build_{offset}"
        assert main(["-q", "build", str(_video(sample)), "--gps", str(sample / "demo.gpx"),
                     "--map", pbf, "--camera", str(sample / "camera.yaml"), "--detections",
                     str(sample / "detections.txt"), "--gps-offset", offset, "--offline",
                     "--out", str(build_out)]) == 0
        from_road = json.loads(road_out.read_text())
        from_build = json.loads((build_out / "road.json").read_text())
        # The same matches, fix by fix, on the same clock.
        assert from_build["matches"] == from_road["matches"]
        assert from_build["route_osm_way_ids"] == from_road["route_osm_way_ids"]
        roads[offset] = from_build
    # The offset moves every fix's time on the scenario clock by exactly the offset.
    t0 = [m["t"] for m in roads["0"]["matches"]]
    t1 = [m["t"] for m in roads["1.5"]["matches"]]
    assert t0[0] == pytest.approx(0.0, abs=1e-6)
    assert all(b - a == pytest.approx(1.5, abs=1e-6) for a, b in zip(t0, t1, strict=True))


@pytest.mark.parametrize("command", ["detect", "track", "build"])
def test_detect_track_and_build_take_the_same_detector_options(command, capsys):
    assert main([command, "--help"]) == 0
    text = capsys.readouterr().out
    for option in ("--detector", "--model-dir", "--detect-every", "--score", "--no-tiles",
                   "--refine", "--detections", "--fps"):
        assert option in text, (command, option)


def test_score_sets_the_tracker_thresholds_in_one_place():
    base = TrackerConfig()
    assert tracker_for_score(base, None) == base
    t = tracker_for_score(base, 0.6)
    assert t.high_score == 0.6 and t.new_track_score == pytest.approx(0.65)
    assert t.low_score == base.low_score
    assert Settings(detector=DetectorSettings(score=0.6)).tracker_config() == t


@pytest.mark.parametrize("inputs, error, name", [
    (Inputs(video=Path("/nonexistent/v.mp4")), MissingInputError, "v.mp4"),
    (Inputs(fps=float("nan")), ImpossibleValueError, "fps"),
    (Inputs(fps=-2.0), ImpossibleValueError, "fps"),
    (Inputs(ego_speed_mps=500.0), ImpossibleValueError, "ego speed"),
    (Inputs(gps_offset_s=float("inf")), ImpossibleValueError, "gps_offset_s"),
])
def test_impossible_inputs_are_input_errors(inputs, error, name):
    with pytest.raises(error, match=name):
        inputs.check()


def test_settings_refuse_impossible_values():
    for bad in (DetectorSettings(detect_every=0), DetectorSettings(score=1.5),
                DetectorSettings(refine=-1)):
        with pytest.raises(ImpossibleValueError):
            Settings(detector=bad).check()
