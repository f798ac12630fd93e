"""The batch manifest: a CSV with one row per video, validated whole before anything runs.

Columns: ``video`` (required), ``name`` (the row's id and output subfolder; default the
video's stem, made unique), ``gps``, ``map``, ``camera``, ``detections``, ``keyframes``,
``fps``, ``gps_offset_s``, ``ego_speed_mps``. A path is relative to the manifest's folder
unless absolute; a cell may also be an fsspec URL (``s3://bucket/drive.mp4``), and so may the
manifest itself, whose relative cells then resolve against its own URL.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path

from vid2sim.app.batch import storage
from vid2sim.app.batch.storage import Where
from vid2sim.app.inputs import INPUT_NUMBERS, INPUT_ROLES, Inputs
from vid2sim.base.errors import FormatError, InputError, MissingInputError

# Manifest column -> label used in messages (the input roles of a build).
PATH_COLUMNS = dict(INPUT_ROLES)
NUMBER_COLUMNS = INPUT_NUMBERS
MANIFEST_COLUMNS = ("video", "name", *[c for c in PATH_COLUMNS if c != "video"],
                    *NUMBER_COLUMNS)
# How many bad manifest rows the one-line validation error spells out.
MAX_ROWS_IN_ERROR = 5
#: Names in the batch folder that belong to the batch itself, not to a row.
BATCH_CSV = "batch.csv"
INDEX_CSV = "index.csv"
INDEX_PARQUET = "index.parquet"
FLEET_HTML = "fleet.html"
STATE_DIR = "_batch"
RESERVED_NAMES = frozenset({BATCH_CSV, INDEX_CSV, INDEX_PARQUET, FLEET_HTML, STATE_DIR})


@dataclass(slots=True)
class BatchRow:
    """One manifest row, validated: absolute paths (or URLs), parsed numbers, a unique name."""

    line: int
    name: str
    video: Where
    gps: Where | None = None
    map_path: Where | None = None
    camera_path: Where | None = None
    detections: Where | None = None
    keyframes: Where | None = None
    fps: float | None = None
    gps_offset_s: float | None = None
    ego_speed_mps: float = 0.0

    def sources(self) -> dict[str, Where]:
        """Role -> location of every input given, in :data:`INPUT_ROLES` order."""
        values = {"video": self.video, "gps": self.gps, "map": self.map_path,
                  "camera": self.camera_path, "detections": self.detections,
                  "keyframes": self.keyframes}
        return {role: values[role] for role, _ in INPUT_ROLES if values[role] is not None}

    def check_numbers(self) -> None:
        """The checks a single build makes of the row's numbers (finite, physical); raises
        :class:`InputError`. Files are checked where they are (local or URL) by the reader."""
        Inputs(fps=self.fps, gps_offset_s=self.gps_offset_s,
               ego_speed_mps=self.ego_speed_mps).check()

    def inputs(self, local: dict[str, Path] | None = None) -> Inputs:
        """The row as the :class:`Inputs` of one build.

        ``local`` maps roles to local copies of URL inputs (a worker downloads them); a URL
        input without one cannot be built from and raises :class:`InputError`.
        """
        paths: dict[str, Path] = {}
        for role, where in self.sources().items():
            if local and role in local:
                paths[role] = local[role]
            elif isinstance(where, Path):
                paths[role] = where
            else:
                raise MissingInputError(where, "a URL input needs a local copy to be built from")
        return Inputs(video=paths["video"], gps=paths.get("gps"), map=paths.get("map"),
                      camera=paths.get("camera"), detections=paths.get("detections"),
                      keyframes=paths.get("keyframes"), fps=self.fps,
                      gps_offset_s=self.gps_offset_s, ego_speed_mps=self.ego_speed_mps)

    def numbers(self) -> dict[str, float | None]:
        """The row's numbers by manifest column."""
        return {"fps": self.fps, "gps_offset_s": self.gps_offset_s,
                "ego_speed_mps": self.ego_speed_mps}


def read_manifest(path: str | Path) -> list[BatchRow]:
    """Read and validate a batch manifest (CSV with a header; see the module docstring).

    Every row is checked before any build starts: missing or unknown columns, empty
    ``video``, files that do not exist, numbers that do not parse, bad or duplicate names.
    All problems are collected into one :class:`InputError` naming the manifest and the
    first few manifest lines.
    """
    where = storage.location(path)
    reader = _csv_reader(where, storage.read_text(where))
    base = storage.parent(where)
    rows: list[BatchRow] = []
    problems: list[tuple[int, str]] = []
    seen_names: dict[str, int] = {}
    for record in reader:
        line = reader.line_num
        cells = {k: (v or "").strip() for k, v in record.items() if k is not None}
        if not any(cells.values()):
            continue  # a blank line
        if None in record:
            problems.append((line, "more cells than header columns"))
            continue
        row, problem = _row(line, cells, base, seen_names)
        if problem is not None:
            problems.append((line, problem))
        else:
            rows.append(row)
    if problems:
        shown = "; ".join(f"line {line}: {msg}" for line, msg in problems[:MAX_ROWS_IN_ERROR])
        more = (f"; and {len(problems) - MAX_ROWS_IN_ERROR} more"
                if len(problems) > MAX_ROWS_IN_ERROR else "")
        # One error for rows of every kind of problem: no one subclass names them all.
        raise InputError(where, f"{len(problems)} bad row(s): {shown}{more}",
                         "paths are relative to the manifest's folder; nothing was built")
    if not rows:
        raise FormatError(where, "no rows", "one line per video under the header")
    _name_unnamed(rows, set(seen_names))
    return rows


