"""vid2sim batch: a manifest of demo-sample rows, failure isolation, resume, validation."""

from __future__ import annotations

import contextlib
import csv
import io
import shutil
from pathlib import Path

import pytest

from vid2sim.app.batch import BatchRow, done_outcome, read_manifest
from vid2sim.base.errors import FormatError
from vid2sim.cli import main


def _rows(out: Path) -> dict[str, dict[str, str]]:
    with open(out / "batch.csv", encoding="utf-8", newline="") as fh:
        return {r["name"]: r for r in csv.DictReader(fh)}


def _run(argv: list[str]) -> tuple[int, str]:
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        rc = main(argv)
    return rc, stdout.getvalue()


@pytest.fixture(scope="module")
def sample(tmp_path_factory) -> Path:
    """One demo sample (imported detections: no weights) and a broken video beside it."""
    from vid2sim.samples.demo_sample import generate_demo_sample

    folder = tmp_path_factory.mktemp("batch_sample")
    generate_demo_sample(folder, seed=7)
    # A file that is not a video: OpenCV cannot open it, build raises an InputError.
    (folder / "broken.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42 truncated")
    return folder


@pytest.fixture(scope="module")
def first_run(sample, tmp_path_factory):
    """The batch once with two workers: two good rows (same files) and one broken video."""
    manifest = sample / "manifest.csv"
    manifest.write_text("video,name,camera,detections,keyframes\n"
                        "demo.mp4,evaluated,camera.yaml,detections.txt,keyframes.json\n"
                        "demo.mp4,plain,,detections.txt,\n"
                        "broken.mp4,,,detections.txt,\n", encoding="utf-8")
    out = tmp_path_factory.mktemp("batch_out") / "batch"
    rc, stdout = _run(["batch", str(manifest), "--out", str(out), "--jobs", "2", "--offline"])
    return manifest, out, rc, stdout


def test_one_broken_row_fails_alone_and_the_batch_exits_1(first_run):
    _, out, rc, stdout = first_run
    assert rc == 1
    for name in ("evaluated", "plain"):
        for file in ("scenario.json", "scenario.xosc", "tracks.csv", "report.html"):
            assert (out / name / file).stat().st_size > 0, (name, file)
    assert (out / "evaluated" / "metrics.json").is_file()
    assert not (out / "broken").exists(), "a failed build leaves no output folder"
    assert not [p for p in out.iterdir() if p.name.startswith(".")], "no staging left"
    assert "3 rows: 2 ok, 0 skipped, 1 failed" in stdout
    assert "videos per hour" in stdout
    assert "failed: broken (manifest line 4): " in stdout


def test_batch_csv_records_every_row(first_run):
    _, out, _, _ = first_run
    with open(out / "batch.csv", encoding="utf-8", newline="") as fh:
        reader = csv.DictReader(fh)
        assert reader.fieldnames == ["name", "status", "seconds", "duration_s", "distance_m",
                                     "actors", "lead_share", "f1", "mean_iou", "peak_rss_mb",
                                     "error"]
        rows = {r["name"]: r for r in reader}
    assert list(rows) == ["evaluated", "plain", "broken"], "manifest order"
    evaluated, plain, broken = rows["evaluated"], rows["plain"], rows["broken"]
    assert evaluated["status"] == plain["status"] == "ok"
    # The demo clip lasts 24 s at 10 fps; no GPS: the ego stands still.
    assert float(evaluated["duration_s"]) == pytest.approx(23.9, abs=0.2)
    assert float(plain["distance_m"]) == 0.0
    assert int(evaluated["actors"]) > 0 and 0.0 < float(evaluated["lead_share"]) <= 1.0
    # Keyframes give F1 / IoU; a row without them leaves the cells empty.
    assert 0.5 < float(evaluated["f1"]) <= 1.0 and 0.5 < float(evaluated["mean_iou"]) <= 1.0
    assert plain["f1"] == plain["mean_iou"] == ""
    assert float(plain["peak_rss_mb"]) > 50, "a build's worker holds at least numpy + OpenCV"
    assert evaluated["error"] == plain["error"] == ""
    assert broken["status"] == "failed"
    assert "broken.mp4" in broken["error"] and "\n" not in broken["error"]
    assert broken["f1"] == broken["duration_s"] == ""


