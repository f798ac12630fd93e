"""Readers of GPS formats: known answers per format, malformed input, content-based detection."""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.base.errors import (
    FormatError,
    ImpossibleValueError,
    InconsistentInputError,
    MissingInputError,
)
from vid2sim.geo.readers import (
    KNOTS_TO_MPS,
    UERE_M,
    kitti_time_s,
    nmea_checksum_ok,
    read_gps,
)

T0 = datetime(2024, 5, 17, 9, 0, 0, tzinfo=UTC).timestamp()


# --------------------------------------------------------------------------- helpers


def nmea(body: str) -> str:
    """A sentence with a correct checksum: '$' + body + '*HH'."""
    cs = 0
    for ch in body:
        cs ^= ord(ch)
    return f"${body}*{cs:02X}"


def nmea_coord(value: float, lat: bool) -> tuple[str, str]:
    """Signed degrees -> (ddmm.mmmm / dddmm.mmmm, hemisphere)."""
    hemi = ("N" if value >= 0 else "S") if lat else ("E" if value >= 0 else "W")
    v = abs(value)
    deg = int(v)
    minutes = (v - deg) * 60
    width = 2 if lat else 3
    return f"{deg:0{width}d}{minutes:07.4f}", hemi


def rmc(hhmmss: str, lat: float, lon: float, knots: float, course: float, ddmmyy: str,
        talker: str = "GP", status: str = "A") -> str:
    la, ns = nmea_coord(lat, True)
    lo, ew = nmea_coord(lon, False)
    return nmea(f"{talker}RMC,{hhmmss},{status},{la},{ns},{lo},{ew},{knots:.2f},{course:.1f},"
                f"{ddmmyy},,,A")


def gga(hhmmss: str, lat: float, lon: float, alt: float, hdop: float = 1.0,
        quality: int = 1, talker: str = "GP", geoid: float | None = 18.0) -> str:
    la, ns = nmea_coord(lat, True)
    lo, ew = nmea_coord(lon, False)
    g = "" if geoid is None else f"{geoid:.1f}"
    return nmea(f"{talker}GGA,{hhmmss},{la},{ns},{lo},{ew},{quality},08,{hdop:.1f},{alt:.1f},M,"
                f"{g},M,,")


def gpx_text(version: str = "1.1", points: str = "", routes: bool = False) -> str:
    ns = "http://www.topografix.com/GPX/1/1" if version == "1.1" else \
        "http://www.topografix.com/GPX/1/0"
    body = (f"<rte>{points.replace('trkpt', 'rtept')}</rte>" if routes
            else f"<trk><trkseg>{points}</trkseg></trk>")
    return (f'<?xml version="1.0" encoding="UTF-8"?>\n<gpx version="{version}" creator="test" '
            f'xmlns="{ns}">{body}</gpx>\n')


