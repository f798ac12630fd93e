"""Range RATE on real video with the real detector: the parked cars of KITTI raw 0001.

The detector (YOLOX-nano), tracker and ranging run once on the 108 frames; every car track
whose median lateral offset lies beyond the neighbouring lane is taken as parked (the tram is
never detected as a vehicle; the tracks in the ego lane or the next one, cars far ahead
driving away, are left out and listed). For a static car the range rate is known exactly from the OXTS forward speed
and yaw rate (derivation in ``vid2sim/evaluate/ranging/static.py``), and its range must shrink by what the
ego travels. A third truth, independent of every monocular cue, triangulates each car's outer
rear corner from its bearings along the odometry path.

``pytest -s`` prints the table (per range bin, per track, overall). The asserts are regression
bounds a little above what the pipeline measured at commit e83fd4b (each bound says what was
measured, and what it was at f5df590). What the figures showed at f5df590:
- The row of cars parked on the left (~10 m lateral, tracks 1-9) stands 0.3-0.4 m below the
  ego's road plane (box bottoms against triangulated ranges give a camera height of 1.9-2.1 m
  instead of 1.65 m), so the ground cue reads 10-20 % short; per-track width learning then
  adopts widths of 1.27-1.46 m and the width cue agrees. Ranges come out ~15 % short and
  shrink at ~3/4 of the ego's speed: closing rates ~2.7 m/s too slow at 10-13 m/s. Without
  width learning the median |rate error| drops from 3.3 to 1.9 m/s; with the vehicles'
  horizon (183 px) instead of the lane markings' (174 px) to 1.5 m/s.
- In the last 5-10 frames before a car leaves the image its box is cut at the left border:
  the range stops falling (8-10 m while the truth reaches 4-6 m) and the rate decays to zero.
- Cars in a car park behind a hedge (16-23 m to the left) get boxes over several cars or
  their flanks: rates of the wrong sign, most of the 40+ m bin.
- Track 7 switches to another car after frame ~35 (kept: nothing is dropped for
  disagreeing with the truth).
Since then: the road's spread grows with lateral offset and sizes count their common error
once (widths no longer lock in the ground cue's error), a track that left at the side is not
revived (track 7), and weak detections start tracks, which adds 110 boxes of the car park
behind the hedge, the hardest cars here: the rate figures below are over more and harder
boxes than at f5df590.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from vid2sim.core.camera import fit_camera_to_frames, load_camera
from vid2sim.detect.pipeline import detect_and_range
from vid2sim.detect.tracking.tracker import TrackerConfig
from vid2sim.detect.vehicles.detector import load_detector
from vid2sim.detect.video import video_info
from vid2sim.evaluate.ranging.static import (
    ParkedEvaluation,
    camera_from_imu_m,
    ego_motion,
    evaluate_parked,
    range_consistency,
    rate_errors,
    static_range_rate,
    triangulation_ratios,
)


def test_static_range_rate_matches_differentiated_geometry():
    # An ego turning and speeding up past a fixed point; the camera 1.08 m ahead of and
    # 0.31 m right of the IMU whose vf/wz are given. Differentiate the point's camera-frame
    # x numerically and compare with the closed form.
    t = np.linspace(0.0, 4.0, 4001)
    vf = 8.0 + 1.5 * t
    wz = 0.15 * np.sin(1.3 * t)
    yaw = np.concatenate(([0.0], np.cumsum(0.5 * (wz[1:] + wz[:-1]) * np.diff(t))))
    x_imu = np.concatenate(([0.0], np.cumsum(0.5 * ((vf * np.cos(yaw))[1:]
                                                     + (vf * np.cos(yaw))[:-1]) * np.diff(t))))
    y_imu = np.concatenate(([0.0], np.cumsum(0.5 * ((vf * np.sin(yaw))[1:]
                                                     + (vf * np.sin(yaw))[:-1]) * np.diff(t))))
    lever = np.array([1.08, -0.31])
    cam = np.column_stack((x_imu + np.cos(yaw) * lever[0] - np.sin(yaw) * lever[1],
                           y_imu + np.sin(yaw) * lever[0] + np.cos(yaw) * lever[1]))
    for point in (np.array([40.0, 9.0]), np.array([25.0, -6.0]), np.array([60.0, 0.5])):
        d = point - cam
        x = np.cos(yaw) * d[:, 0] + np.sin(yaw) * d[:, 1]
        y = -np.sin(yaw) * d[:, 0] + np.cos(yaw) * d[:, 1]
        truth = static_range_rate(vf, wz, y, camera_left_of_imu_m=lever[1])
        numeric = np.gradient(x, t)
        assert np.max(np.abs(numeric - truth)[5:-5]) < 1e-3
        # Without the lever arm the error is |wz| * 0.31 m, and a yaw term of the wrong sign
        # would be off by 2 |wz y|: the closed form is not trivially satisfied.
        assert np.max(np.abs(numeric + vf - wz * y)[5:-5]) > 0.03
        assert np.max(np.abs(numeric + vf + wz * y)[5:-5]) > 1.0


def test_kitti_oxts_axes_and_lever_arm(kitti_raw_dir):
    from vid2sim.geo.readers import read_kitti_oxts

    cam = camera_from_imu_m(kitti_raw_dir)
    # The left grey camera is ahead of, right of and above the OXTS unit (KITTI setup sheet:
    # IMU behind the rear axle side, cameras at the windscreen).
    assert cam == pytest.approx([1.08, -0.31, 0.73], abs=0.02)
    motion = ego_motion(kitti_raw_dir)
    # wz positive = turning left: the dead-reckoned heading change must equal the GPS course
    # change from the project's reader (course clockwise from north, hence the minus).
    trace = read_kitti_oxts(kitti_raw_dir)
    course = np.unwrap(np.radians([f.course_deg for f in trace.fixes]))
    assert math.degrees(motion.yaw_rad[-1]) == pytest.approx(
        -math.degrees(course[-1] - course[0]), abs=0.5)
    assert math.degrees(motion.yaw_rad[-1]) < -5.0  # the drive bends right by ~8 deg
    # The video file says 10 fps; the camera captured every 0.103 s.
    assert np.mean(motion.frame_dt_s) == pytest.approx(0.1032, abs=0.001)


@pytest.fixture(scope="module")
def parked(kitti_raw_dir, model_dir) -> ParkedEvaluation:
    """The pipeline's output on the video (detector run once) and the parked cars' truth."""
    video = kitti_raw_dir / "video.mp4"
    info = video_info(video)
    camera, _ = fit_camera_to_frames(load_camera(kitti_raw_dir / "camera.yaml"), info.width,
                                     info.height)
    detector = load_detector("yolox-nano", model_dir, score_threshold=TrackerConfig().low_score)
    result, camera, _ = detect_and_range(video, camera, detector=detector, progress=False)
    ev = evaluate_parked(result, camera, ego_motion(kitti_raw_dir))
    print("\n" + ev.report("KITTI raw 0001, detect_every=1"))
    return ev


def test_parked_cars_found(parked):
    # Measured: 17 parked tracks (10 in the row on the left, 7 in a car park behind a hedge;
    # 13 at f5df590, before weak detections started tracks), 2 left out (cars far ahead in
    # the ego lane and the next, driving away).
    assert len(parked.keep) >= 14
    assert len(parked.excluded) <= 3
    assert len(parked.rows) >= 350  # measured 449 boxes (300 at f5df590)


def test_parked_car_range_rate(parked):
    err = rate_errors(parked.rows)
    assert err["all"]["rmse"] < 5.0  # measured 4.35 m/s (5.55 at f5df590)
    assert err["all"]["mae"] < 2.9  # measured 2.50 m/s median |error| (3.25)
    assert err["0-20 m"]["mae"] < 2.0  # measured 1.46 m/s (3.22)
    assert err["20-40 m"]["mae"] < 3.0  # measured 2.36 m/s (3.10, fewer hedge cars)
    assert err["40-inf m"]["mae"] < 4.0  # measured 3.26 m/s (8.31; car park behind a hedge)
    # Closing speed underestimated (truth about -10 to -13 m/s): the estimate is slower.
    assert abs(err["all"]["bias"]) < 2.8  # measured +2.34 m/s (+2.70)


def test_parked_car_range_consistency(parked):
    cons = range_consistency(parked.rows)
    scales = np.array([c["scale"] for c in cons.values()])
    # Slope of estimated vs odometry-predicted range per track: 1 if ranges shrink at the
    # ego's speed. Measured median 0.78 (0.65 at f5df590; 0.67-1.14 on the row on the left,
    # -0.7 to 0.4 in the car park but for one at 2.1).
    assert np.nanmedian(scales) > 0.7
    res = np.abs([r.range_m - r.odo_range_m for r in parked.rows])
    assert np.median(res) < 1.9  # measured 1.61 m with the centre window (1.19 without; 1.88)
    ratios = triangulation_ratios(parked.rows, parked.tri)
    # Estimated / triangulated range of the tracks with >= 10 deg of parallax: measured
    # median 0.90 over 11 tracks (0.85 over 9 at f5df590).
    assert len(ratios) >= 9
    assert 0.85 < np.median(list(ratios.values())) < 1.1
