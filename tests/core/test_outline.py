"""Vehicle outlines: the cuboid is the old box, the hull's bottom and sides sit where a camera
sees a car's tyres, arches and mirrors, at any range, offset, pitch and yaw."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.core.camera import Camera
from vid2sim.core.outline import (
    CAR_SHAPE,
    CLASS_SHAPES,
    CUBOID,
    OutlineShape,
    outline_boxes,
    outline_points,
    project_outline,
    shape_matrix,
    shape_matrix_for,
)

KITTI = Camera(1242, 375, 721.5, 721.5, 609.6, 172.9, height_m=1.65)


@settings(max_examples=80)
@given(r=st.floats(3, 80), y=st.floats(-10, 10), w=st.floats(0.6, 2.6), h=st.floats(1.0, 4.0),
       length=st.floats(1.5, 14), yaw=st.floats(-1.2, 1.2), pitch=st.floats(-3, 3))
def test_cuboid_outline_is_the_projected_box(r, y, w, h, length, yaw, pitch):
    cam = KITTI.with_pitch(pitch)
    got = project_outline(cam, r, y, w, h, length, CUBOID, yaw, clip=False)
    want = cam.project_box(np.array([r + length / 2, y]), length, w, h, yaw, clip=False)
    assert (got is None) == (want is None)
    if got is not None:
        np.testing.assert_allclose(got, want, atol=1e-6)


@settings(max_examples=80)
@given(r=st.floats(1.5, 60), cam_h=st.floats(1.0, 2.5), o=st.floats(0.2, 1.5),
       c=st.floats(0.1, 0.6))
def test_bottom_is_the_lower_of_tyre_contact_and_bumper(r, cam_h, o, c):
    # Level camera, car straight ahead: the tyre contact at r + o on the road is hidden by the
    # bumper edge (height c at r) exactly when the bumper projects lower, so the hull's bottom
    # is the visible one either way.
    cam = replace(KITTI, height_m=cam_h)
    shape = replace(CAR_SHAPE, contact_m=o, rear_clearance_m=c, widest_m=min(o, 0.8))
    box = project_outline(cam, r, 0.0, 1.8, 1.5, 4.4, shape, clip=False)
    horizon = cam.horizon_y_px()
    contact = horizon + cam.fy * cam_h / (r + o)
    bumper = horizon + cam.fy * (cam_h - c) / r
    assert box[3] == pytest.approx(max(contact, bumper), abs=1e-6)
    hidden = cam_h * o / (r + o) > c  # the ray to the contact passes above the bumper edge
    assert hidden == (bumper > contact + 1e-9) or abs(bumper - contact) < 1e-6


def test_car_box_reads_the_body_ahead_of_the_rear_face():
    # What the issue measured on real boxes: w_px ~ f W / (Z + d), W ~ 1.8 m, d ~ 0.9 m, at
    # 4-10 m; and the bottom edge at the tyres, 0.8 m ahead of the rear.
    for z in (6.0, 8.0, 10.0):
        box = project_outline(KITTI, z, 0.0, 1.8, 1.47, 4.4, CAR_SHAPE, clip=False)
        d = KITTI.fx * 1.8 / (box[2] - box[0]) - z
        assert 0.6 < d < 1.0
        ground = KITTI.fy * KITTI.height_m / (box[3] - KITTI.horizon_y_px())
        assert ground - z == pytest.approx(CAR_SHAPE.contact_m, abs=0.02)
    # The cuboid of the same car puts both at the rear face: 8-14 % nearer at 6 m.
    cub = project_outline(KITTI, 6.0, 0.0, 1.8, 1.47, 4.4, CUBOID, clip=False)
    out = project_outline(KITTI, 6.0, 0.0, 1.8, 1.47, 4.4, CAR_SHAPE, clip=False)
    assert 1.08 < (cub[2] - cub[0]) / (out[2] - out[0]) < 1.16
    # Far away the mirrors, 2.8 m ahead but 0.1 m further out each side, make the sides.
    far = project_outline(KITTI, 40.0, 0.0, 1.8, 1.47, 4.4, CAR_SHAPE, clip=False)
    body = KITTI.fx * 1.8 / (40.0 + CAR_SHAPE.widest_m)
    assert far[2] - far[0] > body


@settings(max_examples=40)
@given(r=st.floats(4, 60), y=st.floats(-6, 6), cat=st.sampled_from(sorted(CLASS_SHAPES)))
def test_outline_mirrors_left_and_right(r, y, cat):
    # A vehicle at +y and one at -y give boxes mirrored about the principal column.
    cam = replace(KITTI, cx=(KITTI.image_width - 1) / 2)
    a = project_outline(cam, r, y, 1.8, 1.5, 4.4, CLASS_SHAPES[cat], clip=False)
    b = project_outline(cam, r, -y, 1.8, 1.5, 4.4, CLASS_SHAPES[cat], clip=False)
    assert a[0] - cam.cx == pytest.approx(cam.cx - b[2], abs=1e-6)
    assert a[1] == pytest.approx(b[1], abs=1e-6) and a[3] == pytest.approx(b[3], abs=1e-6)


def test_points_stay_within_the_vehicle_and_shapes_are_checked():
    pts = outline_points(np.array([1.8]), np.array([1.5]), np.array([4.4]),
                         shape_matrix([CAR_SHAPE]))[0]
    assert pts[:, 0].min() == 0.0 and pts[:, 0].max() == pytest.approx(4.4)
    assert pts[:, 2].min() == 0.0 and pts[:, 2].max() == pytest.approx(1.5)
    assert np.abs(pts[:, 1]).max() == pytest.approx(0.9 + CAR_SHAPE.mirror_out_m)
    # A short vehicle (motorcycle length with a bus shape) keeps its points inside.
    short = outline_points(np.array([0.8]), np.array([1.4]), np.array([2.0]),
                           shape_matrix([CLASS_SHAPES["bus"]]))[0]
    assert short[:, 0].min() >= 0.0 and short[:, 0].max() <= 2.0
    rows = shape_matrix_for(["car", "spaceship", "truck"])
    np.testing.assert_array_equal(rows[1], rows[0])
    np.testing.assert_array_equal(rows[2], shape_matrix([CLASS_SHAPES["truck"]])[0])
    with pytest.raises(ValueError, match="contact_m"):
        replace(CAR_SHAPE, contact_m=-0.1)
    with pytest.raises(ValueError):
        OutlineShape(*([math.nan] + [0.0] * 13))


def test_vectorised_boxes_match_single_ones():
    r = np.array([5.0, 12.0, 30.0])
    y = np.array([0.0, -3.5, 4.0])
    cats = ["car", "truck", "bus"]
    got = outline_boxes(KITTI, r, y, np.full(3, 2.0), np.full(3, 2.0), np.full(3, 6.0),
                        shape_matrix_for(cats))
    for k in range(3):
        one = project_outline(KITTI, r[k], y[k], 2.0, 2.0, 6.0, CLASS_SHAPES[cats[k]],
                              clip=False)
        np.testing.assert_allclose(got[k], one)