def gpx_point(lat: float, lon: float, t_s: float, ele: float | None = None,
              extra: str = "") -> str:
    t = datetime.fromtimestamp(t_s, UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    e = f"<ele>{ele}</ele>" if ele is not None else ""
    return f'<trkpt lat="{lat}" lon="{lon}">{e}<time>{t}</time>{extra}</trkpt>'


def write_oxts(folder: Path, rows: list[list[float]], stamps: list[str]) -> Path:
    data = folder / "oxts" / "data"
    data.mkdir(parents=True)
    for i, r in enumerate(rows):
        (data / f"{i:010d}.txt").write_text(" ".join(repr(v) for v in r) + "\n")
    (folder / "oxts" / "timestamps.txt").write_text("\n".join(stamps) + "\n")
    return folder


def oxts_row(lat: float, lon: float, vn: float, ve: float, acc: float = 0.05) -> list[float]:
    r = [0.0] * 30
    r[0], r[1], r[2] = lat, lon, 100.0
    r[6], r[7], r[8] = vn, ve, math.hypot(vn, ve)
    r[23] = acc
    return r


# --------------------------------------------------------------------------- GPX


def test_gpx11_track_times_positions_and_elevation(tmp_path):
    pts = "".join(gpx_point(60.17 + i * 1e-4, 24.94, T0 + i, ele=20.0 + i) for i in range(5))
    f = tmp_path / "drive.gpx"
    f.write_text(gpx_text("1.1", pts))
    tr = read_gps(f)
    assert tr.format == "gpx"
    assert [fx.t_utc_s for fx in tr.fixes] == [T0 + i for i in range(5)]
    assert tr.fixes[2].lat_deg == pytest.approx(60.1702)
    assert tr.fixes[4].alt_m == pytest.approx(24.0)
    assert tr.video_start_utc_s is None


def test_gpx10_speed_course_hdop(tmp_path):
    extra = "<course>90.5</course><speed>12.5</speed><hdop>1.2</hdop>"
    pts = "".join(gpx_point(60.17, 24.94 + i * 1e-4, T0 + i, extra=extra) for i in range(3))
    f = tmp_path / "old.gpx"
    f.write_text(gpx_text("1.0", pts))
    fx = read_gps(f).fixes[0]
    assert fx.speed_mps == pytest.approx(12.5)
    assert fx.course_deg == pytest.approx(90.5)
    assert fx.accuracy_m == pytest.approx(1.2 * UERE_M)


def test_gpx11_extension_speed_and_course(tmp_path):
    tpx = "http://www.garmin.com/xmlschemas/TrackPointExtension/v2"
    extra = (f'<extensions><gpxtpx:TrackPointExtension xmlns:gpxtpx="{tpx}">'
             "<gpxtpx:speed>8.25</gpxtpx:speed><gpxtpx:course>271.5</gpxtpx:course>"
             "</gpxtpx:TrackPointExtension></extensions>")
    osmand = "<extensions><speed>3.5</speed><bearing>10</bearing></extensions>"
    pts = gpx_point(60.17, 24.94, T0, extra=extra) + gpx_point(60.17, 24.941, T0 + 1, extra=osmand)
    f = tmp_path / "ext.gpx"
    f.write_text(gpx_text("1.1", pts))
    a, b = read_gps(f).fixes
    assert (a.speed_mps, a.course_deg) == (pytest.approx(8.25), pytest.approx(271.5))
    assert (b.speed_mps, b.course_deg) == (pytest.approx(3.5), pytest.approx(10.0))


def test_gpx_route_with_times(tmp_path):
    pts = "".join(gpx_point(60.17, 24.94 + i * 1e-4, T0 + 2 * i) for i in range(4))
    f = tmp_path / "route.xml"  # extension says nothing; content does
    f.write_text(gpx_text("1.1", pts, routes=True))
    tr = read_gps(f)
    assert tr.format == "gpx" and len(tr.fixes) == 4
    assert tr.fixes[-1].t_utc_s - tr.fixes[0].t_utc_s == pytest.approx(6.0)


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(-89.9, 89.9), st.floats(-179.9, 179.9),
                          st.floats(-400, 8000)), min_size=1, max_size=15))
def test_gpx_round_trip_property(tmp_path_factory, pts):
    import gpxpy.gpx

    gpx = gpxpy.gpx.GPX()
    seg = gpxpy.gpx.GPXTrackSegment()
    seg.points = [gpxpy.gpx.GPXTrackPoint(la, lo, elevation=el,
                                          time=datetime.fromtimestamp(T0 + i, UTC))
                  for i, (la, lo, el) in enumerate(pts)]
    trk = gpxpy.gpx.GPXTrack()
    trk.segments.append(seg)
    gpx.tracks.append(trk)
    f = tmp_path_factory.mktemp("gpx") / "p.gpx"
    f.write_text(gpx.to_xml())
    fixes = read_gps(f).fixes
    assert [fx.t_utc_s for fx in fixes] == [T0 + i for i in range(len(pts))]
    for fx, (la, lo, el) in zip(fixes, pts, strict=True):
        assert fx.lat_deg == pytest.approx(la, abs=1e-9)
        assert fx.lon_deg == pytest.approx(lo, abs=1e-9)
        assert fx.alt_m == pytest.approx(el, abs=1e-6)


def test_gpx_without_times_is_an_input_error(tmp_path):
    f = tmp_path / "notime.gpx"
    f.write_text(gpx_text("1.1", '<trkpt lat="60.1" lon="24.9"></trkpt>' * 3))
    with pytest.raises(FormatError):  # points without <time>
        read_gps(f)


