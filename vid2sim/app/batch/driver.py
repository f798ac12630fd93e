"""The batch driver: plan which rows to build, hand them to an engine, keep the index.

The driver reads the manifest, the previous index and the hash cache, and decides per row
without reading any video: a row whose inputs' (size, modification stamp) still match the
hash cache, whose cached hashes equal the ones its last successful build recorded, and whose
row folder holds ``scenario.json`` and ``report.html`` is skipped; a row that failed before
keeps its error (unless ``--retry-failed`` or its inputs changed); every other row goes to
the engine. Workers hash what the driver could not look up, build, and send back small
outcome records, which the driver writes into ``index.parquet``, ``index.csv`` and
``batch.csv`` (atomically, at most every :data:`FLUSH_INTERVAL_S`) and the hash cache.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from vid2sim.app.batch import storage
from vid2sim.app.batch.fleet import write_fleet_report
from vid2sim.app.batch.hashing import HashCache
from vid2sim.app.batch.index import (
    SETTINGS_ROLE,
    RowOutcome,
    index_record,
    read_index,
    write_batch_csv,
    write_index,
)
from vid2sim.app.batch.local import run_local
from vid2sim.app.batch.manifest import (
    BATCH_CSV,
    FLEET_HTML,
    INDEX_CSV,
    INDEX_PARQUET,
    STATE_DIR,
    BatchRow,
    read_manifest,
)
from vid2sim.app.batch.ray_engine import check_ray, run_ray
from vid2sim.app.batch.storage import Where
from vid2sim.app.batch.worker import (
    ATTEMPTS_DIR,
    RowTask,
    attempts_dir,
    clean_stale,
    done_outcome,
    settings_key,
    staging_owner,
)
from vid2sim.app.settings import Settings
from vid2sim.base.errors import FormatError, ImpossibleValueError, OutputError

log = logging.getLogger(__name__)

ENGINES = ("local", "ray")
#: Default retries of a row whose worker died: a node lost to preemption or a kill by the
#: out-of-memory killer is often transient; a deterministic crash then costs 3 builds.
DEFAULT_MAX_RETRIES = 2
#: Least seconds between index rewrites while rows finish: rewriting a 100,000-row index
#: after every row would cost the driver O(rows^2); a kill loses at most this much of the
#: record (those rows are found built by the next run's workers and skipped).
FLUSH_INTERVAL_S = 1.0
#: ... and at least this many times the last rewrite's duration, so that the driver spends
#: at most a tenth of its time rewriting a large index.
FLUSH_COST_FACTOR = 10.0
HASH_CACHE = (STATE_DIR, "hashes.csv")


@dataclass(slots=True)
class BatchSummary:
    """The batch's outcome, for the CLI summary and exit code."""

    out_dir: Where
    outcomes: list[RowOutcome]
    wall_s: float
    engine: str = "local"

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outcomes)

    @property
    def failed(self) -> list[RowOutcome]:
        return [o for o in self.outcomes if o.status == "failed"]

    def summary(self) -> str:
        n_ok = self.count("ok")
        per_hour = 3600.0 * n_ok / self.wall_s if self.wall_s > 0 else 0.0
        index = storage.join(self.out_dir, INDEX_CSV)
        lines = [(f"batch: {len(self.outcomes)} rows: {n_ok} ok, {self.count('skipped')} "
                 f"skipped, {self.count('failed')} failed in {self.wall_s:.1f} s "
                 f"({per_hour:.0f} videos per hour, engine {self.engine}); {index}, "
                  f"{storage.join(self.out_dir, FLEET_HTML)}")]
        for o in self.failed[:10]:
            lines.append(f"failed: {o.name} (manifest line {o.line}): {o.error}")
        if len(self.failed) > 10:
            lines.append(f"... and {len(self.failed) - 10} more failed rows in {INDEX_CSV}")
        return "\n".join(lines)


