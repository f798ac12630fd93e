"""Every GPS reader, and the smoother after it, on arbitrary and damaged bytes: a trace or the
project's InputError, nothing else; deep JSON, huge times, impossible jumps."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.damage import FUZZ, damaged, input_error_or_result
from vid2sim.base.errors import FormatError, ImpossibleValueError, InconsistentInputError
from vid2sim.geo.readers import read_gps
from vid2sim.geo.trace import smooth_ego
from vid2sim.samples.sample_gps import SAMPLE_START_UTC_S

T0 = SAMPLE_START_UTC_S


def _read_and_smooth(path: Path):
    """What `vid2sim trace` does with a GPS file."""
    trace = read_gps(path)
    return smooth_ego(trace)


def _bdd() -> bytes:
    locs = [{"timestamp": T0 * 1000 + 1000 * i, "latitude": 40.7 + i * 1e-4,
             "longitude": -74.0, "speed": 8.0, "course": 12.0, "accuracy": 5.0}
            for i in range(6)]
    return json.dumps({"startTime": T0 * 1000, "locations": locs}).encode()


def _csv() -> bytes:
    rows = [f"{T0 + i},{60.17 + i * 1e-4:.6f},24.94,{5 + i},10.0,90.0" for i in range(6)]
    return ("t,lat,lon,alt,speed,heading\n" + "\n".join(rows) + "\n").encode()


def _sentence(body: str) -> str:
    checksum = 0
    for ch in body:
        checksum ^= ord(ch)
    return f"${body}*{checksum:02X}"


def _nmea() -> bytes:
    lines = []
    for i in range(6):
        lat = f"6010.{2000 + 6 * i:04d}"
        lines += [_sentence(f"GPRMC,0900{i:02d}.00,A,{lat},N,02456.4000,E,10.00,45.0,170524,,,A"),
                  _sentence(f"GPGGA,0900{i:02d}.00,{lat},N,02456.4000,E,1,08,1.0,12.0,M,18.0,M,,")]
    return ("\n".join(lines) + "\n").encode()


def _gpx() -> bytes:
    pts = "".join(f'<trkpt lat="{60.17 + i * 1e-4:.5f}" lon="24.94"><ele>10.0</ele>'
                  f"<time>2024-05-17T09:00:0{i}Z</time></trkpt>" for i in range(6))
    return ('<?xml version="1.0" encoding="UTF-8"?>\n<gpx version="1.1" creator="test" '
            'xmlns="http://www.topografix.com/GPX/1/1"><trk><trkseg>' + pts
            + "</trkseg></trk></gpx>\n").encode()


def _oxts_line(lat: float) -> str:
    row = [0.0] * 30
    row[0], row[1], row[2], row[6], row[7], row[8], row[23] = lat, 8.4, 100.0, 3.0, 4.0, 5.0, 0.05
    return " ".join(repr(v) for v in row) + "\n"


@pytest.mark.parametrize("sample,name", [(_bdd, "info.json"), (_csv, "trace.csv"),
                                         (_nmea, "log.nmea"), (_gpx, "track.gpx")])
@FUZZ
@given(data=st.data())
def test_gps_file_damage_gives_input_error_only(tmp_path, sample, name, data):
    path = tmp_path / name
    path.write_bytes(data.draw(damaged(sample())))
    input_error_or_result(_read_and_smooth, path)


@FUZZ
@given(data=st.data(), which=st.sampled_from(["data", "timestamps", "camera"]))
def test_kitti_oxts_damage_gives_input_error_only(tmp_path, data, which):
    drive = tmp_path / "drive"
    shutil.rmtree(drive, ignore_errors=True)
    (drive / "oxts" / "data").mkdir(parents=True)
    for i in range(5):
        (drive / "oxts" / "data" / f"{i:010d}.txt").write_text(_oxts_line(49.0 + i * 1e-5))
    (drive / "oxts" / "timestamps.txt").write_text(
        "".join(f"2011-09-26 13:02:2{i}.500000000\n" for i in range(5)))
    (drive / "image_00_timestamps.txt").write_text("2011-09-26 13:02:20.600000000\n")
    target = {"data": sorted((drive / "oxts" / "data").glob("*.txt"))[2],
              "timestamps": drive / "oxts" / "timestamps.txt",
              "camera": drive / "image_00_timestamps.txt"}[which]
    target.write_bytes(data.draw(damaged(target.read_bytes())))
    input_error_or_result(_read_and_smooth, drive)


def test_json_nested_100000_deep_is_an_input_error(tmp_path):
    path = tmp_path / "deep.json"
    path.write_text('{"locations": ' + "[" * 100_000 + "]" * 100_000 + "}")
    with pytest.raises(FormatError):  # nested too deeply for the parser
        read_gps(path)


@pytest.mark.parametrize("t,error", [("1e300", ImpossibleValueError),  # not a time
                                     ("-1e300", ImpossibleValueError),
                                     ("1e12", InconsistentInputError)])  # as ms: 31 years
def test_fix_time_that_is_not_a_time_is_an_input_error(tmp_path, t, error):
    path = tmp_path / "t.csv"
    path.write_text(f"t,lat,lon\n0,60.17,24.94\n{t},60.171,24.94\n")
    with pytest.raises(error):
        read_gps(path)


def test_a_trace_longer_than_a_day_is_an_input_error(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text(f"t,lat,lon\n{T0},60.17,24.94\n{T0 + 3 * 86400},60.171,24.94\n")
    with pytest.raises(InconsistentInputError):  # three days are not one drive
        read_gps(path)
