"""Faults: a worker killed mid-row, stale staging, a failed rebuild of a built row."""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from tests.batch.conftest import offline
from vid2sim.app.batch import BatchRow, RowTask, run_batch, run_row
from vid2sim.app.batch.worker import clean_stale

#: A killed attempt's staging folder, as build names them (".<name>." + 8 random chars).
SEEDED_STAGING = ".kf.zz99zz99"
#: Longest wait for the build to reach its write stage [s] (a 5 s clip builds in 3-15 s on
#: a loaded 2-core machine, plus the worker's start-up).
WAIT_S = 180.0


def _kill_mid_write(out: Path, name: str, seen: dict) -> None:
    """Wait until the build of ``name`` writes its staging folder, then SIGKILL its process.

    Records in ``seen`` the killed pid and every partial row folder observed meanwhile.
    """
    markers = out / "_batch" / "attempts" / name
    deadline = time.monotonic() + WAIT_S
    while time.monotonic() < deadline:
        row_dir = out / name
        if row_dir.exists() and not (row_dir / "scenario.json").exists():
            seen.setdefault("partial", []).append(sorted(p.name for p in row_dir.iterdir()))
        staging = [p for p in out.glob(f".{name}.*") if p.name != SEEDED_STAGING]
        found = sorted(markers.glob("*.json")) if markers.is_dir() else []
        if staging and found:
            pid = json.loads(found[0].read_text(encoding="utf-8"))["pid"]
            os.kill(pid, signal.SIGKILL)
            seen["pid"], seen["staging"] = pid, staging[0].name
            return
        time.sleep(0.01)
    seen["timeout"] = True


@pytest.mark.parametrize("engine", ["local", "ray"])
def test_a_worker_killed_mid_write_is_retried_and_leaves_no_partial_row(
        engine, clip, tmp_path, request):
    if engine == "ray":
        request.getfixturevalue("ray_runtime")
    manifest = tmp_path / "one.csv"
    manifest.write_text("video,name,camera,detections,keyframes\n"
                        f"{clip / 'demo.mp4'},kf,{clip / 'camera.yaml'},"
                        f"{clip / 'detections.txt'},{clip / 'keyframes.json'}\n",
                        encoding="utf-8")
    out = tmp_path / "out"
    # What an earlier killed attempt left: a staging folder with half its files.
    (out / SEEDED_STAGING).mkdir(parents=True)
    (out / SEEDED_STAGING / "tracks.csv").write_text("frame\n", encoding="utf-8")
    seen: dict = {}
    killer = threading.Thread(target=_kill_mid_write, args=(out, "kf", seen), daemon=True)
    killer.start()
    summary = run_batch(manifest, out, offline(), engine=engine, jobs=1, max_retries=2)
    killer.join(timeout=5)
    assert "timeout" not in seen and "pid" in seen, "the build was seen writing and killed"
    assert not seen.get("partial"), f"partial row folders seen: {seen.get('partial')}"
    (outcome,) = summary.outcomes
    assert outcome.status == "ok" and outcome.attempts == 2, outcome
    (record,) = pq.read_table(out / "index.parquet").to_pylist()
    assert record["status"] == "ok" and record["attempts"] == 2
    for file in ("scenario.json", "report.html", "metrics.json", "tracks.csv"):
        assert (out / "kf" / file).stat().st_size > 0, file
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")], \
        "the killed attempt's staging and the seeded one are gone"


def test_every_attempt_killed_is_a_failed_row_with_its_attempts(clip, tmp_path):
    manifest = tmp_path / "one.csv"
    manifest.write_text(f"video,name,camera,detections,keyframes\n{clip / 'demo.mp4'},kf,"
                        f"{clip / 'camera.yaml'},{clip / 'detections.txt'},"
                        f"{clip / 'keyframes.json'}\n", encoding="utf-8")
    out = tmp_path / "out"
    seen: dict = {}
    killer = threading.Thread(target=_kill_mid_write, args=(out, "kf", seen), daemon=True)
    killer.start()
    summary = run_batch(manifest, out, offline(), engine="local", jobs=1, max_retries=0)
    killer.join(timeout=5)
    assert "pid" in seen
    (outcome,) = summary.outcomes
    assert outcome.status == "failed" and outcome.attempts == 1
    assert "worker process died" in outcome.error and "--retry-failed" in outcome.error
    assert not (out / "kf").exists()


def test_clean_stale_removes_staging_and_restores_an_aside_row(tmp_path):
    (tmp_path / ".a.k3j4h5g6").mkdir()                 # a build's staging of row a
    (tmp_path / ".a.old-1234abcd").mkdir()             # row a renamed aside, never replaced
    (tmp_path / ".a.old-1234abcd" / "scenario.json").write_text("{}", encoding="utf-8")
    (tmp_path / ".a.b.k3j4h5g6").mkdir()               # row a.b's staging: not row a's
    (tmp_path / ".a.csv.x1y2.tmp").write_text("", encoding="utf-8")  # a file: not staging
    removed = clean_stale(tmp_path, "a")
    assert removed == [".a.k3j4h5g6"]
    assert (tmp_path / "a" / "scenario.json").read_text(encoding="utf-8") == "{}"
    assert sorted(p.name for p in tmp_path.iterdir()) == [".a.b.k3j4h5g6", ".a.csv.x1y2.tmp",
                                                          "a"]
    # With the row folder in place, an aside folder is an old build: deleted.
    (tmp_path / ".a.old-99").mkdir()
    assert clean_stale(tmp_path, "a") == [".a.old-99"]


def test_a_failed_rebuild_leaves_the_built_row_as_it_was(clip, tmp_path):
    row = BatchRow(line=2, name="r", video=clip / "demo.mp4", detections=clip / "detections.txt")
    out = tmp_path / "out"
    assert run_row(RowTask(row, offline(), out)).status == "ok"
    before = {p.name: p.read_bytes() for p in (out / "r").iterdir() if p.is_file()}
    broken = BatchRow(line=2, name="r", video=clip / "broken.mp4",
                      detections=clip / "detections.txt")
    outcome = run_row(RowTask(broken, offline(), out))
    assert outcome.status == "failed" and "broken.mp4" in outcome.error
    assert {p.name: p.read_bytes() for p in (out / "r").iterdir() if p.is_file()} == before
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]
