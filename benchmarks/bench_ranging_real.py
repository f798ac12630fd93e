"""Monocular ranging on REAL detector boxes against lidar truth, by range bin (issue 13).

    python benchmarks/bench_ranging_real.py [--cache DIR] [--shared DIR] [--skip-build]
                                            [--cuboid]

The project's own YOLOX-nano (``../shared/models``, the detector code of ``vid2sim track``:
tiles and the centre window on, score >= 0.3) runs on real images; each image's vehicle boxes
are ranged on their own (one frame, no temporal fusion) and matched one-to-one to the
annotated vehicles (IoU >= 0.5 with the annotation's 2D box, used for the association only).
The truth is the annotated 3D box: the range of its nearest end (the rear face of a car
driving ahead) in the camera's vehicle frame. Per range bin (< 10, 10-20, 20-40, > 40 m):
count, signed median error (bias), median and 90th percentile of |error|.

(a) ``tri_dgp_front``: TRI's front camera, cuboids annotated on lidar. The camera of each
    frame is the one on the ground plane through the cars' cuboid bottoms within 50 m
    (scene_01: 1.40 m high, 0.71 deg down; 0.14 m RMS); scene_02 has no car within 50 m and
    takes the calibration's extrinsics (which agree with the cuboids' ground to 4 cm and
    0.07 deg on scene_01).
(b) The six KITTI tracking images (``kitti_tracking/image_02``): truth from the labels' 3D
    boxes (lidar), never their 2D boxes (projected cuboids).
(c) ``vid2sim build`` on KITTI raw 0001 (video, OXTS, camera): the cars parked 5-11 m to the
    left and within 45 m must replay standing still (scenario.json actor speeds); the median
    speed, the bias (median velocity along the ego's heading) and the speed per actor, as
    built and without the assembly's static hold (what the ranging alone gives).

``--cuboid`` also ranges (a) and (b) with the cuboid outline (the model before issue 13).
Detections are cached per image in ``--cache`` (default /tmp/vid2sim-realboxes):
delete it after changing the detector.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from vid2sim.app.build import build
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.base.errors import InputError
from vid2sim.core import scenario as scenario_io
from vid2sim.core.camera import Camera, load_camera
from vid2sim.core.records import Detection, TrackedBox
from vid2sim.detect.ranging import RangingConfig, cuboid_config, range_tracks
from vid2sim.detect.vehicles.detector import load_detector
from vid2sim.detect.vehicles.external import read_kitti_tracking_labels
from vid2sim.evaluate.ranging.dgp import calibration_camera, ground_camera, read_dgp_scene
from vid2sim.evaluate.ranging.realboxes import (
    RealBoxRow,
    dgp_rows,
    kitti_rows,
    read_rotation_y,
)
from vid2sim.evaluate.ranging.static import replayed_static_speeds
from vid2sim.evaluate.ranging.table import bin_figures, format_bin_table
from vid2sim.export.assemble import AssembleConfig

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
SCORE = 0.3  # the detector's own default threshold (MODELS.md: "score threshold about 0.3")
VEHICLES = ("car", "truck", "bus")
KITTI_SIX = {"0001": (10, 15, 20), "0016": (2, 7, 12)}


def detect_cached(image: Path, detector, cache: Path) -> list[Detection]:
    """The detector's boxes on one image, cached as JSON under ``cache``."""
    key = cache / (image.parent.parent.name + "_" + image.parent.name + "_" + image.stem + ".json")
    if key.is_file():
        return [Detection(tuple(d[0]), d[1], d[2]) for d in json.loads(key.read_text())]
    dets = detector().detect(cv2.imread(str(image), cv2.IMREAD_COLOR))
    key.parent.mkdir(parents=True, exist_ok=True)
    key.write_text(json.dumps([[list(d.box_px), d.score, d.category] for d in dets]))
    return dets


def range_image(dets: list[Detection], camera: Camera, config: RangingConfig):
    """Range one image's vehicle detections, each its own one-frame track."""
    boxes = [TrackedBox(0, 0.0, i, d.category, d.score, *d.box_px)
             for i, d in enumerate(d for d in dets if d.score >= SCORE
                                   and d.category in VEHICLES)]
    return range_tracks(boxes, camera, config=config).boxes


