"""The road's course ahead from the ego's own drive."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.core.records import EgoLateral, EgoTrack, Origin
from vid2sim.geo.course import RoadCourse, road_course


def _circle(radius_m: float, speed_mps: float = 10.0, duration_s: float = 20.0):
    t = np.arange(0.0, duration_s, 0.1)
    phi = speed_mps * t / radius_m
    return t, radius_m * np.sin(phi), radius_m * (1 - np.cos(phi)), phi


@pytest.mark.parametrize("radius_m", [60.0, 150.0, -80.0])
def test_bend_on_a_circle(radius_m):
    # Driving on a circle (negative radius: bending right) the course u metres past the
    # join lies R (1 - cos(u / R)) to the side of its tangent there.
    t, x, y, _ = _circle(radius_m)
    course = RoadCourse(t, x, y)
    ahead = np.array([5.0, 10.0, 20.0, 30.0, 40.0])
    got = course.bend_m(np.full(5, 3.0), ahead, 10.0)
    u = np.maximum(ahead - 10.0, 0.0)
    want = radius_m * (1 - np.cos(u / radius_m))
    np.testing.assert_allclose(got, want, rtol=0.03, atol=0.01)
    # beyond the end of the drive the course is unknown
    assert np.isnan(course.bend_m(np.array([19.0]), np.array([40.0]), 10.0)).all()


def test_a_standing_start_and_a_too_short_drive():
    t = np.arange(0.0, 10.0, 0.1)
    x = np.maximum(t - 3.0, 0.0) * 8.0  # stands for 3 s, then drives straight east
    course = RoadCourse(t, x, np.zeros_like(x))
    np.testing.assert_allclose(course.bend_m(np.array([1.0, 5.0]), np.array([30.0, 30.0]), 10.0),
                               0.0, atol=1e-9)
    short = RoadCourse(t[:3], np.zeros(3), np.zeros(3))
    assert len(short) == 0 and np.isnan(short.bend_m(np.array([0.1]), np.array([20.0]), 10.0))


def test_the_ego_changing_lanes_does_not_bend_the_course():
    # Straight east at 10 m/s; a lane change 3 m to the left between 5 and 8 s. The lane
    # track says where in its lane the ego was, so the course is the first lane: straight.
    t = np.arange(0.0, 15.0, 0.1)
    u = np.clip((t - 5.0) / 3.0, 0.0, 1.0)
    y = 3.0 * u ** 3 * (10 - 15 * u + 6 * u * u)
    lane = (y > 1.5).astype(int)
    heading = np.arctan2(np.gradient(y, t), 10.0)
    ego = EgoTrack(Origin(0, 0, 0), t, 10.0 * t, y, heading, np.full(len(t), 10.0),
                   np.zeros(len(t)), np.zeros(len(t)))
    lateral = EgoLateral(ego=ego, lane=lane, offset_in_lane_m=y - 3.0 * lane,
                         offset_from_centerline_m=np.full(len(t), np.nan),
                         correction_m=np.zeros(len(t)), lane_width_m=np.full(len(t), 3.0))
    course = road_course(lateral)
    bend = course.bend_m(np.full(6, 2.0), np.array([15.0, 30.0, 45.0, 60.0, 75.0, 90.0]), 10.0)
    np.testing.assert_allclose(bend, 0.0, atol=0.05)
    # the ego's own path would have bent 3 m
    raw = RoadCourse(t, 10.0 * t, y).bend_m(np.array([2.0]), np.array([90.0]), 10.0)
    assert raw[0] == pytest.approx(3.0, abs=0.05)


@settings(max_examples=30)
@given(heading=st.floats(-3.1, 3.1), radius=st.floats(40.0, 2000.0),
       sign=st.sampled_from([-1.0, 1.0]), t0=st.floats(0.0, 5.0))
def test_bend_does_not_depend_on_where_the_road_points(heading, radius, sign, t0):
    t, x, y, _ = _circle(sign * radius)
    c, s = np.cos(heading), np.sin(heading)
    turned = RoadCourse(t, c * x - s * y + 500.0, s * x + c * y - 200.0)
    plain = RoadCourse(t, x, y)
    ahead = np.array([12.0, 25.0, 35.0])
    np.testing.assert_allclose(turned.bend_m(np.full(3, t0), ahead, 10.0),
                               plain.bend_m(np.full(3, t0), ahead, 10.0), atol=1e-6)
