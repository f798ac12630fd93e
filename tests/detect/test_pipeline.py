"""The detection stage end to end: frames -> (imported or real) detections -> tracks -> CSV,
and the `vid2sim detect` / `vid2sim models` commands."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest

from vid2sim.cli import main
from vid2sim.core.records import VEHICLE_CATEGORIES, Detection, TrackedBox
from vid2sim.core.tables import DETECTIONS_CSV_COLUMNS as CSV_COLUMNS
from vid2sim.core.tables import write_detections_csv
from vid2sim.detect.pipeline import run_detect
from vid2sim.detect.vehicles.detector import load_detector

N_FRAMES = 20


def car_box(i: int) -> tuple[float, float, float, float]:
    """Where the synthetic car is in frame i [px]: drifting right 4 px per frame."""
    return (20.0 + 4 * i, 40.0, 60.0 + 4 * i, 70.0)


@pytest.fixture
def clip(tmp_path) -> Path:
    """A 20-frame 10 frames/s video of a grey block drifting right."""
    path = tmp_path / "clip.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (160, 96))
    for i in range(N_FRAMES):
        img = np.zeros((96, 160, 3), np.uint8)
        x1, y1, x2, y2 = (int(v) for v in car_box(i))
        img[y1:y2, x1:x2] = 180
        writer.write(img)
    writer.release()
    return path


@pytest.fixture
def mot_file(tmp_path) -> Path:
    """The block's boxes as a MOT-challenge file (1-based frames)."""
    path = tmp_path / "boxes.txt"
    lines = []
    for i in range(N_FRAMES):
        x1, y1, x2, y2 = car_box(i)
        lines.append(f"{i + 1},-1,{x1},{y1},{x2 - x1},{y2 - y1},0.9,car")
    path.write_text("\n".join(lines) + "\n")
    return path


def imported(every: int = 1) -> dict[int, list[Detection]]:
    return {i: [Detection(car_box(i), 0.9, "car")] for i in range(0, N_FRAMES, every)}


def test_run_detect_with_imported_boxes_and_frame_callback(clip):
    seen = []
    rows = run_detect(clip, detector=None, detections=imported(), progress=False,
                      on_frame=lambda f: seen.append((f.index, f.image_bgr.shape)))
    assert [r.frame for r in rows] == list(range(N_FRAMES))
    assert {r.track_id for r in rows} == {1}
    assert rows[5].t_s == pytest.approx(0.5, abs=1e-3)
    assert (rows[5].x1, rows[5].y2) == pytest.approx((40.0, 70.0))
    assert seen == [(i, (96, 160, 3)) for i in range(N_FRAMES)]


def test_detect_every_runs_the_detector_on_every_nth_frame_only(clip):
    class CountingDetector:
        def __init__(self):
            self.calls = 0

        def detect(self, image_bgr):
            self.calls += 1
            # find the bright block: a stand-in detector for this synthetic clip only
            ys, xs = np.nonzero(image_bgr[:, :, 0] > 90)
            return [Detection((float(xs.min()), float(ys.min()), float(xs.max() + 1),
                               float(ys.max() + 1)), 0.9, "car")]

    det = CountingDetector()
    decoded = []
    rows = run_detect(clip, detector=det, detect_every=4, progress=False,
                      on_frame=lambda f: decoded.append(f.index))
    assert det.calls == 5 and decoded == [0, 4, 8, 12, 16]
    assert [r.frame for r in rows] == list(range(N_FRAMES))  # carried between detections
    assert len({r.track_id for r in rows}) == 1
    last = rows[-1]  # frame 19, predicted 3 frames past the last detection
    assert (last.x1 + last.x2) / 2 == pytest.approx(sum(car_box(19)[::2]) / 2, abs=4.0)


