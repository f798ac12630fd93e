"""Ranging REAL detector boxes against lidar truth (issue 13); skips without ../shared.

The project's YOLOX-nano (the detector code of ``vid2sim track``, score >= 0.3) runs on the
TRI DGP front-camera frames and the six KITTI tracking images; each image's vehicle boxes are
ranged on their own and matched to the annotated vehicles (IoU >= 0.5 with the annotation's 2D
box, for the association only). The truth is the annotated 3D box (lidar): the range of its
nearest end. Figures per range bin are printed (``pytest -s``) and kept in
``benchmarks/bench_ranging_real.py`` and the README; the asserts are regression floors a
little above what was measured (each says what), not accuracy targets.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tests.conftest import DATA
from vid2sim.base.errors import InputError
from vid2sim.core.camera import Camera, load_camera
from vid2sim.core.records import TrackedBox
from vid2sim.detect.ranging import RangingConfig, cuboid_config, range_tracks
from vid2sim.detect.vehicles.detector import load_detector
from vid2sim.detect.vehicles.external import read_kitti_tracking_labels
from vid2sim.evaluate.ranging.dgp import calibration_camera, ground_camera, read_dgp_scene
from vid2sim.evaluate.ranging.realboxes import dgp_rows, kitti_rows, read_rotation_y
from vid2sim.evaluate.ranging.table import bin_figures, format_bin_table

SCORE = 0.3
KITTI_SIX = {"0001": (10, 15, 20), "0016": (2, 7, 12)}


def _range(dets, camera: Camera, config: RangingConfig):
    boxes = [TrackedBox(0, 0.0, i, d.category, d.score, *d.box_px)
             for i, d in enumerate(d for d in dets if d.score >= SCORE
                                   and d.category in ("car", "truck", "bus"))]
    return range_tracks(boxes, camera, config=config).boxes


@pytest.fixture(scope="module")
def detections(model_dir, kitti_tracking_dir):
    """YOLOX-nano boxes of every image used here, by image path (detector run once)."""
    tri = DATA / "tri_dgp_front"
    if not tri.exists():
        pytest.skip(f"TRI DGP scenes not found at {tri}")
    det = load_detector("yolox-nano", model_dir, score_threshold=SCORE)
    frames = [f for scene in ("scene_01", "scene_02") for f in read_dgp_scene(tri / scene)]
    images = [f.image for f in frames] + [
        kitti_tracking_dir / "image_02" / seq / f"{f:06d}.png"
        for seq, fs in KITTI_SIX.items() for f in fs]
    return frames, {p: det.detect(cv2.imread(str(p), cv2.IMREAD_COLOR)) for p in images}


def _tri_figures(detections, config):
    frames, dets = detections
    rows = []
    for frame in frames:
        try:
            camera, _, _ = ground_camera(frame)
        except InputError:  # scene_02: no car within 50 m to fit the ground on
            camera = calibration_camera(frame)
        rows += dgp_rows(frame, camera, _range(dets[frame.image], camera, config))
    t, e = np.array([r.truth_m for r in rows]), np.array([r.range_m for r in rows])
    return {f.label: f for f in bin_figures(t, e)}


def _kitti_figures(detections, kitti_tracking_dir, config):
    _, dets = detections
    rows = []
    for seq, frames in KITTI_SIX.items():
        camera = load_camera(kitti_tracking_dir / "calib" / f"{seq}.txt")
        labels = read_kitti_tracking_labels(kitti_tracking_dir / "label_02" / f"{seq}.txt")
        yaws = read_rotation_y(kitti_tracking_dir / "label_02" / f"{seq}.txt")
        for f in frames:
            image = kitti_tracking_dir / "image_02" / seq / f"{f:06d}.png"
            rows += kitti_rows(f"{seq}/{f}", labels.get(f, []), yaws, camera,
                               _range(dets[image], camera, config))
    t, e = np.array([r.truth_m for r in rows]), np.array([r.range_m for r in rows])
    return {f.label: f for f in bin_figures(t, e)}


def test_tri_front_camera_against_lidar(detections):
    figs = _tri_figures(detections, RangingConfig())
    print("\n" + format_bin_table("TRI DGP, YOLOX-nano vs lidar", list(figs.values())))
    # The lead (a Lexus LS with a roof rack 6.3 m ahead, three frames): measured -6.8 %
    # (its box bottom is its cast shadow, 0.3 m behind the rear face, not its tyres 1.1 m
    # ahead of it); the cuboid model read +4.9 %. 10-40 m: a pickup at 17 m and a car at 35 m
    # (whose box takes in its shadow, 15 px below its tyres), measured -5.6 and -4.3 %.
    assert figs["< 10 m"].n == 3 and figs["< 10 m"].med_abs_rel < 0.09
    assert figs["10-20 m"].med_abs_rel < 0.08 and figs["20-40 m"].med_abs_rel < 0.06
    assert figs["all"].n >= 20


def test_kitti_six_images_against_label_3d_boxes(detections, kitti_tracking_dir):
    figs = _kitti_figures(detections, kitti_tracking_dir, RangingConfig())
    cub = _kitti_figures(detections, kitti_tracking_dir, cuboid_config())
    print("\n" + format_bin_table("KITTI six images, YOLOX-nano vs label 3D boxes",
                                  list(figs.values())))
    print(format_bin_table("... with the cuboid model", list(cub.values())))
    # 20-40 m (23 boxes, parked rows on both sides): measured bias -0.1 % (the cuboid model
    # +7.9 %), median |error| 14.1 % (9.5 %: the parked cars 13-19 m to the right of 0016 read
    # 20-46 % long with either model, the row on the left of 0001 now reads short). Below
    # 10 m: +10.6 % (cuboid +22.4 %).
    assert abs(figs["20-40 m"].bias_rel) < 0.04 < cub["20-40 m"].bias_rel
    assert figs["20-40 m"].med_abs_rel < 0.16
    assert figs["< 10 m"].bias_rel < cub["< 10 m"].bias_rel
