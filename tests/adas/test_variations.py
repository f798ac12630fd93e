"""--vary parsing and sampling, the scenario transforms (known answers), physical checks."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from vid2sim.adas.variations import (
    MAX_GRID,
    PARAMETERS,
    apply_variation,
    find_roles,
    label,
    offset_speed,
    parse_vary,
    scale_deceleration,
    shift_along,
    shift_cut_in,
    variations,
)
from vid2sim.base.errors import FormatError, ImpossibleValueError, InputError
from vid2sim.core.scenario import Trajectory
from vid2sim.export.highway import ReplayEnv
from vid2sim.samples.scenarios import BRAKING_LEAD, braking_lead_scenario, straight_scenario


def _straight(t, s, speed, y=0.0):
    return Trajectory(t, s, np.full_like(t, y), np.zeros_like(t), speed)


# --------------------------------------------------------------------------- the spec


def test_grid_and_lists_and_single_values():
    axes = parse_vary("lead_decel=0.5:1.5:5,gap=0.6:1.2:4,noise=0/1/2,ego_speed=-1")
    assert [a.name for a in axes] == ["lead_decel", "gap", "noise", "ego_speed"]
    assert axes[0].values == (0.5, 0.75, 1.0, 1.25, 1.5)
    assert axes[1].values == (0.6, 0.8, 1.0, 1.2)  # 10 significant digits, no 0.7999999
    assert axes[2].values == (0.0, 1.0, 2.0) and axes[3].values == (-1.0,)
    grid = variations(axes)
    assert len(grid) == 5 * 4 * 3 and grid[0] == {"lead_decel": 0.5, "gap": 0.6, "noise": 0.0,
                                                  "ego_speed": -1.0}
    assert label(grid[0]) == "lead_decel=0.5 gap=0.6 noise=0 ego_speed=-1"
    assert label({}) == "recorded"


def test_random_sampling_is_seeded_and_within_range():
    axes = parse_vary("lead_decel=0.5:2,cut_in=-1/0/1", random=True)
    a = variations(axes, samples=50, seed=3)
    assert a == variations(axes, samples=50, seed=3) and a != variations(axes, 50, seed=4)
    assert all(0.5 <= d["lead_decel"] <= 2.0 and d["cut_in"] in (-1.0, 0.0, 1.0) for d in a)


@pytest.mark.parametrize("text", [
    "", "lead_decel", "lead_decel=", "=1", "speed=1", "gap=1,gap=2", "gap=a:b:3", "gap=0.5:1",
    "gap=0.5:1:x", "gap=1:2:3:4",
])
def test_malformed_specs_are_format_errors(text):
    with pytest.raises(FormatError):
        parse_vary(text)


@pytest.mark.parametrize("text", [
    "gap=1:0.5:3", "gap=0.5:1:1", "gap=0.5:1:0", "noise=-0.5", "gap=nan", "gap=inf",
    f"gap=1:2:{MAX_GRID + 1}",
])
def test_impossible_ranges_counts_and_values_are_refused(text):
    with pytest.raises(ImpossibleValueError):
        parse_vary(text)


@given(st.text(alphabet="lead_cgpnoisezt=:,./-0123456789 ", max_size=40))
def test_any_spec_parses_or_is_an_input_error(text):
    try:
        axes = parse_vary(text)
    except InputError:
        return
    for a in axes:
        assert a.name in PARAMETERS and a.values and all(np.isfinite(a.values))


@given(st.dictionaries(st.sampled_from(sorted(PARAMETERS)),
                       st.tuples(st.floats(0.01, 5.0), st.floats(0.0, 5.0),
                                 st.integers(2, 6)), min_size=1))
def test_grid_specs_round_trip(spec):
    text = ",".join(f"{k}={lo!r}:{lo + span!r}:{n}" for k, (lo, span, n) in spec.items())
    axes = parse_vary(text)
    assert len(variations(axes)) == int(np.prod([n for _, _, n in spec.values()]))
    for a in axes:
        lo, span, n = spec[a.name]
        assert len(a.values) == n
        assert a.values[0] == pytest.approx(lo) and a.values[-1] == pytest.approx(lo + span)


# --------------------------------------------------------------------------- transforms


def test_scale_deceleration_known_answer():
    t = np.round(np.arange(0.0, 10.0 + 1e-9, 0.1), 6)
    # 20 m/s, brakes at 2 m/s^2 between 2 s and 6 s (down to 12 m/s), then holds
    v = np.clip(20.0 - 2.0 * np.clip(t - 2.0, 0.0, 4.0), 0, None)
    s = np.r_[0.0, np.cumsum(0.5 * (v[1:] + v[:-1]) * 0.1)]
    tr = _straight(t, s, v)
    assert scale_deceleration(tr, 1.0) is tr
    doubled = scale_deceleration(tr, 2.0)
    # 4 m/s^2 for 4 s: 20 -> 4 m/s (the 1 s average blurs the corners: +-0.5 s)
    assert doubled.speed[-1] == pytest.approx(4.0, abs=0.05)
    assert doubled.speed[40] == pytest.approx(20.0 - 4.0 * 2.0, abs=0.5)
    tripled = scale_deceleration(tr, 3.0)  # 6 m/s^2: stops after 3.3 s and stays stopped
    assert tripled.speed[-1] == 0.0 and np.all(tripled.speed >= 0.0)
    assert tripled.x[-1] == pytest.approx(tripled.x[-20])
    later = scale_deceleration(tr, 2.0, from_t_s=4.0)  # as recorded until 4 s
    np.testing.assert_allclose(later.speed[:35], v[:35], atol=1e-9)
    assert later.speed[-1] == pytest.approx(8.0, abs=0.5)


def test_shift_and_speed_offset_known_answers():
    t = np.round(np.arange(0.0, 5.0 + 1e-9, 0.1), 6)
    tr = _straight(t, 10.0 + 8.0 * t, np.full_like(t, 8.0))
    np.testing.assert_allclose(shift_along(tr, 5.0).x, tr.x + 5.0)
    np.testing.assert_allclose(shift_along(tr, -15.0).x, tr.x - 15.0)  # before its start
    fast = offset_speed(tr, 2.0)
    np.testing.assert_allclose(fast.x, 10.0 + 10.0 * t)  # past its end, straight on
    np.testing.assert_allclose(fast.speed, 10.0)


def test_cut_in_shift_delays_the_lateral_motion():
    sc = straight_scenario(duration_s=10.0)
    path = ReplayEnv(sc, ego_mode="log").path
    t = np.round(np.arange(0.0, 10.0 + 1e-9, 0.1), 6)
    y = np.clip((t - 3.0) / 3.0, 0.0, 1.0) * -3.5 + 1.75  # left lane -> right lane, 3-6 s
    tr = Trajectory(t, 30.0 + 12.0 * t, y, np.zeros_like(t), np.full_like(t, 12.0))
    late = shift_cut_in(tr, 1.0, path)
    np.testing.assert_allclose(late.x, tr.x, atol=1e-6)  # the motion along the path is kept
    np.testing.assert_allclose(late.y[10:], y[:-10], atol=1e-6)  # one second later
    assert shift_cut_in(tr, 0.0, path) is tr


# --------------------------------------------------------------------------- on scenarios


def test_roles_and_gap_scaling_on_the_braking_lead_scenario():
    sc = braking_lead_scenario()
    roles = find_roles(sc)
    assert roles.lead_id == "lead" and roles.lead_first_t_s == 0.0
    assert roles.lead_first_gap_m == pytest.approx(BRAKING_LEAD["lead_ahead_m"] - 4.45, abs=0.05)
    assert roles.cut_in_id is None
    varied, reason = apply_variation(sc, {"gap": 0.5}, roles)
    assert reason == ""
    assert find_roles(varied).lead_first_gap_m == pytest.approx(0.5 * roles.lead_first_gap_m,
                                                                abs=0.05)
    assert "variation: lead lead initial gap x0.5" in varied.source.assumptions
    same, _ = apply_variation(sc, {"gap": 1.0, "lead_decel": 1.0, "noise": 2.0}, roles)
    np.testing.assert_array_equal(same.actors[0].trajectory.x, sc.actors[0].trajectory.x)


def test_impossible_variants_are_skipped_with_a_reason():
    sc = braking_lead_scenario()
    roles = find_roles(sc)
    varied, reason = apply_variation(sc, {"ego_speed": -15.0}, roles)
    assert varied is None and reason.startswith("negative ego speed")
    varied, reason = apply_variation(sc, {"gap": 0.0}, roles)
    assert varied is None and reason == "initial gap of 0.0 m (scale 0)"
    varied, reason = apply_variation(sc, {"lead_decel": -0.5}, roles)
    assert varied is None and reason.startswith("negative deceleration scale")
    # a car 10 m ahead of the lead (centre to centre, 5.6 m apart): 10 % more initial gap
    # moves the lead 2.6 m on, 30 % 7.7 m, into it
    front = replace(sc.actors[0], id="front",
                    trajectory=shift_along(sc.actors[0].trajectory, 10.0))
    crowded = replace(sc, actors=[*sc.actors, front])
    assert apply_variation(crowded, {"gap": 1.1}, roles)[1] == ""
    varied, reason = apply_variation(crowded, {"gap": 1.3}, roles)
    assert varied is None and reason == "vehicles lead and front overlap at t=0.0 s"
    varied, reason = apply_variation(sc, {"cut_in": 1.0}, roles)
    assert varied is None and reason == "no cut-in in the log"


@given(st.floats(-50.0, 50.0), st.floats(1.0, 20.0))
def test_shifting_along_the_path_is_reversible(shift, speed):
    from vid2sim.samples.scenarios import left_turn_centerline, trajectory_along

    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.1), 6)
    tr = trajectory_along(left_turn_centerline(), 20.0 + speed * t, t)
    back = shift_along(shift_along(tr, shift), -shift)
    # exact where both shifts stay on the recorded path (beyond it, straight extrapolation
    # from a curve's end is not the curve)
    s = np.r_[0.0, np.cumsum(np.hypot(np.diff(tr.x), np.diff(tr.y)))]
    inside = (s - abs(shift) >= 0.0) & (s + abs(shift) <= s[-1])
    np.testing.assert_allclose(back.x[inside], tr.x[inside], atol=0.05)
    np.testing.assert_allclose(back.y[inside], tr.y[inside], atol=0.05)
    moved = shift_along(tr, shift)  # every point moved by |shift| along the path or less
    assert np.all(np.hypot(moved.x - tr.x, moved.y - tr.y) <= abs(shift) + 1e-6)