def tri_rows(data: Path, detector, cache: Path, config: RangingConfig) -> list[RealBoxRow]:
    rows: list[RealBoxRow] = []
    for scene in sorted(p for p in (data / "tri_dgp_front").iterdir() if p.is_dir()):
        for frame in read_dgp_scene(scene):
            try:
                camera, _, _ = ground_camera(frame)
            except InputError:
                camera = calibration_camera(frame)
            ranged = range_image(detect_cached(frame.image, detector, cache), camera, config)
            rows += dgp_rows(frame, camera, ranged)
    return rows


def kitti_six_rows(data: Path, detector, cache: Path, config: RangingConfig
                   ) -> list[RealBoxRow]:
    rows: list[RealBoxRow] = []
    root = data / "kitti_tracking"
    for seq, frames in KITTI_SIX.items():
        camera = load_camera(root / "calib" / f"{seq}.txt")
        labels = read_kitti_tracking_labels(root / "label_02" / f"{seq}.txt")
        yaws = read_rotation_y(root / "label_02" / f"{seq}.txt")
        for f in frames:
            image = root / "image_02" / seq / f"{f:06d}.png"
            ranged = range_image(detect_cached(image, detector, cache), camera, config)
            rows += kitti_rows(f"{seq}/{f:06d}", labels.get(f, []), yaws, camera, ranged)
    return rows


def print_rows(title: str, rows: list[RealBoxRow]) -> None:
    truth = np.array([r.truth_m for r in rows])
    est = np.array([r.range_m for r in rows])
    print(format_bin_table(title, bin_figures(truth, est)))
    print()


def parked_build(data: Path, models: Path) -> None:
    raw = data / "kitti_raw_0001"
    for label, assemble in (("as built", AssembleConfig()),
                            ("without the static hold (the ranging alone)",
                             AssembleConfig(static_speed_fraction=0.0))):
        settings = Settings(detector=DetectorSettings(model_dir=models), allow_download=False,
                            progress=False, assemble=assemble)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            result = build(Inputs(video=raw / "video.mp4", gps=raw, camera=raw / "camera.yaml"),
                           Path(tmp) / "build", settings)
            scen = scenario_io.load(result.files["scenario"])
        rs = replayed_static_speeds(scen)
        print(f"(c) KITTI raw 0001 vid2sim build, {label} ({time.perf_counter() - t0:.0f} s): "
              f"parked cars 5-11 m left within 45 m: {len(rs.per_actor)} actors, "
              f"{rs.speed_mps.size} samples; median speed {rs.median_speed_mps:.2f} m/s (bar "
              f"0.5), bias (median velocity along the ego) {rs.bias_mps:+.2f} m/s, 90th "
              f"percentile speed {np.percentile(rs.speed_mps, 90):.2f} m/s")
        for aid, (n, med, bias) in sorted(rs.per_actor.items()):
            print(f"    actor {aid:>6s}: {n:3d} samples, median speed {med:5.2f} m/s, along the "
                  f"ego {bias:+5.2f} m/s")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=SHARED)
    parser.add_argument("--cache", type=Path, default=Path("/tmp/vid2sim-realboxes"))
    parser.add_argument("--skip-build", action="store_true", help="leave out (c)")
    parser.add_argument("--cuboid", action="store_true",
                        help="also range (a) and (b) with the cuboid outline (the model before "
                        "issue 13), for comparison")
    args = parser.parse_args(argv)
    data, models = args.shared / "data", args.shared / "models"
    for p in (data / "tri_dgp_front", data / "kitti_tracking", models):
        if not p.exists():
            print(f"missing {p}", file=sys.stderr)
            return 2
    loaded = []

    def detector():
        if not loaded:
            loaded.append(load_detector("yolox-nano", models, score_threshold=SCORE))
        return loaded[0]

    configs = {"default": RangingConfig()}
    if args.cuboid:
        configs["cuboid"] = cuboid_config()
    for name, cfg in configs.items():
        print_rows(f"(a) TRI DGP front camera, YOLOX-nano boxes vs lidar cuboids ({name} "
                   "ranging, single frames)", tri_rows(data, detector, args.cache, cfg))
        print_rows(f"(b) KITTI tracking six images, YOLOX-nano boxes vs the labels' 3D boxes "
                   f"({name} ranging, single frames)",
                   kitti_six_rows(data, detector, args.cache, cfg))
    if not args.skip_build:
        parked_build(data, models)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
