"""``vid2sim probe``: what recordings hold, as a table, so a user knows what a build will use."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import cv2

from vid2sim.base.errors import InputError
from vid2sim.core.container import ContainerInfo, probe_container
from vid2sim.geo.embedded import find_telemetry, read_embedded

COLUMNS = ("file", "codec", "size", "fps", "frame interval ms", "rotation", "duration",
           "start", "telemetry")


@dataclass(frozen=True, slots=True)
class ProbeRow:
    """One recording's line of the table (each cell as shown)."""

    cells: tuple[str, ...]
    problem: str | None = None


def probe_recording(path: Path) -> ProbeRow:
    """The table row of one recording; a file FFmpeg cannot read gives a row naming the
    problem (the table still shows the others)."""
    path = Path(path)
    try:
        info = probe_container(path)
    except InputError as exc:
        return ProbeRow((path.name, *["-"] * (len(COLUMNS) - 1)), problem=exc.problem)
    v = info.video
    if v is None:
        return ProbeRow((path.name, "-", "-", "-", "-", "-", _duration(info), _start(info),
                         _telemetry(path)), problem="no video stream")
    interval = "-"
    if v.interval_s is not None:
        lo, med, hi = (1000 * x for x in v.interval_s)
        interval = (f"{med:.1f} (variable {lo:.1f}-{hi:.1f})" if v.variable_rate
                    else f"{med:.1f} (constant)")
    codec = v.codec + ("" if _decodes(path) else " (cannot decode)")
    return ProbeRow((path.name, codec, f"{v.width}x{v.height}", f"{v.nominal_fps:.3f}",
                     interval, f"{v.rotation_deg} deg", _duration(info), _start(info),
                     _telemetry(path)))


def _decodes(path: Path) -> bool:
    cap = cv2.VideoCapture(str(path))
    try:
        return bool(cap.isOpened() and cap.grab())
    finally:
        cap.release()


def _duration(info: ContainerInfo) -> str:
    return "-" if info.duration_s is None else f"{info.duration_s:.2f} s"


def _start(info: ContainerInfo) -> str:
    if info.creation_utc_s is None:
        return "-"
    return datetime.fromtimestamp(info.creation_utc_s, UTC).strftime("%Y-%m-%d %H:%M:%S")


def _telemetry(path: Path) -> str:
    """The telemetry tracks and, for the one a build reads, its fixes and their rate."""
    try:
        tracks = find_telemetry(path)
    except InputError as exc:
        return f"unreadable ({exc.problem})"
    if not tracks:
        return "none"
    parts = [f"{t.kind} ({t.label})" for t in tracks]
    try:
        trace = read_embedded(path)
    except InputError as exc:
        return f"{parts[0]}: {exc.problem}" + "".join(f"; {p}" for p in parts[1:])
    fixes = trace.fixes
    span = fixes[-1].t_utc_s - fixes[0].t_utc_s if len(fixes) > 1 else 0.0
    rate = f", {(len(fixes) - 1) / span:.1f} Hz" if span > 0 else ""
    parts[0] += f": {len(fixes)} fixes{rate}"
    return "; ".join(parts)


def probe_table(paths: list[Path]) -> tuple[str, int]:
    """The table of ``paths`` as aligned text, and how many could not be read."""
    rows = [probe_recording(p) for p in paths]
    table = [COLUMNS, *[r.cells for r in rows]]
    widths = [max(len(row[k]) for row in table) for k in range(len(COLUMNS))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths, strict=True)).rstrip()
             for row in table]
    bad = [(p, r.problem) for p, r in zip(paths, rows, strict=True) if r.problem]
    lines += [f"warning: {p}: {problem}" for p, problem in bad]
    return "\n".join(lines), len(bad)
