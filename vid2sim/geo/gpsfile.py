"""What every GPS reader shares: the checks and clean-up of a list of fixes."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

from vid2sim.errors import InputError
from vid2sim.records import GpsFix, GpsTrace

KNOTS_TO_MPS = 1852.0 / 3600.0
# A receiver's user-equivalent range error: horizontal one-sigma accuracy ~ HDOP x UERE.
# 5 m is a typical value for an uncorrected single-frequency consumer receiver; it only sets
# the relative weight of fixes in the smoother, so a rough value is enough.
UERE_M = 5.0


# --------------------------------------------------------------------------- shared checks


def finish_trace(fixes: list[GpsFix], fmt: str, path: Path, n_skipped: int = 0,
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


def read_text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8", errors="replace").lstrip("\ufeff")
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror or exc}") from exc


def optional_value(value: float | None, lo: float = -math.inf, hi: float = math.inf) -> float | None:
    """A finite value inside [lo, hi], else None (for optional fields such as speed)."""
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) and lo <= v <= hi else None