def _csv_reader(where: Where, text: str) -> csv.DictReader:
    """A reader of the manifest's rows under its checked header (a ``video`` column, no
    unknown one; names stripped of spaces)."""
    reader = csv.DictReader(io.StringIO(text))
    header = [h.strip() for h in (reader.fieldnames or [])]
    if "video" not in header:
        raise FormatError(where, f"no 'video' column in the header ({','.join(header) or 'empty'})",
                          "the first line must name the columns, e.g. video,name,gps")
    unknown = [h for h in header if h not in MANIFEST_COLUMNS]
    if unknown:
        raise FormatError(where, f"unknown column(s) {', '.join(unknown)}",
                          f"known: {', '.join(MANIFEST_COLUMNS)}")
    reader.fieldnames = header
    return reader


def _row(line: int, cells: dict[str, str], base: Where, seen_names: dict[str, int]
         ) -> tuple[BatchRow | None, str | None]:
    """Manifest line ``line`` as a row, or the problems that keep it from being one (files
    that do not exist, numbers that do not parse or are not physical, a bad or repeated
    name); a good name is entered in ``seen_names``."""
    paths, row_problems = _row_paths(cells, base)
    numbers, number_problems = _row_numbers(cells)
    row_problems += number_problems
    name = cells.get("name", "")
    if name:
        name_problem = bad_name(name)
        if name_problem:
            row_problems.append(name_problem)
        elif name in seen_names:
            row_problems.append(f"name '{name}' already used on line {seen_names[name]}")
        else:
            seen_names[name] = line
    if row_problems:
        return None, "; ".join(row_problems)
    row = BatchRow(line=line, name=name, video=paths["video"], gps=paths["gps"],
                   map_path=paths["map"], camera_path=paths["camera"],
                   detections=paths["detections"], keyframes=paths["keyframes"],
                   fps=numbers["fps"], gps_offset_s=numbers["gps_offset_s"],
                   ego_speed_mps=numbers["ego_speed_mps"] or 0.0)
    try:
        row.check_numbers()  # a single build's checks (finite, physical), before any build
    except InputError as exc:
        return None, exc.problem
    return row, None


def _row_paths(cells: dict[str, str], base: Where) -> tuple[dict[str, Where | None], list[str]]:
    """The row's input locations (relative to ``base``) and the ones that do not exist."""
    paths: dict[str, Where | None] = {}
    problems: list[str] = []
    for column, label in PATH_COLUMNS.items():
        cell = cells.get(column, "")
        if not cell:
            paths[column] = None
            if column == "video":
                problems.append("empty video")
            continue
        p = _resolve(cell, base)
        if not storage.exists(p):
            problems.append(f"no such {label} file {cell}")
        paths[column] = p
    return paths, problems


def _row_numbers(cells: dict[str, str]) -> tuple[dict[str, float | None], list[str]]:
    """The row's numbers (None where empty) and the ones that do not parse or cannot be a
    frame rate or a speed."""
    numbers: dict[str, float | None] = {}
    problems: list[str] = []
    for column in NUMBER_COLUMNS:
        cell = cells.get(column, "")
        try:
            numbers[column] = float(cell) if cell else None
        except ValueError:
            problems.append(f"{column} '{cell}' is not a number")
            numbers[column] = None
    if numbers["fps"] is not None and numbers["fps"] <= 0:
        problems.append(f"fps must be > 0, got {numbers['fps']:g}")
    if numbers["ego_speed_mps"] is not None and numbers["ego_speed_mps"] < 0:
        problems.append(f"ego_speed_mps must be >= 0, got {numbers['ego_speed_mps']:g}")
    return numbers, problems


def _resolve(cell: str, base: Where) -> Where:
    """A manifest cell as a location: URLs as given, relative paths against ``base``."""
    if "://" in cell:
        return storage.location(cell)
    if isinstance(base, Path):
        p = Path(cell).expanduser()
        return p if p.is_absolute() else base / p
    return storage.join(base, cell)


def bad_name(name: str) -> str | None:
    """Why ``name`` cannot be an output subfolder, or None."""
    if name in (".", "..") or "/" in name or "\\" in name:
        return f"name '{name}' must be a plain folder name"
    if name.startswith("."):
        # build stages its outputs in hidden ".<name>.*" folders beside the output.
        return f"name '{name}' must not start with '.'"
    if name in RESERVED_NAMES:
        return f"name '{name}' is one of the batch's own files ({', '.join(sorted(RESERVED_NAMES))})"
    return None


def _name_unnamed(rows: list[BatchRow], taken: set[str]) -> None:
    """Give rows without a name their video's stem, made unique with _2, _3, ..."""
    for row in rows:
        if row.name:
            continue
        stem = Path(storage.name(row.video)).stem or "video"
        stem = "_" + stem if stem.startswith(".") else stem
        name, k = stem, 2
        while name in taken or name in RESERVED_NAMES:
            name, k = f"{stem}_{k}", k + 1
        row.name = name
        taken.add(name)
