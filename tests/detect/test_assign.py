"""Lanes of tracked vehicles relative to the ego lane, from the lane markings."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.lane_tracks import make_track
from vid2sim.core.records import RangedBox, TrackedBox
from vid2sim.detect.assign import assign_lanes_and_lead, lane_indices, lane_offsets, relane
from vid2sim.detect.ranging import RangingConfig

CFG = RangingConfig()


def box(frame, t, tid=1, category="car") -> TrackedBox:
    return TrackedBox(frame, t, tid, category, 0.9, 0, 0, 10, 10)


# --------------------------------------------------------------------------- hysteresis


def test_a_vehicle_keeps_its_road_lane_when_the_ego_changes_lanes():
    # The vehicle holds its lane 3 m left of the ego's first lane; the ego moves into that
    # lane at frame 3: the vehicle is "left" until then and in the ego lane after, with no
    # hysteresis to overcome (its offset from the new ego lane is 0).
    offset = np.array([3.0, 3.0, 3.0, 0.0, 0.0])
    idx = lane_indices(offset, 3.0, 0.3, ego_lane=np.array([0, 0, 0, 1, 1]))
    assert idx.tolist() == [1, 1, 1, 0, 0]
    # per-sample widths: a lane 2.8 m wide puts a car 1.6 m left in the next lane
    assert lane_indices(np.array([1.6, 1.6]), np.array([3.6, 2.8]), 0.1).tolist() == [0, 1]
    # unknown offsets hold the lane (0 before any is known)
    assert lane_indices(np.array([np.nan, 3.2, np.nan]), 3.0, 0.3).tolist() == [0, 1, 1]


def test_hysteresis_ignores_flicker_along_a_boundary():
    # A car drives along the ego lane's left boundary (1.75 m of a 3.5 m lane) with 0.2 m of
    # noise: with 0.3 m of hysteresis its lane never flips; it changes only once its centre
    # is 0.3 m past the boundary (2.05 m), and then stays until 0.3 m past on the way back.
    wobble = np.array([1.6, 1.9, 1.7, 1.95, 1.65, 2.0, 1.8, 1.7])
    assert lane_indices(wobble, 3.5, 0.3).tolist() == [0] * 8
    assert lane_indices(wobble, 3.5, 0.0).tolist() == [0, 1, 0, 1, 0, 1, 1, 0]
    crossing = np.array([1.0, 1.9, 2.0, 2.1, 1.9, 1.6, 1.5, 1.4, 1.0])
    assert lane_indices(crossing, 3.5, 0.3).tolist() == [0, 0, 0, 1, 1, 1, 1, 0, 0]


@settings(max_examples=60)
@given(y=st.lists(st.floats(-12, 12), min_size=1, max_size=40), w=st.floats(2.5, 4.0),
       hyst=st.floats(0.0, 0.6), shift=st.integers(-3, 3))
def test_lane_indices_properties(y, w, hyst, shift):
    y = np.array(y)
    idx = lane_indices(y, w, hyst)
    # a lane index is never more than the hysteresis beyond its lane's boundary ...
    assert np.all(np.abs(y - idx * w) <= w / 2 + hyst + 1e-9)
    # ... and without hysteresis it is the nearest lane
    assert np.all(np.abs(y - lane_indices(y, w, 0.0) * w) <= w / 2 + 1e-9)
    # a constant ego lane (any number) changes nothing relative to it
    np.testing.assert_array_equal(lane_indices(y, w, hyst, np.full(len(y), shift)), idx)
    # a change happens only once the centre is past the boundary by the hysteresis
    for k in np.flatnonzero(np.diff(idx)) + 1:
        assert abs(y[k] - idx[k - 1] * w) > w / 2 + hyst - 1e-9


# --------------------------------------------------------------------------- lane model


def test_lane_offsets_follow_the_measured_lane_not_the_camera_axis():
    # The camera sits 0.6 m left of its lane's middle (lane 3 m wide) and the lane bends
    # right at 1/250 m: a car on the lane's centre line whose rear (the face its box shows)
    # is 15 m ahead is at lateral -0.6 - x^2 / 500.
    t = np.arange(0.0, 1.0, 0.1)
    track = make_track(t, 0.6, curvature_inv_m=-1 / 250)
    x_rear = 15.0
    lat_on_centre = -0.6 - x_rear ** 2 / 500.0
    boxes = [box(i, t[i]) for i in range(len(t))]
    rng = np.full(len(t), 15.0)
    offset, width, ego_lane = lane_offsets(boxes, rng, np.full(len(t), lat_on_centre), CFG,
                                           track)
    np.testing.assert_allclose(offset, 0.0, atol=1e-9)
    np.testing.assert_allclose(width, 3.0)
    assert (ego_lane == 0).all()
    # the camera axis puts it 1.2 m right: in the ego lane of 3.6 m, but 1.2 m off its middle
    _, _, off_axis = assign_lanes_and_lead(boxes, rng, np.full(len(t), lat_on_centre), CFG)
    np.testing.assert_allclose(off_axis, lat_on_centre)
    names2, lead2, _off2 = assign_lanes_and_lead(boxes, rng, np.full(len(t), lat_on_centre),
                                                CFG, track)
    assert set(names2) == {0} and lead2.all()
    # one lane to the left of it is "left"
    names3, lead3, _ = assign_lanes_and_lead(boxes, rng, np.full(len(t), lat_on_centre + 3.0),
                                             CFG, track)
    assert set(names3) == {1} and not lead3.any()


def test_unknown_positions_have_no_lane_and_are_never_the_lead():
    t = np.arange(0.0, 0.5, 0.1)
    boxes = [box(i, t[i]) for i in range(len(t))]
    rng = np.array([20.0, np.nan, 20.0, 200.0, 20.0])
    lat = np.array([0.0, 0.0, np.nan, 0.0, 0.0])
    names, lead, offset = assign_lanes_and_lead(boxes, rng, lat, CFG)
    assert names == [0, None, None, None, 0]
    assert lead.tolist() == [True, False, False, False, True]
    assert np.isnan(offset[2])


class _StraightThenLeft:
    """A course straight for 30 m ahead, then bending left: 2 m at 40 m ahead."""

    rate = 2.0 / (40.0 - 30.0)

    def bend_m(self, t_s, ahead_m, join_m):
        return np.maximum(np.asarray(ahead_m, float) - 30.0, 0.0) * self.rate


def test_relane_with_the_road_course():
    t = np.arange(0.0, 1.0, 0.1)
    track = make_track(t, 0.0)
    # a car 40 m ahead, 2 m left: the lane model (straight) says "left" in a 3 m lane; the
    # course bends 2 m left there: it is on the lane's centre line
    boxes = [RangedBox(i, t[i], 1, "car", 0.9, 0, 0, 10, 10, range_m=40.0, lateral_m=2.0,
                       range_rate_mps=0.0, range_std_m=1.0, is_lead=False)
             for i in range(len(t))]
    straight = relane(boxes, CFG, track)
    assert {b.lane for b in straight} == {1} and not any(b.is_lead for b in straight)
    bent = relane(boxes, CFG, track, _StraightThenLeft())
    assert {b.lane for b in bent} == {0} and all(b.is_lead for b in bent)
    assert [b.lane_offset_m for b in bent] == pytest.approx([0.0] * len(t), abs=1e-9)
    assert relane([], CFG, track) == []
