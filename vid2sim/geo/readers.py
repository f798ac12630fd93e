"""GPS readers: GPX, NMEA 0183, BDD100K info JSON, KITTI OXTS and CSV -> one ``GpsTrace``.

One reader per format behind :func:`read_gps`, which picks the reader from the file's CONTENT
(the extension is only a tie-breaker), so ``drive.txt`` holding NMEA or ``log.dat`` holding GPX
are read correctly. Every problem with the input raises :class:`~vid2sim.errors.InputError`
naming the file and what is wrong.

Conventions of the record every reader returns (:class:`~vid2sim.records.GpsFix`):
time in seconds since the Unix epoch (UTC) on the format's own clock, WGS-84 degrees, speed in
m/s, course in degrees clockwise from north, accuracy as a one-sigma horizontal error in metres.
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from vid2sim.errors import InputError
from vid2sim.records import GpsFix, GpsTrace

KNOTS_TO_MPS = 1852.0 / 3600.0
# A receiver's user-equivalent range error: horizontal one-sigma accuracy ~ HDOP x UERE.
# 5 m is a typical value for an uncorrected single-frequency consumer receiver; it only sets
# the relative weight of fixes in the smoother, so a rough value is enough.
UERE_M = 5.0
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
        raise InputError(path, "no such file or folder", "check the path")
    if path.is_dir():
        return read_kitti_oxts(path)
    try:
        head = path.read_bytes()[:_HEAD_BYTES]
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror or exc}") from exc
    if not head.strip():
        raise InputError(path, "empty file", "expected a GPS log (GPX, NMEA, BDD JSON, CSV)")
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff \t\r\n")
    reader = _detect(text, path)
    if reader is None:
        raise InputError(path, "unknown GPS format",
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
    first = text.splitlines()[0] if text else ""
    if _csv_header_columns(first) is not None:
        return read_csv
    if path.name == "timestamps.txt" or _OXTS_LINE.match(first):
        raise InputError(path, "looks like a single KITTI OXTS file",
                         "pass the drive folder or its oxts/ folder instead")
    return None


_NMEA_LINE = re.compile(r"\$[A-Z]{2}(RMC|GGA|GSA|GSV|VTG|GLL|ZDA),")  # also after logger prefixes
_OXTS_LINE = re.compile(r"^\s*-?\d+\.\d+(\s+-?\d+(\.\d+)?([eE][-+]?\d+)?){20,}\s*$")


# --------------------------------------------------------------------------- shared checks


def _finish(fixes: list[GpsFix], fmt: str, path: Path, n_skipped: int = 0,
            warnings: list[str] | None = None,
            video_start_utc_s: float | None = None) -> GpsTrace:
    """Validate ranges, sort by time, drop duplicate times, and wrap into a GpsTrace."""
    warnings = list(warnings or [])
    if not fixes:
        raise InputError(path, f"no usable GPS fixes in this {fmt} file"
                         + (f" ({n_skipped} records skipped)" if n_skipped else ""),
                         "is the receiver reporting a fix, and do the records carry a time?")
    for i, f in enumerate(fixes):
        if not (math.isfinite(f.t_utc_s) and math.isfinite(f.lat_deg) and math.isfinite(f.lon_deg)):
            raise InputError(path, f"fix {i + 1}: time or position is not a finite number")
        if not -90.0 <= f.lat_deg <= 90.0:
            raise InputError(path, f"fix {i + 1}: latitude {f.lat_deg} outside [-90, 90]",
                             "are lat and lon swapped?")
        if not -180.0 <= f.lon_deg <= 180.0:
            raise InputError(path, f"fix {i + 1}: longitude {f.lon_deg} outside [-180, 180]")
    times = [f.t_utc_s for f in fixes]
    if any(b < a for a, b in itertools.pairwise(times)):
        warnings.append("fixes were not in time order; sorted them by time")
        fixes = sorted(fixes, key=lambda f: f.t_utc_s)
    unique: list[GpsFix] = [fixes[0]]
    n_dup = 0
    for f in fixes[1:]:
        # Loggers repeat a fix (same time) when the receiver has no new one; keep the first.
        if f.t_utc_s <= unique[-1].t_utc_s:
            n_dup += 1
            continue
        unique.append(f)
    if n_dup:
        warnings.append(f"dropped {n_dup} fixes repeating an earlier time")
    return GpsTrace(fixes=unique, format=fmt, path=path, video_start_utc_s=video_start_utc_s,
                    n_skipped=n_skipped + n_dup, warnings=warnings)


def _read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8", errors="replace").lstrip("\ufeff")
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror or exc}") from exc


def _opt(value: float | None, lo: float = -math.inf, hi: float = math.inf) -> float | None:
    """A finite value inside [lo, hi], else None (for optional fields such as speed)."""
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) and lo <= v <= hi else None


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
        gpx = gpxpy.parse(_read_text(path))
    except (gpxpy.gpx.GPXException, ValueError) as exc:
        raise InputError(path, f"not a valid GPX file: {exc}") from exc
    points = [p for track in gpx.tracks for seg in track.segments for p in seg.points]
    points += [p for route in gpx.routes for p in route.points]
    fixes: list[GpsFix] = []
    n_no_time = 0
    for p in points:
        if p.time is None:
            n_no_time += 1
            continue
        t = p.time if p.time.tzinfo is not None else p.time.replace(tzinfo=UTC)
        hdop = _opt(getattr(p, "horizontal_dilution", None), 0.0, 1e3)
        ext = _gpx_extension_values(p)
        speed = _opt(getattr(p, "speed", None), 0.0, 1e3)
        course = _opt(getattr(p, "course", None), 0.0, 360.0)
        fixes.append(GpsFix(
            t_utc_s=t.timestamp(), lat_deg=float(p.latitude), lon_deg=float(p.longitude),
            alt_m=_opt(p.elevation),
            speed_mps=speed if speed is not None else _opt(ext.get("speed"), 0.0, 1e3),
            course_deg=course if course is not None else _opt(ext.get("course"), 0.0, 360.0),
            accuracy_m=None if hdop is None else hdop * UERE_M))
    warnings = []
    if not points:
        raise InputError(path, "GPX file has no track or route points",
                         "waypoints alone are not a trajectory")
    if n_no_time and not fixes:
        raise InputError(path, "GPX points carry no <time>",
                         "a trajectory needs timestamps; export the track with times")
    if n_no_time:
        warnings.append(f"skipped {n_no_time} GPX points without <time>")
    return _finish(fixes, "gpx", path, n_skipped=n_no_time, warnings=warnings)


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


# --------------------------------------------------------------------------- NMEA


@dataclass(slots=True)
class _NmeaEpoch:
    tod_s: float
    date: tuple[int, int, int] | None = None
    lat: float | None = None
    lon: float | None = None
    alt_m: float | None = None
    speed_mps: float | None = None
    course_deg: float | None = None
    accuracy_m: float | None = None


def nmea_checksum_ok(sentence: str) -> bool:
    """True when ``$BODY*HH`` carries the XOR of BODY's characters as two hex digits."""
    if not sentence.startswith("$") or "*" not in sentence:
        return False
    body, _, given = sentence[1:].rpartition("*")
    given = given.strip()
    if len(given) != 2:
        return False
    acc = 0
    for ch in body:
        acc ^= ord(ch)
    try:
        return acc == int(given, 16)
    except ValueError:
        return False


