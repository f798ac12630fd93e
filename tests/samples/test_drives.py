"""Synthetic drives: their ground truth is consistent (noiseless fixes lie on the true route,
positions never run backwards, stops stand still, ends part-way along a street), the receiver
noise has the stated size and correlation, and the README's sample trace is a drive on the
Helsinki map that ``vid2sim road`` matches cleanly."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.geo.test_osm import ORIGIN, helsinki_pbf, town_osm  # noqa: F401 - fixture
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import Origin
from vid2sim.geo.alongroute import join_xy, signed_offsets
from vid2sim.geo.mapmatch import match
from vid2sim.geo.matcheval import rmf_corridor, score_route
from vid2sim.geo.osm import load_network
from vid2sim.samples.drives import (
    SAMPLE_ORIGIN,
    gauss_markov,
    helsinki_sample,
    simulate_drive,
)


@pytest.fixture(scope="module")
def town(town_osm):  # noqa: F811 - the imported fixture
    return load_network(town_osm, ORIGIN)


@pytest.fixture(scope="module")
def helsinki():
    return load_network(helsinki_pbf(), SAMPLE_ORIGIN)


def _check_truth(net, d, rate_hz):
    route = join_xy(net, d.route_edges)
    s_on, off = signed_offsets(route, np.column_stack([d.x_m, d.y_m]))
    np.testing.assert_allclose(off, 0.0, atol=1e-6)  # noiseless fixes lie on the route
    np.testing.assert_allclose(s_on, d.true_s_m, atol=1e-6)  # where the truth says
    assert np.all(np.diff(d.true_s_m) >= 0)  # never backwards
    assert np.allclose(np.diff(d.t_s), 1.0 / rate_hz)
    lengths = net.edge_length_m[d.route_edges]
    assert 0.0 <= d.true_s_m[0] < lengths[0]  # the first fix on the first piece
    assert d.true_s_m[-1] >= lengths[:-1].sum()  # the last on the last piece


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), rate=st.sampled_from([0.2, 1.0, 10.0]),
       at_junctions=st.booleans())
def test_noiseless_drives_lie_on_their_route(town, seed, rate, at_junctions):
    d = simulate_drive(town, np.random.default_rng(seed), min_length_m=150.0,
                       max_length_m=2000.0, noise_m=0.0, outlier_share=0.0, rate_hz=rate,
                       ends_at_junctions=at_junctions)
    _check_truth(town, d, rate)
    assert 150.0 <= d.length_m <= 2000.0
    assert not d.is_outlier.any()


def test_helsinki_drives_start_part_way_and_stop_halfway(helsinki):
    starts = []
    for seed in range(12):
        d = simulate_drive(helsinki, np.random.default_rng(seed), noise_m=0.0,
                           outlier_share=0.0, stop_s=20.0, ends_at_junctions=False)
        _check_truth(helsinki, d, 1.0)
        still = np.flatnonzero(np.diff(d.true_s_m) == 0.0)
        assert still.size == 20  # 20 s standing at 1 Hz, halfway along the drive
        assert abs(d.true_s_m[still[0]] - d.true_s_m[0] - d.length_m / 2) < 15.0
        starts.append(d.true_s_m[0] / helsinki.edge_length_m[d.route_edges[0]])
    assert 0.1 < np.median(starts) < 0.9  # anywhere along the first piece, not its start


def test_noise_and_outliers_have_the_stated_size(helsinki):
    d = simulate_drive(helsinki, np.random.default_rng(5), noise_m=5.0, outlier_share=0.02,
                       min_length_m=2500.0)
    _, off = signed_offsets(join_xy(helsinki, d.route_edges), np.column_stack([d.x_m, d.y_m]),
                            d.true_s_m, 100.0)
    across = off[~d.is_outlier]
    assert np.std(across) == pytest.approx(5.0, rel=0.25)  # one axis of 2-D Gaussian noise
    assert np.all(np.abs(off[d.is_outlier]) <= 80.0 + 1e-6)


def test_gauss_markov_bias_has_its_sigma_and_correlation_time():
    t = np.arange(0.0, 200_000.0, 1.0)
    b = gauss_markov(np.random.default_rng(1), t, 2.0, 60.0)
    assert np.std(b[:, 0]) == pytest.approx(2.0, rel=0.05)
    lag = 60
    r = np.corrcoef(b[:-lag, 1], b[lag:, 1])[0, 1]
    assert r == pytest.approx(math.exp(-1.0), abs=0.03)


def test_route_nodes_must_be_joined_by_a_road(town):
    with pytest.raises(ValueError, match="no drivable route"):
        simulate_drive(town, np.random.default_rng(0), route_nodes=(1, 999_999))


# --------------------------------------------------------------------------- README sample


def test_the_readme_sample_matches_on_the_map_it_suggests(tmp_path, helsinki, capsys):
    from vid2sim.cli import main
    from vid2sim.samples.sample_gps import write_sample_gpx

    gpx = write_sample_gpx(tmp_path / "sample.gpx")
    drive, fixes = helsinki_sample()
    assert 200 < len(fixes) < 400 and drive.length_m > 2000.0
    # the README's commands, as a new user types them
    out = tmp_path / "road.json"
    assert main(["road", str(gpx), "--map", str(helsinki_pbf()), "--out", str(out)]) == 0
    road = json.loads(out.read_text())
    share = np.mean([m["osm_way_id"] is not None for m in road["matches"]])
    assert share >= 0.98
    assert "break" not in capsys.readouterr().out
    # the road's centerline against the true road pieces (whole), 5 m corridor
    frame, ours = EnuFrame(Origin(**road["origin"])), EnuFrame(SAMPLE_ORIGIN)
    lines = []
    for r in road["roads"]:  # into the sample's frame, through lat/lon
        lat, lon, _ = frame.to_geodetic(np.array(r["centerline"]))
        lines.append(ours.to_enu(lat, lon)[:, :2])
    assert len(lines) == 1
    assert rmf_corridor(join_xy(helsinki, drive.route_edges), lines) <= 0.01
    # and the matcher's driven stretch against the true one
    res = match(helsinki, drive.x_m, drive.y_m, drive.t_s)
    score = score_route(helsinki, drive.route_edges, (drive.true_s_m[0], drive.true_s_m[-1]),
                        helsinki, res)
    assert score.rmf_corridor <= 0.01
    print(f"\nREADME sample: {share:.1%} of fixes matched, road RMF "
          f"{rmf_corridor(join_xy(helsinki, drive.route_edges), lines):.2%}, match RMF "
          f"{score.rmf_corridor:.2%} (pieces {score.rmf_pieces:.2%})")
