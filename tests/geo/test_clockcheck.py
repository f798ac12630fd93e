"""GPS clock integrity: late records are sorted in, a clock that jumps is re-timed from the
positions, one fix per time stamp, and a trace no reading makes consistent is refused; the
smoothed ego never drives faster than the fixes themselves say."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from vid2sim.base.errors import InconsistentInputError
from vid2sim.cli import main
from vid2sim.geo.clockcheck import local_xy, repair_clock
from vid2sim.geo.readers import read_gps
from vid2sim.geo.trace import smooth_ego

LAT0, LON0 = 60.17, 24.94


def _drive(n: int, speed: float, rate_hz: float, noise_m: float, seed: int = 0):
    """Fixes of a straight eastward drive: times [s] and flat positions [m]."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / rate_hz
    xy = np.column_stack([speed * t, np.zeros(n)]) + rng.normal(0.0, noise_m, (n, 2))
    return t, xy


def _csv(path, t, xy):
    lat = LAT0 + xy[:, 1] / 111_320.0
    lon = LON0 + xy[:, 0] / (111_320.0 * math.cos(math.radians(LAT0)))
    rows = "\n".join(f"{1.7e9 + a:.3f},{b:.8f},{c:.8f}" for a, b, c in zip(t, lat, lon,
                                                                       strict=True))
    path.write_text("t,lat,lon\n" + rows + "\n")
    return path


def _max_ego_speed(path) -> float:
    ego, _ = smooth_ego(read_gps(path))
    return float(ego.speed_mps.max())


# --------------------------------------------------------------------------- known answers


def test_a_clock_jumping_back_is_retimed_to_follow_the_fix_before():
    t, xy = _drive(120, 11.0, 1.0, 3.0)
    stamped = t.copy()
    stamped[60:] -= 6.0  # the receiver clock steps back 6 s; the car drives on
    rep = repair_clock(stamped, xy)
    np.testing.assert_array_equal(rep.keep, np.arange(120))  # file order kept
    np.testing.assert_allclose(rep.t_s, t)  # one interval after fix 60, as driven
    (w,) = rep.warnings
    assert "back 6.0 s at fix 61" in w and "fixes 61-120" in w


def test_a_clock_jumping_forward_while_driving_is_retimed():
    t, xy = _drive(120, 11.0, 1.0, 3.0, seed=1)
    stamped = t.copy()
    stamped[60:] += 60.0  # 11 m between two fixes 61 s apart: no room to stop and go
    rep = repair_clock(stamped, xy)
    assert np.diff(rep.t_s).max() < 2.0
    assert rep.t_s[-1] - rep.t_s[0] == pytest.approx(119.0, abs=1.0)
    assert "forward" in rep.warnings[0] and "fix 61" in rep.warnings[0]


def test_a_real_stop_without_fixes_is_left_a_gap():
    """Before and after the gap the car is slow and the fixes lie far enough apart for a
    stop: nothing says the clock is wrong."""
    t, xy = _drive(100, 4.0, 1.0, 1.0, seed=2)
    stamped = t.copy()
    stamped[50:] += 40.0
    rep = repair_clock(stamped, xy)
    np.testing.assert_allclose(rep.t_s, stamped)
    assert not rep.warnings


def test_records_written_late_are_sorted_in():
    t, xy = _drive(80, 11.0, 1.0, 3.0, seed=3)
    order = np.arange(80)
    order[[40, 41, 42]] = [42, 40, 41]  # the fix of t = 42 written before those of 40, 41
    rep = repair_clock(t[order], xy[order])
    np.testing.assert_allclose(rep.t_s, t)
    np.testing.assert_array_equal(order[rep.keep], np.arange(80))
    assert "fixes 42, 43" in rep.warnings[0] and "sorted" in rep.warnings[0]


def test_one_time_at_two_places_keeps_the_fix_between_its_neighbours():
    t, xy = _drive(40, 11.0, 1.0, 0.5, seed=4)
    t = np.insert(t, 20, t[20])
    xy = np.insert(xy, 20, xy[20] + [0.0, 60.0], axis=0)  # the same time, 60 m off the road
    rep = repair_clock(t, xy)
    assert 20 not in rep.keep and 21 in rep.keep
    assert np.all(np.diff(rep.t_s) > 0)
    assert "fixes 21, 22 carry the same time" in rep.warnings[0]


def test_a_jump_to_another_place_and_time_is_refused():
    t, xy = _drive(120, 11.0, 1.0, 3.0, seed=5)
    t[60:] -= 6.0
    xy[60:] += [900.0, 0.0]  # 900 m away at an earlier time: no drive of these fixes
    with pytest.raises(InconsistentInputError, match="fix 61"):
        repair_clock(t, xy)


