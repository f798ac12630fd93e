"""vid2sim batch on Ray and on the local pool: outcomes, the index, resume, equal outputs."""

from __future__ import annotations

import contextlib
import csv
import io
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from tests.batch.conftest import offline
from vid2sim.app.batch import driver, run_batch, storage
from vid2sim.base.errors import InconsistentInputError
from vid2sim.base.fileio import sha256_file
from vid2sim.cli import main

OK_ROWS = ("full", "plain")


@pytest.fixture(scope="module")
def ray_run(clip, ray_runtime, tmp_path_factory):
    """The acceptance manifest once on the session's Ray runtime (2 CPUs)."""
    out = tmp_path_factory.mktemp("ray") / "batch"
    summary = run_batch(clip / "manifest.csv", out, offline(), engine="ray")
    return out, summary


def _index(out: Path) -> dict[str, dict]:
    return {r["id"]: r for r in pq.read_table(out / "index.parquet").to_pylist()}


def test_ray_runs_two_good_rows_and_records_two_failures(ray_run, clip):
    out, summary = ray_run
    assert (summary.count("ok"), summary.count("failed"), summary.count("skipped")) == (2, 2, 0)
    index = _index(out)
    assert list(index) == ["full", "plain", "bad", "nogps"], "manifest order"
    bad, nogps = index["bad"], index["nogps"]
    assert bad["status"] == nogps["status"] == "failed"
    assert bad["error"].startswith(f"{clip / 'broken.mp4'}: OpenCV cannot open this video")
    assert nogps["error"].startswith(f"{clip / 'nofix.gpx'}: GPX file has no track or route")
    for name in OK_ROWS:
        row = index[name]
        assert row["status"] == "ok" and row["error"] == "" and row["attempts"] == 1
        for file in ("scenario.json", "scenario.xosc", "tracks.csv", "report.html"):
            assert (out / name / file).stat().st_size > 0, (name, file)
        assert row["report"] == f"{name}/report.html"
        assert row["host"] and row["seconds"] > 0 and row["peak_rss_mb"] > 50
        assert row["video_sha256"] == sha256_file(clip / "demo.mp4")
        assert row["detections_sha256"] == sha256_file(clip / "detections.txt")
        assert row["stage_detect_track_and_range_s"] > 0
        assert 0.0 < row["lead_range_min_m"] <= row["lead_range_median_m"]
        assert row["duration_s"] == pytest.approx(4.9, abs=0.11)
    full, plain = index["full"], index["plain"]
    # The lead drives 26.9-29.2 m ahead over the first 5 s (truth.json); with the true
    # camera (row "full") the monocular median is within 10% of that.
    assert full["lead_range_median_m"] == pytest.approx(28.0, rel=0.1)
    assert full["gps_sha256"] == sha256_file(clip / "demo.gpx") and plain["gps"] is None
    assert full["stage_road_and_map_matching_s"] > 0 and plain["stage_read_gps_s"] is None
    assert full["n_keyframes"] >= 4 and 0.5 < full["f1"] <= 1.0 and plain["f1"] is None
    assert full["distance_m"] > 30.0 and plain["distance_m"] == 0.0, "GPS moves the ego"
    assert not (out / "bad").exists() and not (out / "nogps").exists()
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")], "no staging left"
    assert not (out / "_batch" / "attempts").exists(), "attempt markers are counted, then gone"


def test_the_index_csv_matches_the_parquet_index(ray_run):
    out, _ = ray_run
    with open(out / "index.csv", encoding="utf-8", newline="") as fh:
        rows = list(csv.DictReader(fh))
    table = pq.read_table(out / "index.parquet")
    assert list(rows[0]) == table.schema.names
    for text, typed in zip(rows, table.to_pylist(), strict=True):
        assert text["id"] == typed["id"] and text["status"] == typed["status"]
        assert text["error"] == typed["error"]
        if typed["lead_range_median_m"] is not None:
            assert float(text["lead_range_median_m"]) == pytest.approx(
                typed["lead_range_median_m"], rel=1e-5)


