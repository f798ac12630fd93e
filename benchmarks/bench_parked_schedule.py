"""Parked cars of KITTI raw 0001 against OXTS, with the detector on every frame and with the
default keyframe schedule (issue 15: speed never bought with silent accuracy loss).

    python benchmarks/bench_parked_schedule.py [--shared ../shared]

The same evaluation as ``tests/detect/test_ranging_parked.py`` (range rate of the static
cars against the ego's OXTS speed and yaw rate, by estimated range, signed median), run
through ``detect_and_range`` once per setting: real truth nobody here produced, on a real
clip with the optical-flow carries between keyframes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from vid2sim.app.settings import Settings
from vid2sim.core.camera import fit_camera_to_frames, load_camera
from vid2sim.detect.pipeline import detect_and_range
from vid2sim.detect.vehicles.detector import load_detector
from vid2sim.detect.video import video_info
from vid2sim.evaluate.ranging.static import ego_motion, evaluate_parked

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=SHARED)
    args = parser.parse_args(argv)
    raw, models = args.shared / "data" / "kitti_raw_0001", args.shared / "models"
    if not raw.is_dir() or not models.is_dir():
        print(f"error: {raw if not raw.is_dir() else models}: not found "
              "(the real data and the detector weights are in ../shared beside the repository; give --shared DIR)", file=sys.stderr)
        return 2
    video = raw / "video.mp4"
    info = video_info(video)
    camera, _ = fit_camera_to_frames(load_camera(raw / "camera.yaml"), info.width, info.height)
    settings = Settings()
    detector = load_detector("yolox-nano", models,
                             score_threshold=settings.tracker_config().low_score)
    for name, schedule in (("detector on every frame", None),
                           (f"default keyframes ({settings.detector.keyframe_s:g} s)",
                            settings.detector.schedule())):
        result, cam, _ = detect_and_range(video, camera, detector=detector, progress=False,
                                          schedule=schedule)
        report = evaluate_parked(result, cam, ego_motion(raw)).report(
            f"KITTI raw 0001, {name}")
        print(report.split("  track")[0])
    return 0


if __name__ == "__main__":
    sys.exit(main())