def test_a_car_standing_still_is_never_set_moving():
    t, xy = _drive(60, 0.0, 1.0, 3.0, seed=6)
    t[30:] -= 5.0
    rep = repair_clock(t, xy)
    assert np.all(np.diff(rep.t_s) > 0)
    assert rep.t_s[-1] - rep.t_s[0] <= 59.0


def test_local_xy_known_answer():
    xy = local_xy(np.array([60.0, 60.001]), np.array([25.0, 25.002]))
    np.testing.assert_allclose(xy[1], [0.002 * 111_320.0 * 0.5, 0.001 * 111_320.0], rtol=1e-9)


# --------------------------------------------------------------------------- properties


@settings(max_examples=30, deadline=None)
@given(speed=st.floats(6.0, 30.0), jump=st.floats(-30.0, -1.5), at=st.integers(15, 85),
       noise=st.floats(0.0, 5.0), seed=st.integers(0, 1000))
def test_a_clock_jumping_back_never_invents_speed(tmp_path_factory, speed, jump, at, noise,
                                                 seed):
    t, xy = _drive(100, speed, 1.0, noise, seed)
    folder = tmp_path_factory.mktemp("clock")
    own = _max_ego_speed(_csv(folder / "true.csv", t, xy))  # the fixes on a true clock
    t[at:] += jump
    try:
        v = _max_ego_speed(_csv(folder / "g.csv", t, xy))
    except InconsistentInputError:
        return  # refusing is allowed; inventing motion is not
    assert v <= 1.5 * max(speed, own)


@settings(max_examples=20, deadline=None)
@given(speed=st.floats(3.0, 30.0), jump=st.floats(10.0, 300.0), at=st.integers(15, 85),
       noise=st.floats(0.0, 5.0), seed=st.integers(0, 1000))
def test_a_clock_jumping_forward_never_invents_speed(tmp_path_factory, speed, jump, at, noise,
                                                    seed):
    """Re-timed where the car cannot have stopped, else a gap (bridged at constant speed
    beyond ``segment_gap_s``): never faster than the car drove. (Shorter gaps are the
    smoother's to interpolate, clock or not.)"""
    t, xy = _drive(100, speed, 1.0, noise, seed)
    folder = tmp_path_factory.mktemp("clock")
    own = _max_ego_speed(_csv(folder / "true.csv", t, xy))  # the fixes on a true clock
    t[at:] += jump
    assert _max_ego_speed(_csv(folder / "g.csv", t, xy)) <= 1.5 * max(speed, own)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 10_000), speed=st.floats(0.0, 25.0),
       rate=st.sampled_from([1.0, 10.0]))
@example(seed=291, speed=25.0, rate=1.0)  # two swaps in 8 fixes: steps of 2 intervals
@example(seed=2511, speed=0.5, rate=1.0)  # three swaps in 13 fixes
def test_records_a_few_places_out_of_order_are_put_back(seed, speed, rate):
    rng = np.random.default_rng(seed)
    t, xy = _drive(60, speed, rate, 2.0, seed)
    order = np.arange(60)
    for start in rng.choice(np.arange(2, 56, 4), 3, replace=False):
        order[start:start + 3] = rng.permutation(order[start:start + 3])
    rep = repair_clock(t[order], xy[order])
    np.testing.assert_allclose(rep.t_s, t)  # no time changed, none dropped


# --------------------------------------------------------------------------- the CLI


def test_trace_with_a_clock_jump_writes_a_warning_and_true_speeds(tmp_path, capsys):
    t, xy = _drive(120, 11.0, 1.0, 5.0, seed=7)
    t[60:] -= 6.0
    gps = _csv(tmp_path / "jump.csv", t, xy)
    out = tmp_path / "ego.csv"
    assert main(["trace", str(gps), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "warning:" in text and "re-timed" in text
    speed = np.loadtxt(out, delimiter=",", skiprows=1, usecols=6)
    assert speed.max() <= 1.5 * 11.0


def test_trace_no_reading_makes_consistent_is_exit_2_nothing_written(tmp_path, capsys):
    t, xy = _drive(120, 11.0, 1.0, 3.0, seed=8)
    t[60:] -= 6.0
    xy[60:] += [900.0, 0.0]
    gps = _csv(tmp_path / "two.csv", t, xy)
    out = tmp_path / "ego.csv"
    assert main(["trace", str(gps), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:")
    assert not out.exists()