def test_rerun_skips_built_rows_and_keeps_failures_unless_asked(first_run):
    manifest, out, _, _ = first_run
    built = {n: (out / n / "scenario.json").stat().st_mtime_ns for n in ("evaluated", "plain")}
    rc, stdout = _run(["batch", str(manifest), "--out", str(out), "--offline"])
    assert rc == 1, "the known failure still counts"
    assert "3 rows: 0 ok, 2 skipped, 1 failed" in stdout
    rows = _rows(out)
    assert [r["status"] for r in rows.values()] == ["skipped", "skipped", "failed"]
    assert rows["broken"]["seconds"] == "", "not rerun without --retry-failed"
    assert rows["broken"]["error"], "the earlier error is kept"
    # Skipped rows keep the figures of the run that built them.
    assert rows["evaluated"]["f1"] and rows["evaluated"]["distance_m"]
    assert {n: (out / n / "scenario.json").stat().st_mtime_ns for n in built} == built

    rc, stdout = _run(["batch", str(manifest), "--out", str(out), "--offline",
                       "--retry-failed"])
    assert rc == 1
    rows = _rows(out)
    assert rows["broken"]["status"] == "failed" and rows["broken"]["seconds"] != ""
    assert rows["evaluated"]["status"] == rows["plain"]["status"] == "skipped"


def test_a_changed_input_is_rebuilt_not_skipped(first_run, sample, tmp_path):
    _, out, _, _ = first_run
    row = BatchRow(line=3, name="plain", video=sample / "demo.mp4",
                   detections=sample / "detections.txt")
    assert done_outcome(row, out) is not None
    changed = tmp_path / "detections.txt"
    shutil.copy(sample / "detections.txt", changed)
    with open(changed, "a", encoding="utf-8") as fh:
        fh.write("1,-1,10.00,10.00,20.00,20.00,0.900,-1,-1,-1\n")
    row.detections = changed
    assert done_outcome(row, out) is None
    # An input added to the row (a camera file) also means a different build.
    row.detections, row.camera_path = sample / "detections.txt", sample / "camera.yaml"
    assert done_outcome(row, out) is None


def test_bad_manifest_rows_fail_in_one_line_before_anything_is_built(sample, tmp_path, capsys):
    manifest = tmp_path / "bad.csv"
    manifest.write_text(f"video,name,fps\n"
                        f"{sample / 'demo.mp4'},a,\n"
                        f"missing.mp4,b,\n"
                        f"{sample / 'demo.mp4'},a,ten\n"
                        f",c,\n", encoding="utf-8")
    out = tmp_path / "out"
    assert main(["batch", str(manifest), "--out", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert captured.err.count("\n") == 1 and captured.err.startswith(f"error: {manifest}: ")
    err = captured.err
    assert "3 bad row(s)" in err
    assert "line 3: no such video file missing.mp4" in err
    assert "line 4: fps 'ten' is not a number; name 'a' already used on line 2" in err
    assert "line 5: empty video" in err
    assert not out.exists(), "nothing written before the whole manifest is valid"


@pytest.mark.parametrize("header, column", [
    ("name,gps", "video"),  # the column that is missing
    ("video,gsp", "gsp"),  # the column that is unknown
])
def test_bad_manifest_header(tmp_path, header, column):
    manifest = tmp_path / "m.csv"
    manifest.write_text(f"{header}\nx.mp4,y\n", encoding="utf-8")
    with pytest.raises(FormatError, match=column):
        read_manifest(manifest)


def test_unnamed_rows_get_unique_names_and_paths_relative_to_the_manifest(sample, tmp_path):
    manifest = sample / "names.csv"
    manifest.write_text("video,name,gps_offset_s\ndemo.mp4,,\ndemo.mp4,demo_2,1.5\n"
                        "demo.mp4,,\n", encoding="utf-8")
    rows = read_manifest(manifest)
    assert [r.name for r in rows] == ["demo", "demo_2", "demo_3"]
    assert rows[0].video == sample / "demo.mp4"
    assert rows[1].gps_offset_s == 1.5 and rows[0].gps_offset_s is None
