"""The GPS clock is found from the motion's profile, or said to be unobservable."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import settings as hsettings
from hypothesis import strategies as st

from vid2sim.calib.sync import SyncConfig, estimate_time_offset, on_video_clock
from vid2sim.core.records import GpsFix, GpsTrace

OFFSET_ONLY = SyncConfig(max_rate_dev=0.0)


def _speed(t):
    return 11.0 + 2.5 * np.sin(0.45 * t) - 1.5 * (t > 7.0)


def _yaw_rate(t):
    return 0.05 * np.exp(-((t - 5.0) / 1.5) ** 2) - 0.03 * np.exp(-((t - 12.0) / 1.0) ** 2)


def _heading(t):
    grid = np.linspace(-5.0, 30.0, 3501)
    rate = _yaw_rate(grid)
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(grid))))
    return np.interp(t, grid, cum)


@pytest.mark.parametrize("offset", [1.5, -0.7, 3.2])
def test_offset_recovered_from_speed_and_turns(offset):
    rng = np.random.default_rng(0)
    t = np.arange(0.0, 16.0, 0.2)  # pairs on the video clock, 0.1 s each
    speed = 0.8 * _speed(t + 0.05) + rng.normal(0, 0.3, t.size)  # visual: another scale
    yaw = 1.2 * (_heading(t + 0.1) - _heading(t)) + rng.normal(0, 0.0005, t.size)
    gps_t = np.arange(0.0, 14.0, 0.1)  # the GPS starts `offset` s into the video
    gps = (gps_t, _speed(gps_t + offset), _heading(gps_t + offset))
    out = estimate_time_offset(t, t + 0.1, speed, yaw, *gps, config=OFFSET_ONLY)
    assert out.observable, out.reason
    assert abs(out.offset_s - offset) < 0.1
    assert 0.0 < out.std_s < 0.3
    assert abs(out.offset_s - offset) < 4 * out.std_s + 0.02
    assert not out.rate_fitted and out.rate == 1.0
    # with the clock rate free (its truth 1) the offset is less certain, and says so
    free = estimate_time_offset(t, t + 0.1, speed, yaw, *gps)
    assert free.observable, free.reason
    assert abs(free.offset_s - offset) < 0.2
    assert abs(free.offset_s - offset) < 2 * free.std_s + 0.02
    assert free.std_s >= out.std_s
    if free.rate_fitted:
        assert abs(free.rate - 1.0) < 2 * free.rate_std + 0.005


def test_uniform_motion_is_unobservable():
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 12.0, 0.2)
    speed = np.full(t.size, 10.0) + rng.normal(0, 0.3, t.size)
    yaw = rng.normal(0, 0.0005, t.size)
    gps_t = np.arange(0.0, 12.0, 0.1)
    out = estimate_time_offset(t, t + 0.1, speed, yaw, gps_t, np.full(gps_t.size, 10.0),
                               np.zeros(gps_t.size))
    assert not out.observable
    assert "uniform" in out.reason or "alike" in out.reason


def test_too_few_samples():
    out = estimate_time_offset(np.arange(3.0), np.arange(3.0) + 0.1, np.ones(3), np.zeros(3),
                               np.arange(10.0), np.ones(10), np.zeros(10))
    assert not out.observable and math.isinf(out.std_s)


# --------------------------------------------------------------------------- clock rate


def _drive(t, phase):
    """Speed [m/s] and heading [rad] of a drive with features along all of it: a speed
    swing of period 9 s and two turns, 6 s and 20 s in."""
    speed = 12.0 + 3.0 * np.sin(2 * np.pi * t / 9.0 + phase) - 2.0 * (t > 14.0)
    grid = np.linspace(-40.0, 80.0, 12001)
    rate = 0.06 * np.exp(-((grid - 6.0) / 1.2) ** 2) - 0.05 * np.exp(-((grid - 20.0) / 1.0) ** 2)
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (rate[1:] + rate[:-1]) * np.diff(grid))))
    return speed, np.interp(t, grid, cum)


def _profiles(offset, rate, phase, seed, length_s=24.0):
    """Visual pairs on the video clock (another scale each, noise) and the GPS on a clock
    that runs ``rate`` GPS seconds per video second, its first fix ``offset`` s into the
    video: GPS time u is world (video) time offset + u / rate."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, length_s, 0.2)
    v, _h = _drive(t + 0.05, phase)
    _, h_b = _drive(t + 0.1, phase)
    speed = 0.7 * v * rate + rng.normal(0, 0.3, t.size)  # metres per video second
    yaw = 1.3 * (h_b - _drive(t, phase)[1]) + rng.normal(0, 0.0005, t.size)
    gps_t = np.arange(0.0, (length_s - offset) * rate - 0.5, 0.1)
    gv, gh = _drive(offset + gps_t / rate, phase)
    return (t, t + 0.1, speed, yaw, gps_t, gv, gh)


