"""One row, on whichever process or node an engine runs it: hash, build, write, summarise.

:func:`run_row` is the whole unit of work. It never raises: an error becomes a "failed"
outcome with one line. It writes the row's outputs itself (the batch driver never touches
video bytes) and returns only a small :class:`RowOutcome`.

Atomic row folders. On a mounted file system (local disk, NFS, ...) the row is built into a
staging folder beside ``DIR/<name>`` that appears under its name in one rename (a build into
a folder that does not exist yet does that; an earlier build of the row is first renamed
aside to ``DIR/.<name>.old-<hex>`` and deleted only once the new one is in place, or renamed
back if the build fails). So a worker killed at any moment leaves either no row folder or a
complete one; it may leave a hidden staging folder, which the next attempt at the row deletes
(and an aside folder, which it renames back when the row folder is missing). On an object
store the row is built in a local temporary folder and uploaded with ``scenario.json`` last
(:func:`storage.upload_folder`).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import resource
import shutil
import socket
import tempfile
import time
import traceback
import uuid
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from vid2sim.app.batch import storage
from vid2sim.app.batch.hashing import HashEntry, hash_inputs
from vid2sim.app.batch.index import SETTINGS_ROLE, RowOutcome, stage_column
from vid2sim.app.batch.manifest import STATE_DIR, BatchRow
from vid2sim.app.batch.storage import Where
from vid2sim.app.settings import Settings
from vid2sim.app.settings_file import settings_tree
from vid2sim.base.errors import InputError
from vid2sim.core import scenario as scenario_io
from vid2sim.core.tables import read_tracks_csv

if TYPE_CHECKING:
    from vid2sim.app.build import BuildResult

#: Closing speeds below this give no time to collision [m/s]: twice the lead range-rate
#: RMSE measured on KITTI and on the composites (0.5-0.6 m/s, docs/measurements.md),
#: so that a TTC is not made of range-rate noise alone.
TTC_MIN_CLOSING_MPS = 1.0
#: Where each attempt at a row leaves a marker (host, pid, start), under ``DIR``.
ATTEMPTS_DIR = (STATE_DIR, "attempts")


@dataclass(slots=True)
class RowTask:
    """What a worker needs for one row (pickled to the worker process or Ray task).

    :param row: the manifest row
    :param settings: the batch's settings (detector threads already set per job)
    :param out_dir: the batch folder (a path or an fsspec URL)
    :param known: the driver's hash-cache entries for the row's inputs
    """

    row: BatchRow
    settings: Settings
    out_dir: Where
    known: dict[str, HashEntry] = field(default_factory=dict)


def attempts_dir(out_dir: Where, name: str) -> Where:
    """Folder of the attempt markers of row ``name``."""
    return storage.join(out_dir, *ATTEMPTS_DIR, name)


def run_row(task: RowTask) -> RowOutcome:
    """Build one row into ``out_dir/<name>/``; never raises.

    Skips the build when the row folder already holds a build of the same inputs (the
    driver could not tell, e.g. its index was lost). The outcome carries the inputs'
    sha256 (for the index) and their hash-cache entries (for the driver's cache).
    """
    peak = PeakRss()
    t0 = time.perf_counter()
    # a worker process that builds several rows (Ray's) loads the net once; the pipeline is
    # imported by the first row a process builds (see _build_row)
    from vid2sim.app.loaders import keep_loaded_detectors

    keep_loaded_detectors()
    row = task.row
    outcome = RowOutcome(name=row.name, status="ok", line=row.line, host=socket.gethostname(),
                         started_utc=datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ"))
    try:
        retry = _mark_attempt(task.out_dir, row.name, outcome)
        with tempfile.TemporaryDirectory(prefix="vid2sim-row-") as tmp:
            local = _download_inputs(row, Path(tmp) / "inputs")
            outcome.sha256, outcome.hash_entries = hash_inputs(row.sources(), task.known, local)
            done = done_outcome(row, task.out_dir, hashes=outcome.sha256,
                                settings=task.settings)
            outcome.sha256[SETTINGS_ROLE] = settings_key(task.settings)
            if done is not None:
                _take_figures(outcome, done)
                outcome.status = "skipped"
            else:
                settings = replace(task.settings, progress=False)
                result = _build_row(row.inputs(local), task.out_dir, row.name, settings,
                                    Path(tmp), retry)
                _record_build(outcome, result)
    except InputError as exc:
        outcome.status, outcome.error = "failed", one_line(str(exc))
    except Exception as exc:  # noqa: BLE001 - one bad video must not stop the batch
        outcome.status = "failed"
        outcome.error = one_line(f"internal error: {type(exc).__name__}: {exc}")
        outcome.traceback = traceback.format_exc()
    outcome.seconds = time.perf_counter() - t0
    outcome.peak_rss_mb = peak.peak_mb()
    return outcome


def one_line(text: str) -> str:
    return " ".join(text.split())


def _take_figures(outcome: RowOutcome, done: RowOutcome) -> None:
    for name in ("duration_s", "actors", "f1", "mean_iou", "precision", "recall",
                 "n_keyframes", "lead_range_min_m", "lead_range_median_m", "lead_range_max_m",
                 "lead_range_rate_median_mps", "lead_closing_speed_max_mps", "lead_ttc_min_s"):
        setattr(outcome, name, getattr(done, name))


def _mark_attempt(out_dir: Where, name: str, outcome: RowOutcome) -> bool:
    """Leave a marker for this attempt (the driver counts them: Ray retries a killed task
    without telling the driver); it names the host and process, so a test can kill it.
    True when an earlier attempt of this run left one (it died: this is a retry)."""
    folder = attempts_dir(out_dir, name)
    earlier = bool(storage.listdir(folder))
    marker = {"host": outcome.host, "pid": os.getpid(), "started_utc": outcome.started_utc}
    storage.write_bytes(storage.join(folder, f"{uuid.uuid4().hex}.json"),
                        json.dumps(marker).encode("utf-8"))
    return earlier


def _download_inputs(row: BatchRow, folder: Path) -> dict[str, Path]:
    """Local copies of the row's URL inputs (role -> path); local inputs are used in place."""
    local: dict[str, Path] = {}
    for role, where in row.sources().items():
        if isinstance(where, str):
            target = folder / role
            target.mkdir(parents=True, exist_ok=True)
            local[role] = storage.download(where, target)
    return local


def _build_row(inputs, out_dir: Where, name: str, settings: Settings, tmp: Path,
               retry: bool) -> BuildResult:
    """``build`` into ``out_dir/<name>`` so that the row folder appears whole (module doc).

    ``retry``: an earlier attempt died, so its leftovers are cleaned first (the driver
    cleans those of earlier runs when it starts: listing a folder of 100,000 rows once per
    row would cost O(rows^2)).
    """
    # The whole pipeline (onnxruntime, highway-env, matplotlib: 0.8 s of imports) is loaded
    # by the first row a process builds, not by a driver resuming a finished manifest.
    from vid2sim.app.segments import build_drive

    def build(inputs, out, settings):
        # a row's video may be a folder of one drive's segments: joined as `build DIR` does
        return build_drive([inputs.video], inputs, out, settings)

    if not isinstance(out_dir, Path):
        result = build(inputs, tmp / "out" / name, settings)
        storage.upload_folder(tmp / "out" / name, storage.join(out_dir, name))
        return result
    row_dir = out_dir / name
    if retry:
        clean_stale(out_dir, name)
    aside = None
    if row_dir.exists():
        aside = out_dir / f".{name}.old-{uuid.uuid4().hex[:8]}"
        row_dir.rename(aside)
    try:
        result = build(inputs, row_dir, settings)
    except BaseException:
        if aside is not None and not row_dir.exists():
            aside.rename(row_dir)  # a failed build leaves the earlier output as it was
        raise
    if aside is not None:
        shutil.rmtree(aside, ignore_errors=True)
    return result


def staging_owner(entry: str) -> str | None:
    """The row whose build staging (``.<name>.<random>``) or aside folder
    (``.<name>.old-<hex>``) ``entry`` is, or None (the random part never holds a dot)."""
    if not entry.startswith(".") or entry.count(".") < 2:
        return None
    name, _, suffix = entry[1:].rpartition(".")
    return name if name and suffix else None


def clean_stale(out_dir: Path, name: str, entries: list[str] | None = None) -> list[str]:
    """Delete what killed attempts at row ``name`` left in ``out_dir``; the names removed.

    Build staging folders (``.<name>.<random>``) go; an aside folder (``.<name>.old-<hex>``)
    is renamed back to ``<name>`` when the row folder is missing (the kill came between the
    two renames), else deleted. Only folders whose suffix after ``.<name>.`` has no dot are
    touched, so row ``a`` never deletes the staging of row ``a.b``. ``entries``: the
    folder's listing when the caller has it.
    """
    removed: list[str] = []
    row_dir = out_dir / name
    for entry in storage.listdir(out_dir) if entries is None else entries:
        if staging_owner(entry) != name:
            continue
        suffix = entry[len(name) + 2:]
        path = out_dir / entry
        if not path.is_dir():
            continue  # atomic_open's temporary files are files, and not ours
        if suffix.startswith("old-") and not row_dir.exists():
            path.rename(row_dir)
            continue
        shutil.rmtree(path, ignore_errors=True)
        removed.append(entry)
    return removed


def _record_build(outcome: RowOutcome, result: BuildResult) -> None:
    outcome.duration_s, outcome.distance_m = result.duration_s, result.distance_m
    outcome.actors, outcome.lead_share = result.n_actors, result.lead_share
    if result.lead_range_m is not None:
        (outcome.lead_range_min_m, outcome.lead_range_median_m,
         outcome.lead_range_max_m) = result.lead_range_m
    outcome.stage_s = {stage_column(k): v for k, v in result.stage_seconds.items()}
    if result.metrics:
        m = result.metrics
        outcome.f1, outcome.mean_iou = m.get("f1"), m.get("mean_iou")
        outcome.precision, outcome.recall = m.get("precision"), m.get("recall")
        outcome.n_keyframes = m.get("keyframes")
    tracks = result.files.get("tracks")
    if tracks is not None and Path(tracks).is_file():
        _lead_motion(outcome, Path(tracks))


def _lead_motion(outcome: RowOutcome, tracks_csv: Path) -> None:
    """Lead range rate and time to collision from the row's ``tracks.csv``."""
    lead = [b for b in read_tracks_csv(tracks_csv)
            if b.is_lead and math.isfinite(b.range_m) and math.isfinite(b.range_rate_mps)]
    if not lead:
        return
    rng = np.array([b.range_m for b in lead])
    rate = np.array([b.range_rate_mps for b in lead])
    outcome.lead_range_rate_median_mps = float(np.median(rate))
    outcome.lead_closing_speed_max_mps = float(max(0.0, -rate.min()))
    closing = rate < -TTC_MIN_CLOSING_MPS
    if closing.any():
        outcome.lead_ttc_min_s = float((rng[closing] / -rate[closing]).min())
    if outcome.lead_range_median_m is None:
        outcome.lead_range_min_m, outcome.lead_range_median_m, outcome.lead_range_max_m = (
            float(rng.min()), float(np.median(rng)), float(rng.max()))


# --------------------------------------------------------------------------- done check


def settings_key(settings: Settings) -> str:
    """sha256 of the settings tree a scenario records (``source.settings``): a batch row
    built with other settings is built again."""
    text = json.dumps(settings_tree(settings), sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def done_outcome(row: BatchRow, out_dir: Where, hashes: dict[str, str] | None = None,
                 settings: Settings | None = None) -> RowOutcome | None:
    """A "skipped" outcome when ``out_dir/<name>`` holds a build of the row's current inputs.

    A build counts as done when its ``scenario.json`` loads, its report is there,
    ``source.inputs`` records the same roles with the same sha256 as the row's files now (a
    file's name or folder may change; its content may not) and, with ``settings``, its
    ``source.settings`` is this settings tree.

    Parameters
    ----------
    hashes : dict, optional
        Role -> sha256 of the row's inputs when the caller knows them (from the hash cache);
        otherwise every input is hashed here (about 1 s per GB).
    """
    row_dir = storage.join(out_dir, row.name)
    scenario_path = storage.join(row_dir, "scenario.json")
    if not storage.is_file(scenario_path) or not storage.is_file(
            storage.join(row_dir, "report.html")):
        return None
    try:
        scenario = scenario_io.from_json(json.loads(storage.read_bytes(scenario_path)),
                                         scenario_path)
    except (InputError, ValueError, OSError):
        return None
    if settings is not None and scenario.source.settings != json.loads(
            json.dumps(settings_tree(settings), default=str)):
        return None
    recorded = {(i.get("role"), i.get("sha256")) for i in scenario.source.inputs}
    sources = row.sources()
    hashes = None if hashes is None else {k: v for k, v in hashes.items()
                                          if k != SETTINGS_ROLE}
    if {role for role, _ in recorded} != set(sources):
        return None
    if hashes is None or set(hashes) != set(sources):
        hashes = {role: storage.sha256_of(where) for role, where in sources.items()}
    if recorded != set(hashes.items()):
        return None
    outcome = RowOutcome(name=row.name, status="skipped", line=row.line,
                         duration_s=scenario.duration_s, actors=len(scenario.actors),
                         sha256=dict(hashes))
    with contextlib.suppress(ValueError, OSError, InputError):
        metrics = json.loads(storage.read_bytes(storage.join(row_dir, "metrics.json")))
        outcome.f1, outcome.mean_iou = metrics.get("f1"), metrics.get("mean_iou")
        outcome.precision, outcome.recall = metrics.get("precision"), metrics.get("recall")
        outcome.n_keyframes = metrics.get("keyframes")
    if isinstance(row_dir, Path):
        with contextlib.suppress(InputError):
            _lead_motion(outcome, row_dir / "tracks.csv")
    return outcome


# --------------------------------------------------------------------------- memory


class PeakRss:
    """Peak resident memory of this process since the object was made [MiB].

    Linux lets a process reset its high-water mark (``echo 5 > /proc/self/clear_refs``), so
    a worker that builds several rows (Ray reuses worker processes) reports each row's own
    peak; elsewhere the process-lifetime peak (``ru_maxrss``) is all there is.
    """

    def __init__(self) -> None:
        try:
            with open("/proc/self/clear_refs", "w") as fh:
                fh.write("5")
            self.per_row = True
        except OSError:
            self.per_row = False

    def peak_mb(self) -> float:
        if self.per_row:
            with contextlib.suppress(OSError, ValueError), open("/proc/self/status") as fh:
                for line in fh:
                    if line.startswith("VmHWM:"):
                        return int(line.split()[1]) / 1024.0
        # ru_maxrss is in KiB on Linux.
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
