"""NMEA 0183 logs (``$GPRMC``/``$GNRMC`` and ``$GPGGA``, checksums verified) -> GpsTrace."""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

from vid2sim.base.errors import FormatError
from vid2sim.core.records import GpsFix, GpsTrace
from vid2sim.geo.gpsfile import KNOTS_TO_MPS, UERE_M, finish_trace, read_text

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
    line: int = 0


@dataclass(slots=True)
class NmeaFixes:
    """The fixes of some NMEA text before the trace checks: ``lines[i]`` is the 0-based line
    of the first sentence of ``fixes[i]`` (embedded readers time a fix by its packet)."""

    fixes: list[GpsFix] = field(default_factory=list)
    lines: list[int] = field(default_factory=list)
    n_bad: int = 0
    n_void: int = 0
    warnings: list[str] = field(default_factory=list)


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
    parsed = parse_nmea_lines(read_text(path).splitlines())
    if not parsed.fixes and parsed.n_bad:
        raise FormatError(path, f"no valid NMEA sentence ({parsed.n_bad} with a bad checksum or "
                         "fields)", "is the log corrupted?")
    return finish_trace(parsed.fixes, "nmea", path, n_skipped=parsed.n_bad + parsed.n_void,
                        warnings=parsed.warnings)


def parse_nmea_lines(lines: Iterable[str]) -> NmeaFixes:
    """The fixes of NMEA 0183 lines (see :func:`read_nmea`); text before a ``$`` on a line
    (a logger's time stamp) is ignored."""
    epochs: list[_NmeaEpoch] = []
    by_key: dict[tuple[int, float], _NmeaEpoch] = {}
    n_bad = 0
    n_void = 0
    # Epochs are keyed by (day counter, time of day): GGA and RMC of one epoch share the time.
    day = 0
    last_tod: float | None = None
    for line_no, raw in enumerate(lines):
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
            ep = _NmeaEpoch(tod_s=tod, line=line_no)
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
    return _fixes_of_epochs(list(by_key.keys()), epochs,
                            NmeaFixes(n_bad=n_bad, n_void=n_void, warnings=warnings))


def _fixes_of_epochs(keys: list[tuple[int, float]], epochs: list[_NmeaEpoch],
                     out: NmeaFixes) -> NmeaFixes:
    """Date each epoch and append its fix to ``out``: dates come only from RMC, so the last
    known date is carried forward (advancing at midnight) and leading GGA-only epochs get
    the first date seen."""
    warnings = out.warnings
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
    for (d, _), ep, date in zip(keys, epochs, dates, strict=True):
        base = date.timestamp() if date is not None else base0 + 86400 * d
        if ep.lat is None:
            continue
        out.fixes.append(GpsFix(t_utc_s=base + ep.tod_s, lat_deg=ep.lat, lon_deg=ep.lon,
                                alt_m=ep.alt_m, speed_mps=ep.speed_mps,
                                course_deg=ep.course_deg, accuracy_m=ep.accuracy_m))
        out.lines.append(ep.line)
    return out
