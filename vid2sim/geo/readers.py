"""GPS readers: GPX, NMEA 0183, BDD100K info JSON, KITTI OXTS and CSV -> one ``GpsTrace``.

One reader per format behind :func:`read_gps`, which picks the reader from the file's CONTENT
(the extension is only a tie-breaker), so ``drive.txt`` holding NMEA or ``log.dat`` holding GPX
are read correctly. Every problem with the input raises :class:`~vid2sim.base.errors.InputError`
naming the file and what is wrong.

Conventions of the record every reader returns (:class:`~vid2sim.core.records.GpsFix`):
time in seconds since the Unix epoch (UTC) on the format's own clock, WGS-84 degrees, speed in
m/s, course in degrees clockwise from north, accuracy as a one-sigma horizontal error in metres.
"""

from __future__ import annotations

import csv
import io
import re
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from vid2sim.base.errors import FormatError, MissingInputError
from vid2sim.base.fileio import parse_json
from vid2sim.core.container import looks_like_container
from vid2sim.core.records import GpsFix, GpsTrace
from vid2sim.geo.embedded import read_cue_file, read_embedded
from vid2sim.geo.gpsfile import KNOTS_TO_MPS, UERE_M, finish_trace, optional_value, read_text
from vid2sim.geo.nmea import nmea_checksum_ok, read_nmea
from vid2sim.geo.oxts import (
    OXTS_ALT,
    OXTS_LAT,
    OXTS_LON,
    OXTS_PITCH,
    OXTS_POS_ACC,
    OXTS_VE,
    OXTS_VF,
    OXTS_VL,
    OXTS_VN,
    OXTS_WZ,
    kitti_time_s,
    read_kitti_oxts,
    read_kitti_oxts_table,
    read_kitti_stamps,
)

__all__ = [
    "KNOTS_TO_MPS",
    "OXTS_ALT",
    "OXTS_LAT",
    "OXTS_LON",
    "OXTS_PITCH",
    "OXTS_POS_ACC",
    "OXTS_VE",
    "OXTS_VF",
    "OXTS_VL",
    "OXTS_VN",
    "OXTS_WZ",
    "UERE_M",
    "kitti_time_s",
    "nmea_checksum_ok",
    "read_bdd_json",
    "read_csv",
    "read_gps",
    "read_gpx",
    "read_kitti_oxts",
    "read_kitti_oxts_table",
    "read_kitti_stamps",
    "read_nmea",
]

_HEAD_BYTES = 64 * 1024


# --------------------------------------------------------------------------- entry point


