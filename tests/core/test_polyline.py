"""Signed offsets from a polyline: known answers, and the indexed search against all pairs."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.core import polyline
from vid2sim.core.polyline import resample_polyline, signed_offsets


def test_offsets_of_points_beside_a_straight_line_are_their_distances_left_positive():
    line = np.array([[0.0, 0.0], [100.0, 0.0]])
    s, d = signed_offsets(line, np.array([[10.0, 3.0], [50.0, -2.5], [120.0, 0.0]]))
    np.testing.assert_allclose(s, [10.0, 50.0, 100.0])
    np.testing.assert_allclose(d, [3.0, -2.5, 0.0])


def test_arc_length_runs_round_a_corner():
    line = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])
    s, d = signed_offsets(line, np.array([[11.0, 5.0]]))
    np.testing.assert_allclose(s, [15.0])
    np.testing.assert_allclose(d, [-1.0])  # right of the northward leg


coords = st.floats(-200, 200, allow_nan=False, allow_infinity=False)


@settings(max_examples=60, deadline=None)
@given(line=st.lists(st.tuples(coords, coords), min_size=2, max_size=40),
       pts=st.lists(st.tuples(coords, coords), min_size=1, max_size=60))
def test_the_indexed_search_gives_the_all_pairs_answer(line, pts):
    line, pts = np.array(line, float), np.array(pts, float)
    exact = signed_offsets(line, pts)
    old = polyline.INDEXED_PAIRS
    try:
        polyline.INDEXED_PAIRS = 0
        fast = signed_offsets(line, pts)
    finally:
        polyline.INDEXED_PAIRS = old
    # the same nearest distance; where two segments are equally near the arc lengths may
    # differ, but the line's point at the indexed arc length is that near
    np.testing.assert_allclose(np.abs(fast[1]), np.abs(exact[1]), rtol=1e-9, atol=1e-6)
    steps = np.hypot(*np.diff(line, axis=0).T)
    keep = np.concatenate([[True], steps > 0])
    at = np.concatenate([[0.0], np.cumsum(steps[steps > 0])])
    def gap(s_m):
        foot = np.column_stack([np.interp(s_m, at, line[keep, 0]),
                                np.interp(s_m, at, line[keep, 1])])
        return np.hypot(*(pts - foot).T)

    np.testing.assert_allclose(gap(fast[0]), gap(exact[0]), rtol=1e-9, atol=1e-6)


@pytest.mark.parametrize("length_m", [1500, 6000])
def test_a_long_road_gives_the_same_offsets_indexed(length_m, monkeypatch):
    s = np.linspace(0, length_m, length_m + 1)
    line = np.column_stack([s, 30 * np.sin(s / 200)])
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(0, length_m, 3000), rng.normal(0, 8, 3000)])
    fast = signed_offsets(line, pts)
    monkeypatch.setattr(polyline, "INDEXED_PAIRS", 10**12)
    exact = signed_offsets(line, pts)
    np.testing.assert_array_equal(fast[0], exact[0])
    np.testing.assert_array_equal(fast[1], exact[1])


def test_resampling_keeps_both_ends_and_spacing():
    xy = resample_polyline(np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 0.0], [10.0, 5.0]]), 1.0)
    np.testing.assert_allclose(xy[0], [0, 0])
    np.testing.assert_allclose(xy[-1], [10, 5])
    assert np.all(np.hypot(*np.diff(xy, axis=0).T) <= 1.0 + 1e-9)
