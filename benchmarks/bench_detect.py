"""Benchmark of the detection stage on the shared KITTI data (not a test: prints figures).

1. Accuracy on ../shared/data/kitti_tracking (6 labelled frames): recall of cars/vans with
   truncation < 0.5, occlusion <= 1, height >= 25 px at IoU >= 0.5, and precision (see
   vid2sim.detect.vehicles.external.score_against_kitti for what counts as a false detection),
   per model, with and without the small-car tiles; also recall of the small targets alone.
2. Speed on ../shared/data/kitti_raw_0001/video.mp4 (108 frames): frames per second of
   decode + detect + track (run_detect), per model and tiling mode.
3. With --tracking: tracker identities on the synthetic forward drive of
   tests/detect/test_tracker.py (camera at 10 m/s past parked cars, known ids) at 2, 5 and
   10 frames/s over several seeds: id switches, cars never reported, tracks mixing cars,
   and tracker time per detected frame.

Usage: python benchmarks/bench_detect.py [--shared ../shared] [--no-speed] [--threads 2]
       python benchmarks/bench_detect.py --tracking --no-accuracy --no-speed
Figures depend on the machine and its load; say so when quoting them.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2

from vid2sim.detect.pipeline import run_detect
from vid2sim.detect.vehicles.detector import load_detector
from vid2sim.detect.vehicles.external import (
    MatchCounts,
    is_kitti_target,
    read_kitti_tracking_labels,
    score_against_kitti,
)
from vid2sim.detect.video import video_info

MODELS = ("yolox-nano", "picodet-s")
SMALL_PX = 40.0  # "small" targets for the tiling comparison: box height 25-40 px


def kitti_frames(tracking_dir: Path):
    """(image path, labels of that frame) for every labelled image at hand."""
    for seq_dir in sorted((tracking_dir / "image_02").iterdir()):
        labels = read_kitti_tracking_labels(tracking_dir / "label_02" / f"{seq_dir.name}.txt")
        for png in sorted(seq_dir.glob("*.png")):
            yield png, labels.get(int(png.stem), [])


def accuracy(tracking_dir: Path, model_dir: Path, score: float, threads: int) -> None:
    print(f"accuracy on {tracking_dir} (score >= {score}, IoU >= 0.5)")
    print(f"{'model':12s} {'tiles':5s} {'recall':>7s} {'prec':>6s} {'found/targets':>14s} "
          f"{'false/dets':>10s} {'small recall':>13s}")
    frames = list(kitti_frames(tracking_dir))
    for name in MODELS:
        for tiles in (False, True):
            det = load_detector(name, model_dir, score_threshold=score,
                                small_object_mode=tiles, threads=threads)
            total = MatchCounts(0, 0, 0, 0)
            small = MatchCounts(0, 0, 0, 0)
            for png, labels in frames:
                dets = det.detect(cv2.imread(str(png)))
                total = total + score_against_kitti(dets, labels)
                small_labels = [lab for lab in labels if not is_kitti_target(lab)
                                or lab.box_px[3] - lab.box_px[1] < SMALL_PX]
                s = score_against_kitti(dets, small_labels)
                small = small + MatchCounts(s.n_targets, s.n_found, 0, 0)
            print(f"{name:12s} {tiles!s:5s} {total.recall:7.3f} {total.precision:6.3f} "
                  f"{total.n_found:6d}/{total.n_targets:<7d} {total.n_false:4d}/{total.n_detections:<5d} "
                  f"{small.recall:6.3f} ({small.n_found}/{small.n_targets})")


def speed(video: Path, model_dir: Path, threads: int, every: int, models: tuple[str, ...]
          ) -> None:
    print(f"speed on {video}: decode + detect + track (run_detect), detect every {every}")
    for name in models:
        for tiles in (False, True):
            det = load_detector(name, model_dir, score_threshold=0.1, small_object_mode=tiles,
                                threads=threads)
            start = time.perf_counter()
            boxes = run_detect(video, detector=det, detect_every=every, progress=False)
            elapsed = time.perf_counter() - start
            n = video_info(video).n_frames
            print(f"{name:12s} tiles={tiles!s:5s} {n / elapsed:6.1f} frames/s "
                  f"({elapsed:.1f} s, {len({b.track_id for b in boxes})} tracks)")


def tracking(seeds: int) -> None:
    """Identity figures of the tracker on the synthetic forward drive (see module doc)."""
    import importlib.util

    from vid2sim.detect.tracking.tracker import Tracker

    path = Path(__file__).resolve().parents[1] / "tests" / "detect" / "test_tracker.py"
    spec = importlib.util.spec_from_file_location("synthetic_drive", path)
    drive = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(drive)
    print("\ntracker on the synthetic forward drive (4 s, 12-13 cars)")
    for fps in (2.0, 5.0, 10.0):
        switches = missing = merged = n_frames = 0
        elapsed = 0.0
        for seed in range(seeds):
            frames, truth = drive.forward_drive(fps, seed=seed)
            start = time.perf_counter()
            s, m, g, _ = drive.id_metrics(frames, truth, fps, Tracker(
                image_size_px=(drive.IMAGE_W, drive.IMAGE_H)))
            elapsed += time.perf_counter() - start
            switches, missing, merged = switches + s, missing + len(m), merged + len(g)
            n_frames += len(frames)
        print(f"  {fps:4.0f} frames/s, {seeds} seeds: id switches {switches}, cars never "
              f"reported {missing}, tracks mixing cars {merged}; "
              f"{1e3 * elapsed / n_frames:.1f} ms per frame")


def main() -> None:
    here = Path(__file__).resolve().parents[1]
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=here.parent / "shared")
    parser.add_argument("--score", type=float, default=0.3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--every", type=int, default=1)
    parser.add_argument("--no-speed", action="store_true")
    parser.add_argument("--no-accuracy", action="store_true")
    parser.add_argument("--models", nargs="+", default=list(MODELS))
    parser.add_argument("--tracking", action="store_true")
    parser.add_argument("--seeds", type=int, default=10)
    args = parser.parse_args()
    model_dir = args.shared / "models"
    if not args.no_accuracy:
        accuracy(args.shared / "data" / "kitti_tracking", model_dir, args.score, args.threads)
    if not args.no_speed:
        speed(args.shared / "data" / "kitti_raw_0001" / "video.mp4", model_dir, args.threads,
              args.every, tuple(args.models))
    if args.tracking:
        tracking(args.seeds)


if __name__ == "__main__":
    main()
