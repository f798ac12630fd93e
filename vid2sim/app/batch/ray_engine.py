"""The Ray engine: one Ray task per row, on a running cluster or a local Ray runtime.

Each row is a task with ``num_cpus = cpus_per_job`` (its onnxruntime and OpenCV threads are
set to the same number, and Ray sets ``OMP_NUM_THREADS`` to it), retried by Ray up to
``max_retries`` times when its worker process or node dies (``retry_exceptions=False``: a bad
video is an outcome, not an exception, and is never retried). The driver keeps a bounded
window of tasks in flight (twice the slots the cluster has, re-read as an autoscaler adds
nodes, or ``--jobs`` when given), so its memory stays flat on a 100,000-row manifest and the
index is written as rows finish. Tasks return small :class:`RowOutcome` records: videos and
outputs never pass through the driver or Ray's object store.

Ray is an optional dependency (``pip install "vid2sim[ray]"``), imported only here, inside
the functions that need it.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import time
from collections.abc import Callable

import cv2

from vid2sim.app.batch.index import RowOutcome
from vid2sim.app.batch.local import worker_died
from vid2sim.app.batch.worker import RowTask, one_line, run_row
from vid2sim.base.errors import InconsistentInputError, InputError

Finished = Callable[[int, RowOutcome], None]

#: Tasks in flight per free task slot of the cluster: 2 keeps every slot busy while the
#: driver records a finished row and submits the next, and shows an autoscaler the demand.
WINDOW_PER_SLOT = 2
#: Seconds between re-reads of the cluster's CPUs (an autoscaler may add nodes).
CLUSTER_POLL_S = 10.0


_NO_RAY = ("--engine ray needs Ray, which is not installed",
           'pip install "vid2sim[ray]", or use --engine local')


def check_ray() -> None:
    """:class:`InputError` (one line) when Ray is not installed, found without importing it
    (a batch with nothing left to build never needs it)."""
    try:
        found = importlib.util.find_spec("ray") is not None
    except (ImportError, ValueError, AttributeError):  # e.g. sys.modules["ray"] is None
        found = False
    if not found:
        raise InputError(None, *_NO_RAY)


def require_ray():
    """The ``ray`` module, or :class:`InputError` (one line) when it is not installed."""
    try:
        # Ray is an optional extra and takes over a second to import: only this engine
        # needs it, so it is imported here and nowhere else.
        import ray
    except ImportError:
        raise InputError(None, *_NO_RAY) from None
    return ray


def connect(address: str | None, num_cpus: int | None) -> bool:
    """Connect to the Ray cluster at ``address`` (``auto``: the one this process runs in),
    or start a local runtime with ``num_cpus`` CPUs (None: all); True if this call started
    or joined it (and so must shut it down). An already initialised Ray is used as is."""
    ray = require_ray()
    if ray.is_initialized():
        return False
    address = address or os.environ.get("RAY_ADDRESS") or None
    kwargs = {"include_dashboard": False, "logging_level": logging.ERROR,
              # rows report through their outcomes; worker chatter stays in Ray's log folder
              "log_to_driver": False}
    try:
        if address:
            ray.init(address=address, **kwargs)
        else:
            ray.init(num_cpus=num_cpus, **kwargs)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise InputError(address or "local Ray runtime", f"cannot start or reach Ray: "
                         f"{one_line(str(exc))}",
                         "start a cluster with `ray start --head`, or omit --address for a "
                         "local runtime") from None
    return True


def _ray_row(task: RowTask) -> RowOutcome:
    """The Ray task body: OpenCV on the task's CPUs, then the row."""
    cv2.setNumThreads(task.settings.detector.threads)
    return run_row(task)


def run_ray(tasks: list[tuple[int, RowTask]], *, address: str | None, jobs: int | None,
            cpus_per_job: int, max_retries: int, finished: Finished) -> None:
    """Run ``tasks`` (row index, task) as Ray tasks; ``finished`` gets each outcome."""
    ray = require_ray()
    started = connect(address, None if jobs is None else jobs * cpus_per_job)
    try:
        _check_fits(ray, cpus_per_job)
    except InputError:
        if started:
            ray.shutdown()
        raise
    remote = ray.remote(_ray_row)
    in_flight: dict = {}  # ObjectRef -> (row index, task, submit time)
    queue = list(reversed(tasks))
    window, polled = _window(ray, jobs, cpus_per_job), time.monotonic()
    try:
        while queue or in_flight:
            if jobs is None and time.monotonic() - polled > CLUSTER_POLL_S:
                window, polled = _window(ray, jobs, cpus_per_job), time.monotonic()
            while queue and len(in_flight) < window:
                i, task = queue.pop()
                ref = remote.options(num_cpus=cpus_per_job, max_retries=max_retries,
                                     retry_exceptions=False,
                                     name=f"vid2sim-batch:{task.row.name}").remote(task)
                in_flight[ref] = (i, task, time.perf_counter())
            ready, _ = ray.wait(list(in_flight), num_returns=1)
            for ref in ready:
                i, task, t_submit = in_flight.pop(ref)
                try:
                    outcome = ray.get(ref)
                except ray.exceptions.WorkerCrashedError:
                    outcome = worker_died(task, max_retries + 1, time.perf_counter() - t_submit)
                except ray.exceptions.RayError as exc:  # node lost, out of memory, cancelled
                    outcome = RowOutcome(
                        name=task.row.name, status="failed", line=task.row.line,
                        seconds=time.perf_counter() - t_submit,
                        error=one_line(f"Ray could not run the row: {type(exc).__name__}: "
                                       f"{str(exc)[:300]}"))
                finished(i, outcome)
    except BaseException:
        # Ctrl-C: stop the rows in flight (their workers are killed; the next run cleans
        # their staging folders and builds them again).
        for ref in in_flight:
            ray.cancel(ref, force=True)
        raise
    finally:
        if started:
            ray.shutdown()


def _check_fits(ray, cpus_per_job: int) -> None:
    """A task needing more CPUs than any node has would wait forever: say so instead."""
    largest = max((float(n.get("Resources", {}).get("CPU", 0.0)) for n in ray.nodes()
                   if n.get("Alive")), default=0.0)
    if cpus_per_job > largest:
        raise InconsistentInputError(
            None, f"--cpus-per-job {cpus_per_job} but the largest Ray node has "
            f"{largest:g} CPUs", "give at most that many CPUs per job")


def _window(ray, jobs: int | None, cpus_per_job: int) -> int:
    """Tasks kept in flight: ``jobs`` when given, else :data:`WINDOW_PER_SLOT` per slot."""
    if jobs is not None:
        return jobs
    cpus = float(ray.cluster_resources().get("CPU", 1.0))
    return max(1, int(cpus // cpus_per_job)) * WINDOW_PER_SLOT
