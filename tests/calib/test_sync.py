"""The GPS clock is found from the motion's profile, or said to be unobservable."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vid2sim.calib.sync import estimate_time_offset


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
    out = estimate_time_offset(t, t + 0.1, speed, yaw, gps_t, _speed(gps_t + offset),
                               _heading(gps_t + offset))
    assert out.observable, out.reason
    assert abs(out.offset_s - offset) < 0.1
    assert 0.0 < out.std_s < 0.3
    assert abs(out.offset_s - offset) < 4 * out.std_s + 0.02


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
