"""Many videos in one run: a CSV manifest -> one :func:`~vid2sim.app.build.build` per row in a
process pool.

The unit of work is one row = one video = one ``build`` into ``OUT/<name>/``. The batch is
idempotent: a row whose ``scenario.json`` already records the sha256 of the row's current
inputs is skipped, so rerunning the same command after a kill (or on a cluster node that
picks the manifest up again) only builds what is missing. ``OUT/batch.csv`` is rewritten
atomically as each row finishes, so the record of what is done survives a kill too.

Each row runs in its own freshly spawned worker process (``max_tasks_per_child=1``):
a memory leak or a crash in native code (OpenCV, onnxruntime) stays with that video, and
the worker's peak resident memory is that one build's. Workers start with
``OMP_NUM_THREADS`` / ``OPENBLAS_NUM_THREADS`` / ``MKL_NUM_THREADS`` = 1 and OpenCV at one
thread, and the detector gets ``max(1, cores // jobs)`` onnxruntime intra-op threads, so
that ``--jobs N`` on the machine's cores does not oversubscribe them.
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import io
import json
import logging
import os
import resource
import time
import traceback
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

from vid2sim import scenario as scenario_io
from vid2sim.app.build import build
from vid2sim.app.inputs import INPUT_NUMBERS, INPUT_ROLES, Inputs
from vid2sim.app.settings import Settings
from vid2sim.errors import InputError
from vid2sim.fileio import read_input_text, sha256_path, write_text_atomic

log = logging.getLogger(__name__)

# Manifest column -> label used in messages (the input roles of a build); the path columns
# are resolved against the manifest's folder.
PATH_COLUMNS = dict(INPUT_ROLES)
NUMBER_COLUMNS = INPUT_NUMBERS
MANIFEST_COLUMNS = ("video", "name", *[c for c in PATH_COLUMNS if c != "video"],
                    *NUMBER_COLUMNS)
RESULT_COLUMNS = ("name", "status", "seconds", "duration_s", "distance_m", "actors",
                  "lead_share", "f1", "mean_iou", "peak_rss_mb", "error")
BATCH_CSV = "batch.csv"
# How many bad manifest rows the one-line validation error spells out.
MAX_ROWS_IN_ERROR = 5
# Thread-pool variables set to 1 in the workers (unless the user set them).
WORKER_THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@dataclass(slots=True)
class BatchRow:
    """One manifest row, validated: absolute paths, parsed numbers, a unique output name."""

    line: int
    name: str
    video: Path
    gps: Path | None = None
    map_path: Path | None = None
    camera_path: Path | None = None
    detections: Path | None = None
    keyframes: Path | None = None
    fps: float | None = None
    gps_offset_s: float | None = None
    ego_speed_mps: float = 0.0

    def inputs(self) -> Inputs:
        """The row as the :class:`Inputs` of one build."""
        return Inputs(video=self.video, gps=self.gps, map=self.map_path,
                      camera=self.camera_path, detections=self.detections,
                      keyframes=self.keyframes, fps=self.fps, gps_offset_s=self.gps_offset_s,
                      ego_speed_mps=self.ego_speed_mps)

    def input_paths(self) -> dict[str, Path]:
        """Role -> path of the inputs ``build`` records (and hashes) in ``source.inputs``."""
        return self.inputs().paths()


@dataclass(slots=True)
class RowOutcome:
    """What happened to one row: one line of ``batch.csv``."""

    name: str
    status: str  # ok, skipped, failed, pending (not finished yet)
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

    def csv_row(self) -> dict[str, str]:
        def fmt(value, digits: int) -> str:
            return "" if value is None else f"{value:.{digits}f}"

        return {"name": self.name, "status": self.status, "seconds": fmt(self.seconds, 1),
                "duration_s": fmt(self.duration_s, 2), "distance_m": fmt(self.distance_m, 1),
                "actors": "" if self.actors is None else str(self.actors),
                "lead_share": fmt(self.lead_share, 3), "f1": fmt(self.f1, 3),
                "mean_iou": fmt(self.mean_iou, 3), "peak_rss_mb": fmt(self.peak_rss_mb, 0),
                "error": self.error}


@dataclass(slots=True)
class BatchSummary:
    """The batch's outcome, for the CLI summary and exit code."""

    out_dir: Path
    outcomes: list[RowOutcome]
    wall_s: float

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outcomes)

    @property
    def failed(self) -> list[RowOutcome]:
        return [o for o in self.outcomes if o.status == "failed"]

    def summary(self) -> str:
        n_ok = self.count("ok")
        per_hour = 3600.0 * n_ok / self.wall_s if self.wall_s > 0 else 0.0
        lines = [(f"batch: {len(self.outcomes)} rows: {n_ok} ok, {self.count('skipped')} "
                 f"skipped, {self.count('failed')} failed in {self.wall_s:.1f} s "
                 f"({per_hour:.0f} videos per hour); {self.out_dir / BATCH_CSV}")]
        for o in self.failed[:10]:
            lines.append(f"failed: {o.name} (manifest line {o.line}): {o.error}")
        if len(self.failed) > 10:
            lines.append(f"... and {len(self.failed) - 10} more failed rows in {BATCH_CSV}")
        return "\n".join(lines)