def read_gps(path: str | Path) -> GpsTrace:
    """Read a GPS file (or a KITTI drive / OXTS folder) into a time-ordered :class:`GpsTrace`.

    Parameters
    ----------
    path
        GPX 1.0/1.1, NMEA 0183 log, BDD100K info JSON, CSV with a header, or a KITTI folder
        (the drive folder containing ``oxts/`` or the ``oxts`` folder itself).

    Returns
    -------
    GpsTrace
        Fixes sorted by ``t_utc_s`` [s since epoch, UTC], duplicates in time removed, with
        ``format`` naming the detected format and ``video_start_utc_s`` set where the format
        records the first video frame's time.

    Raises
    ------
    InputError
        Missing/empty file, unknown format, no usable fixes, unparsable numbers, coordinates
        out of range.
    """
    path = Path(path)
    if not path.exists():
        raise MissingInputError(path, "no such file or folder", "check the path")
    if path.is_dir():
        return read_kitti_oxts(path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(_HEAD_BYTES)
    except OSError as exc:
        raise MissingInputError(path, f"cannot read: {exc.strerror or exc}") from exc
    if not head.strip():
        raise FormatError(path, "empty file", "expected a GPS log (GPX, NMEA, BDD JSON, CSV)")
    if looks_like_container(head):
        return read_embedded(path)  # the GPS inside a video (GoPro, dash-cams)
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff \t\r\n")
    reader = _detect(text, path)
    if reader is None:
        raise FormatError(path, "unknown GPS format",
                         "expected GPX, NMEA 0183, BDD100K info JSON, KITTI OXTS folder or a CSV "
                         "with columns time/lat/lon")
    return reader(path)


def _detect(text: str, path: Path) -> Callable[[Path], GpsTrace] | None:
    """Pick a reader from the first bytes of the file."""
    low = text[:4096].lower()
    if low.startswith("<") and "<gpx" in low:
        return read_gpx
    if low.startswith(("{", "[")):
        return read_bdd_json
    if _NMEA_LINE.search(text[:8192]):
        return read_nmea
    if _SRT_CUE.match(text):
        return read_cue_file  # subtitle telemetry beside a video (DJI, dash-cams)
    first = text.splitlines()[0] if text else ""
    if _csv_header_columns(first) is not None:
        return read_csv
    if path.name == "timestamps.txt" or _OXTS_LINE.match(first):
        raise MissingInputError(path, "looks like a single KITTI OXTS file",
                         "pass the drive folder or its oxts/ folder instead")
    return None


_NMEA_LINE = re.compile(r"\$[A-Z]{2}(RMC|GGA|GSA|GSV|VTG|GLL|ZDA),")  # also after logger prefixes
_SRT_CUE = re.compile(r"\d+\s*\r?\n\s*\d{1,2}:\d{2}:\d{2}[,.]\d{1,3}\s*-->")
_OXTS_LINE = re.compile(r"^\s*-?\d+\.\d+(\s+-?\d+(\.\d+)?([eE][-+]?\d+)?){20,}\s*$")


# --------------------------------------------------------------------------- GPX


def read_gpx(path: Path) -> GpsTrace:
    """GPX 1.0/1.1 tracks and routes (points need ``<time>``), parsed by gpxpy.

    ``<speed>``/``<course>`` (GPX 1.0, or in GPX 1.1 ``<extensions>`` such as Garmin's
    TrackPointExtension) become speed [m/s] and course [deg]; ``<hdop>`` becomes an accuracy
    of HDOP x :data:`UERE_M`.
    """
    import gpxpy
    import gpxpy.gpx

    try:
        gpx = gpxpy.parse(read_text(path))
    except (gpxpy.gpx.GPXException, ValueError) as exc:
        raise FormatError(path, f"not a valid GPX file: {exc}") from exc
    points = [p for track in gpx.tracks for seg in track.segments for p in seg.points]
    points += [p for route in gpx.routes for p in route.points]
    fixes: list[GpsFix] = []
    n_no_time = 0
    for p in points:
        if p.time is None:
            n_no_time += 1
            continue
        t = p.time if p.time.tzinfo is not None else p.time.replace(tzinfo=UTC)
        hdop = optional_value(getattr(p, "horizontal_dilution", None), 0.0, 1e3)
        ext = _gpx_extension_values(p)
        speed = optional_value(getattr(p, "speed", None), 0.0, 1e3)
        course = optional_value(getattr(p, "course", None), 0.0, 360.0)
        fixes.append(GpsFix(
            t_utc_s=t.timestamp(), lat_deg=float(p.latitude), lon_deg=float(p.longitude),
            alt_m=optional_value(p.elevation),
            speed_mps=speed if speed is not None else optional_value(ext.get("speed"), 0.0, 1e3),
            course_deg=course if course is not None else optional_value(ext.get("course"), 0.0, 360.0),
            accuracy_m=None if hdop is None else hdop * UERE_M))
    warnings = []
    if not points:
        raise FormatError(path, "GPX file has no track or route points",
                         "waypoints alone are not a trajectory")
    if n_no_time and not fixes:
        raise FormatError(path, "GPX points carry no <time>",
                         "a trajectory needs timestamps; export the track with times")
    if n_no_time:
        warnings.append(f"skipped {n_no_time} GPX points without <time>")
    return finish_trace(fixes, "gpx", path, n_skipped=n_no_time, warnings=warnings)


def _gpx_extension_values(point) -> dict[str, str]:
    """Speed [m/s] and course [deg] from a point's ``<extensions>``, whatever the namespace:
    Garmin TrackPointExtension v2 (``gpxtpx:speed``, ``gpxtpx:course``) and phone loggers such
    as OsmAnd (``speed``, ``bearing``) put them there in GPX 1.1, which dropped the tags."""
    found: dict[str, str] = {}
    names = {"speed": "speed", "course": "course", "bearing": "course", "heading": "course"}
    for root in getattr(point, "extensions", None) or []:
        for el in root.iter():
            local = str(el.tag).rsplit("}", 1)[-1].lower()
            key = names.get(local)
            if key and key not in found and el.text and el.text.strip():
                found[key] = el.text.strip()
    return found


# --------------------------------------------------------------------------- BDD100K


def read_bdd_json(path: Path) -> GpsTrace:
    """BDD100K info JSON: ``locations`` (or ``gps``) entries with ``timestamp`` [ms since
    epoch], ``latitude``, ``longitude``, ``speed`` [m/s], ``course`` [deg], optional
    ``accuracy`` [m]; ``startTime`` [ms] is the video's first frame.

    Negative speed/course/accuracy mean "invalid" on the phones that recorded BDD and become None.
    """
    data = parse_json(read_text(path), path)
    if not isinstance(data, dict):
        raise FormatError(path, "JSON is not a BDD100K info object",
                         "expected an object with a 'locations' list")
    locs = data.get("locations")
    if not locs and isinstance(data.get("gps"), list):
        locs = data["gps"]
    if not isinstance(locs, list):
        raise FormatError(path, "JSON has no 'locations' list", "is this a BDD100K info file?")
    fixes = []
    n_bad = 0
    for i, loc in enumerate(locs):
        if not isinstance(loc, dict):
            n_bad += 1
            continue
        try:
            t_ms = float(loc["timestamp"])
            lat = float(loc["latitude"])
            lon = float(loc["longitude"])
        except KeyError as exc:
            raise FormatError(path, f"locations[{i}] lacks {exc.args[0]!r}") from exc
        except (TypeError, ValueError, OverflowError) as exc:
            raise FormatError(path, f"locations[{i}]: unparsable number ({exc})") from exc
        fixes.append(GpsFix(t_utc_s=t_ms / 1000.0, lat_deg=lat, lon_deg=lon,
                            alt_m=optional_value(loc.get("altitude")),
                            speed_mps=optional_value(loc.get("speed"), 0.0, 1e3),
                            course_deg=optional_value(loc.get("course"), 0.0, 360.0),
                            accuracy_m=optional_value(loc.get("accuracy"), 0.0, 1e5)))
    start = data.get("startTime")
    start_s = None
    if start is not None:
        try:
            start_s = float(start) / 1000.0
        except (TypeError, ValueError, OverflowError) as exc:
            raise FormatError(path, f"startTime {start!r} is not a number of ms") from exc
    warnings = [f"skipped {n_bad} malformed location entries"] if n_bad else []
    return finish_trace(fixes, "bdd100k", path, n_skipped=n_bad, warnings=warnings,
                   video_start_utc_s=start_s)


# --------------------------------------------------------------------------- CSV

_CSV_ALIASES = {
    "t": ("t", "time", "timestamp", "t_s", "t_utc_s", "time_s", "datetime"),
    "lat": ("lat", "latitude", "lat_deg"),
    "lon": ("lon", "lng", "long", "longitude", "lon_deg"),
    "alt": ("alt", "altitude", "ele", "elevation", "alt_m"),
    "speed": ("speed", "speed_mps"),
    "heading": ("heading", "course", "heading_deg", "course_deg", "bearing"),
    "accuracy": ("accuracy", "accuracy_m", "hacc"),
}


def _csv_split(line: str) -> tuple[list[str], str] | None:
    for delim in (",", ";", "\t"):
        cols = [c.strip().strip('"').strip().lower() for c in line.split(delim)]
        if len(cols) >= 3:
            return cols, delim
    return None


def _csv_header_columns(line: str) -> dict[str, int] | None:
    """Map of canonical column -> index when ``line`` is a CSV header with time, lat, lon."""
    split = _csv_split(line)
    if split is None:
        return None
    cols, _ = split
    found: dict[str, int] = {}
    for key, names in _CSV_ALIASES.items():
        for i, c in enumerate(cols):
            if c in names:
                found[key] = i
                break
    if not all(k in found for k in ("t", "lat", "lon")):
        return None
    return found


def _parse_csv_time(value: str) -> tuple[float, str]:
    """A time cell -> (number, kind) where kind is 'num' (seconds or ms) or 'iso'."""
    try:
        return float(value), "num"
    except ValueError:
        pass
    text = value.strip().replace("Z", "+00:00").replace("z", "+00:00")
    dt = datetime.fromisoformat(text)
    if dt.tzinfo is None:
        dt = dt.replace(tzinfo=UTC)  # a time without a zone is taken as UTC
    return dt.timestamp(), "iso"


def read_csv(path: Path) -> GpsTrace:
    """CSV with a header naming time (``t``/``time``/``timestamp``), ``lat``, ``lon`` and
    optionally ``alt`` [m], ``speed`` [m/s], ``heading`` [deg clockwise from north],
    ``accuracy`` [m]. Delimiter: comma, semicolon or tab.

    Time may be seconds (epoch or relative), milliseconds since the epoch (detected when the
    numbers exceed 1e11, i.e. beyond year 5138 as seconds), or ISO 8601 (no zone = UTC).
    """
    text = read_text(path)
    lines = text.splitlines()
    header = lines[0] if lines else ""
    cols = _csv_header_columns(header)
    split = _csv_split(header)
    if cols is None or split is None:
        raise FormatError(path, "CSV header lacks a time, lat or lon column",
                         "name the columns t|time|timestamp, lat, lon")
    delim = split[1]
    rows = list(csv.reader(io.StringIO(text), delimiter=delim))[1:]
    raw: list[tuple[float, str, float, float, dict[str, float | None]]] = []
    for i, row in enumerate(rows, start=2):
        if not row or all(not c.strip() for c in row):
            continue
        try:
            t, kind = _parse_csv_time(row[cols["t"]])
            lat = float(row[cols["lat"]])
            lon = float(row[cols["lon"]])
        except IndexError as exc:
            raise FormatError(path, f"line {i}: too few columns") from exc
        except (ValueError, OverflowError) as exc:
            raise FormatError(path, f"line {i}: unparsable value ({exc})",
                             "time must be seconds, ms since the epoch or ISO 8601") from exc
        extra: dict[str, float | None] = {}
        for k in ("alt", "speed", "heading", "accuracy"):
            if k in cols and cols[k] < len(row) and row[cols[k]].strip():
                try:
                    extra[k] = float(row[cols[k]])
                except ValueError as exc:
                    raise FormatError(path, f"line {i}: unparsable {k} {row[cols[k]]!r}") from exc
        raw.append((t, kind, lat, lon, extra))
    if not raw:
        raise FormatError(path, "CSV has a header but no rows", "no GPS fixes to read")
    kinds = {r[1] for r in raw}
    if len(kinds) > 1:
        raise FormatError(path, "time column mixes numbers and ISO 8601 dates")
    scale = 1.0
    if kinds == {"num"} and float(np.median([abs(r[0]) for r in raw])) > 1e11:
        scale = 1e-3  # milliseconds since the epoch
    fixes = [GpsFix(t_utc_s=t * scale, lat_deg=lat, lon_deg=lon, alt_m=optional_value(e.get("alt")),
                    speed_mps=optional_value(e.get("speed"), 0.0, 1e3),
                    course_deg=None if optional_value(e.get("heading")) is None else e["heading"] % 360.0,
                    accuracy_m=optional_value(e.get("accuracy"), 0.0, 1e5))
             for t, _, lat, lon, e in raw]
    return finish_trace(fixes, "csv", path)
