"""Lane-change events: cut-ins, cut-outs and lane changes from per-frame lanes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.detect.test_assign import make_track
from vid2sim.core.records import LaneChange, RangedBox
from vid2sim.core.scenario import Actor, Trajectory
from vid2sim.detect.assign import lane_indices
from vid2sim.export.events import (
    EventConfig,
    event_type,
    lane_crossings,
    scenario_events,
    track_crossings,
)

W = 3.0
FPS = 10.0


def _min_jerk(t, start_s, duration_s, a_m, b_m):
    u = np.clip((t - start_s) / duration_s, 0.0, 1.0)
    return a_m + (b_m - a_m) * u ** 3 * (10 - 15 * u + 6 * u * u)


def _crossings(t, offset, ego_lane=None, rng=None, hyst=0.3, width=W):
    e = np.zeros(len(t), int) if ego_lane is None else ego_lane
    lane = lane_indices(offset, width, hyst, e)
    return lane_crossings(t, lane, offset, np.full(len(t), width), e,
                          np.full(len(t), 20.0) if rng is None else rng)


def test_event_types():
    assert event_type(1, 0, True) == "cut_in" and event_type(-1, 0, True) == "cut_in"
    assert event_type(0, -1, True) == "cut_out"
    assert event_type(2, 1, True) == "lane_change"
    assert event_type(1, 0, False) == "lane_change"  # not ahead: no cut-in


def test_cut_in_at_the_moment_the_centre_crosses_the_boundary():
    # From the left lane (3 m) into the ego lane over 3 s from 4 s: the minimum-jerk path is
    # half way (1.5 m, the boundary) at 5.5 s.
    t = np.arange(0.0, 10.0, 1 / FPS)
    offset = _min_jerk(t, 4.0, 3.0, W, 0.0)
    (c,) = _crossings(t, offset)
    assert (c.from_lane, c.to_lane) == (1, 0)
    assert c.t_s == pytest.approx(5.5, abs=0.01)  # interpolated between frames
    assert c.range_m == pytest.approx(20.0)


def test_two_lanes_at_once_give_two_crossings_in_order():
    t = np.arange(0.0, 10.0, 1 / FPS)
    offset = _min_jerk(t, 3.0, 4.0, W, -W)  # left lane to right lane across the ego lane
    found = _crossings(t, offset)
    assert [(c.from_lane, c.to_lane) for c in found] == [(1, 0), (0, -1)]
    assert found[0].t_s < 5.0 < found[1].t_s
    # the boundaries are at +-1.5 m
    for c, b in zip(found, (1.5, -1.5), strict=True):
        assert np.interp(c.t_s, t, offset) == pytest.approx(b, abs=0.01)


def test_noise_along_a_boundary_is_no_event_and_an_ego_lane_change_moves_no_one():
    t = np.arange(0.0, 6.0, 1 / FPS)
    # A car wandering about the left boundary (1.5 +- 0.4 m, faster than a lane change)
    wobble = 1.5 + 0.4 * np.sign(np.sin(2 * np.pi * t / 0.6))
    assert _crossings(t, wobble) == []
    # The ego changes lanes to the left under a car that holds the left lane: the car's
    # offset from the ego lane's centre drops from 3 m to 0 as the ego lane steps.
    ego_lane = (t > 3.5).astype(int)
    assert _crossings(t, W - ego_lane * W, ego_lane) == []


def test_ranges_beyond_the_limit_and_parked_or_oncoming_actors_give_no_events():
    t = np.arange(0.0, 10.0, 1 / FPS)
    offset = _min_jerk(t, 4.0, 3.0, W, 0.0)
    boxes = _boxes(t, offset, range_m=45.0)
    assert track_crossings(boxes, None, W) == {}
    near = _boxes(t, offset, range_m=20.0)
    assert list(track_crossings(near, None, W)) == [7]
    ego = Trajectory(t, 10 * t, np.zeros_like(t), np.zeros_like(t), np.full(len(t), 10.0))
    moving = _actor("7", t, 12.0, 0.0)
    assert [(e.type, e.actor) for e in scenario_events(near, None, [moving], [], W, ego)] == \
        [("cut_in", "7")]
    for still in (_actor("7", t, 0.0, 0.0), _actor("7", t, 12.0, np.pi)):  # parked, oncoming
        assert scenario_events(near, None, [still], [], W, ego) == []
    # a move between lanes +2 and +3 concerns no one; +2 to +1 is kept
    far = _boxes(t, _min_jerk(t, 4.0, 3.0, 2 * W, 3 * W), range_m=20.0)
    assert scenario_events(far, None, [moving], [], W, ego) == []
    nearer = _boxes(t, _min_jerk(t, 4.0, 3.0, 2 * W, W), range_m=20.0)
    assert [(e.type, e.from_lane, e.to_lane) for e in
            scenario_events(nearer, None, [moving], [], W, ego)] == [("lane_change", 2, 1)]


def test_scenario_events_pick_the_track_piece_and_add_the_ego():
    t = np.arange(0.0, 10.0, 1 / FPS)
    boxes = _boxes(t, _min_jerk(t, 4.0, 3.0, W, 0.0))
    ego = Trajectory(t, 10 * t, np.zeros_like(t), np.zeros_like(t), np.full(len(t), 10.0))
    pieces = [_actor("7", t[t < 3.0], 12.0, 0.0), _actor("7-2", t[t >= 3.5], 12.0, 0.0),
              _actor("77", t, 12.0, 0.0)]
    events = scenario_events(boxes, None, pieces, [LaneChange(8.25, 0, 1)], W, ego)
    assert [(e.type, e.actor, e.from_lane, e.to_lane) for e in events] == [
        ("cut_in", "7-2", 1, 0), ("lane_change", "ego", 0, 1)]
    assert events[0].t_s == pytest.approx(5.5, abs=0.01) and events[1].t_s == 8.25


def test_track_crossings_count_lanes_on_the_road_with_the_lane_track():
    # The ego changes lanes to the left at 5 s (lateral 0 -> 3 m); the car holds the lane
    # 3 m left of the ego's first lane: no event. The lanes the ranging reports are
    # relative to the ego lane of each frame.
    t = np.arange(0.0, 10.0, 1 / FPS)
    ego_lat = _min_jerk(t, 4.0, 2.0, 0.0, W)
    track = make_track(t, ego_lat, width_m=W, lane=(ego_lat > W / 2).astype(int))
    car_offset = W - track.lane * W  # from the ego lane's centre
    boxes = _boxes(t, car_offset, ego_lane=track.lane)
    assert {b.lane for b in boxes} == {1, 0}
    assert track_crossings(boxes, track, W) == {}


def _boxes(t, offset, range_m=20.0, ego_lane=None, tid=7):
    e = np.zeros(len(t), int) if ego_lane is None else ego_lane
    lane = lane_indices(offset, W, 0.3, e)
    return [RangedBox(i, float(t[i]), tid, "car", 0.9, 0, 0, 10, 10, range_m=range_m,
                      lateral_m=float(offset[i]), range_rate_mps=0.0, range_std_m=0.5,
                      is_lead=False, lane=int(lane[i]),
                      lane_offset_m=float(offset[i])) for i in range(len(t))]


def _actor(actor_id, t, speed, heading):
    return Actor(actor_id, "car", 4.5, 1.8, 1.5,
                 Trajectory(t, 20 + speed * t, np.zeros_like(t), np.full(len(t), heading),
                            np.full(len(t), speed)))


@settings(max_examples=50, deadline=None)
@given(start=st.floats(1.0, 5.0), duration=st.floats(1.5, 6.0), a=st.integers(-2, 2),
       step=st.sampled_from([-2, -1, 1, 2]), fps=st.sampled_from([5.0, 10.0, 30.0]),
       noise=st.floats(0.0, 0.08), seed=st.integers(0, 10_000))
def test_every_boundary_is_crossed_once_near_its_true_time(start, duration, a, step, fps,
                                                           noise, seed):
    # A lane change of |step| lanes with small noise: one crossing per boundary, each at the
    # moment the true path crosses it within a frame and the noise's share.
    t = np.arange(0.0, start + duration + 3.0, 1 / fps)
    true = _min_jerk(t, start, duration, a * W, (a + step) * W)
    offset = true + np.random.default_rng(seed).normal(0.0, noise, len(t))
    found = _crossings(t, offset)
    sign = 1 if step > 0 else -1
    assert [(c.from_lane, c.to_lane) for c in found] == [
        (a + k * sign, a + (k + 1) * sign) for k in range(abs(step))]
    for c in found:
        boundary = (c.from_lane + c.to_lane) / 2 * W
        t_true = float(np.interp(0.0, sign * (true - boundary), t))
        assert c.t_s == pytest.approx(t_true, abs=1 / fps + 0.15)


def test_config_defaults_are_named():
    cfg = EventConfig()
    assert cfg.min_dwell_s > 0 and cfg.max_range_m > 0 and cfg.min_speed_mps > 0
    assert cfg.max_lane >= 1
