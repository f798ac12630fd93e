"""What happened to each row, and the results index the batch keeps of it.

``DIR/index.parquet`` and ``DIR/index.csv`` hold one row per manifest row (see
:data:`FIXED_COLUMNS` and :func:`stage_column`): the row's id, its inputs and their sha256,
status, error line, host, attempts, wall time per build stage, peak resident memory, lead
range / range-rate / time-to-collision summary and keyframe metrics. ``DIR/batch.csv`` is
the short per-row table the batch has always written (:data:`RESULT_COLUMNS`). All three are
rewritten atomically while rows finish, so a kill leaves the last complete version.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Iterable
from dataclasses import dataclass, field

import pyarrow as pa
import pyarrow.parquet as pq

from vid2sim.app.batch import storage
from vid2sim.app.batch.hashing import HashEntry
from vid2sim.app.batch.manifest import (
    BATCH_CSV,
    INDEX_CSV,
    INDEX_PARQUET,
    NUMBER_COLUMNS,
    PATH_COLUMNS,
    BatchRow,
)
from vid2sim.app.batch.storage import Where

#: Columns of ``batch.csv``.
RESULT_COLUMNS = ("name", "status", "seconds", "duration_s", "distance_m", "actors",
                  "lead_share", "f1", "mean_iou", "peak_rss_mb", "error")
#: The pseudo-input role under which a row's settings tree is hashed (a row built with other
#: settings is built again).
SETTINGS_ROLE = "settings"
#: Row statuses: built in this run, built earlier from the same inputs, failed, not finished.
STATUSES = ("ok", "skipped", "failed", "pending")

_STR, _INT, _FLOAT = pa.string(), pa.int64(), pa.float64()
#: The index's columns before the per-stage times, with their Arrow types.
FIXED_COLUMNS: tuple[tuple[str, pa.DataType], ...] = (
    ("id", _STR), ("line", _INT), ("status", _STR), ("error", _STR), ("attempts", _INT),
    ("host", _STR), ("started_utc", _STR), ("seconds", _FLOAT), ("peak_rss_mb", _FLOAT),
    *[c for role in PATH_COLUMNS for c in ((role, _STR), (f"{role}_sha256", _STR))],
    ("settings_sha256", _STR),
    *[(c, _FLOAT) for c in NUMBER_COLUMNS],
    ("duration_s", _FLOAT), ("distance_m", _FLOAT), ("actors", _INT), ("lead_share", _FLOAT),
    ("lead_range_min_m", _FLOAT), ("lead_range_median_m", _FLOAT), ("lead_range_max_m", _FLOAT),
    ("lead_range_rate_median_mps", _FLOAT), ("lead_closing_speed_max_mps", _FLOAT),
    ("lead_ttc_min_s", _FLOAT),
    ("n_keyframes", _INT), ("precision", _FLOAT), ("recall", _FLOAT), ("f1", _FLOAT),
    ("mean_iou", _FLOAT), ("report", _STR),
)
#: Figures a row's outcome carries (index columns of the same name).
FIGURES = ("duration_s", "distance_m", "actors", "lead_share", "lead_range_min_m",
           "lead_range_median_m", "lead_range_max_m", "lead_range_rate_median_mps",
           "lead_closing_speed_max_mps", "lead_ttc_min_s", "n_keyframes", "precision", "recall",
           "f1", "mean_iou")


def stage_column(stage: str) -> str:
    """Index column of a build stage's wall time: ``detect, track and range`` ->
    ``stage_detect_track_and_range_s``."""
    slug = re.sub(r"[^a-z0-9]+", "_", stage.lower()).strip("_")
    return f"stage_{slug}_s"


@dataclass(slots=True)
class RowOutcome:
    """What happened to one row: a line of ``batch.csv`` and a row of the index."""

    name: str
    status: str  # one of STATUSES
    line: int = 0
    seconds: float | None = None
    duration_s: float | None = None
    distance_m: float | None = None
    actors: int | None = None
    lead_share: float | None = None
    f1: float | None = None
    mean_iou: float | None = None
    peak_rss_mb: float | None = None
    error: str = ""
    traceback: str = ""
    host: str = ""
    attempts: int = 0
    started_utc: str = ""
    lead_range_min_m: float | None = None
    lead_range_median_m: float | None = None
    lead_range_max_m: float | None = None
    lead_range_rate_median_mps: float | None = None
    lead_closing_speed_max_mps: float | None = None
    lead_ttc_min_s: float | None = None
    n_keyframes: int | None = None
    precision: float | None = None
    recall: float | None = None
    #: role -> sha256 of the inputs the row was built (or failed) from
    sha256: dict[str, str] = field(default_factory=dict)
    #: index column (:func:`stage_column`) -> wall time of the stage [s]
    stage_s: dict[str, float] = field(default_factory=dict)
    #: path -> hash-cache entry of the row's inputs (for the driver's cache; not in the index)
    hash_entries: dict[str, HashEntry] = field(default_factory=dict)

    def csv_row(self) -> dict[str, str]:
        """The ``batch.csv`` line."""
        def fmt(value, digits: int) -> str:
            return "" if value is None else f"{value:.{digits}f}"

        return {"name": self.name, "status": self.status, "seconds": fmt(self.seconds, 1),
                "duration_s": fmt(self.duration_s, 2), "distance_m": fmt(self.distance_m, 1),
                "actors": "" if self.actors is None else str(self.actors),
                "lead_share": fmt(self.lead_share, 3), "f1": fmt(self.f1, 3),
                "mean_iou": fmt(self.mean_iou, 3), "peak_rss_mb": fmt(self.peak_rss_mb, 0),
                "error": self.error}

    def copy_figures(self, other: RowOutcome) -> None:
        """Take the build figures, timings and host of the run that built the row."""
        for name in (*FIGURES, "peak_rss_mb", "host", "started_utc", "attempts"):
            setattr(self, name, getattr(other, name))
        self.stage_s = dict(other.stage_s)
        self.sha256 = dict(other.sha256)

    def is_done(self) -> bool:
        return self.status in ("ok", "skipped")


def index_record(row: BatchRow, outcome: RowOutcome) -> dict:
    """The index row of ``outcome`` (manifest row ``row``) as column -> value."""
    rec: dict = {"id": row.name, "line": row.line, "status": outcome.status,
                 "error": outcome.error, "attempts": outcome.attempts, "host": outcome.host,
                 "started_utc": outcome.started_utc, "seconds": outcome.seconds,
                 "peak_rss_mb": outcome.peak_rss_mb}
    sources = row.sources()
    for role in PATH_COLUMNS:
        rec[role] = storage.host_path(sources[role]) if role in sources else None
        rec[f"{role}_sha256"] = outcome.sha256.get(role) if role in sources else None
    rec["settings_sha256"] = outcome.sha256.get(SETTINGS_ROLE)
    rec.update(row.numbers())
    for name in FIGURES:
        rec[name] = getattr(outcome, name)
    rec["report"] = f"{row.name}/report.html" if outcome.is_done() else None
    rec.update(outcome.stage_s)
    return rec


def outcome_from_record(rec: dict) -> RowOutcome:
    """A :class:`RowOutcome` back from an index row (parquet values or CSV text)."""
    types = dict(FIXED_COLUMNS)

    def value(name: str):
        v = rec.get(name)
        if v is None or v == "" or (isinstance(v, float) and math.isnan(v)):
            return None
        kind = types.get(name, _FLOAT)
        try:
            return int(float(v)) if kind == _INT else float(v) if kind == _FLOAT else str(v)
        except (TypeError, ValueError):
            return None

    out = RowOutcome(name=str(rec.get("id") or ""), status=str(rec.get("status") or "pending"),
                     line=value("line") or 0, seconds=value("seconds"),
                     peak_rss_mb=value("peak_rss_mb"), error=value("error") or "",
                     host=value("host") or "", attempts=value("attempts") or 0,
                     started_utc=value("started_utc") or "")
    for name in FIGURES:
        setattr(out, name, value(name))
    out.sha256 = {role: value(f"{role}_sha256") for role in (*PATH_COLUMNS, SETTINGS_ROLE)
                  if value(f"{role}_sha256")}
    out.stage_s = {k: value(k) for k in rec if k.startswith("stage_") and value(k) is not None}
    return out


# --------------------------------------------------------------------------- files


def index_table(records: list[dict]) -> pa.Table:
    """The index as an Arrow table: the fixed columns, then one column per stage seen."""
    stages: list[str] = []
    for rec in records:
        stages.extend(k for k in rec if k.startswith("stage_") and k not in stages)
    schema = pa.schema([*FIXED_COLUMNS, *[(s, _FLOAT) for s in stages]])
    return pa.Table.from_pylist(
        [{name: rec.get(name) for name in schema.names} for rec in records], schema=schema)


def write_index(out_dir: Where, records: list[dict]) -> None:
    """Write ``index.parquet`` and ``index.csv`` into ``out_dir``, each atomically."""
    table = index_table(records)
    buf = io.BytesIO()
    pq.write_table(table, buf)
    storage.write_bytes(storage.join(out_dir, INDEX_PARQUET), buf.getvalue())
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(table.schema.names)
    for rec in table.to_pylist():
        writer.writerow(_csv_cell(rec[name]) for name in table.schema.names)
    storage.write_bytes(storage.join(out_dir, INDEX_CSV), text.getvalue().encode("utf-8"))


def _csv_cell(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def read_index(out_dir: Where) -> dict[str, RowOutcome]:
    """Id -> outcome of an earlier run's index ({} when there is none or it is unreadable).

    ``index.parquet`` first (typed); ``index.csv`` when only it survived; the older
    ``batch.csv`` of batches written before the index existed.
    """
    for records in (_read_parquet(out_dir), _read_csv(storage.join(out_dir, INDEX_CSV))):
        if records is not None:
            return {r.name: r for r in map(outcome_from_record, records) if r.name}
    legacy = _read_csv(storage.join(out_dir, BATCH_CSV))
    if legacy is None:
        return {}
    return {r.name: r for r in (outcome_from_record({**rec, "id": rec.get("name")})
                                for rec in legacy) if r.name}


def read_index_records(out_dir: Where) -> list[dict]:
    """The index rows as dicts (parquet, else CSV); [] when there is no index."""
    for records in (_read_parquet(out_dir), _read_csv(storage.join(out_dir, INDEX_CSV))):
        if records is not None:
            return records
    return []


def _read_parquet(out_dir: Where) -> list[dict] | None:
    try:
        data = storage.read_bytes(storage.join(out_dir, INDEX_PARQUET))
        # ParquetFile, not read_table: read_table goes through pyarrow.dataset, which
        # imports pandas (1 s, a third of a resume's whole time).
        return pq.ParquetFile(io.BytesIO(data)).read().to_pylist()
    except (OSError, pa.ArrowException):
        return None


def _read_csv(where: Where) -> list[dict] | None:
    try:
        text = storage.read_bytes(where).decode("utf-8")
        return list(csv.DictReader(io.StringIO(text)))
    except (OSError, UnicodeDecodeError, csv.Error):
        return None


def write_batch_csv(path: Where, outcomes: Iterable[RowOutcome]) -> None:
    """Write ``batch.csv`` atomically (rows in manifest order; unfinished ones "pending")."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=RESULT_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for outcome in outcomes:
        writer.writerow(outcome.csv_row())
    storage.write_bytes(path, buf.getvalue().encode("utf-8"))