def run_batch(manifest: str | os.PathLike, out_dir: str | os.PathLike, settings: Settings, *,
              engine: str = "local", jobs: int | None = None, cpus_per_job: int | None = None,
              max_retries: int = DEFAULT_MAX_RETRIES, address: str | None = None,
              retry_failed: bool = False, progress: bool = False,
              report: Callable[[str], None] | None = None) -> BatchSummary:
    """Build every row of ``manifest`` into ``out_dir/<name>/`` on ``engine``.

    Parameters
    ----------
    manifest : path or URL
        CSV manifest (validated completely before anything is built or written).
    out_dir : path or URL
        Batch folder: one subfolder per row, ``index.parquet``, ``index.csv``,
        ``batch.csv``, ``fleet.html`` and ``_batch/`` (hash cache, attempt markers).
    settings : Settings
        Settings shared by every row (the detector's threads are set per job).
    engine : {"local", "ray"}
        A process pool on this machine, or one Ray task per row.
    jobs : int, optional
        Rows built at once (local default 1; Ray default: as many as the cluster has slots).
    cpus_per_job : int, optional
        CPUs (onnxruntime threads) per row: local default cores / jobs, Ray default 1.
    max_retries : int
        Further attempts at a row whose worker process died.
    address : str, optional
        Ray cluster address (``auto`` inside a Ray job); default a local Ray runtime.
    retry_failed : bool
        Rebuild rows the index records as failed; without it they keep their recorded error
        (a rerun does not repeat a known failure) unless their inputs changed.
    progress : bool
        A tqdm bar over rows on stderr.
    report : callable, optional
        Receives one line per finished (built or failed) row.
    """
    _check_options(engine, jobs, cpus_per_job, max_retries)
    rows = read_manifest(manifest)
    t0 = time.perf_counter()
    out = storage.location(out_dir)
    if storage.exists(out) and not storage.is_dir(out):
        raise OutputError(out, "is a file, not a folder", "give an output folder")
    say = report or (lambda _msg: None)
    cache_path = storage.join(out, *HASH_CACHE)
    _clean_leftovers(out, rows)
    previous = read_index(out)
    cache = HashCache.load(cache_path)
    outcomes, todo = _plan(rows, out, previous, cache, retry_failed, settings)
    storage.makedirs(out)
    record = _Record(out, rows, outcomes, cache, cache_path)
    record.flush()
    _say_kept(say, outcomes, len(rows) - len(todo))

    jobs, cpus = _jobs_and_cpus(engine, jobs, cpus_per_job)
    settings = dataclasses.replace(settings, detector=dataclasses.replace(
        settings.detector, threads=cpus))
    tasks = [(i, RowTask(rows[i], settings, out,
                         cache.subset([storage.host_path(w) for w in rows[i].sources().values()])))
             for i in todo]
    try:
        with tqdm(total=len(rows), initial=len(rows) - len(todo), unit="video",
                  disable=not progress, dynamic_ncols=True) as bar:
            finished = _on_finished(record, bar, say, progress)
            if tasks and engine == "local":
                run_local(tasks, jobs=jobs, max_retries=max_retries, finished=finished)
            elif tasks:
                run_ray(tasks, address=address, jobs=jobs, cpus_per_job=cpus,
                        max_retries=max_retries, finished=finished)
    finally:
        record.flush()
    if not any(o.status == "pending" for o in outcomes):
        storage.remove(storage.join(out, *ATTEMPTS_DIR))  # every row's markers are counted
    if tasks or not storage.exists(storage.join(out, FLEET_HTML)):
        write_fleet_report(out)
    return BatchSummary(out_dir=out, outcomes=outcomes, wall_s=time.perf_counter() - t0,
                        engine=engine)


def _check_options(engine: str, jobs: int | None, cpus_per_job: int | None,
                   max_retries: int) -> None:
    """The engine's name and the counts, before the manifest is read (and, for Ray, whether
    it is installed: one clear line before any work)."""
    if engine not in ENGINES:
        raise FormatError(None, f"unknown engine '{engine}'", f"one of {', '.join(ENGINES)}")
    if engine == "ray":
        check_ray()
    for option, value, least in (("--jobs", jobs, 1), ("--cpus-per-job", cpus_per_job, 1),
                                 ("--max-retries", max_retries, 0)):
        if value is not None and value < least:
            raise ImpossibleValueError(None, f"{option} must be >= {least}, got {value}")


def _plan(rows: list[BatchRow], out: Where, previous: dict[str, RowOutcome],
          cache: HashCache, retry_failed: bool, settings: Settings
          ) -> tuple[list[RowOutcome], list[int]]:
    """Every row's outcome so far ("pending", or skipped / kept failed by :func:`plan_row`)
    and the indices of the rows a worker must look at."""
    outcomes = [RowOutcome(name=r.name, status="pending", line=r.line) for r in rows]
    todo: list[int] = []
    for i, row in enumerate(rows):
        planned = plan_row(row, out, previous.get(row.name), cache, retry_failed, settings)
        if planned is None:
            todo.append(i)
        else:
            outcomes[i] = planned
    return outcomes, todo


def _say_kept(say: Callable[[str], None], outcomes: list[RowOutcome], n_kept: int) -> None:
    """One line each for the rows skipped as built and the rows kept as failed."""
    n_skipped = sum(o.status == "skipped" for o in outcomes)
    if n_skipped:
        say(f"{n_skipped} of {len(outcomes)} rows already built from the same inputs: skipped")
    if n_kept > n_skipped:
        say(f"{n_kept - n_skipped} rows failed before: kept as failed (--retry-failed "
            "rebuilds them)")


