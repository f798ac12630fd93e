"""The route mismatch fraction (Newson & Krumm 2009): known answers on straight lines, detours
and piece sequences, properties on random polylines, and the scoring of a real match."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.geo.test_osm import ORIGIN, town_osm  # noqa: F401 - fixture
from vid2sim.geo.mapmatch import match
from vid2sim.geo.matcheval import (
    CORRIDOR_M,
    matched_stretches,
    piece_key,
    rmf_corridor,
    rmf_pieces,
    score_route,
    stretch_xy,
)
from vid2sim.geo.osm import load_network

LINE = np.array([[0.0, 0.0], [1000.0, 0.0]])


# --------------------------------------------------------------------------- known answers


def test_identical_routes_score_zero():
    assert rmf_corridor(LINE, LINE) == 0.0
    assert rmf_pieces(["a", "b"], ["a", "b"], {"a": 10.0, "b": 20.0}) == 0.0


@pytest.mark.parametrize(("offset_m", "expected"), [(0.0, 0.0), (3.0, 0.0), (4.9, 0.0),
                                                     (5.1, 2.0), (10.0, 2.0), (500.0, 2.0)])
def test_parallel_road(offset_m, expected):
    # a parallel road within the corridor is the same road; beyond it, all of both is wrong
    assert rmf_corridor(LINE, LINE + [0.0, offset_m]) == pytest.approx(expected, abs=1e-9)


def test_a_route_that_stops_early_misses_the_rest_less_the_corridor():
    # the corridor's round end reaches 5 m past the matched end
    got = rmf_corridor(LINE, np.array([[0.0, 0.0], [600.0, 0.0]]))
    assert got == pytest.approx((400.0 - CORRIDOR_M) / 1000.0, abs=1e-9)


def test_a_detour_round_a_block():
    # 0..400 on the route, 100 m up, 200 m across, 100 m down, 600..1000 on the route again
    detour = np.array([[0, 0], [400, 0], [400, 100], [600, 100], [600, 0], [1000, 0]], float)
    missed = 200.0 - 2 * CORRIDOR_M          # the skipped 200 m, less the legs' corridors
    extra = 2 * (100.0 - CORRIDOR_M) + 200.0  # the legs outside the true corridor, the top
    assert rmf_corridor(LINE, detour) == pytest.approx((missed + extra) / 1000.0, abs=1e-6)


def test_nothing_matched_misses_everything():
    assert rmf_corridor(LINE, []) == 1.0
    assert rmf_pieces(["a"], [], {"a": 5.0}) == 1.0


def test_broken_match_in_pieces():
    first = np.array([[0.0, 0.0], [300.0, 0.0]])
    last = np.array([[700.0, 0.0], [1000.0, 0.0]])
    assert rmf_corridor(LINE, [first, last]) == pytest.approx((400 - 10) / 1000, abs=1e-9)


def test_pieces_known_answers():
    lengths = {"a": 100.0, "b": 200.0, "c": 300.0, "d": 50.0}
    assert rmf_pieces(["a", "b", "c"], ["a", "b", "d"], lengths) == pytest.approx(350 / 600)
    # a loop driven twice but matched once misses the second pass
    assert rmf_pieces(["a", "b", "a"], ["a", "b"], lengths) == pytest.approx(100 / 400)
    # direction matters: the twin of a piece is another key
    twin = {("w", 1, 2): 80.0, ("w", 2, 1): 80.0}
    assert rmf_pieces([("w", 1, 2)], [("w", 2, 1)], twin) == pytest.approx(2.0)


def test_bad_input_raises():
    with pytest.raises(ValueError, match="corridor"):
        rmf_corridor(LINE, LINE, corridor_m=0.0)
    with pytest.raises(ValueError, match="finite"):
        rmf_corridor(LINE, np.array([[0.0, np.nan], [1.0, 1.0]]))
    with pytest.raises(ValueError, match="length"):
        rmf_pieces(["a"], ["a"], {"a": -1.0})
    with pytest.raises(KeyError):
        rmf_pieces(["a"], ["b"], {"a": 1.0})
    assert rmf_corridor(np.zeros((1, 2)), LINE) == math.inf  # no true route to judge


# --------------------------------------------------------------------------- properties

coord = st.floats(-2000.0, 2000.0, allow_nan=False).map(lambda v: round(v, 2))
polyline = st.lists(st.tuples(coord, coord), min_size=2, max_size=8).map(np.array).filter(
    lambda xy: np.hypot(*np.diff(xy, axis=0).T).sum() > 1.0)


def _length(xy):
    return float(np.hypot(*np.diff(xy, axis=0).T).sum())


@settings(max_examples=80, deadline=None)
@given(route=polyline)
def test_a_route_against_itself_scores_zero(route):
    assert rmf_corridor(route, route) == pytest.approx(0.0, abs=1e-9)
    keys = [f"p{k}" for k in range(len(route) - 1)]
    lengths = dict(zip(keys, np.hypot(*np.diff(route, axis=0).T), strict=True))
    assert rmf_pieces(keys, keys[::-1], lengths) == 0.0  # order does not matter


@settings(max_examples=80, deadline=None)
@given(true=polyline, matched=polyline)
def test_the_mismatch_is_symmetric_in_length(true, matched):
    # missed + extra swaps roles when the routes swap: the numerators are equal
    a = rmf_corridor(true, matched) * _length(true)
    b = rmf_corridor(matched, true) * _length(matched)
    assert a == pytest.approx(b, rel=1e-6, abs=1e-6)
    assert a >= 0.0


@settings(max_examples=80, deadline=None)
@given(true=polyline, matched=polyline)
def test_a_disjoint_route_scores_at_least_one(true, matched):
    far = matched + [1e5, 0.0]  # nowhere near the true route
    got = rmf_corridor(true, far)
    assert got >= 1.0
    assert got == pytest.approx(1.0 + _length(far) / _length(true), rel=1e-9)


@settings(max_examples=80, deadline=None)
@given(route=polyline, angle=st.floats(-math.pi, math.pi), shift=st.floats(0.0, 4.99))
def test_a_shift_inside_the_corridor_costs_nothing(route, angle, shift):
    moved = route + shift * np.array([math.cos(angle), math.sin(angle)])
    assert rmf_corridor(route, moved) == pytest.approx(0.0, abs=1e-6)


@settings(max_examples=60, deadline=None)
@given(true=polyline, matched=polyline, narrow=st.floats(0.5, 5.0), wide=st.floats(5.0, 50.0))
def test_a_wider_corridor_never_scores_worse(true, matched, narrow, wide):
    assert rmf_corridor(true, matched, wide) <= rmf_corridor(true, matched, narrow) + 1e-9


# piece lengths in millimetres: a road piece is never shorter than that (and denormal lengths
# would overflow the ratio)
length_mm = st.floats(0.0, 500.0).map(lambda v: round(v, 3))


@settings(max_examples=80, deadline=None)
@given(lengths=st.lists(length_mm, min_size=1, max_size=10),
       take=st.lists(st.booleans(), min_size=10, max_size=10),
       extra=st.lists(length_mm, max_size=4))
def test_pieces_missed_plus_extra(lengths, take, extra):
    true = [f"t{k}" for k in range(len(lengths))]
    table = dict(zip(true, lengths, strict=True))
    table.update({f"x{k}": v for k, v in enumerate(extra)})
    kept = [k for k, t in zip(true, take, strict=False) if t]
    matched = kept + [f"x{k}" for k in range(len(extra))]
    total = sum(lengths)
    got = rmf_pieces(true, matched, table)
    if total == 0:
        assert got == math.inf
        return
    missed = sum(table[k] for k in true if k not in kept)
    assert got == pytest.approx((missed + sum(extra)) / total, rel=1e-9, abs=1e-12)
    matched_len = sum(table[k] for k in matched)
    if matched_len > 0:  # swapping the routes keeps the numerator
        assert rmf_pieces(matched, true, table) * matched_len == pytest.approx(
            got * total, rel=1e-9, abs=1e-9)


# --------------------------------------------------------------------------- on a match


@pytest.fixture(scope="module")
def town(town_osm):  # noqa: F811 - the imported fixture
    return load_network(town_osm, ORIGIN)


def test_stretch_cuts_the_joined_route(town):
    main = [e for e in range(town.n_edges) if town.edge_way_id[e] in (101, 102)
            and town.edge_xy[e][-1, 0] > town.edge_xy[e][0, 0]]
    main.sort(key=lambda e: town.edge_xy[e][0, 0])
    xy = stretch_xy(town, main, 120.0, 420.0)
    # the town is drawn in ENU metres through lat/lon: millimetre round-off
    np.testing.assert_allclose(xy[[0, -1]], [[-180.0, 0.0], [120.0, 0.0]], atol=1e-3)
    assert len(stretch_xy(town, main, 50.0, 50.0)) == 0
    assert piece_key(town, main[0])[0] == 101


def test_score_of_a_straight_drive(town):
    x = np.arange(-250.0, 251.0, 10.0)
    t = np.arange(x.size, dtype=float)
    res = match(town, x, np.full(x.size, 1.5), t)
    east = sorted((e for e in range(town.n_edges) if town.edge_way_id[e] in (101, 102)
                   and town.edge_xy[e][-1, 0] > town.edge_xy[e][0, 0]),
                  key=lambda e: town.edge_xy[e][0, 0])
    score = score_route(town, east, (50.0, 550.0), town, res)
    assert score.rmf_corridor == pytest.approx(0.0, abs=1e-9)
    assert score.rmf_pieces == 0.0 and score.true_length_m == pytest.approx(500.0)
    (drv,) = matched_stretches(town, res)
    np.testing.assert_allclose(drv[[0, -1]], [[-250.0, 0.0], [250.0, 0.0]], atol=1.0)
    # the same fixes driven west match the westbound twins: the corridor cannot tell, the
    # pieces can
    back = match(town, x[::-1], np.full(x.size, 1.5), t)
    wrong_way = score_route(town, east, (50.0, 550.0), town, back)
    assert wrong_way.rmf_corridor == pytest.approx(0.0, abs=1e-9)
    assert wrong_way.rmf_pieces == pytest.approx(2.0)