# --------------------------------------------------------------------------- manifest


def read_manifest(path: str | Path) -> list[BatchRow]:
    """Read and validate a batch manifest (CSV with a header; see the module docstring).

    Every row is checked before any build starts: missing or unknown columns, empty
    ``video``, files that do not exist, numbers that do not parse, bad or duplicate names.
    All problems are collected into one :class:`InputError` naming the manifest and the
    first few manifest lines.
    """
    path = Path(path)
    text = read_input_text(path)
    reader = csv.DictReader(io.StringIO(text))
    header = [h.strip() for h in (reader.fieldnames or [])]
    if "video" not in header:
        raise InputError(path, f"no 'video' column in the header ({','.join(header) or 'empty'})",
                         "the first line must name the columns, e.g. video,name,gps")
    unknown = [h for h in header if h not in MANIFEST_COLUMNS]
    if unknown:
        raise InputError(path, f"unknown column(s) {', '.join(unknown)}",
                         f"known: {', '.join(MANIFEST_COLUMNS)}")
    reader.fieldnames = header
    base = path.parent
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
        row_problems: list[str] = []
        paths: dict[str, Path | None] = {}
        for column, label in PATH_COLUMNS.items():
            cell = cells.get(column, "")
            if not cell:
                paths[column] = None
                if column == "video":
                    row_problems.append("empty video")
                continue
            p = Path(cell).expanduser()
            p = p if p.is_absolute() else base / p
            if not p.exists():
                row_problems.append(f"no such {label} file {cell}")
            paths[column] = p
        numbers: dict[str, float | None] = {}
        for column in NUMBER_COLUMNS:
            cell = cells.get(column, "")
            try:
                numbers[column] = float(cell) if cell else None
            except ValueError:
                row_problems.append(f"{column} '{cell}' is not a number")
                numbers[column] = None
        if numbers["fps"] is not None and numbers["fps"] <= 0:
            row_problems.append(f"fps must be > 0, got {numbers['fps']:g}")
        if numbers["ego_speed_mps"] is not None and numbers["ego_speed_mps"] < 0:
            row_problems.append(f"ego_speed_mps must be >= 0, got {numbers['ego_speed_mps']:g}")
        name = cells.get("name", "")
        if name:
            name_problem = _bad_name(name)
            if name_problem:
                row_problems.append(name_problem)
            elif name in seen_names:
                row_problems.append(f"name '{name}' already used on line {seen_names[name]}")
            else:
                seen_names[name] = line
        if row_problems:
            problems.append((line, "; ".join(row_problems)))
            continue
        row = BatchRow(line=line, name=name, video=paths["video"], gps=paths["gps"],
                       map_path=paths["map"], camera_path=paths["camera"],
                       detections=paths["detections"], keyframes=paths["keyframes"],
                       fps=numbers["fps"], gps_offset_s=numbers["gps_offset_s"],
                       ego_speed_mps=numbers["ego_speed_mps"] or 0.0)
        try:
            row.inputs().check()  # a single build's checks (finite, physical), before any build
        except InputError as exc:
            problems.append((line, exc.problem))
            continue
        rows.append(row)
    if problems:
        shown = "; ".join(f"line {line}: {msg}" for line, msg in problems[:MAX_ROWS_IN_ERROR])
        more = (f"; and {len(problems) - MAX_ROWS_IN_ERROR} more"
                if len(problems) > MAX_ROWS_IN_ERROR else "")
        raise InputError(path, f"{len(problems)} bad row(s): {shown}{more}",
                         "paths are relative to the manifest's folder; nothing was built")
    if not rows:
        raise InputError(path, "no rows", "one line per video under the header")
    _name_unnamed(rows, set(seen_names))
    return rows


