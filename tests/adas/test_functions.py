"""The built-in driving functions: known answers (IDM, ISO limits, TTC), Euro NCAP AEB
car-to-car scenarios, ACC's equilibrium gap, lane keeping on a curve."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vid2sim.adas.episode import run_episode
from vid2sim.adas.functions import (
    AdaptiveCruise,
    EmergencyBraking,
    idm_acceleration,
    iso_acc_limits,
    time_to_contact,
)
from vid2sim.adas.registry import parse_policy
from vid2sim.adas.sensor import CameraFrame, SensorConfig, Track
from vid2sim.core.scenario import Actor, Ego, Road, Scenario, Source, Trajectory
from vid2sim.samples.scenarios import (
    ORIGIN,
    _s_profile,
    left_turn_centerline,
    make_scenario,
    trajectory_along,
)

KMH = 1 / 3.6


def ncap_scenario(ego_kmh: float, target_kmh: float, gap_m: float, target_decel_mps2: float = 0.0,
                  brake_at_s: float = 1.0, duration_s: float = 10.0) -> Scenario:
    """Euro NCAP AEB car-to-car rear: the ego (a driver who does not react) at a constant
    speed behind the target, ``gap_m`` bumper to bumper; the target brakes at
    ``target_decel_mps2`` from ``brake_at_s`` to a stop (CCRb), or keeps its speed (CCRs,
    CCRm). Straight 2-lane road, full overlap."""
    line = np.array([[0.0, 0.0], [600.0, 0.0]])
    t = np.round(np.arange(0.0, duration_s + 1e-9, 0.1), 6)
    v_e, v_t = ego_kmh * KMH, target_kmh * KMH
    ego = trajectory_along(line, 20.0 + v_e * t, t, -1.75)
    if target_decel_mps2 > 0:
        _, s_t = _s_profile(t, v_t, brake_at_s, target_decel_mps2, 0.0)
    else:
        s_t = v_t * t
    target = Actor("target", "car", 4.5, 1.8, 1.5,
                   trajectory_along(line, 20.0 + gap_m + 4.5 + s_t, t, -1.75))
    road = Road("r", "test track", "primary", "osm", [1], 2, 3.5, line)
    return Scenario(ORIGIN, [road], Ego(4.5, 1.8, 1.5, ego), [target], {"fx": 720.0},
                    Source(tool_version="test"))


def test_idm_and_iso_limits_known_answers():
    # free road: a (1 - (v / v0)^4)
    assert idm_acceleration(10.0, 20.0, None, 0.0, time_gap_s=1.5, min_gap_m=2.0,
                            max_accel_mps2=1.5, comfort_decel_mps2=2.0) == pytest.approx(
        1.5 * (1 - 0.5**4))
    # at the desired gap with no closing speed the interaction term is -a
    assert idm_acceleration(10.0, 20.0, 17.0, 0.0, time_gap_s=1.5, min_gap_m=2.0,
                            max_accel_mps2=1.5, comfort_decel_mps2=2.0) == pytest.approx(
        1.5 * (1 - 0.5**4) - 1.5)
    assert iso_acc_limits(3.0) == (5.0, 5.0)
    assert iso_acc_limits(12.5) == pytest.approx((4.25, 3.75))
    assert iso_acc_limits(30.0) == (3.5, 2.5)


def test_time_to_contact_known_answers():
    assert time_to_contact(20.0, 5.0, 0.0) == pytest.approx(4.0)
    assert time_to_contact(20.0, -1.0, 0.0) == math.inf
    # 12 m, no closing speed, closing acceleration 6 m/s^2: 12 = 3 t^2 -> t = 2 s
    assert time_to_contact(12.0, 0.0, 6.0) == pytest.approx(2.0)
    # closing at 10 m/s but braking 8 m/s^2 relative: stops closing after 6.25 m < 10 m
    assert time_to_contact(10.0, 10.0, -8.0) == math.inf
    assert time_to_contact(0.0, 1.0, 0.0) == 0.0


def _frame(speed, lead_range, lead_rate, t=0.0, accel=0.0):
    return CameraFrame(t, speed, accel, 0.0, 0.0, 0, None,
                       Track(lead_range, lead_rate, 0.0, 0, 1.8), ())


def test_aeb_stage_thresholds_grow_with_the_closing_speed():
    aeb = EmergencyBraking()
    # 14 m/s towards a stopped car: partial braking below 0.6 + 14 / 8 = 2.35 s, full
    # braking below 0.6 + 14 / 16 = 1.475 s or when 4 m/s^2 would not do (14^2 / 2g > 4)
    assert aeb.command(_frame(14.0, 14.0 * 2.5, -14.0), 0.0) == 0.0
    assert aeb.stage == 1  # warned: 2.5 s < 1.2 + 14 / 6.8
    assert aeb.command(_frame(14.0, 14.0 * 2.3, -14.0, t=0.1), 0.0) == -4.0
    assert aeb.command(_frame(13.6, 22.0, -13.6, t=0.2), 0.0) == -8.0  # a_req 4.4
    assert [e[1] for e in aeb.events] == ["fcw", "partial", "full"]


@pytest.mark.parametrize("case", [
    # CCRs and CCRm start at TTC 4 s, as the protocol's runs; CCRb at its two headways
    ("CCRs 50", 50, 0, 50 * KMH * 4.0, 0.0),
    ("CCRs 80", 80, 0, 80 * KMH * 4.0, 0.0),
    ("CCRm 50/20", 50, 20, 30 * KMH * 4.0, 0.0),
    ("CCRb 12 m -6", 50, 50, 12.0, 6.0),
    ("CCRb 40 m -2", 50, 50, 40.0, 2.0),
    ("CCRb 40 m -6", 50, 50, 40.0, 6.0),
])
@pytest.mark.parametrize("noise", [0.0, 1.0])
def test_euro_ncap_car_to_car_rear_scenarios(case, noise):
    name, ego_kmh, target_kmh, gap, decel = case
    sc = ncap_scenario(ego_kmh, target_kmh, gap, decel)
    driver = run_episode(sc, parse_policy("log"))
    assert driver.metrics.collision, f"{name}: the scenario must be a crash without AEB"
    for policy in ("aeb", "acc+aeb"):
        r = run_episode(sc, parse_policy(policy), sensor=SensorConfig(level=noise), seed=3)
        print(f"{name} noise {noise} {policy}: min gap {r.metrics.min_gap_m:.2f} m, "
              f"events {r.events[:4]}")
        assert not r.metrics.collision, (name, policy)
        assert r.metrics.min_gap_m > 0.0
    if name.startswith(("CCRs", "CCRm")):  # a steady approach: the warning comes first
        assert run_episode(sc, parse_policy("aeb")).events[0][1] == "fcw"


def test_acc_settles_at_the_idm_equilibrium_gap():
    # lead at 20 m/s, ego at 20 m/s 60 m behind, set speed 30 m/s: IDM's equilibrium is
    # s = (s0 + v T) / sqrt(1 - (v / v0)^4) = 33 / sqrt(1 - (2/3)^4) = 36.8 m (1.84 s)
    line = np.array([[0.0, 0.0], [2000.0, 0.0]])
    t = np.round(np.arange(0.0, 60.0 + 1e-9, 0.1), 6)
    ego = trajectory_along(line, 20.0 + 20.0 * t, t, 0.0)
    ego = Trajectory(ego.t, ego.x, ego.y, ego.heading, np.full(len(t), 30.0))  # set speed
    ego.speed[0] = 20.0
    lead = Actor("lead", "car", 4.5, 1.8, 1.5, trajectory_along(line, 84.5 + 20.0 * t, t, 0.0))
    sc = Scenario(ORIGIN, [Road("r", "", "primary", "osm", [1], 1, 3.5, line)],
                  Ego(4.5, 1.8, 1.5, ego), [lead], {}, Source())
    r = run_episode(sc, parse_policy("acc"))
    gap_end = r.series["gap_m"][-1]
    expected = (3.0 + 20.0 * 1.5) / math.sqrt(1 - (20 / 30) ** 4)
    assert gap_end == pytest.approx(expected, rel=0.05)
    assert r.metrics.max_decel_mps2 <= iso_acc_limits(20.0)[0] + 1e-6


def test_acc_braking_stays_within_iso_limits_on_a_cut_in():
    sc = make_scenario(np.array([[0.0, 0.0], [600.0, 0.0]]), ego_speed_mps=20.0,
                       duration_s=12.0)  # the lead brakes at 2 m/s^2 from 4 s
    acc = AdaptiveCruise(set_speed_mps=20.0)
    r = run_episode(sc, parse_policy("acc"))
    assert not r.metrics.collision
    max_decel, max_jerk = iso_acc_limits(0.0)
    assert r.metrics.max_decel_mps2 <= max_decel + 1e-6
    assert r.metrics.max_jerk_mps3 <= max_jerk + 1e-6
    assert acc.time_gap_s == 1.5


@pytest.mark.parametrize("noise", [0.0, 1.0])
def test_lane_keeping_holds_the_lane_on_a_left_curve(noise):
    sc = make_scenario(left_turn_centerline(radius_m=40.0), ego_speed_mps=10.0,
                       duration_s=16.0, with_actors=False)
    r = run_episode(sc, parse_policy("lka"), sensor=SensorConfig(level=noise), seed=1)
    assert r.metrics.lane_departures == 0 and not r.metrics.collision
    assert r.metrics.duration_s == pytest.approx(16.0)


def test_lane_keeping_brings_an_offset_ego_back_to_the_lane_centre():
    from vid2sim.adas.episode import make_env

    line = np.array([[0.0, 0.0], [400.0, 0.0]])
    t = np.round(np.arange(0.0, 10.0 + 1e-9, 0.1), 6)
    ego = trajectory_along(line, 10.0 + 12.0 * t, t, -1.75 + 0.6)  # 0.6 m left of the lane centre
    sc = Scenario(ORIGIN, [Road("r", "", "primary", "osm", [1], 2, 3.5, line)],
                  Ego(4.5, 1.8, 1.5, ego), [], {}, Source())
    spec = parse_policy("lka")
    env = make_env(sc, spec)
    policy = spec.make(sc, env.unwrapped.config)
    obs, info = env.reset(seed=0)
    assert info["lane_offset_m"] == pytest.approx(0.6, abs=0.01)
    offsets = []
    for _ in range(100):
        obs, _, _, _, info = env.step(policy(obs, info))
        offsets.append(info["lane_offset_m"])
    assert abs(offsets[-1]) < 0.1
    assert min(offsets) > -0.3  # no large overshoot to the right


def _not_tiny(lo, hi):  # speeds and accelerations of 1e-190 overflow the check below
    return st.floats(lo, hi).filter(lambda x: x == 0.0 or abs(x) > 1e-6)


@given(st.floats(0.1, 200.0), _not_tiny(-30.0, 30.0), _not_tiny(-10.0, 10.0))
def test_time_to_contact_is_the_first_root(gap, closing, accel):
    t = time_to_contact(gap, closing, accel)
    if math.isinf(t):
        # never: the gap stays positive for all times (its minimum over t >= 0)
        if accel < 0 and closing > 0:
            assert gap - closing**2 / (-2 * accel) > -1e-6
        else:
            assert closing <= 1e-9 and accel <= 1e-9
        return
    assert t > 0
    scale = gap + abs(closing * t) + abs(0.5 * accel * t * t)  # the terms that cancel
    assert gap - closing * t - 0.5 * accel * t * t == pytest.approx(0.0, abs=1e-9 * scale)
    # no earlier contact
    for f in (0.25, 0.5, 0.9):
        tt = f * t
        assert gap - closing * tt - 0.5 * accel * tt * tt > -1e-9
