"""Road building: lanes from tags, centerline geometry, ego lane, trajectory fallback, the
picture and the ``vid2sim road`` command (synthetic town with known answers)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.geo.test_osm import NODES, ORIGIN, WAYS, osm_xml
from vid2sim.base.defaults import EGO_LENGTH_M
from vid2sim.base.errors import FormatError, InconsistentInputError
from vid2sim.cli import main
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import EgoTrack, GpsFix, GpsTrace
from vid2sim.core.scenario import Road
from vid2sim.geo.alongroute import signed_offsets
from vid2sim.geo.roads import (
    DEFAULT_LANE_WIDTH_M,
    LANE_DEFAULTS,
    build_road,
    lane_index,
    lanes_from_tags,
    plot_road,
    resample_polyline,
    road_json,
)


@pytest.fixture(scope="module")
def town_map(tmp_path_factory):
    """The synthetic town of test_osm as an .osm file."""
    path = tmp_path_factory.mktemp("map") / "town.osm"
    path.write_text(osm_xml(NODES, WAYS), encoding="utf-8")
    return path


# --------------------------------------------------------------------------- lanes from tags


@pytest.mark.parametrize(("tags", "along", "expected"), [
    ({"highway": "primary", "lanes": "4"}, True, (4, 2, 3.5)),
    ({"highway": "primary", "lanes": "3", "oneway": "yes"}, True, (3, 3, 3.5)),
    ({"highway": "secondary", "lanes": "3", "lanes:forward": "1", "lanes:backward": "2"},
     False, (3, 2, 3.25)),
    ({"highway": "secondary", "lanes:forward": "2", "lanes:backward": "1"}, True, (3, 2, 3.25)),
    ({"highway": "residential"}, True, (2, 1, 3.0)),
    ({"highway": "residential", "oneway": "-1"}, False, (1, 1, 3.0)),
    ({"highway": "tertiary", "width": "7 m"}, True, (2, 1, 3.5)),
    ({"highway": "tertiary", "width": "40"}, True, (2, 1, 3.25)),  # implausible: default
    ({"highway": "motorway"}, True, (4, 2, 3.75)),
    ({"highway": "motorway", "oneway": "yes"}, True, (2, 2, 3.75)),
    ({"highway": "service"}, True, (1, 1, 3.0)),
    ({"highway": "primary", "junction": "roundabout"}, True, (1, 1, 3.5)),
    ({"highway": "unknown_type"}, True, (2, 1, DEFAULT_LANE_WIDTH_M)),
])
def test_lanes_from_tags(tags, along, expected):
    assert lanes_from_tags(tags, along) == pytest.approx(expected)


def test_defaults_table_is_complete_and_sane():
    from vid2sim.geo.osm import DRIVABLE_HIGHWAYS

    assert set(LANE_DEFAULTS) == set(DRIVABLE_HIGHWAYS)
    for two_way, one_way, width in LANE_DEFAULTS.values():
        assert 1 <= one_way <= two_way <= 4 and 2.5 <= width <= 4.0


@pytest.mark.parametrize(("offset", "lanes", "forward", "expected"), [
    (-1.5, 4, 2, 1), (-4.5, 4, 2, 0), (-9.0, 4, 2, 0), (1.0, 4, 2, 1),   # two-way, 2 + 2
    (-1.0, 2, 1, 0), (2.0, 2, 1, 0),                                     # two-way, 1 + 1
    (-2.5, 3, 3, 0), (0.0, 3, 3, 1), (2.5, 3, 3, 2), (9.0, 3, 3, 2),     # one-way, 3 lanes
])
def test_lane_index(offset, lanes, forward, expected):
    assert lane_index(np.array([offset]), lanes, forward, 3.0)[0] == expected


# --------------------------------------------------------------------------- geometry


# Millimetre coordinates: map and trace points in metres; points closer than 1e-6 m are the
# same point to resample_polyline (dropped), a boundary the property below does not model.
finite = st.floats(-500.0, 500.0, allow_nan=False).map(lambda v: round(v, 3))


@settings(max_examples=60, deadline=None)
@given(pts=st.lists(st.tuples(finite, finite), min_size=2, max_size=12))
def test_resample_polyline_properties(pts):
    xy = np.array(pts)
    out = resample_polyline(xy, 1.0)
    steps = np.hypot(*np.diff(out, axis=0).T)
    length = np.hypot(*np.diff(xy, axis=0).T).sum()
    if length < 1e-6:
        assert len(out) == 1
        return
    assert steps.max() <= 1.0 + 1e-9
    assert len(out) == math.ceil(length / 1.0 - 1e-9) + 1  # the fewest samples <= 1 m apart
    np.testing.assert_allclose(out[0], xy[0])
    np.testing.assert_allclose(out[-1], xy[-1], atol=1e-6)
    assert steps.sum() <= length + 1e-6  # chords never exceed the arc


@settings(max_examples=60, deadline=None)
@given(angle=st.floats(-math.pi, math.pi), along=st.floats(1.0, 99.0),
       off=st.floats(-20.0, 20.0))
def test_signed_offsets_on_a_straight_line(angle, along, off):
    d = np.array([math.cos(angle), math.sin(angle)])
    n = np.array([-d[1], d[0]])  # left normal
    line = np.vstack([np.zeros(2), 100 * d])
    s, o = signed_offsets(line, (along * d + off * n)[None])
    assert s[0] == pytest.approx(along, abs=1e-6)
    assert o[0] == pytest.approx(off, abs=1e-6)


# --------------------------------------------------------------------------- build_road


def _trace_and_ego(waypoints, offset_m=0.0, speed_mps=10.0, seed=0, noise_m=3.0):
    """GpsTrace at 1 Hz (noisy) and a 10 Hz EgoTrack (true path shifted ``offset_m`` to the
    left of travel) along ENU waypoints about ORIGIN."""
    pts = np.asarray(waypoints, float)
    seg = np.diff(pts, axis=0)
    seg_len = np.hypot(*seg.T)
    s = np.concatenate([[0.0], np.cumsum(seg_len)])
    t_ego = np.arange(0.0, s[-1] / speed_mps, 0.1)
    along = t_ego * speed_mps
    k = np.clip(np.searchsorted(s, along, side="right") - 1, 0, len(seg) - 1)
    d = seg[k] / seg_len[k, None]
    centre = pts[k] + d * (along - s[k])[:, None]
    ego_xy = centre + offset_m * np.column_stack([-d[:, 1], d[:, 0]])
    frame = EnuFrame(ORIGIN)
    lat, lon, _ = frame.to_geodetic(ego_xy)
    heading = np.arctan2(d[:, 1], d[:, 0])
    ego = EgoTrack(ORIGIN, t_ego, ego_xy[:, 0], ego_xy[:, 1], heading,
                   np.full(t_ego.size, speed_mps), lat, lon)
    rng = np.random.default_rng(seed)
    fix_xy = ego_xy[::10] + rng.normal(0.0, noise_m, ego_xy[::10].shape)
    flat, flon, _ = frame.to_geodetic(fix_xy)
    fixes = [GpsFix(1.7e9 + t, la, lo) for t, la, lo in zip(t_ego[::10], flat, flon, strict=True)]
    return GpsTrace(fixes, "csv"), ego


def _max_turn_rad(line):
    h = np.unwrap(np.arctan2(*np.diff(line, axis=0).T[::-1]))
    return float(np.abs(np.diff(h)).max())


def test_build_road_straight_two_way(town_map):
    trace, ego = _trace_and_ego([(-280, 0), (280, 0)], offset_m=-4.5)
    res = build_road(trace, ego, town_map, allow_download=False)
    assert res.source == "osm" and res.route_osm_way_ids == [101, 102]
    (road,) = res.roads
    assert (road.lanes, res.lanes_forward, road.lane_width_m) == (4, 2, 3.0)
    assert road.name == "Main" and road.highway == "residential"
    steps = np.hypot(*np.diff(road.centerline, axis=0).T)
    assert steps.max() <= 1.0 + 1e-9 and steps.min() > 0.5
    # the road runs from one car length before the first fix (x -280) to one beyond the last
    # (x 270), not from the ways' ends (x -300 and 300): the car was never seen there
    np.testing.assert_allclose(road.centerline[[0, -1], 1], 0.0, atol=0.05)
    # (the ends of a smoothed 3 m-noise trace lie within about 4 m of the truth)
    assert road.centerline[0, 0] == pytest.approx(-280.0 - EGO_LENGTH_M, abs=4.0)
    assert road.centerline[-1, 0] == pytest.approx(270.0 + EGO_LENGTH_M, abs=4.0)
    assert res.stats["route_length_m"] == pytest.approx(550.0 + 2 * EGO_LENGTH_M, abs=5.0)
    assert _max_turn_rad(road.centerline) < 1e-3  # one straight line through the join
    assert np.all(res.ego_lane == 0)  # 4.5 m right of the middle: the outer lane
    np.testing.assert_allclose(res.ego_offset_m, -4.5, atol=0.01)
    assert len(res.matches) == len(trace.fixes)
    assert [m["t"] for m in res.matches] == pytest.approx(np.arange(len(trace.fixes)))
    assert res.stats["matched_share"] == 1.0


def test_build_road_inner_lane_and_turn(town_map):
    trace, ego = _trace_and_ego([(-280, 0), (0, 0), (0, 180)], offset_m=-1.5, seed=1)
    res = build_road(trace, ego, town_map, allow_download=False)
    assert res.route_osm_way_ids == [101, 104]
    (road,) = res.roads
    line = road.centerline
    steps = np.hypot(*np.diff(line, axis=0).T)
    assert steps.max() <= 1.0 + 1e-9
    # the only bend is the 90 degree corner, spread over at most two 1 m steps
    h = np.unwrap(np.arctan2(*np.diff(line, axis=0).T[::-1]))
    assert abs(h[-1] - h[0]) == pytest.approx(math.pi / 2, abs=1e-3)
    assert np.all(np.abs(np.diff(h)) < math.pi / 2 + 1e-6)
    assert np.sum(np.abs(np.diff(h)) > 1e-3) <= 2
    on_main = ego.x_m < -20
    assert np.all(res.ego_lane[on_main] == 1)  # 1.5 m right of the middle of 4 lanes


def test_trajectory_fallback_without_map():
    trace, ego = _trace_and_ego([(0, 0), (100, 50), (200, 50)])
    res = build_road(trace, ego, None, allow_download=False)
    assert res.source == "trajectory" and res.route_osm_way_ids == []
    (road,) = res.roads
    assert road.source == "trajectory" and road.lanes == 1
    assert road.lane_width_m == DEFAULT_LANE_WIDTH_M
    assert np.hypot(*np.diff(road.centerline, axis=0).T).max() <= 1.0 + 1e-9
    assert np.abs(res.ego_offset_m).max() < 0.1
    assert all(m["osm_way_id"] is None for m in res.matches)
    assert any("trajectory" in w for w in res.warnings)


def test_road_json_round_trips_through_scenario_road(town_map):
    trace, ego = _trace_and_ego([(-280, 0), (280, 0)])
    data = json.loads(json.dumps(road_json(build_road(trace, ego, town_map))))
    assert set(data) == {"origin", "roads", "route_osm_way_ids", "matches"}
    road = Road.from_json(data["roads"][0])
    assert road.osm_way_ids == [101, 102] and road.centerline.shape[1] == 2


def test_plot_writes_a_png(town_map, tmp_path):
    trace, ego = _trace_and_ego([(-280, 0), (0, 0), (0, 180)])
    res = build_road(trace, ego, town_map, allow_download=False)
    out = tmp_path / "road.png"
    plot_road(res, trace, ego, out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# --------------------------------------------------------------------------- CLI


def _write_csv(path, trace):
    lines = ["t,lat,lon"] + [f"{f.t_utc_s:.3f},{f.lat_deg:.8f},{f.lon_deg:.8f}"
                             for f in trace.fixes]
    path.write_text("\n".join(lines) + "\n")


def test_cli_road_writes_json_and_png(town_map, tmp_path, capsys):
    trace, _ = _trace_and_ego([(-280, 0), (0, 0), (0, 180)], seed=2)
    gps = tmp_path / "drive.csv"
    _write_csv(gps, trace)
    out, png = tmp_path / "road.json", tmp_path / "road.png"
    code = main(["road", str(gps), "--map", str(town_map), "--out", str(out),
                 "--plot", str(png)])
    assert code == 0
    data = json.loads(out.read_text())
    assert data["route_osm_way_ids"] == [101, 104]
    assert len(data["matches"]) == len(trace.fixes)
    assert data["roads"][0]["source"] == "osm" and data["roads"][0]["lanes"] == 4
    assert png.stat().st_size > 1000
    text = capsys.readouterr().out
    assert "matched 100.0%" in text and "2 OSM way(s)" in text and "lanes:" in text
    # same inputs, same bytes
    again = tmp_path / "again.json"
    assert main(["road", str(gps), "--map", str(town_map), "--out", str(again)]) == 0
    assert again.read_bytes() == out.read_bytes()


def _one_line_error(capsys, code):
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert len(err.splitlines()) == 1 and err.startswith("error: ")
    return err


def test_cli_trace_outside_map(town_map, tmp_path, capsys):
    far = ORIGIN.__class__(48.0, 11.0, 0.0)
    frame = EnuFrame(far)
    lat, lon, _ = frame.to_geodetic(np.array([[0.0, 0.0], [50.0, 0.0], [100.0, 0.0]]))
    gps = tmp_path / "far.csv"
    _write_csv(gps, GpsTrace([GpsFix(1.7e9 + k, a, o) for k, (a, o) in
                              enumerate(zip(lat, lon, strict=True))], "csv"))
    err = _one_line_error(capsys, main(["road", str(gps), "--map", str(town_map),
                                        "--out", str(tmp_path / "r.json")]))
    assert "outside" in err and err.count("lon ") == 2 and "lon 10.99" in err
    assert not (tmp_path / "r.json").exists()


@pytest.mark.parametrize(("content", "error"), [
    ("", FormatError),  # an empty file
    ("<osm><way id='1'", FormatError),  # XML cut off
    (osm_xml(NODES, {107: WAYS[107]}), InconsistentInputError),  # no drivable road
])
def test_cli_bad_maps(tmp_path, capsys, raised, content, error):
    trace, _ = _trace_and_ego([(-280, 0), (280, 0)])
    gps = tmp_path / "drive.csv"
    _write_csv(gps, trace)
    bad = tmp_path / "bad.osm"
    bad.write_text(content)
    err = _one_line_error(capsys, main(["road", str(gps), "--map", str(bad),
                                        "--out", str(tmp_path / "r.json")]))
    assert raised == [error] and str(bad) in err


# --------------------------------------------------------------------------- GPS time base


@pytest.mark.parametrize("offset", [None, 0.0, 3.5, -2.0])
def test_fixes_and_ego_share_one_clock(offset):
    from vid2sim.geo.roads import fix_times_s
    from vid2sim.geo.trace import smooth_ego, video_t0_utc

    trace, _ = _trace_and_ego([(-280, 0), (280, 0)])
    # a file whose fixes are out of order: the offset is the video time of the earliest fix
    shuffled = GpsTrace([trace.fixes[3], *trace.fixes[:3], *trace.fixes[4:]], "csv")
    t_fix = fix_times_s(shuffled, offset)
    assert t_fix.min() == pytest.approx(0.0 if offset is None else offset, abs=1e-9)
    assert t_fix[0] == pytest.approx(t_fix.min() + 3.0, abs=1e-9)  # file order kept
    ego, stats = smooth_ego(shuffled, rate_hz=1.0, gps_offset_s=offset)
    t0, how = video_t0_utc(shuffled, offset)
    assert stats.time_alignment == how
    # the ego's clock puts the earliest fix where fix_times_s puts it
    assert ego.t_s[0] == pytest.approx(t_fix.min(), abs=0.5)
    assert t0 == pytest.approx(min(f.t_utc_s for f in shuffled.fixes) - (offset or 0.0))


def test_build_road_takes_the_gps_offset(town_map):
    from vid2sim.geo.trace import smooth_ego

    trace, _ = _trace_and_ego([(-280, 0), (0, 0), (0, 180)], seed=3)
    plain = build_road(trace, smooth_ego(trace, rate_hz=10.0, origin=ORIGIN)[0], town_map,
                       allow_download=False)
    ego, _ = smooth_ego(trace, rate_hz=10.0, gps_offset_s=4.0, origin=ORIGIN)
    shifted = build_road(trace, ego, town_map, gps_offset_s=4.0, allow_download=False)
    assert [m["t"] for m in shifted.matches] == pytest.approx(
        [m["t"] + 4.0 for m in plain.matches])
    # the same fixes on the same road: the same ways and offsets, only the clock moved
    assert [m["osm_way_id"] for m in shifted.matches] == [m["osm_way_id"] for m in plain.matches]
    assert shifted.route_osm_way_ids == plain.route_osm_way_ids == [101, 104]
    np.testing.assert_allclose([m["offset_m"] for m in shifted.matches],
                               [m["offset_m"] for m in plain.matches], atol=1e-9)


def test_lane_numbering_is_stated_once_and_printed(town_map):
    from vid2sim.geo.roads import LANE_NUMBERING, format_summary

    trace, ego = _trace_and_ego([(-280, 0), (280, 0)], offset_m=-4.5)
    text = format_summary(build_road(trace, ego, town_map, allow_download=False))
    assert LANE_NUMBERING in text and "rightmost" in LANE_NUMBERING


def test_cover_points_runs_the_road_on_along_its_route(town_map):
    """The road stage cuts the road a car length beyond the fixes (x 270 on Main, 300 m
    long); a vehicle seen 20 m further ahead makes the scenario's road run on along Main to
    it, one beside another street does not."""
    from vid2sim.geo.roads import cover_points

    trace, ego = _trace_and_ego([(-280, 0), (280, 0)], offset_m=-4.5)
    res = build_road(trace, ego, town_map, allow_download=False)
    ahead = np.array([[290.0, -3.0]])
    (road,) = cover_points(res, res.roads, ahead, reach_m=5.0)
    assert road.centerline[-1, 0] == pytest.approx(295.0, abs=0.5)
    assert road.centerline[0, 0] == pytest.approx(res.roads[0].centerline[0, 0])
    (same,) = cover_points(res, res.roads, np.array([[0.0, 150.0]]), reach_m=5.0)
    np.testing.assert_array_equal(same.centerline, res.roads[0].centerline)
    (capped,) = cover_points(res, res.roads, np.array([[310.0, 0.0]]), reach_m=5.0)
    assert capped.centerline[-1, 0] == pytest.approx(300.0, abs=0.5)  # the route ends there