def _bad_name(name: str) -> str | None:
    """Why ``name`` cannot be an output subfolder, or None."""
    if name in (".", "..") or "/" in name or "\\" in name:
        return f"name '{name}' must be a plain folder name"
    if name.startswith("."):
        # build stages its outputs in hidden ".<name>.*" folders beside the output.
        return f"name '{name}' must not start with '.'"
    if name == BATCH_CSV:
        return f"name '{name}' is the batch's own record"
    return None


def _name_unnamed(rows: list[BatchRow], taken: set[str]) -> None:
    """Give rows without a name their video's stem, made unique with _2, _3, ..."""
    for row in rows:
        if row.name:
            continue
        stem = row.video.stem or "video"
        stem = "_" + stem if stem.startswith(".") else stem
        name, k = stem, 2
        while name in taken:
            name, k = f"{stem}_{k}", k + 1
        row.name = name
        taken.add(name)


# --------------------------------------------------------------------------- one row


def done_outcome(row: BatchRow, out_dir: Path) -> RowOutcome | None:
    """A "skipped" outcome when ``out_dir/<name>`` holds a build of the row's current inputs.

    A build counts as done when its ``scenario.json`` loads, its report is there (both are
    moved in from the staging folder at the very end), and ``source.inputs`` records the
    same roles with the same sha256 as the row's files now (a file's name or folder may
    change; its content may not). Hashing reads every input: about 1 s per GB.
    """
    row_dir = Path(out_dir) / row.name
    scenario_path = row_dir / "scenario.json"
    if not scenario_path.is_file() or not (row_dir / "report.html").is_file():
        return None
    try:
        scenario = scenario_io.load(scenario_path)
    except InputError:
        return None
    recorded = {(i.get("role"), i.get("sha256")) for i in scenario.source.inputs}
    if {role for role, _ in recorded} != set(row.input_paths()):
        return None
    current = {(role, sha256_path(p)) for role, p in row.input_paths().items()}
    if recorded != current:
        return None
    outcome = RowOutcome(name=row.name, status="skipped", line=row.line,
                         duration_s=scenario.duration_s, actors=len(scenario.actors))
    metrics_path = row_dir / "metrics.json"
    if metrics_path.is_file():
        with contextlib.suppress(ValueError, OSError):
            metrics = json.loads(metrics_path.read_text(encoding="utf-8"))
            outcome.f1, outcome.mean_iou = metrics.get("f1"), metrics.get("mean_iou")
    return outcome


def run_row(row: BatchRow, settings: Settings, out_dir: Path) -> RowOutcome:
    """Build one row; never raises (an error becomes a "failed" outcome with one line)."""
    t0 = time.perf_counter()
    outcome = RowOutcome(name=row.name, status="ok", line=row.line)
    try:
        result = build(row.inputs(), Path(out_dir) / row.name,
                       dataclasses.replace(settings, progress=False))
    except InputError as exc:
        outcome.status, outcome.error = "failed", _one_line(str(exc))
    except Exception as exc:  # noqa: BLE001 - one bad video must not stop the batch
        outcome.status = "failed"
        outcome.error = _one_line(f"internal error: {type(exc).__name__}: {exc}")
        outcome.traceback = traceback.format_exc()
    else:
        outcome.duration_s, outcome.distance_m = result.duration_s, result.distance_m
        outcome.actors, outcome.lead_share = result.n_actors, result.lead_share
        if result.metrics:
            outcome.f1, outcome.mean_iou = result.metrics.get("f1"), result.metrics.get("mean_iou")
    outcome.seconds = time.perf_counter() - t0
    # ru_maxrss is in KiB on Linux: the peak of this process, i.e. of this one build when
    # the worker builds one row only (max_tasks_per_child=1).
    outcome.peak_rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return outcome


