"""Known answers and properties of the lane-marking geometry (vid2sim.detect.lanes.geometry)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from tests.detect.lanes.lane_frames import DASHCAM, KITTI_CAM
from vid2sim.core.records import LaneBoundary, LaneObservation, MarkingKind
from vid2sim.detect.lanes.geometry import (
    BevGrid,
    fit_line,
    fit_lines,
    fit_parallel_lines,
    ground_to_pixel_maps,
    hough_lines,
    pattern_kind,
    pick_ego_lane,
    ridge_response,
    weighted_median,
    with_yaw_correction,
)

LOOSE = {"curvature_prior_inv_m": 1e6}  # priors that do not bite: exact recovery
X = np.linspace(3.0, 35.0, 129)


@given(c0=st.floats(-6, 6), c1=st.floats(-0.2, 0.2), c2=st.floats(-0.02, 0.02),
       n=st.integers(4, 60), seed=st.integers(0, 1000))
def test_fit_line_recovers_exact_coefficients(c0, c1, c2, n, seed):
    x = np.sort(np.random.default_rng(seed).uniform(3.0, 35.0, n))
    assume(np.ptp(x) > 5.0)
    y = c0 + c1 * x + 0.5 * c2 * x * x
    coef, cov = fit_line(x, y, np.ones(n), **LOOSE)
    np.testing.assert_allclose(coef, [c0, c1, c2], atol=1e-6)
    assert np.all(np.linalg.eigvalsh(cov) > 0)


def test_fit_lines_batches_match_single_fits_and_empty_lines_stay_finite():
    rng = np.random.default_rng(1)
    y = np.stack([0.5 + 0.01 * X, -2.0 - 0.02 * X + 1e-3 * X * X]) + rng.normal(0, 0.02, (2, 129))
    w = np.ones((3, 129))
    w[2] = 0.0  # a line without points
    coef, _ = fit_lines(X, np.vstack((y, np.zeros(129))), w)
    for k in range(2):
        single, _ = fit_line(X, y[k], w[k])
        np.testing.assert_allclose(coef[k], single, atol=1e-9)
    assert np.isfinite(coef[2]).all()


def test_curvature_prior_keeps_a_short_straight_piece_straight():
    x = np.linspace(10.0, 13.0, 6)
    y = 1.0 + np.random.default_rng(2).normal(0.0, 0.03, 6)
    coef, _ = fit_line(x, y, np.ones(6), curvature_prior_inv_m=0.01)
    assert abs(coef[2]) < 0.01


@given(offsets=st.lists(st.floats(-8, 8), min_size=1, max_size=4, unique=True),
       c1=st.floats(-0.15, 0.15), c2=st.floats(-0.01, 0.01), c3=st.floats(-4e-4, 4e-4),
       b=st.floats(-0.01, 0.01), seed=st.integers(0, 1000))
def test_parallel_fit_recovers_offsets_and_the_shared_shape(offsets, c1, c2, c3, b, seed):
    o = np.array(offsets)
    assume(len(o) == 1 or np.min(np.diff(np.sort(o))) > 0.5)
    y = (o[:, None] + (c1 + b * o[:, None]) * X + 0.5 * c2 * X * X + c3 * X ** 3 / 6.0)
    w = (np.random.default_rng(seed).random((len(o), 129)) < 0.6).astype(float)
    w[:, :10] = 1.0  # every line seen somewhere near
    coef, std = fit_parallel_lines(X, y, w, o, curvature_prior_inv_m=1e6,
                                   curvature_rate_prior_inv_m2=1e6,
                                   pitch_bias_prior_inv_m=1e6 if len(o) > 1 else 1e-9)
    np.testing.assert_allclose(coef[:, 0], o, atol=1e-5)
    b_fit = b if len(o) > 1 else 0.0  # one line cannot tell b from c1
    np.testing.assert_allclose(coef[:, 1], c1 + b_fit * o + (b - b_fit) * o, atol=1e-6)
    np.testing.assert_allclose(coef[:, 2], c2, atol=1e-7)
    np.testing.assert_allclose(coef[:, 3], c3, atol=1e-8)
    assert np.all(std > 0)


def test_parallel_fit_lends_the_solid_lines_direction_to_a_dashed_one():
    rng = np.random.default_rng(3)
    o = np.array([1.7, -1.8])
    truth = o[:, None] + 0.02 * X[None, :]
    y = truth + rng.normal(0.0, 0.05, truth.shape)
    w = np.ones_like(y)
    w[0] = 0.0
    w[0, 40:52] = 1.0  # two short dashes far away
    w[0, 88:100] = 1.0
    alone, _ = fit_line(X, y[0], w[0])
    joint, _ = fit_parallel_lines(X, y, w, o)
    assert abs(joint[0, 0] - 1.7) < abs(alone[0] - 1.7)
    # With the pitch term held at zero the dashed line takes the solid one's direction.
    held, _ = fit_parallel_lines(X, y, w, o, pitch_bias_prior_inv_m=1e-9)
    assert held[0, 1] == pytest.approx(held[1, 1], abs=1e-9)
    assert held[0, 0] == pytest.approx(1.7, abs=0.05)


@given(a=st.floats(-8, 8), h=st.floats(-0.18, 0.18))
def test_hough_peak_is_at_the_line(a, h):
    x = np.arange(4.0, 20.0, 0.25)
    y = a + h * (x - 11.5)
    acc, headings, offsets = hough_lines(x, y, np.ones_like(x), x_ref_m=11.5,
                                         max_heading_rad=0.21, heading_step_rad=0.0105,
                                         half_width_m=10.0, offset_bin_m=0.1)
    i, j = np.unravel_index(np.argmax(acc), acc.shape)
    # within one and a half heading bins: a tilted line's votes spread over neighbouring
    # 0.1 m offset bins, which can tip the peak to the next heading (a=-0.25, h=0.1055)
    assert abs(headings[i] - h) <= 1.5 * 0.0105
    assert abs(offsets[j] - a) <= 0.15


def test_hough_of_nothing_is_empty():
    acc, headings, offsets = hough_lines(np.zeros(0), np.zeros(0), np.zeros(0), x_ref_m=10.0,
                                         max_heading_rad=0.2, heading_step_rad=0.01,
                                         half_width_m=5.0, offset_bin_m=0.1)
    assert acc.shape == (len(headings), len(offsets)) and acc.sum() == 0


@given(dash=st.floats(1.0, 6.0), gap_factor=st.floats(1.5, 4.0), phase=st.floats(0, 1),
       length=st.floats(20.0, 40.0))
def test_dash_patterns_are_dashed(dash, gap_factor, phase, length):
    step = 0.25
    gap = max(1.5, dash * gap_factor)
    assume(length >= 2 * (dash + gap))
    x = np.arange(0.0, length, step)
    painted = np.mod(x + phase * (dash + gap), dash + gap) < dash
    assert pattern_kind(painted, step) is MarkingKind.DASHED


@given(holes=st.lists(st.integers(0, 119), max_size=5))
def test_continuous_paint_with_a_few_worn_spots_is_solid(holes):
    painted = np.ones(120, bool)
    painted[holes] = False
    assert pattern_kind(painted, 0.25) is MarkingKind.SOLID


def test_too_little_paint_is_unknown():
    painted = np.zeros(120, bool)
    painted[10:14] = True  # 1 m
    assert pattern_kind(painted, 0.25) is MarkingKind.UNKNOWN
    assert pattern_kind(np.zeros(0, bool), 0.25) is MarkingKind.UNKNOWN


def _line(offset: float, kind: str = "solid", confidence: float = 0.9) -> LaneBoundary:
    return LaneBoundary(offset, 0.0, 0.0, kind, confidence)


@given(offsets=st.lists(st.floats(-9, 9), max_size=7, unique=True),
       confs=st.lists(st.floats(0, 1), min_size=7, max_size=7))
def test_pick_ego_lane_invariants(offsets, confs):
    lines = [_line(o, confidence=c) for o, c in zip(offsets, confs, strict=False)]
    left, right, fl, fr = pick_ego_lane(lines)
    if left is not None:
        assert 0 < left.offset_m <= 4.0 and left.confidence >= 0.3
        assert all(ln.offset_m > left.offset_m for ln in fl)
    if right is not None:
        assert -4.0 <= right.offset_m <= 0 and right.confidence >= 0.3
        assert all(ln.offset_m < right.offset_m for ln in fr)
    if left is not None and right is not None:
        assert 2.2 <= left.offset_m - right.offset_m <= 4.5
    picked = [ln for ln in (left, right) if ln is not None] + list(fl) + list(fr)
    assert len({id(ln) for ln in picked}) == len(picked)
    assert all(ln in lines for ln in picked)


def test_pick_ego_lane_nearest_lines_and_the_road_edge_ends_the_road():
    lines = [_line(1.6, "dashed"), _line(-1.9), _line(5.0), _line(-3.4, "road_edge"),
             _line(-5.0), _line(0.4, confidence=0.1)]
    left, right, fl, fr = pick_ego_lane(lines)
    assert left.offset_m == 1.6 and right.offset_m == -1.9  # the faint streak is ignored
    assert [ln.offset_m for ln in fl] == [5.0]
    assert [ln.offset_m for ln in fr] == [-3.4]  # nothing beyond the road's edge
    # An implausible pair (6 m): the less confident side is dropped.
    left, right, _, _ = pick_ego_lane([_line(3.0, confidence=0.5), _line(-3.0)])
    assert left is None and right.offset_m == -3.0


@pytest.mark.parametrize("camera", [KITTI_CAM, DASHCAM])
def test_ground_maps_round_trip_through_the_camera(camera):
    grid = BevGrid.make(8.0, 4.0, 30.0, 0.5, 1.0)
    map_u, map_v = ground_to_pixel_maps(camera, grid)
    pix = np.column_stack((map_u.ravel(), map_v.ravel())).astype(float)
    ground, ok = camera.pixel_to_ground(pix)
    xx, yy = np.meshgrid(grid.x_m, grid.y_m, indexing="ij")
    assert ok.all()
    np.testing.assert_allclose(ground[:, 0], xx.ravel(), rtol=1e-4)
    np.testing.assert_allclose(ground[:, 1], yy.ravel(), atol=1e-3)


@given(half=st.floats(2, 12), step=st.sampled_from([0.05, 0.1, 0.25]))
def test_grid_columns_and_offsets_agree(half, step):
    grid = BevGrid.make(half, 3.0, 30.0, step, 0.25)
    cols = grid.column_of(grid.y_m)
    np.testing.assert_allclose(cols, np.arange(len(grid.y_m)), atol=1e-9)
    assert grid.x_m[0] == pytest.approx(30.0) and grid.x_m[-1] == pytest.approx(3.0)


def test_ridge_answers_a_stripe_not_a_step():
    img = np.full((20, 120), 80.0, np.float32)
    img[:, 40:43] = 200.0  # a 15 cm stripe at 5 cm per column
    img[:, 90:] = 160.0  # a step (a shadow's edge)
    r = ridge_response(img, 5)
    assert r[10, 41] > 0.5
    assert r[10, 85:95].max() < 0.05


@given(delta=st.floats(-0.1, 0.1))
def test_yaw_correction_turns_every_line(delta):
    obs = LaneObservation(frame=0, t_s=0.0, left=_line(1.5), right=_line(-1.8),
                          lines_left=(_line(5.0),), lines_right=(_line(-5.2),))
    turned = with_yaw_correction(obs, delta)
    for ln in (turned.left, turned.right, *turned.lines_left, *turned.lines_right):
        assert ln.heading_rad == pytest.approx(delta)
    assert with_yaw_correction(obs, 0.0) is obs


def test_weighted_median():
    assert weighted_median(np.array([1.0, 2.0, 3.0]), np.array([1.0, 1.0, 5.0])) == 3.0
    assert weighted_median(np.array([5.0]), np.array([0.1])) == 5.0


@given(c0=st.floats(-3, 3), c1=st.floats(-0.1, 0.1), c2=st.floats(-0.01, 0.01),
       c3=st.floats(-1e-4, 1e-4), x=st.floats(0, 40))
def test_boundary_y_at_is_the_clothoid(c0, c1, c2, c3, x):
    ln = LaneBoundary(c0, c1, c2, curvature_rate_inv_m2=c3)
    assert ln.y_at(x) == pytest.approx(c0 + c1 * x + c2 * x * x / 2 + c3 * x ** 3 / 6,
                                       abs=1e-9)
    assert math.isfinite(ln.y_at(x))