def test_gpx_broken_xml(tmp_path):
    f = tmp_path / "broken.gpx"
    f.write_text(gpx_text("1.1", gpx_point(60.1, 24.9, T0))[:-20])
    with pytest.raises(FormatError) as e:
        read_gps(f)
    assert "broken.gpx" in str(e.value)


def test_gpx_latitude_out_of_range(tmp_path):
    f = tmp_path / "bad.gpx"
    f.write_text(gpx_text("1.1", gpx_point(95.0, 24.9, T0) + gpx_point(60.0, 24.9, T0 + 1)))
    with pytest.raises(ImpossibleValueError, match="fix 1"):  # latitude 95
        read_gps(f)


# --------------------------------------------------------------------------- NMEA


def test_nmea_checksum_known_sentence():
    # A widely quoted example sentence with its published checksum.
    s = "$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47"
    assert nmea_checksum_ok(s)
    assert not nmea_checksum_ok(s.replace("545.4", "545.5"))
    assert not nmea_checksum_ok(s.split("*")[0])


def test_nmea_rmc_gga_merge(tmp_path):
    lines = []
    for i in range(4):
        hh = f"0900{i:02d}.00"
        lines.append(gga(hh, 60.17 + i * 1e-4, 24.94, 10.0 + i, hdop=0.8))
        lines.append(rmc(hh, 60.17 + i * 1e-4, 24.94, 10.0, 45.0, "170524"))
    f = tmp_path / "log.nmea"
    f.write_text("\r\n".join(lines) + "\r\n")
    tr = read_gps(f)
    assert tr.format == "nmea" and len(tr.fixes) == 4 and tr.n_skipped == 0
    fx = tr.fixes[1]
    assert fx.t_utc_s == pytest.approx(T0 + 1)
    assert fx.lat_deg == pytest.approx(60.1701, abs=1e-7)
    assert fx.speed_mps == pytest.approx(10.0 * KNOTS_TO_MPS)
    assert fx.course_deg == pytest.approx(45.0)
    assert fx.alt_m == pytest.approx(11.0 + 18.0)  # MSL + geoid separation = ellipsoidal
    assert fx.accuracy_m == pytest.approx(0.8 * UERE_M)


def test_nmea_bad_checksum_void_and_garbage_are_counted_and_skipped(tmp_path):
    good = [rmc(f"0900{i:02d}", 60.17, 24.94 + i * 1e-4, 5.0, 90.0, "170524", talker="GN")
            for i in range(5)]
    corrupt = good[2][:20] + "X" + good[2][21:]  # checksum no longer matches
    lines = [good[0], good[1], corrupt, good[3], good[4][:30],  # truncated: no checksum
             rmc("090010", 60.17, 24.94, 0.0, 0.0, "170524", status="V"),
             gga("090011", 60.17, 24.94, 5.0, quality=0),
             "garbage line", nmea("GPGSV,3,1,11,03,03,111,00"), good[4]]
    f = tmp_path / "noisy.txt"
    f.write_text("\n".join(lines))
    tr = read_gps(f)
    assert len(tr.fixes) == 4  # 0, 1, 3, 4
    assert tr.n_skipped == 4  # corrupt, truncated, void RMC, no-fix GGA
    assert any("checksum" in w for w in tr.warnings)


def test_nmea_lines_with_logger_prefixes(tmp_path):
    f = tmp_path / "prefixed.log"
    f.write_text("\n".join(f"2024-05-17 09:00:0{i} INFO " + rmc(f"0900{i:02d}", 60, 24, 1, 1, "170524")
                           for i in range(3)))
    tr = read_gps(f)
    assert tr.format == "nmea" and len(tr.fixes) == 3


def test_nmea_southern_western_hemispheres(tmp_path):
    f = tmp_path / "sw.nmea"
    f.write_text("\n".join(rmc(f"1200{i:02d}", -33.8688, -151.2093 + i * 1e-4, 1, 1, "010124")
                           for i in range(3)))
    fx = read_gps(f).fixes[0]
    assert fx.lat_deg == pytest.approx(-33.8688, abs=1e-6)
    assert fx.lon_deg == pytest.approx(-151.2093, abs=1e-6)