def _one_line(text: str) -> str:
    return " ".join(text.split())


def _init_worker() -> None:
    """Worker start-up: OpenCV on one thread (the environment is set by the parent)."""
    try:
        import cv2

        cv2.setNumThreads(1)
    except ImportError:  # pragma: no cover - OpenCV is a dependency
        pass


@contextlib.contextmanager
def _worker_environment() -> Iterator[None]:
    """Thread-pool variables = 1 for the spawned workers, restored afterwards.

    They must be in the environment before the worker imports numpy (``import vid2sim``
    already does), so they are set in the parent, whose environment spawn copies.
    """
    saved = {k: os.environ.get(k) for k in WORKER_THREAD_ENV}
    for k in WORKER_THREAD_ENV:
        os.environ.setdefault(k, "1")
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


# --------------------------------------------------------------------------- the batch


def read_batch_csv(path: Path) -> dict[str, dict[str, str]]:
    """Name -> record of an earlier run's ``batch.csv`` ({} when absent or unreadable)."""
    try:
        with open(path, encoding="utf-8", newline="") as fh:
            return {r["name"]: r for r in csv.DictReader(fh) if r.get("name")}
    except (OSError, KeyError, csv.Error, UnicodeDecodeError):
        return {}


def write_batch_csv(path: Path, outcomes: list[RowOutcome]) -> None:
    """Write ``batch.csv`` atomically (rows in manifest order; unfinished ones "pending")."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=RESULT_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for outcome in outcomes:
        writer.writerow(outcome.csv_row())
    write_text_atomic(path, buf.getvalue())


def run_batch(manifest: str | Path, out_dir: str | Path, settings: Settings, *,
              jobs: int = 1, retry_failed: bool = False, progress: bool = False,
              report: Callable[[str], None] | None = None) -> BatchSummary:
    """Build every row of ``manifest`` into ``out_dir/<name>/`` with ``jobs`` workers.

    Parameters
    ----------
    manifest : path
        CSV manifest (validated completely before anything is built or written).
    out_dir : path
        Batch folder: one subfolder per row and ``batch.csv``.
    settings : Settings
        Settings shared by every row (each job's detector gets cores / jobs threads).
    jobs : int
        Worker processes (each builds one row at a time).
    retry_failed : bool
        Rebuild rows that ``batch.csv`` records as failed; without it they keep their
        recorded error (a rerun does not repeat a known failure).
    progress : bool
        A tqdm bar over rows on stderr.
    report : callable, optional
        Receives one line per finished (built or failed) row.
    """
    if jobs < 1:
        raise InputError(None, f"--jobs must be >= 1, got {jobs}")
    settings = dataclasses.replace(settings, detector=dataclasses.replace(
        settings.detector, threads=max(1, (os.cpu_count() or 1) // jobs)))
    rows = read_manifest(manifest)
    t0 = time.perf_counter()
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise InputError(out_dir, "is a file, not a folder")
    say = report or (lambda _msg: None)
    csv_path = out_dir / BATCH_CSV
    previous = read_batch_csv(csv_path)
    outcomes = [RowOutcome(name=r.name, status="pending", line=r.line) for r in rows]
    todo: list[int] = []
    for i, row in enumerate(rows):
        done = done_outcome(row, out_dir)
        before = previous.get(row.name, {})
        if done is not None:
            _copy_recorded(done, before)
            outcomes[i] = done
        elif before.get("status") == "failed" and not retry_failed:
            outcomes[i] = RowOutcome(name=row.name, status="failed", line=row.line,
                                     error=before.get("error", ""))
        else:
            todo.append(i)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_batch_csv(csv_path, outcomes)
    n_kept = len(rows) - len(todo)
    n_skipped = sum(o.status == "skipped" for o in outcomes)
    if n_skipped:
        say(f"{n_skipped} of {len(rows)} rows already built from the same inputs: skipped")
    if n_kept > n_skipped:
        say(f"{n_kept - n_skipped} rows failed before: kept as failed (--retry-failed "
            "rebuilds them)")

    from tqdm import tqdm

    with tqdm(total=len(rows), initial=n_kept, unit="video", disable=not progress,
              dynamic_ncols=True) as bar:
        def finished(i: int, outcome: RowOutcome) -> None:
            outcomes[i] = outcome
            write_batch_csv(csv_path, outcomes)
            if outcome.traceback:
                log.info("%s: %s", outcome.name, outcome.traceback.rstrip())
            line = (f"{outcome.name}: {outcome.status} in {outcome.seconds or 0:.1f} s"
                    + (f": {outcome.error}" if outcome.error else ""))
            if progress:
                bar.write(line)
            else:
                say(line)
            bar.update(1)

        _run_pool(rows, todo, settings, out_dir, jobs, finished)
    return BatchSummary(out_dir=out_dir, outcomes=outcomes, wall_s=time.perf_counter() - t0)


def _copy_recorded(outcome: RowOutcome, record: dict[str, str]) -> None:
    """Fill a skipped row's figures from the run that built it (when batch.csv has them)."""
    if record.get("status") not in ("ok", "skipped"):
        return
    for column in ("distance_m", "lead_share", "peak_rss_mb"):
        with contextlib.suppress(ValueError, TypeError):
            setattr(outcome, column, float(record.get(column, "")))


def _run_pool(rows: list[BatchRow], todo: list[int], settings: Settings, out_dir: Path,
              jobs: int, finished: Callable[[int, RowOutcome], None]) -> None:
    """Run ``todo`` rows, at most ``jobs`` at a time, one fresh spawned process per row.

    Only ``jobs`` rows are ever submitted at once, so a worker that dies (killed for memory,
    a crash in native code) breaks the pool for those rows only: they are recorded as failed
    and the rest continue in a new pool.
    """
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    queue = list(reversed(todo))
    with _worker_environment():
        while queue:
            pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context,
                                       initializer=_init_worker, max_tasks_per_child=1)
            running: dict[Future, tuple[int, float]] = {}  # -> row index, submit time
            broken = False
            try:
                while queue or running:
                    while queue and len(running) < jobs and not broken:
                        i = queue.pop()
                        future = pool.submit(run_row, rows[i], settings, out_dir)
                        running[future] = (i, time.perf_counter())
                    if not running:
                        break
                    done, _ = wait(running, return_when=FIRST_COMPLETED)
                    for future in done:
                        i, t_submit = running.pop(future)
                        try:
                            outcome = future.result()
                        except BrokenProcessPool:
                            broken = True
                            outcome = RowOutcome(
                                name=rows[i].name, status="failed", line=rows[i].line,
                                error="the worker process died while this or a concurrent "
                                      "row was building (out of memory? a crash in native "
                                      "code?); --retry-failed rebuilds it",
                                seconds=time.perf_counter() - t_submit)
                        except Exception as exc:  # noqa: BLE001 - e.g. a result that cannot be pickled
                            outcome = RowOutcome(
                                name=rows[i].name, status="failed", line=rows[i].line,
                                error=_one_line(f"internal error: {type(exc).__name__}: {exc}"),
                                seconds=time.perf_counter() - t_submit)
                        finished(i, outcome)
            except BaseException:
                # Ctrl-C: do not wait for builds in flight. Their rows stay "pending" in
                # batch.csv; a worker may still finish its (atomic) build, which the next
                # run then skips, or the next run rebuilds the row.
                pool.shutdown(wait=False, cancel_futures=True)
                raise
            pool.shutdown(wait=True)
