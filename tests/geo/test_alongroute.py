"""The along-route smoother: known answers (constant speed, gaps, outliers, standing still)
and its statistics on noisy positions."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.geo.alongroute import rts_along


def test_noiseless_constant_speed_is_kept():
    t = np.arange(0.0, 60.0, 1.0)
    s = 11.0 * t + 5.0
    out, used = rts_along(t, s, np.full(t.size, 3.0), 1.5, return_accepted=True)
    # the filter starts at rest (velocity prior 0 +- 15 m/s): a few centimetres at first
    np.testing.assert_allclose(out[:5], s[:5], atol=0.1)
    np.testing.assert_allclose(out[5:], s[5:], atol=0.02)
    assert used.all()


def test_gaps_are_bridged_and_outliers_rejected():
    t = np.arange(0.0, 60.0, 1.0)
    s = 8.0 * t
    meas = s.copy()
    meas[20:30] = np.nan       # a tunnel
    meas[45] += 300.0          # one fix 300 m off along the route
    out, used = rts_along(t, meas, np.full(t.size, 3.0), 1.5, return_accepted=True)
    np.testing.assert_allclose(out[5:], s[5:], atol=0.02)  # straight through the tunnel
    assert not used[45] and not used[20:30].any() and used[:20].all()


@settings(max_examples=30, deadline=None)
@given(speed=st.floats(0.0, 25.0), seed=st.integers(0, 1000), rate=st.sampled_from([1.0, 10.0]))
def test_smoothing_reduces_the_noise(speed, seed, rate):
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 120.0, 1.0 / rate)
    truth = speed * t
    meas = truth + rng.normal(0.0, 5.0, t.size)
    out = rts_along(t, meas, np.full(t.size, 5.0), 1.5)
    inner = slice(t.size // 10, -t.size // 10)  # away from the ends
    assert np.sqrt(np.mean((out - truth)[inner] ** 2)) < 0.6 * 5.0
    assert out.shape == t.shape and np.isfinite(out).all()


def test_standing_still_is_steadier_than_the_fixes():
    t = np.arange(0.0, 40.0, 1.0)
    meas = np.full(t.size, 100.0) + np.random.default_rng(3).normal(0.0, 4.0, t.size)
    out = rts_along(t, meas, np.full(t.size, 4.0), 1.5)
    # the model lets the car accelerate (1.5 m/s^2): it wanders, but less than the fixes
    assert np.sqrt(np.mean((out - 100.0) ** 2)) < 0.75 * np.sqrt(np.mean((meas - 100.0) ** 2))
    assert abs(out.mean() - 100.0) < 2.0
    with pytest.raises(IndexError):
        rts_along(t, np.full(t.size, np.nan), np.full(t.size, 4.0), 1.5)  # nothing measured