def test_known_offset_and_rate_recovered():
    """KITTI raw's clocks: GPS 1.5 s late, frames captured every 0.10315 s and played at
    0.1 s. One offset cannot absorb the rate; the joint fit recovers both."""
    data = _profiles(1.5, 1.0315, 0.3, seed=2)
    out = estimate_time_offset(*data)
    assert out.observable and out.rate_fitted, out.reason
    assert abs(out.rate - 1.0315) < 0.01
    assert abs(out.rate - 1.0315) < 2 * out.rate_std
    assert abs(out.offset_s - 1.5) < 0.1
    assert abs(out.offset_s - 1.5) < 2 * out.std_s
    alone = estimate_time_offset(*data, config=OFFSET_ONLY)
    assert abs(alone.offset_s - 1.5) > 2 * abs(out.offset_s - 1.5)


@hsettings(max_examples=15)
@given(offset=st.floats(-3.0, 3.0), rate=st.floats(0.965, 1.035), phase=st.floats(0, 6.28),
       seed=st.integers(0, 2 ** 16))
def test_offset_and_rate_within_their_sigmas(offset, rate, phase, seed):
    out = estimate_time_offset(*_profiles(offset, rate, phase, seed))
    assert out.observable, out.reason
    assert abs(out.offset_s - offset) < 2.5 * out.std_s + 0.02
    assert abs(out.offset_s - offset) < 0.25
    if out.rate_fitted:
        assert abs(out.rate - rate) < 2.5 * out.rate_std + 0.005
    else:  # the rate's possible error is in the offset's one-sigma
        assert out.rate == 1.0 and out.rate_std > 0


def test_one_feature_pins_the_offset_but_not_the_rate():
    """One braking on a straight road: one time to line up, not two."""
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 16.0, 0.2)

    def speed(x):
        return 14.0 - 6.0 / (1 + np.exp(-(x - 8.0) / 0.6))

    vis = 0.9 * speed(t + 0.05) + rng.normal(0, 0.3, t.size)
    gps_t = np.arange(0.0, 15.0, 0.1)
    out = estimate_time_offset(t, t + 0.1, vis, rng.normal(0, 0.0005, t.size), gps_t,
                               speed(gps_t + 1.0), np.zeros(gps_t.size))
    alone = estimate_time_offset(t, t + 0.1, vis, rng.normal(0, 0.0005, t.size), gps_t,
                                 speed(gps_t + 1.0), np.zeros(gps_t.size), config=OFFSET_ONLY)
    assert out.observable, out.reason
    assert not out.rate_fitted and "rate not fitted" in out.reason
    assert abs(out.offset_s - 1.0) < 2 * out.std_s
    assert out.std_s > alone.std_s


def test_a_rate_beyond_the_bound_is_not_fitted():
    out = estimate_time_offset(*_profiles(0.5, 1.09, 0.3, seed=4))
    assert not out.rate_fitted


@given(rate=st.floats(0.9, 1.1), times=st.lists(st.floats(0.0, 1e4), min_size=2,
                                                 max_size=20, unique=True))
def test_on_video_clock_retimes_about_the_first_fix(rate, times):
    times = sorted(times)
    fixes = [GpsFix(1.6e9 + u, 48.0, 11.0, speed_mps=10.0 if i % 2 else None)
             for i, u in enumerate(times)]
    out = on_video_clock(GpsTrace(fixes, "csv"), rate)
    assert out.fixes[0].t_utc_s == fixes[0].t_utc_s
    for a, b in zip(fixes, out.fixes):
        assert b.t_utc_s - out.fixes[0].t_utc_s == pytest.approx(
            (a.t_utc_s - fixes[0].t_utc_s) / rate, abs=1e-5)
        assert (b.speed_mps is None) == (a.speed_mps is None)
        if a.speed_mps is not None:  # metres per video second: the distance is the drive's
            assert b.speed_mps == pytest.approx(a.speed_mps * rate)
        assert (b.lat_deg, b.lon_deg) == (a.lat_deg, a.lon_deg)
    assert on_video_clock(GpsTrace(fixes, "csv"), 1.0).fixes == fixes
