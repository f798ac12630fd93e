"""Fixes on the video clock: the one rule every embedded format is timed by."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from vid2sim.base.errors import FormatError
from vid2sim.core.records import GpsFix, GpsTrace
from vid2sim.geo.gpsfile import finish_trace

#: Largest spread [s] (half the 10-90 % range) of the offsets between a receiver's fix times
#: and the packets carrying them, above which the receiver clock is not one clock with the
#: video (a receiver that jumped, two recordings spliced): a dash-cam writes a sentence within
#: a second of its fix.
MAX_OFFSET_SPREAD_S = 2.0
#: How messages name each embedded format.
FORMAT_LABELS = {"gpmf": "GoPro GPMF", "nmea-track": "NMEA track", "nmea-box": "NMEA box",
                 "subtitle-telemetry": "subtitle", "srt": "SRT subtitle"}


@dataclass(frozen=True, slots=True)
class ClockedFix:
    """A fix with its time on the video clock (``video_t_s``, from the packet) and, where
    the receiver stamped it, the receiver's own time (``receiver_utc_s``)."""

    fix: GpsFix
    video_t_s: float
    receiver_utc_s: float | None = None


def on_video_clock(clocked: list[ClockedFix], fmt: str, path: Path,
                   anchors_s: list[float] | None = None, n_skipped: int = 0,
                   warnings: list[str] | None = None) -> GpsTrace:
    """A trace whose ``video_start_utc_s`` puts each fix at its video time.

    Receiver-stamped fixes keep their stamps (precise spacing) and the video start is the
    median of (stamp - video time); other fixes are placed at anchor + video time, the anchor
    being that median, else the median of ``anchors_s`` (a payload's UTC minus its video
    time, as GPMF's GPSU gives), else 0 (the fixes then carry video time as their time).

    Raises
    ------
    FormatError
        No fix, or receiver stamps that do not follow the packets (see
        :data:`MAX_OFFSET_SPREAD_S`).
    """
    warnings = list(warnings or [])
    if not clocked:
        raise FormatError(path, f"the {FORMAT_LABELS.get(fmt, fmt)} telemetry holds no GPS "
                          "fix" + (f" ({n_skipped} records without a fix or unreadable)"
                                   if n_skipped else ""),
                          "did the receiver get a lock during the recording?")
    offsets = np.array([c.receiver_utc_s - c.video_t_s for c in clocked
                        if c.receiver_utc_s is not None], float)
    anchor = 0.0
    if len(offsets):
        lo, anchor, hi = np.percentile(offsets, [10, 50, 90])
        if (hi - lo) / 2 > MAX_OFFSET_SPREAD_S:
            raise FormatError(path, f"the {FORMAT_LABELS.get(fmt, fmt)} receiver's fix times drift {hi - lo:.1f} s "
                              "against the video's packets", "the receiver clock jumped or the "
                              "file holds two recordings")
    elif anchors_s:
        anchor = float(np.median([a for a in anchors_s if math.isfinite(a)]))
    fixes = [replace(c.fix, t_utc_s=c.receiver_utc_s if c.receiver_utc_s is not None
                     else float(anchor) + c.video_t_s) for c in clocked]
    return finish_trace(fixes, fmt, path, n_skipped=n_skipped, warnings=warnings,
                        video_start_utc_s=float(anchor))
