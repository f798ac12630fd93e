"""Property tests of the text and box telemetry parsers: subtitle cues (DJI, dash-cams),
BlackVue's stamped NMEA lines and the ISO BMFF box walk (ISO/IEC 14496-12 4.2)."""

from __future__ import annotations

import io
import math
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from vid2sim.base.errors import FormatError
from vid2sim.geo.embedded.cuetext import KMH_TO_MPS, parse_cue
from vid2sim.geo.embedded.mp4boxes import iter_boxes, stamped_lines

_lat = st.floats(-89.9, 89.9, allow_nan=False).filter(lambda v: abs(v) > 1e-3)
_lon = st.floats(-179.9, 179.9, allow_nan=False).filter(lambda v: abs(v) > 1e-3)


@given(_lat, _lon, st.floats(-100, 5000))
def test_dji_cues_read_back(lat, lon, alt):
    text = (f'<font size="28">FrameCnt: 12, DiffTime: 33ms\n2023-05-06 13:21:01.106\n'
            f"[iso : 100] [latitude: {lat:.6f}] [longtitude: {lon:.6f}] "
            f"[rel_alt: 1.300 abs_alt: {alt:.3f}] </font>")
    cue = parse_cue(text)
    assert cue is not None
    assert cue.lat_deg == pytest.approx(lat, abs=1e-6) and cue.lon_deg == pytest.approx(lon, abs=1e-6)
    assert cue.alt_m == pytest.approx(alt, abs=1e-3)


@given(_lat, _lon)
def test_old_dji_gps_is_longitude_first(lat, lon):
    cue = parse_cue(f"HOME(1.0,2.0) 2017.08.05 14:11:51\nGPS({lon:.6f},{lat:.6f},16) BAROMETER:48.7")
    assert cue.lat_deg == pytest.approx(lat, abs=1e-6) and cue.lon_deg == pytest.approx(lon, abs=1e-6)


@given(_lat, _lon, st.floats(0, 250), st.sampled_from(["before", "after"]))
def test_dashcam_cues_with_hemisphere_letters(lat, lon, kmh, style):
    ns, ew = ("N" if lat >= 0 else "S"), ("E" if lon >= 0 else "W")
    pos = (f"{ns}:{abs(lat):.6f} {ew}:{abs(lon):.6f}" if style == "before"
           else f"{abs(lat):.6f}{ns} {abs(lon):.6f}{ew}")
    cue = parse_cue(f"2021/05/08 10:20:30 {pos} {kmh:.0f} km/h")
    assert cue.lat_deg == pytest.approx(lat, abs=1e-6) and cue.lon_deg == pytest.approx(lon, abs=1e-6)
    assert cue.speed_mps == pytest.approx(round(kmh) * KMH_TO_MPS, abs=1e-9)
    assert cue.clock_s is not None


@given(st.text(max_size=200))
def test_any_text_is_a_cue_or_none(text):
    cue = parse_cue(text)  # never raises on text it does not know
    assert cue is None or (math.isfinite(cue.lat_deg) and math.isfinite(cue.lon_deg)
                           and (cue.lat_deg, cue.lon_deg) != (0.0, 0.0))


def test_a_cue_at_0_0_is_no_fix():
    assert parse_cue("[latitude: 0.000000] [longitude: 0.000000]") is None


@given(st.lists(st.tuples(st.integers(10**12, 2 * 10**12), st.text(
    alphabet=st.characters(min_codepoint=33, max_codepoint=126, exclude_characters="[]"),
    min_size=1, max_size=40)), min_size=1, max_size=20))
def test_stamped_lines_keep_each_lines_stamp(entries):
    payload = "".join(f"[{ms}]${body}\n" for ms, body in entries).encode()
    lines, stamps = stamped_lines(payload + b"\x00" * 7)
    assert lines == [f"${body}" for _, body in entries]
    assert stamps == [ms / 1000.0 for ms, _ in entries]


_box = st.tuples(st.text(alphabet="abcdefghijklmnopqrstuvwxyz ", min_size=4, max_size=4),
                 st.binary(max_size=64))


@given(st.lists(_box, max_size=10), st.booleans())
def test_box_walk_recovers_every_box(boxes, large):
    raw = b""
    for kind, payload in boxes:
        if large:
            raw += (1).to_bytes(4, "big") + kind.encode() + (16 + len(payload)).to_bytes(8, "big")
        else:
            raw += (8 + len(payload)).to_bytes(4, "big") + kind.encode()
        raw += payload
    found = list(iter_boxes(io.BytesIO(raw), 0, len(raw), Path("x.mp4")))
    assert [b.type for b in found] == [k for k, _ in boxes]
    assert [b.size for b in found] == [len(p) for _, p in boxes]


@given(st.lists(_box, min_size=1, max_size=5), st.data())
def test_a_truncated_box_is_a_format_error(boxes, data):
    raw = b"".join((8 + len(p)).to_bytes(4, "big") + k.encode() + p for k, p in boxes)
    cut = data.draw(st.integers(1, len(raw) - 1))
    try:
        found = list(iter_boxes(io.BytesIO(raw[:cut]), 0, cut, Path("x.mp4")))
    except FormatError:
        return
    assert len(found) < len(boxes)  # cut at a box boundary (or in the last header's 8 bytes)
