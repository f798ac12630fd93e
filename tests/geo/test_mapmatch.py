"""The HMM map matcher: known answers on a synthetic town (direction of two-way streets, turns,
standing still, outliers), properties on random drives, and the accuracy evaluation on the
real Helsinki extract (simulated 1 Hz drives with 5 m noise and 2 % outliers): the issue's bar
on the route mismatch fraction, and regression floors."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.geo.test_osm import ORIGIN, helsinki_pbf, town_osm  # noqa: F401 - fixture
from vid2sim.core.records import Origin
from vid2sim.geo.mapmatch import MatchConfig, match
from vid2sim.geo.matcheval import score_route
from vid2sim.geo.osm import load_network
from vid2sim.samples.drives import simulate_drive


@pytest.fixture(scope="module")
def town(town_osm):  # noqa: F811 - the imported fixture
    return load_network(town_osm, ORIGIN)


def drive(waypoints, speed_mps=10.0, rate_hz=1.0, noise_m=0.0, seed=0, stop=None):
    """Fixes along ENU ``waypoints`` at constant speed; ``stop=(x, y, seconds)`` stands still
    at the first sample past (x, y). Returns t_s, x_m, y_m, true xy."""
    pts = np.asarray(waypoints, float)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    along = list(np.arange(0.0, s[-1], speed_mps / rate_hz))
    if stop is not None:
        sx = s[np.argmin(np.hypot(pts[:, 0] - stop[0], pts[:, 1] - stop[1]))]
        k = int(np.searchsorted(along, sx))
        along[k:k] = [along[k]] * int(stop[2] * rate_hz)
    along = np.array(along)
    true = np.column_stack([np.interp(along, s, pts[:, 0]), np.interp(along, s, pts[:, 1])])
    rng = np.random.default_rng(seed)
    noisy = true + rng.normal(0.0, noise_m, true.shape) if noise_m else true.copy()
    t = np.arange(len(along)) / rate_hz
    return t, noisy[:, 0], noisy[:, 1], true


def _has_uturn(net, edges):
    return any(net.edge_twin[a] == b for a, b in itertools.pairwise(edges))


# --------------------------------------------------------------------------- known answers


def test_eastbound_on_a_two_way_street_uses_the_eastbound_twin(town):
    t, x, y, _ = drive([(-280, 0), (280, 0)], noise_m=4.0, seed=1)
    res = match(town, x, y, t)
    assert res.way_sequence() == [101, 102]
    assert res.matched_share == 1.0
    (piece,) = res.route_edges
    assert all(town.edge_xy[e][-1, 0] > town.edge_xy[e][0, 0] for e in piece)  # eastwards
    far = np.abs(x) > 15  # away from the way change at x = 0
    assert np.all(res.fix_way_id[far] == np.where(x[far] < 0, 101, 102))


def test_westbound_uses_the_other_twin(town):
    t, x, y, _ = drive([(280, 0), (-280, 0)], noise_m=4.0, seed=2)
    res = match(town, x, y, t)
    assert res.way_sequence() == [102, 101]
    assert all(town.edge_xy[e][-1, 0] < town.edge_xy[e][0, 0] for e in res.route_edges[0])


def test_turn_at_a_junction(town):
    t, x, y, _ = drive([(-280, 0), (0, 0), (0, 180)], noise_m=3.0, seed=3)
    res = match(town, x, y, t)
    # Cross is split at the Parallel junction (y = 60) but stays one way
    assert res.way_sequence() == [101, 104]
    assert not _has_uturn(town, res.route_edges[0])


def test_one_way_street_is_never_driven_backwards(town):
    # driving west along y = 60: Parallel is one-way westbound, so it matches
    t, x, y, _ = drive([(280, 60), (-280, 60)], noise_m=3.0, seed=4)
    assert match(town, x, y, t).way_sequence() == [105]
    # driving east along y = 60 is against the one-way: the matcher must not put the car
    # there, so it takes Main (60 m away) or skips; never way 105 eastbound
    t, x, y, _ = drive([(-280, 60), (280, 60)], noise_m=3.0, seed=4)
    res = match(town, x, y, t)
    for e in (e for piece in res.route_edges for e in piece):
        if town.edge_way_id[e] == 105:
            assert town.edge_xy[e][-1, 0] < town.edge_xy[e][0, 0]


def test_standing_still_makes_no_uturn(town):
    t, x, y, _ = drive([(-280, 0), (280, 0)], noise_m=5.0, seed=5, stop=(-100, 0, 40))
    res = match(town, x, y, t)
    assert res.way_sequence() == [101, 102]
    assert not _has_uturn(town, res.route_edges[0])
    assert np.all(np.diff(res.fix_route_s_m) >= 0)  # never backwards along the route


def test_outliers_towards_a_parallel_road_are_skipped(town):
    t, x, y, true = drive([(-280, 0), (280, 0)], noise_m=3.0, seed=6)
    bad = np.array([10, 11, 30, 45])
    y = y.copy()
    y[bad] += 60.0  # lands right on Parallel (one-way the wrong way) and the parking aisle
    res = match(town, x, y, t)
    assert res.way_sequence() == [101, 102]
    assert res.fix_outlier[bad].all()
    # skipped fixes still get the way the car was on, from their neighbours
    assert np.all(res.fix_way_id[bad] == np.where(true[bad, 0] < 0, 101, 102))
    assert np.all(np.abs(res.fix_offset_m[bad]) > 50)  # and an honest offset


def test_offset_sign_is_left_positive(town):
    t, x, y, _ = drive([(-280, -3), (280, -3)])  # 3 m right of Main when driving east
    res = match(town, x, y, t)
    np.testing.assert_allclose(res.fix_offset_m, -3.0, atol=1e-3)
    t, x, y, _ = drive([(280, -3), (-280, -3)])  # westbound: the same line is on the left
    np.testing.assert_allclose(match(town, x, y, t).fix_offset_m, 3.0, atol=1e-3)


def test_heading_breaks_the_tie_of_a_single_fix(town):
    # one fix cannot say which way the car drives, its heading can
    for heading, eastwards in ((0.0, True), (np.pi, False)):
        res = match(town, np.array([-100.0]), np.array([1.0]), np.array([0.0]),
                    heading_rad=np.array([heading]))
        (e,) = res.route_edges[0]
        assert (town.edge_xy[e][-1, 0] > town.edge_xy[e][0, 0]) == eastwards


def test_no_fix_near_a_road_gives_an_empty_match(town):
    res = match(town, np.array([5000.0, 5010.0]), np.array([5000.0, 5000.0]),
                np.array([0.0, 1.0]))
    assert res.route_edges == [] and res.matched_share == 0.0 and res.warnings


# --------------------------------------------------------------------------- properties


@settings(max_examples=15, deadline=None)
@given(speed=st.floats(3.0, 25.0), noise=st.floats(0.0, 6.0), seed=st.integers(0, 10_000),
       eastwards=st.booleans())
def test_random_straight_drives(town, speed, noise, seed, eastwards):
    ends = [(-280, 0), (280, 0)] if eastwards else [(280, 0), (-280, 0)]
    t, x, y, _ = drive(ends, speed_mps=speed, noise_m=noise, seed=seed)
    res = match(town, x, y, t)
    assert res.matched_share == 1.0
    assert np.all(np.diff(res.fix_route_s_m) >= 0)
    assert res.way_sequence() == ([101, 102] if eastwards else [102, 101])
    assert not _has_uturn(town, res.route_edges[0])


# --------------------------------------------------------------------------- Helsinki


N_ROUTES = 24
#: by-pieces route mismatch of the issue-bar drives: measured mean 1.3 % / worst 8.3 %
#: (python -m pytest tests/geo/test_mapmatch.py -k pieces -s), floors with a margin
PIECES_MEAN_FLOOR = 0.03
PIECES_WORST_FLOOR = 0.15


@pytest.fixture(scope="module")
def helsinki_eval():
    """Simulated drives on the real Helsinki extract (seeded), matched from fixes alone."""
    net = load_network(helsinki_pbf(), Origin(60.17, 24.944))
    rng = np.random.default_rng(2024)
    fixes = correct = exact = 0
    lengths = []
    for k in range(N_ROUTES):
        # every third drive stands still 20 s halfway (a red light)
        d = simulate_drive(net, rng, noise_m=5.0, outlier_share=0.02,
                           stop_s=20.0 if k % 3 == 0 else 0.0)
        res = match(net, d.x_m, d.y_m, d.t_s, config=MatchConfig())
        fixes += d.t_s.size
        correct += int((res.fix_way_id == d.true_way_id).sum())
        exact += res.way_sequence() == d.true_ways
        lengths.append(d.length_m)
    figures = {"routes": N_ROUTES, "fixes": fixes, "fix_accuracy": correct / fixes,
               "exact_routes": exact / N_ROUTES, "km": sum(lengths) / 1000.0}
    print(f"\nHelsinki map-matching evaluation: {figures}")
    return figures


def test_helsinki_routes_are_1_to_3_km(helsinki_eval):
    assert helsinki_eval["routes"] >= 20
    assert 20.0 <= helsinki_eval["km"] <= 72.0


def test_helsinki_accuracy_regression_floor(helsinki_eval):
    # measured 0.912 / 0.46 with this seed (0.933 / 0.75 on other drives before the
    # extract's service roads were read: the drives changed with the network): way changes
    # every ~30 m in this extract make 5 m noise at 1 Hz ambiguous near junctions; every
    # inexact route differs only in its first or last way, a piece these junction-to-junction
    # drives enter for a few metres (less than MatchConfig.min_cover_m); floors against
    # regressions
    assert helsinki_eval["fix_accuracy"] >= 0.90
    assert helsinki_eval["exact_routes"] >= 0.4


# --------------------------------------------------------------------------- issue bar

N_RMF_ROUTES = 30


@pytest.fixture(scope="module")
def helsinki_rmf():
    """Route mismatch fractions (Newson & Krumm 2009) of seeded 1 Hz drives on the Helsinki
    extract: 0.8-1.5 km, starting and ending part-way along a street, 5 m noise, 2 % outliers
    of 30-80 m, every third drive standing 20 s. Seeds other than the benchmark's."""
    net = load_network(helsinki_pbf(), Origin(60.17, 24.944))
    scores = []
    for k in range(N_RMF_ROUTES):
        d = simulate_drive(net, np.random.default_rng([17, k]), min_length_m=800.0,
                           max_length_m=1500.0, noise_m=5.0, outlier_share=0.02,
                           stop_s=20.0 if k % 3 == 0 else 0.0, ends_at_junctions=False)
        res = match(net, d.x_m, d.y_m, d.t_s)
        scores.append(score_route(net, d.route_edges, (d.true_s_m[0], d.true_s_m[-1]), net,
                                  res))
    rmf = np.array([s.rmf_corridor for s in scores])
    pieces = np.array([s.rmf_pieces for s in scores])
    print(f"\nHelsinki RMF over {N_RMF_ROUTES} drives: mean {rmf.mean():.2%}, worst "
          f"{rmf.max():.2%}; by whole pieces mean {pieces.mean():.2%}, worst {pieces.max():.2%}")
    return rmf, pieces