def _nmea_tod(field: str) -> float:
    """hhmmss(.sss) -> seconds of the day."""
    if len(field) < 6:
        raise ValueError(field)
    h, m, s = int(field[0:2]), int(field[2:4]), float(field[4:])
    if not (h < 24 and m < 60 and s < 61):
        raise ValueError(field)
    return h * 3600 + m * 60 + s


def _nmea_coord(value: str, hemi: str, deg_digits: int) -> float:
    """ddmm.mmmm (lat) / dddmm.mmmm (lon) with hemisphere letter -> signed degrees."""
    deg = int(value[:deg_digits])
    minutes = float(value[deg_digits:])
    if minutes >= 60:
        raise ValueError(value)
    v = deg + minutes / 60.0
    if hemi in ("S", "W"):
        return -v
    if hemi not in ("N", "E"):
        raise ValueError(hemi)
    return v


def read_nmea(path: Path) -> GpsTrace:
    """NMEA 0183: ``$--RMC`` (date, position, speed [knots], course) and ``$--GGA`` (position,
    HDOP, altitude) of any talker (GP, GN, GL...), merged per epoch.

    Sentences whose checksum is missing or wrong, void RMC (status V), GGA without a fix
    (quality 0) and malformed fields are counted in ``n_skipped`` and skipped. GGA altitude is
    MSL + geoid separation, i.e. ellipsoidal, when the separation is given.
    """
    epochs: list[_NmeaEpoch] = []
    by_key: dict[tuple[int, float], _NmeaEpoch] = {}
    n_bad = 0
    n_void = 0
    # Epochs are keyed by (day counter, time of day): GGA and RMC of one epoch share the time.
    day = 0
    last_tod: float | None = None
    for raw in _read_text(path).splitlines():
        line = raw.strip()
        start = line.find("$")
        if start < 0:
            continue
        line = line[start:]
        m = re.match(r"^\$[A-Z]{2}(RMC|GGA),", line)
        if not m:
            continue
        if not nmea_checksum_ok(line):
            n_bad += 1
            continue
        f = line[1:].rpartition("*")[0].split(",")
        try:
            tod = _nmea_tod(f[1])
            if m.group(1) == "RMC":
                if len(f) < 10:
                    raise ValueError("short RMC")
                if f[2] != "A":
                    n_void += 1
                    continue
                lat = _nmea_coord(f[3], f[4], 2)
                lon = _nmea_coord(f[5], f[6], 3)
                speed = float(f[7]) * KNOTS_TO_MPS if f[7] else None
                course = float(f[8]) % 360.0 if f[8] else None
                dd, mm, yy = int(f[9][0:2]), int(f[9][2:4]), int(f[9][4:6])
                date = (2000 + yy if yy < 80 else 1900 + yy, mm, dd)
                datetime(*date, tzinfo=UTC)  # validates the calendar date
            else:
                if len(f) < 10:
                    raise ValueError("short GGA")
                if not f[6] or int(f[6]) == 0:
                    n_void += 1
                    continue
                lat = _nmea_coord(f[2], f[3], 2)
                lon = _nmea_coord(f[4], f[5], 3)
                hdop = float(f[8]) if f[8] else None
                alt = float(f[9]) if f[9] else None
                if alt is not None and len(f) > 11 and f[11]:
                    alt += float(f[11])
        except (ValueError, IndexError):
            n_bad += 1
            continue
        if last_tod is not None and tod < last_tod - 12 * 3600:
            day += 1  # crossed midnight
        last_tod = tod
        key = (day, round(tod, 3))
        ep = by_key.get(key)
        if ep is None:
            ep = _NmeaEpoch(tod_s=tod)
            by_key[key] = ep
            epochs.append(ep)
        if m.group(1) == "RMC":
            ep.date, ep.lat, ep.lon = date, lat, lon
            ep.speed_mps, ep.course_deg = speed, course
        else:
            if ep.lat is None:
                ep.lat, ep.lon = lat, lon
            ep.alt_m = alt
            ep.accuracy_m = None if hdop is None else hdop * UERE_M
    warnings: list[str] = []
    if n_bad:
        warnings.append(f"skipped {n_bad} NMEA sentences with a bad checksum or malformed fields")
    if n_void:
        warnings.append(f"skipped {n_void} NMEA sentences without a valid fix")
    # Dates come only from RMC: carry the last known date forward (advancing at midnight) and
    # give leading GGA-only epochs the first date seen.
    keys = list(by_key.keys())
    dates: list[datetime | None] = []
    current: datetime | None = None
    current_day = 0
    for (d, _), ep in zip(keys, epochs, strict=True):
        if ep.date is not None:
            current, current_day = datetime(*ep.date, tzinfo=UTC), d
        dates.append(None if current is None else
                     datetime.fromtimestamp(current.timestamp() + 86400 * (d - current_day), UTC))
    first = next((x for x, (d, _) in zip(dates, keys, strict=True) if x is not None), None)
    if first is None:
        warnings.append("no $--RMC sentence gives the date; times are seconds of the day from "
                        "1970-01-01 (consistent within the file)")
        first_day = 0
        base0 = 0.0
    else:
        first_day = keys[dates.index(first)][0]
        base0 = first.timestamp() - 86400 * first_day
    fixes = []
    for (d, _), ep, date in zip(keys, epochs, dates, strict=True):
        base = date.timestamp() if date is not None else base0 + 86400 * d
        if ep.lat is None:
            continue
        fixes.append(GpsFix(t_utc_s=base + ep.tod_s, lat_deg=ep.lat, lon_deg=ep.lon,
                            alt_m=ep.alt_m, speed_mps=ep.speed_mps, course_deg=ep.course_deg,
                            accuracy_m=ep.accuracy_m))
    if not fixes and n_bad:
        raise InputError(path, f"no valid NMEA sentence ({n_bad} with a bad checksum or fields)",
                         "is the log corrupted?")
    return _finish(fixes, "nmea", path, n_skipped=n_bad + n_void, warnings=warnings)


