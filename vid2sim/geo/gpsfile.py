"""What every GPS reader shares: the checks and clean-up of a list of fixes."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np

from vid2sim.base.errors import (
    FormatError,
    ImpossibleValueError,
    InconsistentInputError,
    MissingInputError,
)
from vid2sim.base.fileio import check_input_size
from vid2sim.core.records import GpsFix, GpsTrace
from vid2sim.geo.clockcheck import local_xy, repair_clock

KNOTS_TO_MPS = 1852.0 / 3600.0
# A receiver's user-equivalent range error: horizontal one-sigma accuracy ~ HDOP x UERE.
# 5 m is a typical value for an uncorrected single-frequency consumer receiver; it only sets
# the relative weight of fixes in the smoother, so a rough value is enough.
UERE_M = 5.0

#: Largest GPS file [bytes]: a day of 10 Hz NMEA (RMC + GGA) is about 150 MB.
MAX_GPS_BYTES = 256 * 1024 * 1024
#: Latest fix time [s since the epoch]: 1e10 s is the year 2286; a larger number is not a
#: time (a GPS time of 1e300 once ran the smoother out of memory). Relative clocks (CSV
#: seconds from the start) are small numbers and pass.
MAX_FIX_TIME_S = 1.0e10
#: Longest trace [s]: a day. A trace is one drive; longer logs hold many drives and must be
#: cut to the video (resampling weeks at 10 Hz would take gigabytes).
MAX_TRACE_SPAN_S = 86_400.0
#: Plausible altitude range [m]: the Dead Sea shore to the highest road (5,800 m) with room;
#: outside it a reported altitude is dropped (an optional field), not the fix.
ALTITUDE_RANGE_M = (-1000.0, 10000.0)


# --------------------------------------------------------------------------- shared checks


def finish_trace(fixes: list[GpsFix], fmt: str, path: Path, n_skipped: int = 0,
            warnings: list[str] | None = None,
            video_start_utc_s: float | None = None) -> GpsTrace:
    """Validate ranges, put the fixes on one clock in time order (late records sorted in, a
    jumping clock re-timed, one fix per time: :mod:`vid2sim.geo.clockcheck`), wrap into a
    GpsTrace."""
    warnings = list(warnings or [])
    if not fixes:
        raise FormatError(path, f"no usable GPS fixes in this {fmt} file"
                         + (f" ({n_skipped} records skipped)" if n_skipped else ""),
                         "is the receiver reporting a fix, and do the records carry a time?")
    for i, f in enumerate(fixes):
        if not (math.isfinite(f.t_utc_s) and math.isfinite(f.lat_deg) and math.isfinite(f.lon_deg)):
            raise ImpossibleValueError(path, f"fix {i + 1}: time or position is not a finite number")
        if not -90.0 <= f.lat_deg <= 90.0:
            raise ImpossibleValueError(path, f"fix {i + 1}: latitude {f.lat_deg} outside [-90, 90]",
                             "are lat and lon swapped?")
        if not -180.0 <= f.lon_deg <= 180.0:
            raise ImpossibleValueError(path, f"fix {i + 1}: longitude {f.lon_deg} outside [-180, 180]")
        if abs(f.t_utc_s) > MAX_FIX_TIME_S:
            raise ImpossibleValueError(path, f"fix {i + 1}: time {f.t_utc_s:g} s is not a time (after the "
                             "year 2286)", "times are seconds (or ms, ISO 8601) since the epoch")
    fixes = [f if f.alt_m is None or ALTITUDE_RANGE_M[0] <= f.alt_m <= ALTITUDE_RANGE_M[1]
             else replace(f, alt_m=None) for f in fixes]
    fixes, n_dup = _on_one_clock(fixes, path, warnings)
    if video_start_utc_s is not None and not (math.isfinite(video_start_utc_s)
                                              and abs(video_start_utc_s) <= MAX_FIX_TIME_S):
        raise ImpossibleValueError(path, f"the video start time {video_start_utc_s:g} s is not a time",
                         "times are seconds (or ms) since the epoch")
    span_s = fixes[-1].t_utc_s - fixes[0].t_utc_s
    if span_s > MAX_TRACE_SPAN_S:
        raise InconsistentInputError(path, f"the fixes span {span_s / 3600:.1f} h, more than the "
                         f"{MAX_TRACE_SPAN_S / 3600:.0f} h of one drive",
                         "cut the log to the drive of the video")
    return GpsTrace(fixes=fixes, format=fmt, path=path, video_start_utc_s=video_start_utc_s,
                    n_skipped=n_skipped + n_dup, warnings=warnings)


def _on_one_clock(fixes: list[GpsFix], path: Path, warnings: list[str]
                  ) -> tuple[list[GpsFix], int]:
    """The fixes in time order on one consistent clock (:func:`vid2sim.geo.clockcheck.repair_clock`:
    records written late are sorted in, a clock that jumped is re-timed, one fix per time
    stamp), with the repair's warnings appended; and how many fixes were dropped."""
    t = np.array([f.t_utc_s for f in fixes], float)
    xy = local_xy(np.array([f.lat_deg for f in fixes]), np.array([f.lon_deg for f in fixes]))
    rep = repair_clock(t, xy, path)
    warnings.extend(rep.warnings)
    kept = [fixes[i] if fixes[i].t_utc_s == tt else replace(fixes[i], t_utc_s=tt)
            for i, tt in zip(rep.keep.tolist(), rep.t_s.tolist(), strict=True)]
    return kept, len(fixes) - len(kept)


def read_text(path: Path) -> str:
    """A GPS file's text (undecodable bytes replaced: loggers write odd bytes between
    sentences), refused above :data:`MAX_GPS_BYTES` before it is read."""
    check_input_size(path, MAX_GPS_BYTES, "GPS")
    try:
        return path.read_text(encoding="utf-8", errors="replace").lstrip("\ufeff")
    except OSError as exc:
        raise MissingInputError(path, f"cannot read: {exc.strerror or exc}") from exc


def optional_value(value: float | None, lo: float = -math.inf, hi: float = math.inf) -> float | None:
    """A finite value inside [lo, hi], else None (for optional fields such as speed)."""
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        return None
    return v if math.isfinite(v) and lo <= v <= hi else None
