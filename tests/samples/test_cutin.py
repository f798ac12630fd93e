"""Cut-in clips: the profile's known answers, and a real car pasted into KITTI raw 0001
cutting in from the left lane is found as a ``cut_in`` event at the right moment.

Data-dependent tests skip when ../shared/data or the weights are absent (see conftest.py).
"""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from vid2sim.app.build import build
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.core.camera import fit_camera_to_frames, load_camera
from vid2sim.detect.video import video_info
from vid2sim.samples import composite as cp
from vid2sim.samples.cutin import cut_in_truth, measure_ego_lane, min_jerk

N_FRAMES = 108
#: The seed of the end-to-end clip (any seed: benchmarks/bench_cutin.py runs several).
SEED = 0


def test_min_jerk_is_a_smooth_symmetric_step():
    tau = np.linspace(-0.5, 1.5, 201)
    s = min_jerk(tau)
    assert s[0] == 0.0 and s[-1] == 1.0 and np.all(np.diff(s) >= 0)
    assert min_jerk(np.array([0.5]))[0] == pytest.approx(0.5)
    # symmetric about the middle, so the lane boundary (half way) is crossed there
    u = np.linspace(0, 1, 11)
    np.testing.assert_allclose(min_jerk(u) + min_jerk(1 - u), 1.0, atol=1e-12)


@pytest.fixture(scope="module")
def cut_in_build(kitti_raw_dir, kitti_tracking_dir, model_dir, tmp_path_factory):
    """One cut-in clip built with the real detector (about 20 s)."""
    work = tmp_path_factory.mktemp("cutin")
    info = video_info(kitti_raw_dir / "video.mp4")
    camera, _ = fit_camera_to_frames(load_camera(kitti_raw_dir / "camera.yaml"), info.width,
                                     info.height)
    lane = measure_ego_lane(kitti_raw_dir, camera, N_FRAMES)
    cutout = cp.load_cutout(kitti_tracking_dir, "polo")
    truth = cut_in_truth(SEED, lane, N_FRAMES, cutout.length_m)
    video = work / "cutin.mp4"
    cp.write_composite_clip(kitti_raw_dir, cutout, truth.lead, video)
    settings = Settings(detector=DetectorSettings(model_dir=model_dir), allow_download=False,
                        progress=False)
    out = build(Inputs(video=video, gps=kitti_raw_dir, camera=kitti_raw_dir / "camera.yaml"),
                work / "build", settings)
    return truth, out


def test_truth_starts_in_the_left_lane_and_ends_in_the_ego_lane(cut_in_build):
    truth, _ = cut_in_build
    w = truth.lane_width_m
    assert 2.5 < w < 4.0  # the measured lane of a residential street
    assert truth.lane_offset_m[0] == pytest.approx(w, abs=0.01)
    assert abs(truth.lane_offset_m[-1]) < 0.05
    t = truth.lead.t_s
    assert np.interp(truth.t_enter_s, t, truth.lane_offset_m) == pytest.approx(w / 2, abs=0.05)
    r = np.interp(truth.t_enter_s, t, truth.lead.range_m)
    assert 10.0 <= r <= 26.0


def test_cut_in_event_within_half_a_second_of_the_truth(cut_in_build):
    truth, out = cut_in_build
    scen = json.loads(out.files["scenario"].read_text())
    cut_ins = [e for e in scen["events"] if e["type"] == "cut_in"]
    assert cut_ins, scen["events"]
    best = min(cut_ins, key=lambda e: abs(e["t_s"] - truth.t_enter_s))
    print(f"\ncut-in truth {truth.t_enter_s:.2f} s, event {best['t_s']:.2f} s")
    assert (best["from_lane"], best["to_lane"]) == (1, 0)
    assert abs(best["t_s"] - truth.t_enter_s) <= 0.5  # measured +0.25 s (seed 0)
    # the car is the only vehicle that changes lanes in this drive (parked cars, the tram)
    assert [e for e in scen["events"] if e["actor"] != best["actor"]] == []
    # tracks.csv carries the lane: +1 before the cut-in, 0 after, for the car's track
    with open(out.files["tracks"], newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert "lane" in rows[0]
    car = best["actor"].split("-")[0]
    lanes = [(float(r["t_s"]), r["lane"]) for r in rows if r["track_id"] == car and r["lane"]]
    before = {lane for t, lane in lanes if t < truth.t_enter_s - 1.0}
    after = {lane for t, lane in lanes if t > truth.t_enter_s + 1.0}
    assert before == {"1"} and after == {"0"}