# --------------------------------------------------------------------------- BDD100K


def read_bdd_json(path: Path) -> GpsTrace:
    """BDD100K info JSON: ``locations`` (or ``gps``) entries with ``timestamp`` [ms since
    epoch], ``latitude``, ``longitude``, ``speed`` [m/s], ``course`` [deg], optional
    ``accuracy`` [m]; ``startTime`` [ms] is the video's first frame.

    Negative speed/course/accuracy mean "invalid" on the phones that recorded BDD and become None.
    """
    try:
        data = json.loads(_read_text(path))
    except json.JSONDecodeError as exc:
        raise InputError(path, f"not valid JSON: {exc.msg} at line {exc.lineno}") from exc
    if not isinstance(data, dict):
        raise InputError(path, "JSON is not a BDD100K info object",
                         "expected an object with a 'locations' list")
    locs = data.get("locations")
    if not locs and isinstance(data.get("gps"), list):
        locs = data["gps"]
    if not isinstance(locs, list):
        raise InputError(path, "JSON has no 'locations' list", "is this a BDD100K info file?")
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
            raise InputError(path, f"locations[{i}] lacks {exc.args[0]!r}") from exc
        except (TypeError, ValueError) as exc:
            raise InputError(path, f"locations[{i}]: unparsable number ({exc})") from exc
        fixes.append(GpsFix(t_utc_s=t_ms / 1000.0, lat_deg=lat, lon_deg=lon,
                            alt_m=_opt(loc.get("altitude")),
                            speed_mps=_opt(loc.get("speed"), 0.0, 1e3),
                            course_deg=_opt(loc.get("course"), 0.0, 360.0),
                            accuracy_m=_opt(loc.get("accuracy"), 0.0, 1e5)))
    start = data.get("startTime")
    start_s = None
    if start is not None:
        try:
            start_s = float(start) / 1000.0
        except (TypeError, ValueError) as exc:
            raise InputError(path, f"startTime {start!r} is not a number of ms") from exc
    warnings = [f"skipped {n_bad} malformed location entries"] if n_bad else []
    return _finish(fixes, "bdd100k", path, n_skipped=n_bad, warnings=warnings,
                   video_start_utc_s=start_s)


