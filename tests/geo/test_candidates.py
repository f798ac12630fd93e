"""Candidate search and the matcher's observations: properties on random points and traces."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.geo.test_osm import ORIGIN, town_osm  # noqa: F401 - fixture
from vid2sim.geo.candidates import EdgeIndex
from vid2sim.geo.mapmatch import hmm_steps, observations
from vid2sim.geo.osm import load_network


@pytest.fixture(scope="module")
def index(town_osm):  # noqa: F811 - the imported fixture
    net = load_network(town_osm, ORIGIN)
    return net, EdgeIndex(net)


coord = st.floats(-350.0, 350.0, allow_nan=False)


@settings(max_examples=40, deadline=None)
@given(pts=st.lists(st.tuples(coord, coord), min_size=1, max_size=30),
       radius=st.floats(5.0, 120.0), most=st.integers(1, 6))
def test_candidates_are_true_projections(index, pts, radius, most):
    net, idx = index
    xy = np.array(pts)
    got = idx.candidates(xy, radius, most)
    assert len(got) == len(xy)
    for p, c in zip(xy, got, strict=True):
        pt = shapely.Point(p)
        twins = np.array([net.edge_twin[e] for e in c.edges])
        n_base = int(np.sum([t < 0 or t > e for e, t in zip(c.edges, twins, strict=True)]))
        assert n_base <= most  # at most ``most`` way pieces, each with its twin
        for e, s, d, h in zip(c.edges, c.s_m, c.dist_m, c.heading_rad, strict=True):
            line = shapely.LineString(net.edge_xy[e])
            assert d == pytest.approx(line.distance(pt), abs=1e-6) and d <= radius + 1e-6
            assert -1e-9 <= s <= net.edge_length_m[e] + 1e-6
            foot = line.interpolate(s)
            assert foot.distance(pt) == pytest.approx(d, abs=1e-6)  # s is the projection
            ahead = line.interpolate(min(s + 0.5, line.length))
            behind = line.interpolate(max(s - 0.5, 0.0))
            want = math.atan2(ahead.y - behind.y, ahead.x - behind.x)
            assert abs(math.remainder(h - want, 2 * math.pi)) < 1e-6
        # every way piece within the radius and nearer than the farthest kept is kept
        near = [i for i in range(net.n_edges) if (net.edge_twin[i] < 0 or net.edge_twin[i] > i)
                and shapely.LineString(net.edge_xy[i]).distance(pt) < (
                    c.dist_m.max() - 1e-6 if len(c.dist_m) else radius)]
        assert set(near) <= set(c.edges.tolist())


@settings(max_examples=40, deadline=None)
@given(pts=st.lists(st.tuples(coord, coord), min_size=1, max_size=30))
def test_nearest_distance(index, pts):
    net, idx = index
    xy = np.array(pts)
    got = idx.nearest_distance(xy, 60.0)
    for p, d in zip(xy, got, strict=True):
        best = min(shapely.LineString(g).distance(shapely.Point(p)) for g in net.edge_xy)
        if best <= 60.0:
            assert d == pytest.approx(best, abs=1e-6)
        else:
            assert np.isnan(d)


@settings(max_examples=60, deadline=None)
@given(dts=st.lists(st.floats(0.01, 3.0), min_size=1, max_size=80), seed=st.integers(0, 99),
       window=st.floats(0.1, 2.0))
def test_observations_group_fixes_under_the_window(dts, seed, window):
    t = np.cumsum(dts)
    xy = np.random.default_rng(seed).normal(0.0, 10.0, (t.size, 2))
    obs = observations(xy, t, window)
    assert np.all(np.diff(obs.fix) > 0) and obs.fix[0] >= 0 and obs.fix[-1] < t.size
    assert np.all(np.diff(obs.t_s) > 0)
    assert len(obs.t_s) <= t.size and obs.size.sum() == t.size and np.all(obs.size >= 1)
    for k, f in enumerate(obs.fix):  # the fix standing for a group lies inside it
        assert abs(t[f] - obs.t_s[k]) < window + 1e-9
    if np.all(np.diff(t) >= window):  # a 1 Hz trace is used fix by fix
        np.testing.assert_array_equal(obs.fix, np.arange(t.size))
        np.testing.assert_array_equal(obs.xy, xy)


def test_ten_hz_becomes_about_one_observation_per_window():
    t = np.arange(0.0, 60.0, 0.1)
    xy = np.column_stack([10.0 * t, np.zeros_like(t)])
    obs = observations(xy, t, 0.9)
    # groups of 9 or 10 fixes (0.8-0.9 s, the 0.9 s boundary falls either side in floats)
    assert 60 / 1.0 - 1 <= len(obs.t_s) <= 60 / 0.8 + 1
    # the median of a straight, even drive is its middle
    np.testing.assert_allclose(obs.xy[:, 0], 10.0 * obs.t_s, atol=1e-6)


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 60), sigma=st.floats(1.0, 20.0), thin=st.floats(0.0, 4.0),
       seed=st.integers(0, 99), unknown=st.booleans())
def test_hmm_steps(n, sigma, thin, seed, unknown):
    xy = np.cumsum(np.random.default_rng(seed).normal(0.0, 6.0, (n, 2)), axis=0)
    travel = np.full(n, np.inf if unknown else 5.0)
    steps = hmm_steps(xy, np.full(n, sigma), thin, travel)
    if n == 0:
        assert steps.size == 0
        return
    assert steps[0] == 0 and steps[-1] == n - 1 and np.all(np.diff(steps) > 0)
    if unknown or thin == 0:  # sparse fixes (speed unknown) are all kept
        np.testing.assert_array_equal(steps, np.arange(n))
        return
    inner = steps[1:-1] if n > 2 else steps[:0]
    gaps = np.hypot(*np.diff(xy[np.concatenate([[0], inner])], axis=0).T)
    assert np.all(gaps >= thin * sigma - 1e-9)  # every step far enough from the one before