def test_nmea_midnight_rollover(tmp_path):
    lines = [rmc("235958", 60.0, 24.0, 1, 0, "311224"), rmc("235959", 60.0, 24.0, 1, 0, "311224"),
             rmc("000000", 60.0, 24.0, 1, 0, "010125"), gga("000001", 60.0, 24.0, 1.0)]
    f = tmp_path / "midnight.nmea"
    f.write_text("\n".join(lines))
    t = [fx.t_utc_s for fx in read_gps(f).fixes]
    assert t[1] - t[0] == pytest.approx(1.0)
    assert t[2] - t[1] == pytest.approx(1.0)
    assert t[3] - t[2] == pytest.approx(1.0)  # the GGA-only epoch inherits the new date


def test_nmea_gga_only_has_no_date_but_consistent_times(tmp_path):
    f = tmp_path / "gga.log"
    f.write_text("\n".join(gga(f"1000{i:02d}.50", 60.0, 24.0 + i * 1e-4, 12.0, geoid=None)
                           for i in range(3)))
    tr = read_gps(f)
    assert [fx.t_utc_s for fx in tr.fixes] == pytest.approx([36000.5, 36001.5, 36002.5])
    assert tr.fixes[0].alt_m == pytest.approx(12.0)  # no geoid separation given: as reported
    assert tr.fixes[0].speed_mps is None
    assert any("date" in w for w in tr.warnings)


def test_nmea_only_corrupt_is_an_input_error(tmp_path):
    f = tmp_path / "bad.nmea"
    f.write_text("\n".join(rmc("090000", 60, 24, 1, 1, "170524")[:-2] + "00" for _ in range(3)))
    with pytest.raises(FormatError):  # every sentence fails its checksum
        read_gps(f)


@settings(max_examples=60, deadline=None)
@given(lat=st.floats(-89.99, 89.99), lon=st.floats(-179.99, 179.99),
       knots=st.floats(0, 150), course=st.floats(0, 359.9))
def test_nmea_rmc_round_trip_property(tmp_path_factory, lat, lon, knots, course):
    f = tmp_path_factory.mktemp("nmea") / "p.nmea"
    f.write_text("\n".join(rmc(f"0900{i:02d}", lat, lon, knots, course, "170524")
                           for i in range(2)))
    fx = read_gps(f).fixes[0]
    # ddmm.mmmm keeps 1e-4 minutes = 1.7e-6 deg.
    assert fx.lat_deg == pytest.approx(lat, abs=2e-6)
    assert fx.lon_deg == pytest.approx(lon, abs=2e-6)
    assert fx.speed_mps == pytest.approx(round(knots, 2) * KNOTS_TO_MPS, abs=1e-9)


# --------------------------------------------------------------------------- BDD100K


def bdd(locs: list[dict], start_ms: float | None = None) -> str:
    d: dict = {"rideID": "x", "locations": locs}
    if start_ms is not None:
        d["startTime"] = start_ms
    return json.dumps(d)


def test_bdd_locations_and_start_time(tmp_path):
    locs = [{"timestamp": T0 * 1000 + 1000 * i, "latitude": 40.7 + i * 1e-4, "longitude": -74.0,
             "speed": 8.0 if i else -1.0, "course": 12.0, "accuracy": 5.0} for i in range(4)]
    f = tmp_path / "a.json"
    f.write_text(bdd(locs, start_ms=T0 * 1000 - 500))
    tr = read_gps(f)
    assert tr.format == "bdd100k"
    assert tr.video_start_utc_s == pytest.approx(T0 - 0.5)
    assert tr.fixes[0].speed_mps is None  # -1 means invalid
    assert tr.fixes[1].speed_mps == pytest.approx(8.0)
    assert tr.fixes[1].course_deg == pytest.approx(12.0)
    assert tr.fixes[3].t_utc_s == pytest.approx(T0 + 3)


def test_bdd_errors(tmp_path):
    f = tmp_path / "b.json"
    f.write_text(json.dumps({"foo": 1}))
    with pytest.raises(FormatError, match="locations"):  # names the missing key
        read_gps(f)
    f.write_text('{"locations": [{"timestamp": 1, "latitude": "north", "longitude": 2}]}')
    with pytest.raises(FormatError, match=r"locations\[0\]"):
        read_gps(f)
    f.write_text('{"locations": [}')
    with pytest.raises(FormatError, match="line 1"):
        read_gps(f)
    f.write_text('{"locations": []}')
    with pytest.raises(FormatError):  # no fix to read
        read_gps(f)