def test_helsinki_route_mismatch_issue_bar(helsinki_rmf):
    rmf, _ = helsinki_rmf
    assert rmf.mean() <= 0.02  # the issue's bar: mean RMF <= 2 %, no route worse than 10 %
    assert rmf.max() <= 0.10


def test_helsinki_route_mismatch_by_pieces_regression_floor(helsinki_rmf):
    # whole road pieces count an end piece the car barely entered (or left) in full: the
    # ends dominate this figure (see vid2sim.geo.matcheval); a floor against regressions
    _, pieces = helsinki_rmf
    assert pieces.mean() <= PIECES_MEAN_FLOOR and pieces.max() <= PIECES_WORST_FLOOR


def test_a_run_of_off_map_fixes_breaks_the_chain(town):
    t, x, y, _ = drive([(-280, 0), (280, 0)], noise_m=2.0, seed=7)
    gap = np.flatnonzero((x > -60) & (x < 60))
    assert gap.size > MatchConfig().max_skip
    y = y.copy()
    y[gap] = 900.0  # far from every road, for longer than the matcher may skip
    res = match(town, x, y, t)
    assert res.n_breaks == 1 and len(res.route_edges) == 2 and res.warnings
    assert np.all(res.fix_way_id[gap] == -1) and np.all(res.fix_piece[gap] == -1)
    assert np.all(res.fix_way_id[x < -80] == 101) and np.all(res.fix_way_id[x > 80] == 102)
    assert res.way_sequence() == [101, 102]


