"""The lead and lane geometry of vid2sim.core.lead: lane names, the ego lane's centre line ahead."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.lane_tracks import make_track
from vid2sim.core.lead import (
    COURSE_JOIN_M,
    LANE_MODEL_REACH_M,
    MAX_RELATIVE_LANE,
    ego_lane_at,
    lane_centre_ahead_m,
    lane_centre_m,
    lane_index,
    lane_name,
    lead_of,
    smoothed_curvature,
)


def test_lane_names_and_their_inverse():
    assert [lane_index(n) for n in ("ego", "left", "right", "left2", "right3")] == \
        [0, 1, -1, 2, -3]
    for bad in ("", "left1", "left02", "up", "right-2", "egoo", "leftx"):
        assert lane_index(bad) is None


@given(st.integers(-MAX_RELATIVE_LANE, MAX_RELATIVE_LANE))
def test_lane_name_round_trips(k):
    assert lane_index(lane_name(k)) == k


def test_centre_line_on_a_circle_within_and_beyond_the_reach():
    # A lane bending left at 1/200 m, the camera 0.3 m left of its middle, the car turned
    # 0.01 rad to the right of the lane: y = -0.3 + 0.01 x + x^2 / 400 up to the reach,
    # straight along the direction there beyond.
    k, r = 1 / 200, LANE_MODEL_REACH_M
    assert lane_centre_m(0.0, -0.3, 0.01, k) == pytest.approx(-0.3)
    assert lane_centre_m(10.0, -0.3, 0.01, k) == pytest.approx(-0.3 + 0.1 + 0.25)
    y_r = -0.3 + 0.01 * r + k * r * r / 2
    assert lane_centre_m(r, -0.3, 0.01, k) == pytest.approx(y_r)
    assert lane_centre_m(r + 15, -0.3, 0.01, k) == pytest.approx(y_r + (0.01 + k * r) * 15)
    # behind the camera the line goes straight back
    assert lane_centre_m(-4.0, -0.3, 0.01, k) == pytest.approx(-0.3 - 0.04)
    # vectorised over boxes
    np.testing.assert_allclose(lane_centre_m(np.array([0.0, 10.0]), np.array([0.0, 1.0]),
                                             0.0, 0.0), [0.0, 1.0])


@settings(max_examples=60)
@given(x=st.floats(-50, 150), off=st.floats(-3, 3), h=st.floats(-0.2, 0.2),
       k=st.floats(-0.02, 0.02), reach=st.floats(1, 60))
def test_centre_line_is_smooth_at_the_reach_and_straight_beyond(x, off, h, k, reach):
    y = lane_centre_m(x, off, h, k, reach)
    assert math.isfinite(float(y))
    # continuous with a continuous slope at the reach (a clothoid does not kink)
    eps = 1e-4
    below, above = lane_centre_m(reach - eps, off, h, k, reach), lane_centre_m(
        reach + eps, off, h, k, reach)
    assert abs(float(above - below)) <= abs(h + k * reach) * 2 * eps + 1e-9
    if x > reach:  # a straight line: the second difference vanishes
        d2 = (y - 2 * lane_centre_m(x + 1, off, h, k, reach)
              + lane_centre_m(x + 2, off, h, k, reach))
        assert abs(float(d2)) < 1e-6


def test_centre_line_follows_the_course_beyond_the_join():
    j = COURSE_JOIN_M
    # the lane model says straight ahead 0.5 m right; the course bends 2 m left by 30 m
    y = lane_centre_ahead_m(np.array([5.0, j, 30.0, 30.0]), -0.5, 0.0, 0.0,
                            np.array([np.nan, 0.0, 2.0, np.nan]))
    np.testing.assert_allclose(y, [-0.5, -0.5, 1.5, -0.5])
    # the model's direction at the join carries on: heading 0.01 + curvature 0.001 * 10
    y2 = lane_centre_ahead_m(30.0, 0.0, 0.01, 0.001, 0.0)
    y_join = lane_centre_m(j, 0.0, 0.01, 0.001)
    assert float(y2) == pytest.approx(y_join + (0.01 + 0.001 * j) * (30.0 - j))


@settings(max_examples=40)
@given(x=st.floats(0, 120), off=st.floats(-3, 3), h=st.floats(-0.1, 0.1),
       k=st.floats(-0.01, 0.01))
def test_course_on_the_lane_models_own_curve_changes_nothing_within_the_reach(x, off, h, k):
    # A course that bends exactly as the lane model (within its reach) gives the model back.
    j, r = COURSE_JOIN_M, LANE_MODEL_REACH_M
    xr, jr = min(max(x, 0.0), r), min(j, r)
    bend = 0.0 if x <= j else k * (xr * (x - 0.5 * xr) - jr * (j - 0.5 * jr)) - k * jr * (x - j)
    got = lane_centre_ahead_m(x, off, h, k, bend)
    assert float(got) == pytest.approx(float(lane_centre_m(x, off, h, k)), abs=1e-9)


# --------------------------------------------------------------------------- the ego lane at any instant


def test_ego_lane_at_interpolates_and_keeps_the_lane_of_the_latest_frame():
    t = np.arange(0.0, 2.01, 0.1)
    # a lane change to the left: lateral passes 1.5 m (w = 3 m) at 1.0 s, where the track
    # puts the new lane (LaneTrack backdates a change to its crossing)
    lat = np.interp(t, [0.0, 0.5, 1.5, 2.0], [0.0, 0.0, 3.0, 3.0])
    track = make_track(t, lat, heading_rad=0.02, curvature_inv_m=0.001,
                       lane=(t >= 1.0 - 1e-9).astype(int))
    at = ego_lane_at(track, np.array([0.25, 1.04, 1.06, 5.0]))
    assert at.lane.tolist() == [0, 1, 1, 1]
    # the camera's offset from its lane's middle: lateral minus lane x width
    np.testing.assert_allclose(at.offset_m[:3], [0.0, np.interp(1.04, t, lat) - 3.0,
                                                 np.interp(1.06, t, lat) - 3.0], atol=1e-9)
    np.testing.assert_allclose(at.centre_m[:3], -at.offset_m[:3])
    np.testing.assert_allclose(at.heading_rad[:3], 0.02)
    np.testing.assert_allclose(at.curvature_inv_m[:3], 0.001)
    assert np.isnan(at.offset_m[3]) and np.isnan(at.lane_width_m[3])  # far from any frame


def test_smoothed_curvature_is_the_median_over_a_second():
    t = np.arange(0.0, 3.0, 0.1)
    k = np.full(len(t), 0.002)
    k[10] = 0.05  # one frame's curvature from a shadow
    k[20] = np.nan
    track = make_track(t, 0.0, curvature_inv_m=k)
    np.testing.assert_allclose(smoothed_curvature(track), 0.002)


def test_a_heading_spike_of_two_frames_does_not_move_the_lane_far_ahead():
    t = np.arange(0.0, 3.0, 0.1)
    h = np.full(len(t), 0.01)
    h[15:17] = 0.12  # the lane track's heading jumps on clutter for two frames
    at = ego_lane_at(make_track(t, 0.0, heading_rad=h), t)
    np.testing.assert_allclose(at.heading_rad, 0.01)  # the median over 0.5 s


def test_the_lead_rule_is_one_function_for_one_instant_and_over_time():
    ahead = np.array([[30.0, 30.0, -5.0], [12.0, np.nan, 12.0], [8.0, 8.0, 8.0]])
    lateral = np.array([[0.2, 0.2, 0.2], [0.5, 0.5, 0.5], [2.5, 2.5, 2.5]])  # third: next lane
    # per instant: the nearest ahead in the corridor; none where nobody qualifies
    assert lead_of(ahead, lateral, 3.5).tolist() == [1, 0, 1]
    assert lead_of(ahead[:, 0], lateral[:, 0], 3.5) == 1
    assert lead_of(ahead[:1, 2:], lateral[:1, 2:], 3.5).tolist() == [-1]  # behind the ego
    # "nearest" by another measure (the gap) among those ahead
    assert lead_of(np.array([10.0, 12.0]), np.zeros(2), 3.5,
                   nearness_m=np.array([6.0, 5.0])) == 1
    assert lead_of(np.zeros((0, 4)), np.zeros((0, 4)), 3.5).tolist() == [-1] * 4
