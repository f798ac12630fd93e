"""The fits' vectorised camera model against the project's Camera (one model, two codes)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.calib import cameramodel as geo
from vid2sim.core.camera import Camera


def _camera(k1=-0.2, k2=0.02, pitch=1.5, yaw=-1.0, roll=0.7) -> Camera:
    return Camera(1280, 440, 1000.0, 1000.0, 640.0, 220.0, dist=(k1, k2, 0.0, 0.0, 0.0),
                  height_m=1.5, pitch_deg=pitch, yaw_deg=yaw, roll_deg=roll)


def test_ground_and_projection_match_camera():
    cam = _camera()
    px = np.random.default_rng(0).uniform([0, 240], [1280, 440], (200, 2))
    ground, ok = cam.pixel_to_ground(px)
    c = np.array([cam.cx, cam.cy])
    rot = geo.rotations(*(math.radians(a) for a in (1.5, -1.0, 0.7)))[0]
    mine, ok2 = geo.ground_points(geo.pixels_to_normalised(px, 1000.0, c, -0.2, 0.02), rot, 1.5)
    assert (ok == ok2).all()
    assert np.nanmax(np.abs(ground - mine)) < 1e-9
    uv, _ = cam.project(ground)
    xn, _ = geo.project_normalised(geo.camera_points(ground, 1.5, rot))
    assert np.abs(geo.normalised_to_pixels(xn, 1000.0, c, -0.2, 0.02) - uv).max() < 1e-9


def test_horizon_and_vanishing_point_match_camera():
    cam = _camera(k1=0.0, k2=0.0)
    c = np.array([cam.cx, cam.cy])
    a = [math.radians(v) for v in (1.5, -1.0, 0.7)]
    assert abs(geo.horizon_row(1000.0, c, *a) - cam.horizon_y_px()) < 1e-9
    far, _ = cam.project(np.array([[1e7, 0.0, 1.5]]))
    assert np.abs(geo.forward_vanishing_point(1000.0, c, *a) - far[0]).max() < 1e-3


@settings(max_examples=60, deadline=None)
@given(k1=st.floats(-0.5, 0.5), k2=st.floats(-0.1, 0.1),
       x=st.floats(-0.6, 0.6), y=st.floats(-0.3, 0.3))
def test_undistort_inverts_distort(k1, k2, x, y):
    p = np.array([[x, y]])
    r2 = x * x + y * y
    # where the radial model is monotonic (a lens, not a fold)
    if 1 + 3 * k1 * r2 + 5 * k2 * r2 * r2 <= 0.2:
        return
    assert np.abs(geo.undistort(geo.distort(p, k1, k2), k1, k2) - p).max() < 1e-9


@settings(max_examples=40, deadline=None)
@given(p=st.floats(-0.5, 0.5), y=st.floats(-0.5, 0.5), r=st.floats(-0.5, 0.5))
def test_rotations_are_rotations(p, y, r):
    rot = geo.rotations(p, y, r)[0]
    assert np.abs(rot @ rot.T - np.eye(3)).max() < 1e-12
    assert abs(np.linalg.det(rot) - 1.0) < 1e-12
    cam = Camera(100, 100, 50, 50, 50, 50, pitch_deg=math.degrees(p), yaw_deg=math.degrees(y),
                 roll_deg=math.degrees(r))
    assert np.abs(rot - cam.R_veh_from_cam).max() < 1e-12
