"""Lane markings on the real KITTI raw 0001 drive; skips when ../shared/data is absent.

The street: the ego in the right lane, a dashed line on its left, the kerb (no paint) on its
right, a solid line one lane further left. The truth is independent of the measurement: a
painted line does not move, so every frame's measured line placed in the world with the
OXTS GPS/INS pose must fall on one smooth curve (vid2sim.evaluate.lane_checks). The asserts are
regression bounds a little above what the method achieves (figures in
benchmarks/bench_lanes.py and the README, measured at a2556fa).
"""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from vid2sim.app.inputs import Inputs
from vid2sim.app.loaders import load_trace, smooth_trace
from vid2sim.app.settings import Settings
from vid2sim.core.camera import load_camera
from vid2sim.core.records import MarkingKind
from vid2sim.detect.lanes.markings import LaneMarkingDetector
from vid2sim.detect.lanes.track import lane_track
from vid2sim.evaluate.lane_checks import kitti_camera_poses, world_line_scatter
from vid2sim.geo.lateral import fuse_lateral


def fuse_lateral_with_speed(*args, **kwargs):
    """fuse_lateral as the build runs it: the lane track re-run with the ego's speed."""
    kwargs.setdefault("refilter", lambda track, speed: lane_track(track.observations,
                                                                   speed_mps=speed))
    return fuse_lateral(*args, **kwargs)



@pytest.fixture(scope="module")
def measured(kitti_raw_dir):
    cap = cv2.VideoCapture(str(kitti_raw_dir / "video.mp4"))
    camera = load_camera(kitti_raw_dir / "camera.yaml")
    detector = None
    obs = []
    while True:
        ok, image = cap.read()
        if not ok:
            break
        if detector is None:
            h, w = image.shape[:2]
            detector = LaneMarkingDetector(replace(camera, image_width=w, image_height=h))
        obs.append(detector.measure(image, len(obs), len(obs) / 10.0))
    cap.release()
    poses = kitti_camera_poses(kitti_raw_dir)
    return obs, poses


def test_detection_rate(measured):
    obs, _ = measured
    assert len(obs) == 108
    both = np.mean([o.found for o in obs])
    either = np.mean([o.left is not None or o.right is not None for o in obs])
    print(f"KITTI raw 0001: both boundaries {both:.1%}, at least one {either:.1%}")
    assert both >= 0.75  # measured 81.5 %
    assert either >= 0.95  # measured 99.1 %


def test_lines_stay_put_in_the_world(measured):
    obs, poses = measured
    left0 = np.array([o.left.offset_m if o.left else np.nan for o in obs])
    left8 = np.array([o.left.y_at(8.0) if o.left else np.nan for o in obs])
    single0 = world_line_scatter(left0, poses)
    single8 = world_line_scatter(left8, poses, 8.0)
    track = lane_track(obs, speed_mps=poses["speed_mps"][: len(obs)])
    tracked = world_line_scatter(-track.ego_offset_m, poses)
    print(f"scatter: single frame x=0 {single0['rms_m']:.3f} m, x=8 m {single8['rms_m']:.3f}"
          f" m, lane track + OXTS speed {tracked['rms_m']:.3f} m (p95 {tracked['p95_m']:.3f})")
    assert single8["rms_m"] <= 0.045  # measured 0.027 m
    assert single0["rms_m"] <= 0.15  # measured 0.097 m (a heading error times 6-10 m)
    assert tracked["rms_m"] <= 0.05  # measured 0.032 m
    assert tracked["p95_m"] <= 0.12  # measured 0.070 m
    assert tracked["n"] == len(obs)


def test_the_street_as_the_video_shows_it(measured):
    obs, poses = measured
    track = lane_track(obs, speed_mps=poses["speed_mps"][: len(obs)])
    assert track.lane_changes == [] and (track.lane == 0).all()
    assert 2.8 <= np.nanmedian(track.lane_width_m) <= 3.1  # measured 2.95 m, kerb to dashes
    left = np.array(track.left_kind)
    right = np.array(track.right_kind)
    assert np.mean(left == MarkingKind.DASHED.value) >= 0.6  # measured 81 %
    assert np.mean(right == MarkingKind.ROAD_EDGE.value) >= 0.5  # measured 65 %
    # The solid line one lane to the left is seen as a further line on most frames.
    assert np.mean(track.lines_left >= 1) >= 0.6


def test_no_map_the_ego_stays_and_is_in_the_rightmost_lane(measured, kitti_raw_dir):
    obs, _ = measured
    inputs = Inputs(video=kitti_raw_dir / "video.mp4", gps=kitti_raw_dir / "oxts")
    ego, _ = smooth_trace(load_trace(inputs), inputs, Settings(progress=False))
    result = fuse_lateral_with_speed(ego, lane_track(obs), None)
    assert result.source == "lane markings (no map)"
    assert (result.lane == 0).all() and result.lane_changes == []
    np.testing.assert_array_equal(result.ego.x_m, ego.x_m)
    centre = result.lane_center_xy_m
    assert np.isfinite(centre).all(axis=1).mean() > 0.9
