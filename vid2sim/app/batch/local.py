"""The local engine: rows on a process pool of this machine, one fresh process per row.

Each row runs in its own freshly spawned worker process (``max_tasks_per_child=1``): a memory
leak or a crash in native code (OpenCV, onnxruntime) stays with that video, and the worker's
peak resident memory is that one build's. Workers start with ``OMP_NUM_THREADS`` /
``OPENBLAS_NUM_THREADS`` / ``MKL_NUM_THREADS`` = 1 and OpenCV at one thread; the detector
gets the job's onnxruntime threads (``--cpus-per-job``, default cores / jobs), so ``--jobs N``
on the machine's cores does not oversubscribe them.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool

import cv2

from vid2sim.app.batch.index import RowOutcome
from vid2sim.app.batch.worker import RowTask, one_line, run_row

# Thread-pool variables set to 1 in the workers (unless the user set them).
WORKER_THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")

Finished = Callable[[int, RowOutcome], None]


def _init_worker() -> None:
    """Worker start-up: OpenCV on one thread (the environment is set by the parent)."""
    cv2.setNumThreads(1)


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


def run_local(tasks: list[tuple[int, RowTask]], *, jobs: int, max_retries: int,
              finished: Finished) -> None:
    """Run ``tasks`` (row index, task), at most ``jobs`` at a time, one process per row.

    Only ``jobs`` rows are ever submitted at once, so a worker that dies (killed for memory,
    a crash in native code) breaks the pool for those rows only. Python's pool cannot tell
    which of them died, so each is tried again, up to ``max_retries`` times, in a new pool;
    then it is recorded as failed and the rest continue.
    """
    context = multiprocessing.get_context("spawn")
    queue = list(reversed(tasks))
    tries: dict[int, int] = {}
    with _worker_environment():
        while queue:
            pool = ProcessPoolExecutor(max_workers=jobs, mp_context=context,
                                       initializer=_init_worker, max_tasks_per_child=1)
            running: dict[Future, tuple[int, RowTask, float]] = {}
            broken = False
            try:
                while queue or running:
                    while queue and len(running) < jobs and not broken:
                        i, task = queue.pop()
                        tries[i] = tries.get(i, 0) + 1
                        running[pool.submit(run_row, task)] = (i, task, time.perf_counter())
                    if not running:
                        break
                    done, _ = wait(running, return_when=FIRST_COMPLETED)
                    for future in done:
                        i, task, t_submit = running.pop(future)
                        try:
                            outcome = future.result()
                        except BrokenProcessPool:
                            broken = True
                            if tries[i] <= max_retries:
                                queue.append((i, task))
                                continue
                            outcome = worker_died(task, tries[i], time.perf_counter() - t_submit)
                        except Exception as exc:  # noqa: BLE001 - e.g. a result that cannot be pickled
                            outcome = RowOutcome(
                                name=task.row.name, status="failed", line=task.row.line,
                                error=one_line(f"internal error: {type(exc).__name__}: {exc}"),
                                seconds=time.perf_counter() - t_submit)
                        outcome.attempts = tries[i]
                        finished(i, outcome)
            except BaseException:
                # Ctrl-C: do not wait for builds in flight. Their rows stay "pending" in the
                # index; a worker may still finish its (atomic) build, which the next run
                # then skips, or the next run rebuilds the row.
                pool.shutdown(wait=False, cancel_futures=True)
                raise
            pool.shutdown(wait=True)


def worker_died(task: RowTask, attempts: int, seconds: float) -> RowOutcome:
    """The outcome of a row whose worker process died on every attempt."""
    return RowOutcome(
        name=task.row.name, status="failed", line=task.row.line, seconds=seconds,
        attempts=attempts,
        error=f"the worker process died on each of {attempts} attempt(s) (out of memory? a "
              "crash in native code? killed?); --retry-failed rebuilds it")