def _jobs_and_cpus(engine: str, jobs: int | None, cpus_per_job: int | None
                   ) -> tuple[int | None, int]:
    """Rows at once and CPUs per row: local, one row sharing the machine's cores unless told;
    Ray, one CPU per row and as many rows as the cluster has slots (``jobs`` None)."""
    if engine == "local":
        jobs = jobs or 1
        return jobs, cpus_per_job or max(1, (os.cpu_count() or 1) // jobs)
    return jobs, cpus_per_job or 1


def _on_finished(record: _Record, bar: tqdm, say: Callable[[str], None], progress: bool
                 ) -> Callable[[int, RowOutcome], None]:
    """What the engine calls as each row ends: record it, say one line, advance the bar."""
    def finished(i: int, outcome: RowOutcome) -> None:
        record.finished(i, outcome)
        if outcome.traceback:
            log.info("%s: %s", outcome.name, outcome.traceback.rstrip())
        line = (f"{outcome.name}: {outcome.status} in {outcome.seconds or 0:.1f} s"
                + (f" ({outcome.attempts} attempts)" if outcome.attempts > 1 else "")
                + (f": {outcome.error}" if outcome.error else ""))
        if progress:
            bar.write(line)
        else:
            say(line)
        bar.update(1)

    return finished


def plan_row(row: BatchRow, out: Where, before: RowOutcome | None, cache: HashCache,
             retry_failed: bool, settings: Settings | None = None) -> RowOutcome | None:
    """What to do with ``row`` without reading its inputs: a "skipped" or kept "failed"
    outcome, or None when a worker must look at it (build it, or hash and compare). With
    ``settings``, a row recorded with another settings tree counts as changed."""
    cached: dict[str, str] = {}
    for role, where in row.sources().items():
        try:
            sha = cache.lookup(where, storage.stat_key(where))
        except OSError:
            return None  # the input vanished since the manifest check: the worker says so
        if sha is not None:
            cached[role] = sha
    known = len(cached) == len(row.sources())
    if settings is not None:
        cached[SETTINGS_ROLE] = settings_key(settings)
    elif before is not None:  # settings not asked about: compare the inputs alone
        before = copy.copy(before)
        before.sha256 = {k: v for k, v in before.sha256.items() if k != SETTINGS_ROLE}
    if before is not None and before.is_done() and known and before.sha256 == cached \
            and _built(out, row.name):
        outcome = RowOutcome(name=row.name, status="skipped", line=row.line)
        outcome.copy_figures(before)
        return outcome
    if before is not None and before.status == "failed" and not retry_failed:
        # Keep a known failure unless an input it was hashed from has changed since.
        changed = bool(before.sha256) and (not known or before.sha256 != cached)
        if not changed:
            outcome = RowOutcome(name=row.name, status="failed", line=row.line,
                                 error=before.error)
            outcome.copy_figures(before)
            outcome.seconds = None
            return outcome
    if known and (before is None or not before.sha256):
        # No usable record (a lost index, an index of an older version): the row folder's
        # own scenario.json says what it was built from; reading it reads no video.
        return done_outcome(row, out, hashes=cached, settings=settings)
    return None


def _built(out: Where, name: str) -> bool:
    row_dir = storage.join(out, name)
    return storage.is_file(storage.join(row_dir, "scenario.json")) and storage.is_file(
        storage.join(row_dir, "report.html"))


def _clean_leftovers(out: Where, rows: list[BatchRow]) -> None:
    """Remove what a killed earlier run left: the driver's temporary index files, the
    attempt markers of rows it had in flight, the staging folders of workers killed with it
    (one listing of the folder; one batch writes into a folder at a time)."""
    storage.remove(storage.join(out, *ATTEMPTS_DIR))
    if not isinstance(out, Path):
        return
    names = {r.name for r in rows}
    entries = storage.listdir(out)
    for name in sorted({staging_owner(e) for e in entries} & names):
        clean_stale(out, name, entries)
    ours = (INDEX_CSV, INDEX_PARQUET, BATCH_CSV, FLEET_HTML)
    for folder, files in ((out, ours), (out / STATE_DIR, (HASH_CACHE[-1],))):
        for entry in entries if folder == out else storage.listdir(folder):
            if entry.endswith(".tmp") and any(entry.startswith(f".{n}.") for n in files):
                storage.remove(folder / entry)


class _Record:
    """The index, ``batch.csv`` and the hash cache of a running batch."""

    def __init__(self, out: Where, rows: list[BatchRow], outcomes: list[RowOutcome],
                 cache: HashCache, cache_path: Where):
        self.out, self.rows, self.outcomes = out, rows, outcomes
        self.cache, self.cache_path = cache, cache_path
        self.flushed, self.flush_s = 0.0, 0.0

    def finished(self, i: int, outcome: RowOutcome) -> None:
        marker_dir = attempts_dir(self.out, outcome.name)
        markers = storage.listdir(marker_dir)
        storage.remove(marker_dir)
        # Ray retries a killed task without telling the driver: the markers count them.
        outcome.attempts = max(outcome.attempts, len(markers))
        for path, entry in outcome.hash_entries.items():
            self.cache.add(path, entry)
        self.outcomes[i] = outcome
        if time.monotonic() - self.flushed >= max(FLUSH_INTERVAL_S,
                                                  FLUSH_COST_FACTOR * self.flush_s):
            self.flush()

    def flush(self) -> None:
        t0 = time.monotonic()
        write_index(self.out, [index_record(r, o) for r, o in zip(self.rows, self.outcomes,
                                                                  strict=True)])
        write_batch_csv(storage.join(self.out, BATCH_CSV), self.outcomes)
        self.cache.save(self.cache_path)
        self.flushed = time.monotonic()
        self.flush_s = self.flushed - t0
