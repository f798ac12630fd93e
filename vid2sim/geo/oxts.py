"""KITTI raw OXTS folders (``oxts/data/*.txt`` + ``oxts/timestamps.txt``) -> GpsTrace."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from vid2sim.base.errors import FormatError, InconsistentInputError, MissingInputError
from vid2sim.core.records import GpsFix, GpsTrace
from vid2sim.geo.gpsfile import finish_trace, optional_value, read_text

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
    raise MissingInputError(path, "folder is not a KITTI drive or OXTS folder",
                     "expected oxts/data/*.txt and oxts/timestamps.txt")


def read_kitti_stamps(path: Path) -> list[float]:
    """A KITTI ``timestamps.txt`` (one stamp per line) -> seconds (:func:`kitti_time_s`)."""
    out = []
    for i, line in enumerate(read_text(path).splitlines()):
        if not line.strip():
            continue
        try:
            out.append(kitti_time_s(line))
        except ValueError as exc:
            raise FormatError(path, f"line {i + 1}: unparsable timestamp {line.strip()!r}") from exc
    return out


def _oxts_values(path: Path) -> list[float]:
    parts = read_text(path).split()
    if len(parts) < _OXTS_MIN_FIELDS:
        raise FormatError(path, f"{len(parts)} fields, expected 30", "truncated OXTS file?")
    try:
        return [float(x) for x in parts]
    except ValueError as exc:
        raise FormatError(path, f"unparsable number ({exc})") from exc


def read_kitti_oxts_table(path: Path) -> np.ndarray:
    """Every OXTS line of a KITTI drive (or its ``oxts`` folder) as rows of numbers, one row
    per ``oxts/data`` file in order; the first 24 columns of ``oxts/dataformat.txt``
    (``OXTS_*``: position, attitude, velocities, accelerations, rates, accuracy)."""
    oxts, _ = _kitti_folder(Path(path))
    files = sorted((oxts / "data").glob("*.txt"))
    if not files:
        raise MissingInputError(oxts / "data", "no OXTS data files")
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
        raise MissingInputError(oxts, "missing timestamps.txt", "a KITTI OXTS folder has one")
    stamps = read_kitti_stamps(stamps_file)
    if not files:
        raise MissingInputError(oxts / "data", "no OXTS data files")
    if len(stamps) != len(files):
        raise InconsistentInputError(stamps_file, f"{len(stamps)} timestamps for {len(files)} data files",
                         "the drive is incomplete")
    fixes = []
    for f, t in zip(files, stamps, strict=True):
        v = _oxts_values(f)
        vn, ve = v[OXTS_VN], v[OXTS_VE]
        fixes.append(GpsFix(
            t_utc_s=t, lat_deg=v[OXTS_LAT], lon_deg=v[OXTS_LON], alt_m=v[OXTS_ALT],
            speed_mps=math.hypot(vn, ve), course_deg=math.degrees(math.atan2(ve, vn)) % 360.0,
            accuracy_m=optional_value(v[OXTS_POS_ACC], 0.0, 1e5)))
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
    return finish_trace(fixes, "kitti_oxts", Path(path), video_start_utc_s=video_start)