def test_a_gps_outage_is_bridged_by_the_route(town):
    # no fixes at all for 20 s (a tunnel): one continuous route through the gap
    t, x, y, _ = drive([(-280, 0), (0, 0), (0, 180)], noise_m=2.0, seed=8)
    keep = (t < 20) | (t > 40)
    res = match(town, x[keep], y[keep], t[keep])
    assert res.n_breaks == 0 and res.way_sequence() == [101, 104]


@pytest.mark.parametrize("rate_hz", [0.2, 1.0, 10.0])
def test_chord_speed_known_answers(rate_hz):
    from vid2sim.geo.mapmatch import _chord_speed

    t = np.arange(0.0, 60.0, 1.0 / rate_hz)
    x = np.where(t < 30, 12.0 * t, 360.0)  # 12 m/s, then standing
    speed = _chord_speed(np.column_stack([x, np.zeros_like(x)]), t)
    if rate_hz < 0.3:  # fewer than 3 fixes in 8 s: unknown, taken as driving
        assert np.all(np.isinf(speed))
        return
    cruising = (t > 5) & (t < 25)
    np.testing.assert_allclose(speed[cruising], 12.0, rtol=1e-9)
    np.testing.assert_allclose(speed[t > 35], 0.0, atol=1e-9)
    assert np.all(np.isinf(speed) | (speed >= 0))
