"""Many videos in one run: a CSV manifest -> one :func:`~vid2sim.app.build.build` per row, on
a local process pool or on Ray, with a results index and resume.

The unit of work is one row = one video = one ``build`` into ``OUT/<name>/``, written
atomically by the worker that built it. The batch is idempotent: a row whose inputs still
have the sha256 its last build recorded is skipped, so rerunning the same command after a
kill (or on a cluster that picks the manifest up again) only builds what is missing; a hash
cache keyed by (path, size, modification stamp) keeps a resume from re-reading the videos.

- :mod:`~vid2sim.app.batch.manifest`: the manifest and its validation;
- :mod:`~vid2sim.app.batch.storage`: paths and fsspec URLs (shared file systems, object
  stores);
- :mod:`~vid2sim.app.batch.hashing`: the hash cache;
- :mod:`~vid2sim.app.batch.index`: row outcomes, ``index.parquet`` / ``index.csv`` /
  ``batch.csv``;
- :mod:`~vid2sim.app.batch.worker`: one row (hash, build, atomic row folder, figures);
- :mod:`~vid2sim.app.batch.local`, :mod:`~vid2sim.app.batch.ray_engine`: the engines;
- :mod:`~vid2sim.app.batch.driver`: :func:`run_batch`, which plans and records;
- :mod:`~vid2sim.app.batch.fleet`: the fleet summary page.
"""

from vid2sim.app.batch.driver import DEFAULT_MAX_RETRIES, ENGINES, BatchSummary, run_batch
from vid2sim.app.batch.fleet import write_fleet_report
from vid2sim.app.batch.index import RowOutcome, read_index
from vid2sim.app.batch.manifest import BatchRow, read_manifest
from vid2sim.app.batch.worker import RowTask, done_outcome, run_row

__all__ = ["DEFAULT_MAX_RETRIES", "ENGINES", "BatchRow", "BatchSummary", "RowOutcome",
           "RowTask", "done_outcome", "read_index", "read_manifest", "run_batch", "run_row",
           "write_fleet_report"]
