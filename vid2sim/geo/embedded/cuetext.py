"""Telemetry written as subtitle text (SRT cues, ``mov_text`` samples): one fix per cue.

Drones and many dash-cams write their position into a subtitle track (or a sidecar ``.SRT``
file) whose cues span the frames they describe, so a cue's start is the fix's time on the
video clock. The text is not standardised; the layouts read here, with their sources:

- DJI (Mavic 2/3, Mini, Air 2, FPV): ``[latitude: 22.543096] [longitude: 113.958805]``
  (some firmware spells ``longtitude``), ``[rel_alt: 1.3 abs_alt: 15.6]`` or
  ``[altitude: 15.6]``, and a line ``2023-05-06 13:21:01.106`` (local time); described in the
  README of JuanIrache/DJI_SRT_Parser and in G. Walzl's ``dji_fpv_srt_telemetry.py`` notes.
- DJI (Phantom 3/4, older Mavic): ``GPS(113.9588,22.5431,15)`` = longitude, latitude,
  altitude, and ``2017.08.05 14:11:51``; same sources.
- Dash-cams: a date and time (``2021/05/08 10:20:30``), the position with hemisphere letters
  (``N:51.123456 E:7.123456``, ``N51.123456 E7.123456`` or ``51.123456N 7.123456E``) and a
  speed (``52 km/h`` or ``32 mph``).

The cue's date-time, where present, is the camera's clock (often local time): it is kept only
to place the fixes on a calendar, never to time them against the video.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from datetime import UTC, datetime

KMH_TO_MPS = 1000.0 / 3600.0
MPH_TO_MPS = 1609.344 / 3600.0

_NUM = r"[-+]?\d+(?:\.\d+)?"
_DJI_LAT = re.compile(rf"\[\s*latitude\s*:\s*({_NUM})", re.IGNORECASE)
_DJI_LON = re.compile(rf"\[?\s*long?t?itude\s*:\s*({_NUM})", re.IGNORECASE)
_DJI_ALT = re.compile(rf"(?:abs_alt|altitude)\s*:\s*({_NUM})", re.IGNORECASE)
_DJI_GPS = re.compile(rf"GPS\s*\(\s*({_NUM})\s*,\s*({_NUM})\s*(?:,\s*({_NUM}))?\s*\)")
_HEMI_BEFORE = re.compile(r"\b([NS])\s*:?\s*(\d+(?:\.\d+)?)\s*[,;]?\s*([EW])\s*:?\s*(\d+(?:\.\d+)?)")
_HEMI_AFTER = re.compile(r"(\d+(?:\.\d+)?)\s*([NS])\b\s*[,;]?\s*(\d+(?:\.\d+)?)\s*([EW])\b")
_SPEED = re.compile(rf"({_NUM})\s*(km/h|kmh|kph|mph)", re.IGNORECASE)
_DATETIME = re.compile(r"(\d{4})[-/.](\d{2})[-/.](\d{2})[ T]+(\d{2}):(\d{2}):(\d{2})(?:[.,](\d+))?")
_TAGS = re.compile(r"<[^>]*>")


@dataclass(frozen=True, slots=True)
class CueFix:
    """What one cue says: position [deg], altitude [m], speed [m/s], clock time [s since the
    epoch, the camera's clock read as UTC]; None where the cue does not say."""

    lat_deg: float
    lon_deg: float
    alt_m: float | None = None
    speed_mps: float | None = None
    clock_s: float | None = None


def parse_cue(text: str) -> CueFix | None:
    """The fix one cue's text holds, or None (a cue without a position, or a position of
    0, 0: receivers without a lock write zeros).

    Raises
    ------
    ValueError
        Never for unknown text (None); only numbers that do not parse as numbers.
    """
    text = _TAGS.sub(" ", text)
    position = _position(text)
    if position is None:
        return None
    lat, lon, alt = position
    if lat == 0.0 and lon == 0.0:
        return None
    speed = None
    if (m := _SPEED.search(text)) is not None:
        factor = MPH_TO_MPS if m.group(2).lower() == "mph" else KMH_TO_MPS
        speed = float(m.group(1)) * factor
    return CueFix(lat_deg=lat, lon_deg=lon, alt_m=alt, speed_mps=speed, clock_s=_clock(text))


def _position(text: str) -> tuple[float, float, float | None] | None:
    lat_m, lon_m = _DJI_LAT.search(text), _DJI_LON.search(text)
    if lat_m and lon_m:
        alt_m = _DJI_ALT.search(text)
        return float(lat_m.group(1)), float(lon_m.group(1)), (
            float(alt_m.group(1)) if alt_m else None)
    if (m := _DJI_GPS.search(text)) is not None:
        # DJI's GPS(...) is longitude first
        return float(m.group(2)), float(m.group(1)), (
            float(m.group(3)) if m.group(3) else None)
    if (m := _HEMI_BEFORE.search(text)) is not None:
        return _signed(m.group(2), m.group(1)), _signed(m.group(4), m.group(3)), None
    if (m := _HEMI_AFTER.search(text)) is not None:
        return _signed(m.group(1), m.group(2)), _signed(m.group(3), m.group(4)), None
    return None


def _signed(value: str, hemisphere: str) -> float:
    v = float(value)
    return -v if hemisphere in ("S", "W") else v


def _clock(text: str) -> float | None:
    m = _DATETIME.search(text)
    if m is None:
        return None
    y, mo, d, h, mi, s = (int(m.group(k)) for k in range(1, 7))
    frac = float("0." + m.group(7)[:6]) if m.group(7) else 0.0
    try:
        return datetime(y, mo, d, h, mi, s, tzinfo=UTC).timestamp() + frac
    except ValueError:
        return None