# --------------------------------------------------------------------------- KITTI OXTS

# Column indices in a KITTI OXTS data line (see oxts/dataformat.txt of a raw drive).
OXTS_LAT, OXTS_LON, OXTS_ALT, OXTS_PITCH = 0, 1, 2, 4
OXTS_VN, OXTS_VE, OXTS_VF, OXTS_VL = 6, 7, 8, 9
OXTS_WZ = 19
OXTS_POS_ACC = 23
_OXTS_MIN_FIELDS = 24


def kitti_time_s(stamp: str) -> float:
    """A KITTI timestamp ``YYYY-MM-DD hh:mm:ss.nnnnnnnnn`` -> seconds.

    KITTI stamps are local time without a zone; they are read as if UTC, which keeps every
    KITTI clock of one drive (OXTS, cameras) consistent with each other, all that alignment
    needs. Nanoseconds are kept through numpy's datetime64.
    """
    ns = np.datetime64(stamp.strip().replace(" ", "T"), "ns")
    return float(ns.astype("int64")) / 1e9


def _kitti_folder(path: Path) -> tuple[Path, Path]:
    """(oxts folder, drive folder) for either the drive folder or the oxts folder itself."""
    if (path / "oxts" / "data").is_dir():
        return path / "oxts", path
    if (path / "data").is_dir() and (path / "timestamps.txt").is_file():
        return path, path.parent
    raise InputError(path, "folder is not a KITTI drive or OXTS folder",
                     "expected oxts/data/*.txt and oxts/timestamps.txt")


def read_kitti_stamps(path: Path) -> list[float]:
    """A KITTI ``timestamps.txt`` (one stamp per line) -> seconds (:func:`kitti_time_s`)."""
    out = []
    for i, line in enumerate(_read_text(path).splitlines()):
        if not line.strip():
            continue
        try:
            out.append(kitti_time_s(line))
        except ValueError as exc:
            raise InputError(path, f"line {i + 1}: unparsable timestamp {line.strip()!r}") from exc
    return out


def _oxts_values(path: Path) -> list[float]:
    parts = _read_text(path).split()
    if len(parts) < _OXTS_MIN_FIELDS:
        raise InputError(path, f"{len(parts)} fields, expected 30", "truncated OXTS file?")
    try:
        return [float(x) for x in parts]
    except ValueError as exc:
        raise InputError(path, f"unparsable number ({exc})") from exc


