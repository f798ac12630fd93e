"""Scenario assembly from an ego track and ranged tracked boxes (known answers)."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.core.camera import Camera
from vid2sim.core.records import EgoTrack, Origin, RangedBox
from vid2sim.core.scenario import Source, dumps_canonical, from_json
from vid2sim.export.assemble import (
    AssembleConfig,
    assemble_scenario,
    heading_from_motion,
    local_linear_smooth,
    straight_road_for,
)

ORIGIN = Origin(60.17, 24.94, 12.0)
CAMERA = Camera.default_for(1280, 720)


def ego_track(heading_rad: float = 0.0, speed_mps: float = 10.0, duration_s: float = 10.0,
              dt_s: float = 0.1) -> EgoTrack:
    t = np.round(np.arange(0.0, duration_s + 1e-9, dt_s), 6)
    x = speed_mps * t * math.cos(heading_rad)
    y = speed_mps * t * math.sin(heading_rad)
    n = t.size
    return EgoTrack(ORIGIN, t, x, y, np.full(n, heading_rad), np.full(n, speed_mps),
                    np.full(n, ORIGIN.lat), np.full(n, ORIGIN.lon))


def box(t_s: float, track_id: int, range_m: float, lateral_m: float, category: str = "car",
        width_m: float = float("nan")) -> RangedBox:
    return RangedBox(frame=round(t_s * 10), t_s=t_s, track_id=track_id, category=category,
                     score=0.9, x1=0, y1=0, x2=1, y2=1, range_m=range_m, lateral_m=lateral_m,
                     range_rate_mps=0.0, range_std_m=0.5, is_lead=False, width_m=width_m)


def test_vehicle_position_composes_ego_pose_range_half_length_and_lateral():
    # ego heading north at 10 m/s; a car 20 m ahead (rear), 3 m to the LEFT, same speed
    ego = ego_track(heading_rad=math.pi / 2)
    rows = [box(t, 1, 20.0, 3.0) for t in np.arange(0.0, 5.0, 0.1)]
    sc, warnings = assemble_scenario(ego, [], rows, CAMERA, source=Source())
    a = sc.actors[0]
    assert (a.length_m, a.width_m, a.height_m) == (4.5, 1.8, 1.5)  # car prior, no width
    st = a.trajectory.state_at(2.0)
    # left of a north-heading car is WEST (negative x); centre = rear + 2.25 m
    assert float(st["x"]) == pytest.approx(-3.0, abs=1e-6)
    assert float(st["y"]) == pytest.approx(20.0 + 20.0 + 2.25, abs=1e-6)
    assert float(st["heading"]) == pytest.approx(math.pi / 2, abs=1e-6)
    assert float(st["speed"]) == pytest.approx(10.0, abs=1e-6)
    assert any("no road map" in w for w in warnings)
    assert sc.roads[0].source == "assumed"


def test_gaps_bridged_or_split_and_short_pieces_dropped():
    ego = ego_track()
    t1 = [*np.arange(0.0, 2.0, 0.1), *np.arange(2.6, 4.0, 0.1)]  # 0.6 s gap: bridged
    t2 = [*np.arange(0.0, 2.0, 0.1), *np.arange(3.5, 5.0, 0.1)]  # 1.5 s gap: split
    t3 = list(np.arange(6.0, 6.3, 0.1))  # 0.2 s: dropped
    rows = ([box(t, 1, 15.0, 0.0) for t in t1] + [box(t, 2, 25.0, -3.5) for t in t2]
            + [box(t, 3, 30.0, 3.5) for t in t3])
    sc, warnings = assemble_scenario(ego, [], rows, CAMERA, source=Source())
    assert [a.id for a in sc.actors] == ["1", "2", "2-2"]
    assert sc.actors[0].trajectory.t[0] == pytest.approx(0.0)
    assert sc.actors[0].trajectory.t[-1] == pytest.approx(3.9)
    assert any("dropped" in w for w in warnings)


def test_dimensions_from_class_prior_and_clipped_width():
    ego = ego_track()
    rows = [box(t, 4, 30.0, 0.0, "truck", width_m=2.4 + 0.01 * (i % 3))
            for i, t in enumerate(np.arange(0.0, 2.0, 0.1))]
    rows += [box(t, 5, 30.0, 3.5, "car", width_m=5.0) for t in np.arange(0.0, 2.0, 0.1)]
    sc, _ = assemble_scenario(ego, [], rows, CAMERA, source=Source())
    truck, car = sc.actors
    assert (truck.category, truck.length_m, truck.height_m) == ("truck", 8.0, 3.2)
    assert truck.width_m == pytest.approx(2.41)
    assert car.width_m == pytest.approx(1.4 * 1.8)  # an implausible width is clipped


def test_stationary_vehicle_keeps_a_heading_and_zero_speed():
    ego = ego_track(heading_rad=0.3, speed_mps=5.0)
    # parked car: range shrinks as the ego drives past it
    rows = [box(t, 8, 40.0 - 5.0 * t, 4.0) for t in np.arange(0.0, 4.0, 0.1)]
    sc, _ = assemble_scenario(ego, [], rows, CAMERA, source=Source())
    traj = sc.actors[0].trajectory
    assert np.max(traj.speed) < 1e-6
    np.testing.assert_allclose(traj.heading, 0.3)  # the ego's heading: facing along the road


def test_noisy_track_is_smoothed():
    rng = np.random.default_rng(1)
    ego = ego_track()
    t = np.arange(0.0, 8.0, 1 / 30)
    rows = [box(ti, 1, 20.0 + rng.normal(0, 0.5), rng.normal(0, 0.2)) for ti in t]
    sc, _ = assemble_scenario(ego, [], rows, CAMERA, source=Source())
    traj = sc.actors[0].trajectory
    inner = (traj.t > 1) & (traj.t < 7)
    assert np.sqrt(np.mean((traj.speed[inner] - 10.0) ** 2)) < 1.0
    assert np.max(np.abs(np.unwrap(traj.heading[inner]))) < 0.15


def test_scenario_round_trips_canonical_json_with_source_and_camera():
    ego = ego_track()
    rows = [box(t, 1, 20.0, 0.0) for t in np.arange(0.0, 3.0, 0.1)]
    src = Source(inputs=[{"name": "v.mp4", "sha256": "ab"}], tool_version="0.1.0")
    sc, _ = assemble_scenario(ego, [], rows, CAMERA, source=src)
    data = json.loads(dumps_canonical(sc.to_json()))
    again = from_json(data)
    assert again.camera["fx"] == pytest.approx(CAMERA.fx, abs=1e-4)
    assert again.source.inputs == src.inputs
    assert any("no camera file" in a for a in again.source.assumptions)
    assert src.assumptions == []  # the caller's record is not modified
    assert dumps_canonical(again.to_json()) == dumps_canonical(data)


def test_straight_road_puts_the_ego_in_the_middle_lane():
    ego = ego_track(heading_rad=math.pi)  # driving west
    road = straight_road_for(ego, lanes=2, lane_width_m=3.5)
    # two lanes: the ego is in the right one, so the centerline is 1.75 m to its left, and
    # the left of a west-heading car is south (negative y)
    assert road.centerline[0, 1] == pytest.approx(-1.75)
    assert road.centerline[0, 0] > 0 > road.centerline[-1, 0]
    road3 = straight_road_for(ego, lanes=3)
    assert road3.centerline[0, 1] == pytest.approx(0.0)


@settings(max_examples=25, deadline=None)
@given(st.floats(-5.0, 5.0), st.floats(-3.0, 3.0), st.floats(0.1, 1.0))
def test_local_linear_smooth_is_exact_on_lines(slope, intercept, sigma_s):
    t = np.sort(np.random.default_rng(0).uniform(0, 10, 80))
    level, d = local_linear_smooth(t, intercept + slope * t, sigma_s)
    np.testing.assert_allclose(level, intercept + slope * t, atol=1e-6)
    np.testing.assert_allclose(d, slope, atol=1e-6)


def test_heading_held_while_slow():
    vx = np.array([0.0, 0.1, 5.0, 5.0, 0.1, 0.0])
    vy = np.array([0.0, 0.0, 5.0, 0.0, 0.0, 0.0])
    h = heading_from_motion(vx, vy, np.full(6, 2.0), AssembleConfig().stationary_speed_mps)
    np.testing.assert_allclose(h, [math.pi / 4, math.pi / 4, math.pi / 4, 0.0, 0.0, 0.0])


def test_heading_regularised_by_the_road_axis():
    from vid2sim.export.assemble import heading_along_road

    cfg = AssembleConfig()  # 15 deg, oncoming below -1 m/s, hold below 1 m/s
    axis = np.full(4, 0.5)
    # a "parked" car whose noisy range rate makes it drift at 3 m/s, 60 deg off the road
    vx = np.full(4, 3 * math.cos(0.5 + math.radians(60)))
    vy = np.full(4, 3 * math.sin(0.5 + math.radians(60)))
    np.testing.assert_allclose(heading_along_road(vx, vy, axis, cfg), 0.5 + math.radians(15))
    # oncoming traffic: the reversed axis, plus its small real yaw (5 deg to its left)
    h_true = 0.5 + math.pi + math.radians(5)
    v = np.full(4, 10.0)
    np.testing.assert_allclose(
        heading_along_road(v * math.cos(h_true), v * math.sin(h_true), axis, cfg), h_true)
    # standing still: the road axis
    np.testing.assert_allclose(heading_along_road(np.zeros(4), np.zeros(4), axis, cfg), 0.5)


def test_road_axis_follows_a_curved_centerline():
    from vid2sim.export.assemble import road_axis_heading
    from vid2sim.samples.scenarios import left_turn_centerline

    road = straight_road_for(ego_track())
    road.centerline = left_turn_centerline()
    h = road_axis_heading([road], np.array([40.0, 120.0]), np.array([2.0, 100.0]))
    np.testing.assert_allclose(h, [0.0, math.pi / 2], atol=0.03)


# --------------------------------------------------------------------------- static vehicles


def _parked_rows(scale: float, track_id: int = 7, ego_speed: float = 10.0, world_x: float = 60.0,
                 lateral: float = 7.0) -> list[RangedBox]:
    """A car parked at world x ``world_x`` (rear), ``lateral`` m left of an ego driving east
    at ``ego_speed``, ranged with a monocular scale error: range read as ``scale`` times the
    truth (0.8: shrinking at 80 % of the closing speed), its spread growing with range."""
    rows = []
    for t in np.arange(0.0, 4.0, 0.1):
        true = world_x - ego_speed * t
        rows.append(replace(box(float(t), track_id, scale * true, lateral),
                            range_std_m=0.02 * true ** 1.5))
    return rows


def test_parked_car_seen_with_a_range_scale_error_replays_standing_still():
    ego = ego_track()
    sc, _ = assemble_scenario(ego, [], _parked_rows(0.8), CAMERA, source=Source(),
                              ego_noise_m=0.05)
    tr = sc.actors[0].trajectory
    # Without the hold it would move at (1 - 0.8) x 10 = 2 m/s along the ego.
    assert np.all(tr.speed == 0.0)
    assert np.ptp(tr.x) == 0.0 and np.ptp(tr.y) == 0.0
    # Held at its best-seen (nearest) position: the last rows read 0.8 x 12-20 m.
    near_world_x = 0.8 * (60.0 - 39.0) + 39.0 + 2.25
    assert float(tr.x[0]) == pytest.approx(near_world_x, abs=2.0)
    assert float(tr.y[0]) == pytest.approx(7.0, abs=1e-6)


def test_moving_car_slow_ego_and_noisy_gps_are_not_held():
    ego = ego_track()
    # A car driving at half the ego's speed: its range closes at 5 m/s.
    rows = [box(float(t), 3, 40.0 - 5.0 * t, 3.5) for t in np.arange(0.0, 4.0, 0.1)]
    sc, _ = assemble_scenario(ego, [], rows, CAMERA, source=Source(), ego_noise_m=0.05)
    assert np.median(sc.actors[0].trajectory.speed) == pytest.approx(5.0, abs=0.1)
    # The ego creeping at 2 m/s: its motion cannot tell a parked car from a creeping one.
    slow = ego_track(speed_mps=2.0)
    sc, _ = assemble_scenario(slow, [], _parked_rows(0.8, ego_speed=2.0), CAMERA,
                              source=Source(), ego_noise_m=0.05)
    assert np.median(sc.actors[0].trajectory.speed) == pytest.approx(0.4, abs=0.05)
    # A phone-grade GPS (3 m): the ego's position error would move a held car in the image.
    sc, _ = assemble_scenario(ego, [], _parked_rows(0.8), CAMERA, source=Source(),
                              ego_noise_m=3.0)
    assert np.median(sc.actors[0].trajectory.speed) == pytest.approx(2.0, abs=0.1)


def test_a_track_faster_than_any_vehicle_is_dropped_not_written():
    # ego at 10 m/s; track 1 follows at 20 m; track 2's range grows 8 m a frame: it moves at
    # 10 + 80 = 90 m/s in the world, over the 70 m/s bound, so it is a mis-ranged track
    ego = ego_track()
    t = np.arange(0.0, 3.0, 0.1)
    rows = ([box(ti, 1, 20.0, 0.0) for ti in t]
            + [box(ti, 2, 15.0 + 80.0 * ti, 3.5) for ti in t])
    sc, warnings = assemble_scenario(ego, [], rows, CAMERA, source=Source())
    assert [a.id for a in sc.actors] == ["1"]
    assert any(w.startswith("track 2: world speed 90 m/s") for w in warnings)
    # the bound is a setting: above 90 m/s both stay
    sc, _ = assemble_scenario(ego, [], rows, CAMERA, source=Source(),
                              config=AssembleConfig(max_actor_speed_mps=95.0))
    assert [a.id for a in sc.actors] == ["1", "2"]