def test_write_detections_csv(tmp_path):
    rows = [TrackedBox(3, 0.3, 1, "truck", 0.87654, 1.0, 2.0, 3.5, 4.25)]
    out = tmp_path / "sub" / "detections.csv"
    write_detections_csv(rows, out)
    with open(out, newline="") as fh:
        table = list(csv.reader(fh))
    assert tuple(table[0]) == CSV_COLUMNS
    assert table[1] == ["3", "0.300000", "1", "truck", "0.8765", "1.00", "2.00", "3.50", "4.25"]
    assert [p.name for p in out.parent.iterdir()] == ["detections.csv"]


def test_cli_detect_with_imported_boxes(clip, mot_file, tmp_path, capsys):
    out = tmp_path / "det.csv"
    code = main(["detect", str(clip), "--detections", str(mot_file), "--out", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    assert "20 frames" in text and "1 tracks" in text and "car 1" in text
    with open(out, newline="") as fh:
        assert len(list(csv.DictReader(fh))) == N_FRAMES


def test_cli_detect_bad_input_exits_2(tmp_path, capsys):
    code = main(["detect", str(tmp_path / "nope.mp4"), "--detections", str(tmp_path / "x.txt"),
                 "--out", str(tmp_path / "o.csv")])
    assert code == 2
    assert "error:" in capsys.readouterr().err
    assert not (tmp_path / "o.csv").exists()


def test_cli_models_list(capsys, model_dir):
    assert main(["models", "list", "--model-dir", str(model_dir)]) == 0
    text = capsys.readouterr().out
    assert "yolox-nano" in text and str(model_dir / "yolox_nano.onnx") in text


def test_real_video_tracks(kitti_raw_dir, model_dir):
    """KITTI raw 0001 (parked cars along a residential street), default detector, every
    3rd frame: every row is a vehicle, and the cars passed are followed for many frames."""
    det = load_detector("yolox-nano", model_dir, score_threshold=0.1)
    rows = run_detect(kitti_raw_dir / "video.mp4", detector=det, detect_every=3,
                      progress=False)
    assert rows and {r.category for r in rows} <= set(VEHICLE_CATEGORIES)
    lengths = {}
    for r in rows:
        lengths[r.track_id] = lengths.get(r.track_id, 0) + 1
    assert max(lengths.values()) >= 30  # one car followed for >= 3 s
    assert all(r.x2 > r.x1 and r.y2 > r.y1 for r in rows)
    assert max(r.frame for r in rows) <= 107


def test_imported_boxes_all_beyond_the_video_are_an_input_error(clip, tmp_path, capsys):
    # A detections file made for another, longer video: one error line and exit 2, not an
    # empty detections.csv that reads as "no vehicles".
    path = tmp_path / "other_video.txt"
    path.write_text("".join(f"{f},-1,20,40,40,30,0.9,car\n" for f in (500, 501, 502)))
    out = tmp_path / "detections.csv"
    assert main(["-q", "detect", str(clip), "--detections", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {clip}: none of the imported boxes")
    assert "499..501" in err[0]
    assert not out.exists()
    # Boxes on some of the video's frames are used as before.
    rows = run_detect(clip, detector=None, detections={**imported(), 500: imported()[0]},
                      progress=False)
    assert [r.frame for r in rows] == list(range(N_FRAMES))


def test_cli_detect_refine_option(clip, tmp_path, capsys, model_dir):
    from vid2sim.detect.vehicles.detector import REFINE_MAX_BOXES

    assert main(["detect", "--help"]) == 0
    help_text = " ".join(capsys.readouterr().out.split())
    assert "--refine N" in help_text
    assert f"default {REFINE_MAX_BOXES} with tiles, 0 with --no-tiles" in help_text
    for args, label in ((["--refine", "1"], "with yolox-nano + tiles + 1 refined;"),
                        (["--no-tiles"], "with yolox-nano;")):
        out = tmp_path / f"det{len(args)}.csv"
        assert main(["detect", str(clip), "--model-dir", str(model_dir), *args,
                     "--out", str(out)]) == 0
        assert label in capsys.readouterr().out
        assert out.exists()
    assert main(["-q", "detect", str(clip), "--refine", "-1", "--out",
                 str(tmp_path / "x.csv")]) == 2
