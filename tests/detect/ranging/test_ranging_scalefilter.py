"""The range filter that fuses the box's scale change: known answers on generated
measurements, then the pitch it does not care about."""

from __future__ import annotations

import numpy as np
import pytest

from tests.detect.ranging.test_ranging_outline import KITTI
from vid2sim.core.outline import project_outline
from vid2sim.core.records import TrackedBox
from vid2sim.detect.ranging import RangingConfig, range_tracks
from vid2sim.detect.ranging.scalefilter import (
    RangeMeasurements,
    filter_range,
    filter_range_adaptive,
    log_width_var,
    rigid_scale_breaks,
)
from vid2sim.detect.ranging.smoother import _kf_rts_cv

F_PX, D_M = 1000.0, 0.8
GRID = (0.05, 0.15, 0.4, 1.0, 2.5, 6.0)


def _meas(t, abs_m, abs_sd, log_w, log_w_sd, width_prior, width_prior_sd, lin_x):
    """Measurements with the exact width law ln w = ln(f W) - ln(Z + d), linearised at
    ``lin_x`` with the prior width."""
    n = t.size
    nan = np.full(n, np.nan)
    a = np.log(F_PX * width_prior / (lin_x + D_M))
    return RangeMeasurements(
        t_s=t, abs_m=nan if abs_m is None else abs_m,
        abs_var_m2=np.full(n, np.nan) if abs_sd is None else np.broadcast_to(abs_sd ** 2, (n,)),
        log_w=nan if log_w is None else log_w, log_w_var=np.full(n, log_w_sd ** 2),
        lin_x_m=lin_x, lin_c=np.full(n, np.log(width_prior)), lin_a=a,
        lin_b=-1.0 / (lin_x + D_M), lin_e=np.ones(n),
        start_m=float(lin_x[0]), log_width_prior=float(np.log(width_prior)),
        log_width_prior_var=float((width_prior_sd / width_prior) ** 2))


def test_absolute_cue_alone_is_the_constant_velocity_smoother():
    rng = np.random.default_rng(0)
    t = np.arange(100) * 0.1
    z = 35.0 - t + rng.normal(0, 1.1, t.size)
    m = _meas(t, z, 1.1, None, 0.05, 1.75, 0.1, 35.0 - t)
    got = filter_range(m, (0.05,), 8.0, inverse=False)[0]
    x, v, _, ll = _kf_rts_cv(list(t), list(z), [1.21] * t.size, [True] * t.size, 0.05, 8.0)
    np.testing.assert_allclose(got.range_m, x, atol=1e-6)
    np.testing.assert_allclose(got.range_rate_mps, v, atol=1e-6)
    assert got.log_likelihood == pytest.approx(ll, rel=1e-6)


def test_scale_change_gives_the_rate_without_the_width():
    """Only the box width, of a car 12 % wider than the prior believes: the range is 12 %
    off (nothing says how wide it is), the rate right to the same share (a direct measure of
    Z-dot / Z)."""
    rng = np.random.default_rng(1)
    t = np.arange(80) * 0.1
    truth = 30.0 - 2.0 * t
    w_true = 1.75 * 1.12
    log_w = np.log(F_PX * w_true / (truth + D_M)) + rng.normal(0, 0.01, t.size)
    m = _meas(t, None, None, log_w, 0.01, 1.75, 0.01, truth / 1.12)
    fr = filter_range_adaptive(m, GRID, 8.0, 2.0)
    ratio = np.median(fr.range_m / truth)
    assert ratio == pytest.approx(1 / 1.12, rel=0.02)
    assert np.median(fr.range_rate_mps) == pytest.approx(-2.0 / 1.12, abs=0.1)


def test_width_is_learnt_from_the_absolute_cue():
    """Absolute ranges (5 % noise) and box widths of a car 1.95 m wide against a 1.75 m
    prior: the filter learns the width, and range and rate are right."""
    rng = np.random.default_rng(2)
    t = np.arange(120) * 0.1
    truth = 12.0 + 1.5 * t
    log_w = np.log(F_PX * 1.95 / (truth + D_M)) + rng.normal(0, 0.01, t.size)
    abs_m = truth * (1 + rng.normal(0, 0.05, t.size))
    m = _meas(t, abs_m, 0.05 * truth, log_w, 0.01, 1.75, 0.12, abs_m)
    fr = filter_range_adaptive(m, GRID, 8.0, 2.0)
    assert np.exp(np.median(fr.log_width)) == pytest.approx(1.95, rel=0.03)
    assert np.median(np.abs(fr.range_m - truth) / truth) < 0.02
    assert np.sqrt(np.mean((fr.range_rate_mps - 1.5) ** 2)) < 0.15


def test_log_width_variance():
    assert log_width_var(np.array([2.0]), np.array([2.0]), np.array([100.0]))[0] == \
        pytest.approx(8.0 / 1e4)


def test_rate_survives_a_pitch_drift_the_horizon_does_not_see():
    """The camera tips down 0.8 deg over 8 s (load settling) with no lane markings to tell:
    the bottom edge drifts 10 px, the width does not. A lead 14 m ahead closing at 1 m/s keeps
    its rate: the absolute cue's drift goes into the learnt width, not into the rate."""
    rng = np.random.default_rng(4)
    boxes, truth = [], []
    for k in range(80):
        t = k / 10
        cam = KITTI.with_pitch(0.1 * t)
        box = np.array(project_outline(cam, 14.0 - t, 0.2, 1.78, 1.47, 4.3)) + rng.normal(0, 1, 4)
        boxes.append(TrackedBox(k, t, 1, "car", 0.9, *box))
        truth.append(14.0 - t)
    res = range_tracks(boxes, KITTI, config=RangingConfig(per_frame_pitch=False))
    rate = np.array([b.range_rate_mps for b in res.boxes])
    print(f"pitch drift: rate RMSE {np.sqrt(np.mean((rate + 1) ** 2)):.2f} m/s")
    assert np.sqrt(np.mean((rate + 1) ** 2)) < 0.25


def test_a_track_that_takes_up_a_further_object_is_split_where_its_box_shrinks():
    # a tram receding from 60 to 64 m at 1 m/s (box ~ 1 / Z), a one-second gap, then a car
    # at 110 m that the tracker gave the same id: both sides of the box halve at once
    t = np.concatenate((np.arange(40) * 0.1, 5.0 + np.arange(10) * 0.1))
    z = np.concatenate((60.0 + t[:40], 110.0 + np.zeros(10)))
    w = np.where(np.arange(50) < 40, 721.5 * 3.6 / z, 721.5 * 1.8 / z)
    h = np.where(np.arange(50) < 40, 721.5 * 3.5 / z, 721.5 * 1.5 / z)
    whole = np.ones(50, dtype=bool)
    args = (1.0, 0.02, 20.0, 3.0)
    breaks = rigid_scale_breaks(t, w, h, whole, z, *args)
    assert np.flatnonzero(breaks).tolist() == [40]
    # a car pulling away at 15 m/s from 20 m is one vehicle throughout
    t2 = np.arange(30) * 0.1
    z2 = 20.0 + 15.0 * t2
    assert not rigid_scale_breaks(t2, 721.5 * 1.8 / z2, 721.5 * 1.5 / z2, np.ones(30, bool),
                                  z2, *args).any()
    # a box cut by the border is not compared
    whole[40] = False
    assert np.flatnonzero(rigid_scale_breaks(t, w, h, whole, z, *args)).tolist() == [41]