# --------------------------------------------------------------------------- KITTI OXTS


def test_kitti_synthetic_folder_speed_course_and_video_start(tmp_path):
    rows = [oxts_row(49.0 + i * 1e-5, 8.4, vn=3.0, ve=4.0) for i in range(3)]
    stamps = [f"2011-09-26 13:02:2{i}.500000000" for i in range(3)]
    write_oxts(tmp_path, rows, stamps)
    (tmp_path / "image_00_timestamps.txt").write_text("2011-09-26 13:02:20.600000000\n")
    for p in (tmp_path, tmp_path / "oxts"):
        tr = read_gps(p)
        assert tr.format == "kitti_oxts" and len(tr.fixes) == 3
        fx = tr.fixes[0]
        assert fx.speed_mps == pytest.approx(5.0)
        assert fx.course_deg == pytest.approx(math.degrees(math.atan2(4.0, 3.0)))
        assert fx.accuracy_m == pytest.approx(0.05)
        assert tr.video_start_utc_s - fx.t_utc_s == pytest.approx(0.1, abs=1e-6)


def test_kitti_camera_folder_timestamps(tmp_path):
    write_oxts(tmp_path, [oxts_row(49, 8.4, 1, 0)] * 2,
               ["2011-09-26 13:02:20.0", "2011-09-26 13:02:20.1"])
    (tmp_path / "image_02").mkdir()
    (tmp_path / "image_02" / "timestamps.txt").write_text("2011-09-26 13:02:19.950000000\n")
    tr = read_gps(tmp_path)
    assert tr.video_start_utc_s - tr.fixes[0].t_utc_s == pytest.approx(-0.05, abs=1e-6)


def test_kitti_errors(tmp_path):
    write_oxts(tmp_path, [oxts_row(49, 8.4, 1, 0)] * 2, ["2011-09-26 13:02:20.0"])
    with pytest.raises(InconsistentInputError, match="1 timestamps for 2 data files"):
        read_gps(tmp_path)
    other = tmp_path / "empty_dir"
    other.mkdir()
    with pytest.raises(MissingInputError):  # a folder without OXTS files
        read_gps(other)


def test_kitti_timestamp_keeps_nanoseconds():
    a = kitti_time_s("2011-09-26 13:02:25.964389445")
    b = kitti_time_s("2011-09-26 13:02:26.074347616")
    assert b - a == pytest.approx(0.109958171, abs=1e-6)