def read_kitti_oxts_table(path: Path) -> np.ndarray:
    """Every OXTS line of a KITTI drive (or its ``oxts`` folder) as rows of numbers, one row
    per ``oxts/data`` file in order; the first 24 columns of ``oxts/dataformat.txt``
    (``OXTS_*``: position, attitude, velocities, accelerations, rates, accuracy)."""
    oxts, _ = _kitti_folder(Path(path))
    files = sorted((oxts / "data").glob("*.txt"))
    if not files:
        raise InputError(oxts / "data", "no OXTS data files")
    return np.array([_oxts_values(f)[:_OXTS_MIN_FIELDS] for f in files], dtype=float)


def read_kitti_oxts(path: Path) -> GpsTrace:
    """A KITTI raw OXTS folder: ``oxts/data/NNNNNNNNNN.txt`` + ``oxts/timestamps.txt``.

    Speed [m/s] = hypot(vn, ve); course [deg] = atan2(ve, vn) (clockwise from north);
    accuracy = ``pos_accuracy`` [m]. The video start is the first stamp of
    ``image_00_timestamps.txt`` or ``image_0N/timestamps.txt`` beside ``oxts/`` when present.
    """
    oxts, drive = _kitti_folder(Path(path))
    files = sorted((oxts / "data").glob("*.txt"))
    stamps_file = oxts / "timestamps.txt"
    if not stamps_file.is_file():
        raise InputError(oxts, "missing timestamps.txt", "a KITTI OXTS folder has one")
    stamps = read_kitti_stamps(stamps_file)
    if not files:
        raise InputError(oxts / "data", "no OXTS data files")
    if len(stamps) != len(files):
        raise InputError(stamps_file, f"{len(stamps)} timestamps for {len(files)} data files",
                         "the drive is incomplete")
    fixes = []
    for f, t in zip(files, stamps, strict=True):
        v = _oxts_values(f)
        vn, ve = v[OXTS_VN], v[OXTS_VE]
        fixes.append(GpsFix(
            t_utc_s=t, lat_deg=v[OXTS_LAT], lon_deg=v[OXTS_LON], alt_m=v[OXTS_ALT],
            speed_mps=math.hypot(vn, ve), course_deg=math.degrees(math.atan2(ve, vn)) % 360.0,
            accuracy_m=_opt(v[OXTS_POS_ACC], 0.0, 1e5)))
    video_start = None
    candidates = [drive / "image_00_timestamps.txt"]
    candidates += [drive / f"image_0{k}" / "timestamps.txt" for k in range(4)]
    candidates += [drive / f"image_0{k}_timestamps.txt" for k in range(1, 4)]
    for c in candidates:
        if c.is_file():
            cam = read_kitti_stamps(c)
            if cam:
                video_start = cam[0]
                break
    return _finish(fixes, "kitti_oxts", Path(path), video_start_utc_s=video_start)


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
    text = _read_text(path)
    lines = text.splitlines()
    header = lines[0] if lines else ""
    cols = _csv_header_columns(header)
    split = _csv_split(header)
    if cols is None or split is None:
        raise InputError(path, "CSV header lacks a time, lat or lon column",
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
            raise InputError(path, f"line {i}: too few columns") from exc
        except ValueError as exc:
            raise InputError(path, f"line {i}: unparsable value ({exc})",
                             "time must be seconds, ms since the epoch or ISO 8601") from exc
        extra: dict[str, float | None] = {}
        for k in ("alt", "speed", "heading", "accuracy"):
            if k in cols and cols[k] < len(row) and row[cols[k]].strip():
                try:
                    extra[k] = float(row[cols[k]])
                except ValueError as exc:
                    raise InputError(path, f"line {i}: unparsable {k} {row[cols[k]]!r}") from exc
        raw.append((t, kind, lat, lon, extra))
    if not raw:
        raise InputError(path, "CSV has a header but no rows", "no GPS fixes to read")
    kinds = {r[1] for r in raw}
    if len(kinds) > 1:
        raise InputError(path, "time column mixes numbers and ISO 8601 dates")
    scale = 1.0
    if kinds == {"num"} and float(np.median([abs(r[0]) for r in raw])) > 1e11:
        scale = 1e-3  # milliseconds since the epoch
    fixes = [GpsFix(t_utc_s=t * scale, lat_deg=lat, lon_deg=lon, alt_m=_opt(e.get("alt")),
                    speed_mps=_opt(e.get("speed"), 0.0, 1e3),
                    course_deg=None if _opt(e.get("heading")) is None else e["heading"] % 360.0,
                    accuracy_m=_opt(e.get("accuracy"), 0.0, 1e5))
             for t, _, lat, lon, e in raw]
    return _finish(fixes, "csv", path)
