"""Ranging on real footage against KITTI's lidar tracklets, in every range bin.

    python benchmarks/bench_tracklets.py [--shared DIR] [--tracks tracks.csv] [--out DIR]
                                         [--crop-bottom ROWS] [--no-gps] [--video-clock]
                                         [--keyframe-rate HZ]

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
alone, as ``vid2sim track`` does). ``--video-clock`` gives the build the OXTS fixes as a
GPS CSV on the video's clock (fix k at frame k's video time: KITTI records one OXTS sample
per camera frame): ``video.mp4`` plays at a nominal 10 fps while the camera captured at
9.69 Hz (``image_00_timestamps.txt``), so on the OXTS's own clock the ego is 3.2 % of the
elapsed time late against the frames. ``--keyframe-rate HZ`` also builds with the tracklets
as keyframes at that rate and prints the keyframe F1 and mean IoU.
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


def video_clock_gps(raw: Path, folder: Path, fps: float) -> Path:
    """The OXTS fixes as a GPS CSV, fix k at frame k's video time k / fps."""
    rows = ["t,lat,lon,alt"]
    for k, f in enumerate(sorted((raw / "oxts" / "data").glob("*.txt"))):
        lat, lon, alt = f.read_text().split()[:3]
        rows.append(f"{k / fps:.4f},{lat},{lon},{alt}")
    out = folder / "oxts_video_clock.csv"
    out.write_text("\n".join(rows) + "\n")
    return out


def drive_truth(raw: Path, video: Path):
    """The tracklet truth of KITTI raw 0001 in ``video``'s frames."""
    info = video_info(video)
    xml = raw / "tracklet_labels.xml"
    return tracklet_truth(read_tracklets(xml), calibration_beside(xml), (info.width, info.height),
                          camera_height_m=1.65, fps=info.fps, motion=ego_motion(raw),
                          n_frames=info.n_frames)


def build_tracks(models: Path, out: Path, video: Path, camera: Path, gps: Path | None,
                 keyframes: Path | None = None, keyframe_rate_hz: float | None = None) -> Path:
    """``vid2sim build`` of the drive into ``out``; its tracks.csv."""
    settings = Settings(detector=DetectorSettings(model_dir=models), allow_download=False,
                        progress=False)
    t0 = time.perf_counter()
    result = build(Inputs(video=video, gps=gps, camera=camera, keyframes=keyframes,
                          keyframe_rate_hz=keyframe_rate_hz), out, settings)
    print(f"build: {time.perf_counter() - t0:.1f} s wall", file=sys.stderr)
    if result.metrics:
        m = result.metrics
        print(f"keyframes {m['keyframes']} at {keyframe_rate_hz:g} Hz ({m['projection']}): TP "
              f"{m['tp']} FP {m['fp']} FN {m['fn']}, precision {m['precision']:.3f}, recall "
              f"{m['recall']:.3f}, F1 {m['f1']:.3f}, mean IoU {m['mean_iou']:.3f}\n")
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
    parser.add_argument("--video-clock", action="store_true",
                        help="the OXTS fixes on the video's clock (one per frame)")
    parser.add_argument("--keyframe-rate", type=float, default=None, metavar="HZ",
                        help="also score the tracklets as keyframes at this rate")
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
        gps = None if args.no_gps else (
            video_clock_gps(raw, Path(tmp), video_info(video).fps) if args.video_clock
            else raw / "oxts")
        keyframes = raw / "tracklet_labels.xml" if args.keyframe_rate else None
        tracks = args.tracks or build_tracks(models, args.out or Path(tmp) / "build", video,
                                             camera, gps, keyframes, args.keyframe_rate)
        rows = match_tracklets(read_tracks_csv(tracks), truth)
    what = (f"KITTI raw 0001 cropped to its top {args.crop_bottom} rows"
            if args.crop_bottom else "KITTI raw 0001")
    what += " without GPS" if args.no_gps else " with the OXTS on the video's clock" if (
        args.video_clock) else ""
    print(format_tracklet_report(rows, f"{what} vs its tracklets"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