def test_kitti_real_drive(kitti_raw_dir):
    tr = read_gps(kitti_raw_dir)
    assert tr.format == "kitti_oxts"
    assert len(tr.fixes) == len(list((kitti_raw_dir / "oxts" / "data").glob("*.txt")))
    dt = [b.t_utc_s - a.t_utc_s for a, b in zip(tr.fixes, tr.fixes[1:], strict=False)]
    assert 0.09 < sorted(dt)[len(dt) // 2] < 0.11  # 10 Hz
    assert tr.video_start_utc_s is not None
    assert abs(tr.video_start_utc_s - tr.fixes[0].t_utc_s) < 0.1
    assert 48.9 < tr.fixes[0].lat_deg < 49.1 and 8.3 < tr.fixes[0].lon_deg < 8.5  # Karlsruhe


# --------------------------------------------------------------------------- CSV


@pytest.mark.parametrize("tcol,cells,expect", [
    ("t", ["0", "1.5", "3"], [0.0, 1.5, 3.0]),
    ("time", [str(T0), str(T0 + 1), str(T0 + 2)], [T0, T0 + 1, T0 + 2]),
    ("timestamp", [str(int(T0 * 1000)), str(int(T0 * 1000) + 500), str(int(T0 * 1000) + 1000)],
     [T0, T0 + 0.5, T0 + 1.0]),
    ("Time", ["2024-05-17T09:00:00Z", "2024-05-17T09:00:01Z", "2024-05-17T11:00:02+02:00"],
     [T0, T0 + 1, T0 + 2]),
])
def test_csv_time_formats(tmp_path, tcol, cells, expect):
    rows = "\n".join(f"{c},60.17,{24.94 + i * 1e-4}" for i, c in enumerate(cells))
    f = tmp_path / "g.csv"
    f.write_text(f"{tcol},lat,lon\n{rows}\n")
    tr = read_gps(f)
    assert tr.format == "csv"
    assert [fx.t_utc_s for fx in tr.fixes] == pytest.approx(expect)


def test_csv_optional_columns_semicolon_and_order(tmp_path):
    f = tmp_path / "g.txt"
    f.write_text("latitude;longitude;timestamp;alt;speed;heading\n"
                 "60.1;24.9;2;5;3.5;370\n60.1;24.9;1;;;\n")
    tr = read_gps(f)
    assert [fx.t_utc_s for fx in tr.fixes] == [1.0, 2.0]
    assert tr.fixes[0].speed_mps is None and tr.fixes[0].alt_m is None
    assert tr.fixes[1].speed_mps == 3.5 and tr.fixes[1].course_deg == pytest.approx(10.0)
    assert any("sorted" in w for w in tr.warnings)


def test_csv_duplicate_times_dropped(tmp_path):
    f = tmp_path / "d.csv"
    f.write_text("t,lat,lon\n0,60,24\n1,60,24\n1,60.1,24\n2,60,24\n")
    tr = read_gps(f)
    assert [fx.t_utc_s for fx in tr.fixes] == [0, 1, 2]
    assert tr.n_skipped == 1


@pytest.mark.parametrize("content,error,where", [
    ("t,lat,lon\n0,60,24\n1,abc,24\n", FormatError, "line 3"),
    ("t,lat,lon\n0,60,24\n1,60,200\n", ImpossibleValueError, "fix 2"),  # longitude 200
    ("t,lat,lon\n", FormatError, ""),  # a header, no rows
    ("t,lat,lon\n0,60\n", FormatError, "line 2"),
    ("t,lat,lon\n0,60,24\n2024-01-01T00:00:00,60,24\n", FormatError, ""),  # mixed times
])
def test_csv_malformed(tmp_path, content, error, where):
    f = tmp_path / "bad.csv"
    f.write_text(content)
    with pytest.raises(error, match=where) as e:
        read_gps(f)
    assert "bad.csv" in str(e.value)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-89, 89), st.floats(-179, 179)), min_size=1, max_size=20))
def test_csv_round_trip_property(tmp_path_factory, pts):
    f = tmp_path_factory.mktemp("csv") / "p.csv"
    f.write_text("t,lat,lon\n" + "".join(f"{i},{la!r},{lo!r}\n" for i, (la, lo) in enumerate(pts)))
    tr = read_gps(f)
    assert [(fx.lat_deg, fx.lon_deg) for fx in tr.fixes] == pts


# --------------------------------------------------------------------------- detection


def test_unknown_empty_and_missing(tmp_path):
    f = tmp_path / "x.gpx"
    f.write_text("")
    with pytest.raises(FormatError):  # an empty file
        read_gps(f)
    f.write_text("hello world\nthis is not GPS\n")
    with pytest.raises(FormatError):  # no GPS format
        read_gps(f)
    with pytest.raises(MissingInputError):
        read_gps(tmp_path / "missing.gpx")


def test_detection_ignores_misleading_extension(tmp_path):
    f = tmp_path / "track.gpx"  # really NMEA
    f.write_text("\n".join(rmc(f"0900{i:02d}", 60, 24, 1, 1, "170524") for i in range(2)))
    assert read_gps(f).format == "nmea"
    g = tmp_path / "track.nmea"  # really CSV
    g.write_text("time,lat,lon\n0,60,24\n1,60,24\n")
    assert read_gps(g).format == "csv"


def test_single_oxts_file_gets_a_hint(tmp_path):
    f = tmp_path / "0000000000.txt"
    f.write_text(" ".join(repr(v) for v in oxts_row(49.0, 8.4, 1.0, 1.0)))  # as OXTS writes
    with pytest.raises(MissingInputError, match="drive folder"):  # a file, not the folder
        read_gps(f)
