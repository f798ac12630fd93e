"""The CSV tables vid2sim writes and reads back: ego.csv, detections.csv, tracks.csv.

Every writer is atomic (a temporary file renamed over the target) and deterministic (fixed
decimals, fixed row order), so the same records give the same bytes.
"""

from __future__ import annotations

import csv
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from vid2sim.base.errors import FormatError, MissingInputError
from vid2sim.base.fileio import atomic_open
from vid2sim.core.lead import MAX_RELATIVE_LANE
from vid2sim.core.records import EgoTrack, RangedBox, TrackedBox, VehicleCategory

EGO_CSV_COLUMNS = ("t_s", "lat", "lon", "x_m", "y_m", "heading_rad", "speed_mps")
DETECTIONS_CSV_COLUMNS = ("frame", "t_s", "track_id", "category", "score", "x1", "y1", "x2",
                          "y2")
TRACKS_CSV_COLUMNS = ("frame", "t_s", "track_id", "category", "score", "x1", "y1", "x2", "y2",
                      "range_m", "lateral_m", "range_rate_mps", "range_std_m", "is_lead", "lane")
#: Columns a tracks.csv must have: files written before the ``lane`` column still read.
TRACKS_CSV_REQUIRED = TRACKS_CSV_COLUMNS[:-1]


# --------------------------------------------------------------------------- ego.csv


def write_ego_csv(ego: EgoTrack, path: str | Path) -> None:
    """Write ``t_s,lat,lon,x_m,y_m,heading_rad,speed_mps`` atomically with fixed decimals
    (mm in position, 1e-8 deg ~ 1 mm in lat/lon), so identical input gives identical bytes."""
    cols = (
        (ego.t_s, 3), (ego.lat_deg, 8), (ego.lon_deg, 8), (ego.x_m, 3), (ego.y_m, 3),
        (ego.heading_rad, 5), (ego.speed_mps, 3),
    )
    # Adding 0.0 after rounding turns -0.0 into 0.0, so "-0.000" never appears.
    cells = [[f"{v:.{d}f}" for v in (np.round(np.asarray(a, float), d) + 0.0)] for a, d in cols]
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(",".join(EGO_CSV_COLUMNS) + "\n")
        for row in zip(*cells, strict=True):
            fh.write(",".join(row) + "\n")


# --------------------------------------------------------------------------- detections.csv


def write_detections_csv(boxes: list[TrackedBox], path: str | Path) -> None:
    """Write tracked boxes as ``frame,t_s,track_id,category,score,x1,y1,x2,y2`` (atomic).

    Times in seconds (6 decimals), boxes in pixels (2 decimals).
    """
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(",".join(DETECTIONS_CSV_COLUMNS) + "\n")
        for b in boxes:
            fh.write(f"{b.frame},{b.t_s:.6f},{b.track_id},{b.category},{b.score:.4f},"
                     f"{b.x1:.2f},{b.y1:.2f},{b.x2:.2f},{b.y2:.2f}\n")


# --------------------------------------------------------------------------- tracks.csv


def _fmt(v: float, digits: int) -> str:
    return "nan" if not np.isfinite(v) else f"{v:.{digits}f}"


def write_tracks_csv(boxes: list[RangedBox], path: str | Path) -> None:
    """Write ``tracks.csv`` atomically, one row per tracked vehicle per processed frame.

    Columns ``frame,t_s,track_id,category,score,x1,y1,x2,y2,range_m,lateral_m,range_rate_mps,
    range_std_m,is_lead,lane``; ``is_lead`` is 1 on the lead vehicle's row, else 0; ``lane``
    is the vehicle's lane relative to the ego lane of that frame (0 the ego lane, +1 the next
    to the left, -1 the next to the right), empty where unknown; unknown values (the range
    rate of a one-frame track) are ``nan``.
    """
    with atomic_open(path, "w", encoding="utf-8", newline="") as fh:
        wr = csv.writer(fh, lineterminator="\n")
        wr.writerow(TRACKS_CSV_COLUMNS)
        for b in sorted(boxes, key=lambda b: (b.frame, b.track_id)):
            wr.writerow([b.frame, f"{b.t_s:.4f}", b.track_id, b.category, f"{b.score:.3f}",
                         f"{b.x1:.1f}", f"{b.y1:.1f}", f"{b.x2:.1f}", f"{b.y2:.1f}",
                         _fmt(b.range_m, 2), _fmt(b.lateral_m, 2), _fmt(b.range_rate_mps, 2),
                         _fmt(b.range_std_m, 2), int(b.is_lead), _lane_cell(b.lane)])


def _lane_cell(lane: int | None) -> str:
    return "" if lane is None else str(int(lane))


def read_tracks_csv(path: str | Path) -> list[RangedBox]:
    """Read a ``tracks.csv`` written by :func:`write_tracks_csv` (or by hand).

    A file without the ``lane`` column (written before it existed) reads with every lane
    unknown (None).

    Raises
    ------
    InputError
        If the file is missing, lacks a column, or holds a value that is not a number (or a
        lane that is not a whole number of lanes within +-16).
    """
    return list(iter_tracks_csv(path))


def iter_tracks_csv(path: str | Path) -> Iterator[RangedBox]:
    """The rows of a ``tracks.csv`` one at a time, in file order (frame order for the files
    :func:`write_tracks_csv` writes), so a long clip's table is never held whole; errors as
    :func:`read_tracks_csv`'s, raised at the row where they occur."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(path, "no such file")
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            reader = csv.DictReader(fh)
            missing = [c for c in TRACKS_CSV_REQUIRED if c not in (reader.fieldnames or [])]
            if missing:
                raise FormatError(path, f"not a tracks.csv: lacks column(s) {', '.join(missing)}",
                                  "write it with `vid2sim track`")
            for line, row in enumerate(reader, start=2):
                try:
                    box = _row_to_box(row)
                except (TypeError, ValueError, KeyError) as exc:
                    raise FormatError(path, f"line {line}: {exc}") from None
                yield box
    except OSError as exc:
        raise MissingInputError(path, f"cannot read: {exc}") from None
    except UnicodeDecodeError as exc:
        raise FormatError(path, f"cannot read: {exc}") from None


def _row_to_box(row: dict[str, str]) -> RangedBox:
    return RangedBox(
        frame=int(row["frame"]), t_s=float(row["t_s"]), track_id=int(row["track_id"]),
        category=VehicleCategory(row["category"]), score=float(row["score"]), x1=float(row["x1"]),
        y1=float(row["y1"]), x2=float(row["x2"]), y2=float(row["y2"]),
        range_m=float(row["range_m"]), lateral_m=float(row["lateral_m"]),
        range_rate_mps=float(row["range_rate_mps"]), range_std_m=float(row["range_std_m"]),
        is_lead=row["is_lead"].strip() in ("1", "true", "True"),
        lane=_lane_from_cell(row.get("lane")))


def _lane_from_cell(cell: str | None) -> int | None:
    """A ``lane`` cell -> the lane relative to the ego lane (None for an empty cell or no
    column)."""
    text = (cell or "").strip()
    if not text:
        return None
    index = int(text)  # a ValueError names the line
    if abs(index) > MAX_RELATIVE_LANE:
        raise ValueError(f"lane {index} is more than {MAX_RELATIVE_LANE} lanes from the ego's")
    return index
