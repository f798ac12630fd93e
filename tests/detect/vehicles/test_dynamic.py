"""The dynamic-shape copy of the detector weights, batched windows, and the sparse-folder bar."""

from __future__ import annotations

import csv

import cv2
import numpy as np
import pytest

from vid2sim.cli import main
from vid2sim.core.records import Detection
from vid2sim.detect.vehicles._dynamic import dynamic_copy
from vid2sim.detect.vehicles.detector import YoloxDetector, load_detector
from vid2sim.detect.vehicles.external import (
    MatchCounts,
    read_kitti_tracking_labels,
    score_against_kitti,
)
from vid2sim.detect.video import iter_frames


def test_dynamic_copy_is_cached_keyed_and_leaves_the_weights_alone(model_dir, tmp_path):
    weights = model_dir / "yolox_nano.onnx"
    before = weights.stat().st_mtime_ns
    copy = dynamic_copy(weights, cache=tmp_path)
    assert copy is not None and copy.parent == tmp_path and copy.name.startswith("yolox_nano.")
    assert dynamic_copy(weights, cache=tmp_path) == copy  # reused, not converted again
    assert weights.stat().st_mtime_ns == before


def test_batched_windows_give_the_boxes_of_single_windows(kitti_raw_dir, model_dir):
    frame = next(iter_frames(kitti_raw_dir / "video.mp4")).image_bgr
    det = load_detector("yolox-nano", model_dir, small_object_mode=False)
    assert isinstance(det, YoloxDetector) and det.batch_windows and det.free_shape
    crops = [frame[:, :600], frame[:, 400:1000], frame[100:300, 200:500]]
    batched = det._windows(crops)
    for crop, (boxes, scores, ids) in zip(crops, batched, strict=True):
        single_boxes, single_scores, single_ids = det._window(crop)
        assert boxes == pytest.approx(single_boxes, abs=0.05)
        assert scores == pytest.approx(single_scores, abs=1e-4)
        assert (ids == single_ids).all()


def test_free_shape_keeps_the_letterbox_scale(model_dir):
    det = load_detector("yolox-nano", model_dir, small_object_mode=False)
    blob, (sx, sy) = det._prepare(np.zeros((374, 1242, 3), np.uint8))
    # 1242 x 374 at 416 / 1242: 416 x 125, rounded up to 128 plus a 32 px grey margin
    assert blob.shape == (3, 160, 416)
    assert sx == sy == pytest.approx(1242 / 416, rel=1e-3)
    assert blob[:, 150, 10] == pytest.approx([114, 114, 114])


def test_detect_on_a_folder_of_sparse_labelled_frames(kitti_tracking_dir, model_dir, tmp_path):
    """`vid2sim detect` on each labelled KITTI folder (three frames 0.5 s apart, named by
    frame number), default settings: recall and precision >= 0.85 for cars and vans."""
    total = MatchCounts(0, 0, 0, 0)
    for seq in ("0001", "0016"):
        folder = kitti_tracking_dir / "image_02" / seq
        out = tmp_path / f"{seq}.csv"
        assert main(["-q", "detect", str(folder), "--model-dir", str(model_dir),
                     "--out", str(out)]) == 0
        labels = read_kitti_tracking_labels(kitti_tracking_dir / "label_02" / f"{seq}.txt")
        with open(out, newline="") as fh:
            rows = list(csv.DictReader(fh))
        for i, png in enumerate(sorted(folder.glob("*.png"))):
            assert cv2.imread(str(png)) is not None
            found = [Detection(tuple(float(r[k]) for k in ("x1", "y1", "x2", "y2")),
                               float(r["score"]), r["category"])
                     for r in rows if int(r["frame"]) == i]
            total = total + score_against_kitti(found, labels.get(int(png.stem), []))
    assert total.n_targets == 25
    assert total.recall >= 0.85, total
    assert total.precision >= 0.85, total
