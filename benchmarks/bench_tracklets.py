"""Ranging on real footage against KITTI's lidar tracklets, in every range bin.

    python benchmarks/bench_tracklets.py [--shared DIR] [--tracks tracks.csv] [--out DIR]
                                         [--crop-bottom ROWS] [--no-gps]

Runs ``vid2sim build video.mp4 --gps oxts --camera camera.yaml`` on KITTI raw 0001 in-process,
as a user would (the default settings, the project's YOLOX-nano from ``../shared/models``),
matches every ``tracks.csv`` row to the projected tracklet of its frame (IoU >= 0.5, one to
one) and prints: range by TRUE range bin (< 10, 10-20, 20-40, > 40 m) with n, signed median
and median |error|; range rate (truth: central difference of the tracklet's nearest-corner
depth over +-2 frames, per video second) RMSE and median bias; lateral offset; each split
parked/moving (the tracklet's world speed with the OXTS ego motion) and bottom cut by the
image border or not. ``--tracks`` scores an existing ``tracks.csv`` instead of building.

``--crop-bottom ROWS`` keeps only the top ROWS rows of every frame (a real clip in which the
near cars' box bottoms sit on the image border; cropping keeps fx, fy, cx, cy) and its own
camera file, with the same tracklet truth clipped to the crop: the border-cut regime on real
pixels. ``--no-gps`` builds without the OXTS trajectory (every vehicle ranged from its boxes
alone, as ``vid2sim track`` does).
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from vid2sim.app.build import build
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.core.tables import read_tracks_csv
from vid2sim.detect.video import video_info
from vid2sim.evaluate.ranging.static import ego_motion
from vid2sim.evaluate.ranging.tracklets import calibration_beside, read_tracklets, tracklet_truth
from vid2sim.evaluate.ranging.trackletscore import format_tracklet_report, match_tracklets

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


def crop_clip(raw: Path, rows: int, folder: Path) -> tuple[Path, Path]:
    """KITTI raw 0001 with only the top ``rows`` rows of every frame, and its camera file."""
    reader = cv2.VideoCapture(str(raw / "video.mp4"))
    fps = reader.get(cv2.CAP_PROP_FPS)
    video = folder / f"crop{rows}.mp4"
    writer = None
    while True:
        ok, frame = reader.read()
        if not ok:
            break
        if writer is None:
            writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), fps,
                                     (frame.shape[1], rows))
        writer.write(np.ascontiguousarray(frame[:rows]))
    reader.release()
    if writer is None:
        raise SystemExit(f"error: {raw / 'video.mp4'}: no frames")
    writer.release()
    camera = folder / f"camera_crop{rows}.yaml"
    camera.write_text(re.sub(r"image_height: *\d+", f"image_height: {rows}",
                             (raw / "camera.yaml").read_text()))
    return video, camera


def drive_truth(raw: Path, video: Path):
    """The tracklet truth of KITTI raw 0001 in ``video``'s frames."""
    info = video_info(video)
    xml = raw / "tracklet_labels.xml"
    return tracklet_truth(read_tracklets(xml), calibration_beside(xml), (info.width, info.height),
                          camera_height_m=1.65, fps=info.fps, motion=ego_motion(raw),
                          n_frames=info.n_frames)


def build_tracks(raw: Path, models: Path, out: Path, video: Path, camera: Path,
                 gps: bool = True) -> Path:
    """``vid2sim build`` of the drive into ``out``; its tracks.csv."""
    settings = Settings(detector=DetectorSettings(model_dir=models), allow_download=False,
                        progress=False)
    t0 = time.perf_counter()
    result = build(Inputs(video=video, gps=raw / "oxts" if gps else None, camera=camera),
                   out, settings)
    print(f"build: {time.perf_counter() - t0:.1f} s wall", file=sys.stderr)
    return result.files["tracks"]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=SHARED)
    parser.add_argument("--tracks", type=Path, default=None,
                        help="score this tracks.csv instead of building")
    parser.add_argument("--out", type=Path, default=None,
                        help="keep the build's outputs here (default: a temporary folder)")
    parser.add_argument("--crop-bottom", type=int, default=None, metavar="ROWS",
                        help="keep the top ROWS rows of every frame (the border-cut regime)")
    parser.add_argument("--no-gps", action="store_true",
                        help="build without the OXTS trajectory (boxes alone, as track)")
    args = parser.parse_args(argv)
    raw, models = args.shared / "data" / "kitti_raw_0001", args.shared / "models"
    need = [raw / "tracklet_labels.xml"] + ([models] if args.tracks is None else [])
    for p in need:
        if not p.exists():
            print(f"error: {p}: not found (the real data and the detector weights are in "
                  "../shared beside the repository; give --shared DIR)", file=sys.stderr)
            return 2
    with tempfile.TemporaryDirectory() as tmp:
        video, camera = raw / "video.mp4", raw / "camera.yaml"
        if args.crop_bottom:
            video, camera = crop_clip(raw, args.crop_bottom, Path(tmp))
        truth = drive_truth(raw, video)
        tracks = args.tracks or build_tracks(raw, models, args.out or Path(tmp) / "build",
                                             video, camera, gps=not args.no_gps)
        rows = match_tracklets(read_tracks_csv(tracks), truth)
    what = (f"KITTI raw 0001 cropped to its top {args.crop_bottom} rows"
            if args.crop_bottom else "KITTI raw 0001")
    print(format_tracklet_report(rows, f"{what}{' without GPS' if args.no_gps else ''} vs "
                                 "its tracklets"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