def test_rerun_skips_built_rows_without_hashing_or_engine(ray_run, clip, monkeypatch):
    out, _ = ray_run
    before = {n: (out / n / "scenario.json").stat().st_mtime_ns for n in OK_ROWS}

    def no_hashing(*_args, **_kwargs):
        raise AssertionError("the rerun read an input to hash it")

    def no_engine(*_args, **_kwargs):
        raise AssertionError("the rerun started an engine")

    monkeypatch.setattr("vid2sim.base.fileio.sha256_file", no_hashing)
    monkeypatch.setattr(storage, "sha256_of", no_hashing)
    monkeypatch.setattr(driver, "run_ray", no_engine)
    summary = run_batch(clip / "manifest.csv", out, offline(), engine="ray")
    assert (summary.count("skipped"), summary.count("failed"), summary.count("ok")) == (2, 2, 0)
    index = _index(out)
    assert [index[n]["status"] for n in index] == ["skipped", "skipped", "failed", "failed"]
    assert index["bad"]["error"].startswith(f"{clip / 'broken.mp4'}: OpenCV cannot open")
    # Skipped rows keep the figures, hashes and stage times of the run that built them.
    assert index["full"]["f1"] > 0.5 and index["full"]["stage_replay_evaluation_s"] > 0
    assert index["plain"]["video_sha256"] == index["full"]["video_sha256"]
    assert {n: (out / n / "scenario.json").stat().st_mtime_ns for n in OK_ROWS} == before


def test_local_engine_gives_byte_identical_rows_through_a_file_url(ray_run, clip, tmp_path):
    ray_out, ray_summary = ray_run
    out = tmp_path / "local"
    summary = run_batch(clip / "manifest.csv", f"file://{out}", offline(), engine="local",
                        jobs=2)
    assert (summary.count("ok"), summary.count("failed")) == (2, 2)
    for name in OK_ROWS:
        for file in ("scenario.json", "tracks.csv", "scenario.xosc", "road.xodr"):
            if (ray_out / name / file).exists():
                assert (out / name / file).read_bytes() == (ray_out / name / file).read_bytes(), \
                    (name, file)
    for on_ray, local in zip(ray_summary.outcomes, summary.outcomes, strict=True):
        assert (local.name, local.status, local.error) == (on_ray.name, on_ray.status,
                                                           on_ray.error)


def test_batch_writes_a_fleet_page_linking_each_report(ray_run):
    out, _ = ray_run
    page = (out / "fleet.html").read_text(encoding="utf-8")
    for name in OK_ROWS:
        assert f"href='{name}/report.html'" in page
    assert page.count("data:image/png;base64,") == 2, "stage times and distributions"
    assert "GPX file has no track or route points" in page


def test_engine_ray_without_ray_installed_is_one_error_line(clip, tmp_path, monkeypatch,
                                                            capsys):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now raises ImportError
    out = tmp_path / "out"
    rc = main(["batch", str(clip / "manifest.csv"), "--out", str(out), "--engine", "ray"])
    captured = capsys.readouterr()
    assert rc == 2
    assert captured.err.count("\n") == 1
    assert captured.err.startswith("error: --engine ray needs Ray, which is not installed")
    assert 'pip install "vid2sim[ray]"' in captured.err
    assert not out.exists(), "nothing done"


def test_a_job_larger_than_any_ray_node_is_refused(clip, ray_runtime, tmp_path):
    manifest = tmp_path / "m.csv"
    manifest.write_text(f"video,detections\n{clip / 'demo.mp4'},{clip / 'detections.txt'}\n",
                        encoding="utf-8")
    with pytest.raises(InconsistentInputError, match="--cpus-per-job 3 .* 2 CPUs"):
        run_batch(manifest, tmp_path / "out", offline(), engine="ray", cpus_per_job=3)
    assert ray_runtime.is_initialized(), "a runtime the caller started is left running"


def test_batch_report_command(ray_run, tmp_path):
    out, _ = ray_run
    stdout = io.StringIO()
    page = tmp_path / "fleet_copy.html"
    with contextlib.redirect_stdout(stdout):
        assert main(["batch-report", str(out), "--out", str(page)]) == 0
    assert str(page) in stdout.getvalue()
    text = page.read_text(encoding="utf-8")
    assert "vid2sim fleet summary" in text and "replay evaluation" in text


def test_batch_report_without_an_index_is_one_error_line(tmp_path, capsys):
    assert main(["batch-report", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: {tmp_path}: no batch index here")
