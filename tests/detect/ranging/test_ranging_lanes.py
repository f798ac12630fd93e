"""Lane-marking horizon on synthetic road images with a known vanishing point."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from vid2sim.core.camera import Camera
from vid2sim.detect.lanes.vanishing import HorizonEstimator

CAM = Camera(image_width=1280, image_height=720, fx=1000.0, fy=1000.0, cx=639.5, cy=359.5,
             height_m=1.3)


def road_image(camera: Camera, seed: int, dash_phase_m: float = 0.0) -> np.ndarray:
    """Asphalt with noise, lane markings at +-1.8 m and +-5.4 m (dashed centre lines) drawn by
    projecting road points with ``camera``, plus clutter: a car-like box and a few random
    short edges above and below the horizon."""
    rng = np.random.default_rng(seed)
    h, w = camera.image_height, camera.image_width
    img = np.full((h, w, 3), 90, np.uint8)
    hor = int(camera.horizon_y_px())
    img[: max(hor, 0)] = (200, 170, 140)  # sky
    img = cv2.add(img, rng.normal(0, 6, img.shape).clip(-20, 20).astype(np.int8),
                  dtype=cv2.CV_8U)
    for y_m, dashed in ((1.8, True), (-1.8, True), (5.4, False), (-5.4, False)):
        xs = np.arange(3.0, 120.0, 0.5)
        for x0 in xs:
            if dashed and ((x0 + dash_phase_m) % 9.0) > 3.0:
                continue
            pts = np.array([[x0, y_m, 0.0], [x0 + 0.5, y_m, 0.0]])
            uv, ok = camera.project(pts)
            if not ok.all():
                continue
            width = max(1, int(0.12 * camera.fx / x0))
            cv2.line(img, tuple(int(v) for v in uv[0]), tuple(int(v) for v in uv[1]),
                     (235, 235, 235), width, cv2.LINE_AA)
    cv2.rectangle(img, (600, hor - 30), (700, hor + 60), (30, 30, 30), -1)
    for _ in range(15):
        x, y = int(rng.integers(0, w)), int(rng.integers(0, h))
        ang = rng.uniform(0, np.pi)
        d = int(rng.integers(10, 60))
        cv2.line(img, (x, y), (int(x + d * np.cos(ang)), int(y + d * np.sin(ang))),
                 (255, 255, 255), 2)
    return img


@pytest.mark.parametrize("pitch_deg", [-1.5, 0.0, 2.0])
def test_vanishing_point_of_synthetic_markings(pitch_deg):
    true_cam = CAM.with_pitch(pitch_deg)
    est = HorizonEstimator(CAM, every=1)  # it only knows the level camera
    for k in range(6):
        est.add_frame(road_image(true_cam, seed=k, dash_phase_m=1.5 * k))
    row, votes = est.estimate()
    assert votes >= 5
    assert row == pytest.approx(true_cam.horizon_y_px(), abs=4.0)


def test_every_nth_frame_and_no_markings():
    est = HorizonEstimator(CAM, every=5)
    blank = np.full((720, 1280, 3), 90, np.uint8)
    for _ in range(10):
        est.add_frame(blank)
    est.add_frame(None)  # frames skipped undecoded are ignored
    assert est.estimate() == (None, 0)
    # Frames of another size (a downscaled copy) still give rows in the camera's pixels.
    small = cv2.resize(road_image(CAM.with_pitch(1.0), seed=1), (640, 360))
    est2 = HorizonEstimator(CAM, every=1)
    row = est2.add_frame(small, index=40)
    assert row == pytest.approx(CAM.with_pitch(1.0).horizon_y_px(), abs=5.0)
    assert est2.frames == [40]  # each row keeps its video frame, for the per-frame horizon
    est3 = HorizonEstimator(CAM, every=2)
    for _ in range(3):
        est3.add_frame(road_image(CAM, seed=2))
    assert est3.frames == [0, 2]  # without an index: the count of frames seen


def test_camera_yaw_from_vanishing_column():
    from dataclasses import replace

    from vid2sim.detect.lanes.vanishing import yaw_for_vanishing_column

    true_cam = replace(CAM.with_pitch(1.0), yaw_deg=2.0)  # mounted turned 2 deg to the left
    est = HorizonEstimator(CAM.with_pitch(1.0), every=1)
    for k in range(5):
        est.add_frame(road_image(true_cam, seed=20 + k, dash_phase_m=2.0 * k))
    column, votes = est.estimate_column()
    assert votes >= 4
    yaw = yaw_for_vanishing_column(CAM.with_pitch(1.0), column)
    assert yaw == pytest.approx(2.0, abs=0.3)
