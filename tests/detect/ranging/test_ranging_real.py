"""Ranging against real labelled data (KITTI); skips when ../shared/data is absent.

Input are the LABELLED 2D boxes (so the figures isolate ranging from detection); the truth is
the labelled rear distance Z - l/2 of each vehicle with a box at least 25 px high. Each
labelled frame is ranged on its own (single-frame ranging, no temporal fusion). A KITTI label's
2D box is the projection of its 3D cuboid (94 % within 1.5 px), not what a detector sees, so
these boxes are ranged with the cuboid outline (:func:`cuboid_config`): the model of what these
boxes are. The outline model on real detector boxes is checked against lidar in
``tests/detect/test_ranging_real_boxes.py``.

Issue 5 asks for a median absolute relative error <= 8 % below 40 m. Measured (see the
printed lines, ``pytest -s``) it is reached on all of them: the six imaged frames, every 20th
frame of all 12 sequences, with and without temporal fusion. The asserts are regression
bounds a little above what the method achieves (measured at e83fd4b, noted by each), so a
change that makes ranging worse fails here.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vid2sim.core.camera import load_camera
from vid2sim.core.records import TrackedBox
from vid2sim.detect.pipeline import range_and_assign
from vid2sim.detect.ranging import RangingConfig, cuboid_config
from vid2sim.detect.vehicles.external import read_kitti_tracking_labels
from vid2sim.evaluate.ranging.kitti import (
    join_rows,
    kitti_label_boxes,
    kitti_rate_figures,
    kitti_rate_rows,
)

# What a detector would call each labelled class (COCO has no van: a van is a "car").
KITTI_TO_CATEGORY = {"Car": "car", "Van": "car", "Truck": "truck"}
SIX_FRAMES = {"0001": (10, 15, 20), "0016": (2, 7, 12)}
BINS_M = ((0.0, 20.0), (20.0, 40.0), (40.0, np.inf))
# The default config trusts a KITTI calibration's pitch to 0.25 deg (the body's pitch to the
# road is not calibrated); a rig whose pitch to the road is known better says so (0.05 deg);
# GUESSED treats the calibration like a dash-cam's guessed mounting (1 deg).
CALIBRATED = cuboid_config(RangingConfig(camera_pitch_std_deg=0.05))
GUESSED = cuboid_config(RangingConfig(camera_pitch_std_deg=1.0))
LABEL_BOXES = cuboid_config()


def _range_frames(data: Path, seq: str, frames, config: RangingConfig):
    """(truth rear range, estimate, truncated, occluded) per labelled vehicle >= 25 px."""
    camera = load_camera(data / "calib" / f"{seq}.txt")
    labels = read_kitti_tracking_labels(data / "label_02" / f"{seq}.txt")
    rows = []
    for frame in frames if frames is not None else sorted(labels)[::20]:
        objs = [lb for lb in labels.get(frame, []) if lb.type in KITTI_TO_CATEGORY]
        if not objs:
            continue
        boxes = [TrackedBox(frame, 0.0, lb.track_id, KITTI_TO_CATEGORY[lb.type], 1.0,
                            *lb.box_px) for lb in objs]
        result = range_and_assign(boxes, camera, config=config)
        for lb, rb in zip(objs, result.boxes, strict=True):
            if lb.box_px[3] - lb.box_px[1] < 25:
                continue
            truth = lb.location_m[2] - lb.size_hwl_m[2] / 2
            rows.append((truth, rb.range_m, lb.truncated, lb.occluded))
    return np.array(rows, dtype=float).reshape(-1, 4)


def _medians(rows: np.ndarray) -> dict[str, float]:
    truth, est = rows[:, 0], rows[:, 1]
    rel = np.abs(est - truth) / truth
    out = {}
    for lo, hi in BINS_M:
        m = (truth >= lo) & (truth < hi)
        out[f"{lo:g}-{hi:g} m"] = float(np.median(rel[m])) if m.any() else float("nan")
    out["below 40 m"] = float(np.median(rel[truth < 40]))
    out["n"] = len(rows)
    return out


def _line(name: str, med: dict[str, float]) -> str:
    parts = [f"{k} {v:.1%}" for k, v in med.items() if k != "n"]
    return f"{name} (n={med['n']}): " + ", ".join(parts)


def test_six_labelled_frames_single_frame(kitti_tracking_dir):
    res = {}
    for name, cfg in (("guessed pitch (1 deg)", GUESSED), ("default (0.25 deg)", LABEL_BOXES),
                      ("calibrated (0.05 deg)", CALIBRATED)):
        rows = np.vstack([_range_frames(kitti_tracking_dir, s, f, cfg)
                          for s, f in SIX_FRAMES.items()])
        assert np.isfinite(rows[:, 1]).all(), "every labelled vehicle must get a range"
        res[name] = _medians(rows)
        print(_line(f"KITTI six frames, {name}", res[name]))
    # 0001's frames hold a row of occluded cars parked 20-26 m to the left and 1.2-1.6 m
    # below the ego's road plane (a slope), 0016's cars 13-19 m to the right and partly
    # occluded. Measured 5.5 % (default), 5.5 % (0.05 deg), 7.3 % (1 deg); before the shared
    # row offset, learnt heights and the lateral road spread 10.6 / 12.6 / 14.1 %.
    assert res["default (0.25 deg)"]["below 40 m"] < 0.07
    assert res["calibrated (0.05 deg)"]["below 40 m"] < 0.07
    assert res["guessed pitch (1 deg)"]["below 40 m"] < 0.09


def test_all_labelled_frames_single_frame(kitti_tracking_dir):
    # Labels exist for every frame of 12 sequences; every 20th frame, ranged alone, gives
    # ~700 vehicles on many streets: a steadier figure than six frames.
    seqs = sorted(p.stem for p in (kitti_tracking_dir / "label_02").glob("*.txt"))
    default = np.vstack([_range_frames(kitti_tracking_dir, s, None, LABEL_BOXES)
                         for s in seqs])
    print(_line("KITTI all sequences, default (0.25 deg)", _medians(default)))
    rows = np.vstack([_range_frames(kitti_tracking_dir, s, None, CALIBRATED) for s in seqs])
    clean = rows[(rows[:, 2] == 0) & (rows[:, 3] <= 1)]
    med_all, med_clean = _medians(rows), _medians(clean)
    print(_line("KITTI all sequences, calibrated (0.05 deg)", med_all))
    print(_line("KITTI all sequences, calibrated, unoccluded/untruncated", med_clean))
    # Measured 5.5 % clean and 6.0 % all with the 0.05 deg calibration, 6.4 % with the
    # default 0.25 deg (6.6 % before the vehicle horizon left out parked cars; all boxes
    # include turned, occluded, truncated).
    assert med_clean["below 40 m"] < 0.065
    assert med_all["below 40 m"] < 0.07
    assert _medians(default)["below 40 m"] < 0.075
    # No systematic scale error: the signed median within a few percent.
    signed = (rows[:, 1] - rows[:, 0]) / rows[:, 0]
    assert abs(np.median(signed[rows[:, 0] < 40])) < 0.05


def test_all_labelled_sequences_as_tracks(kitti_tracking_dir):
    # The labelled boxes of every 2nd frame (5 Hz) as tracks, each sequence ranged like a
    # video: horizon from the vehicles, widths learnt per track, Kalman/RTS over time.
    rows = []
    for lab in sorted((kitti_tracking_dir / "label_02").glob("*.txt")):
        camera = load_camera(kitti_tracking_dir / "calib" / lab.name)
        labels = read_kitti_tracking_labels(lab)
        objs = [lb for frame in sorted(labels)[::2] for lb in labels[frame]
                if lb.type in KITTI_TO_CATEGORY]
        boxes = [TrackedBox(lb.frame, lb.frame / 10.0, lb.track_id, KITTI_TO_CATEGORY[lb.type],
                            1.0, *lb.box_px) for lb in objs]
        result = range_and_assign(boxes, camera, config=LABEL_BOXES)
        rows += [(lb.location_m[2] - lb.size_hwl_m[2] / 2, rb.range_m, lb.truncated,
                  lb.occluded) for lb, rb in zip(objs, result.boxes, strict=True)
                 if lb.frame % 20 == 0 and lb.box_px[3] - lb.box_px[1] >= 25]
    rows = np.array(rows, dtype=float)
    med = _medians(rows)
    print(_line("KITTI all sequences as tracks, default", med))
    # Measured 5.1 % (5.4 % before the vehicle horizon left out parked cars, 7.7 % before the
    # shared row offset and learnt heights).
    assert med["below 40 m"] < 0.065


def test_range_rate_and_lead_on_labelled_sequences(kitti_tracking_dir):
    # Range RATE on real data: the labelled boxes of every frame (10 Hz) of all sequences as
    # tracks, against the slope of the labelled rear distance (a quadratic over 1.1 s; the
    # labels' position noise gives it ~0.04 m/s, windows of 0.7-1.5 s agree to ~0.1 m/s).
    # Truth and figures from vid2sim.evaluate.ranging.kitti, shared with
    # `python benchmarks/bench_ranging.py --kitti-rate`, which prints them per sequence.
    labels = sorted((kitti_tracking_dir / "label_02").glob("*.txt"))
    per_seq = {}
    for lab in labels:
        objs, boxes = kitti_label_boxes(lab)
        res = range_and_assign(boxes, load_camera(kitti_tracking_dir / "calib" / lab.name),
                           config=LABEL_BOXES)
        per_seq[lab.stem] = kitti_rate_rows(objs, res.boxes)
    for name, rows in {**per_seq, "all": join_rows(per_seq)}.items():
        f = kitti_rate_figures(rows)
        print(f"KITTI {name} range rate [m/s]: lead (n={f['lead_n']}) RMSE {f['lead_rmse']:.2f}"
              f" median |e| {f['lead_med']:.2f}, lead range median |rel| "
              f"{f['lead_range_rel']:.1%}, labelled lead marked is_lead on "
              f"{f['lead_same']:.1%} of {f['lead_frames']} frames (some lead on "
              f"{f['lead_any']:.1%}); all below 40 m (n={f['all_n']}) RMSE {f['all_rmse']:.2f} "
              f"median |e| {f['all_med']:.2f} p90 {f['all_p90']:.2f}; RMSE 0-20 m "
              f"{f['bin_0-20_rmse']:.2f}, 20-40 m {f['bin_20-40_rmse']:.2f}, 40+ m "
              f"{f['bin_40-inf_rmse']:.2f}; truth fit residual {f['truth_resid_m']:.3f} m")
    assert f["truth_resid_m"] < 0.05  # the truth itself: 3.3 cm residual (labels' noise)
    # Issue 5 asks a lead range-rate RMSE <= 0.5 m/s: reached where one car is followed
    # (0005 0.23, 0010 0.26, 0003 0.49), not overall: the lead by label is often a parked or
    # turning car briefly straight ahead on a bend or a crest (0007 #59/#60, 0000, 0001).
    # Measured at e83fd4b: lead RMSE 0.64 m/s (0.92 at f5df590), median 0.19 m/s, range
    # 4.0 %, the labelled lead marked is_lead on 97.8 % of its frames (the misses: cars whose
    # labelled centre sits near the lane line, |X| ~ 1.7-1.9 m). Since the horizon from
    # vehicles leaves out the parked ones (their ground is lower), the lead range is 5.1 %
    # (these runs have no lane markings; the single-frame figures improved: 6.6 -> 6.4 %).
    assert f["lead_rmse"] < 0.75
    assert f["lead_med"] < 0.25
    assert f["lead_range_rel"] < 0.06
    assert f["lead_same"] > 0.96
    assert f["lead_any"] > 0.97  # measured 99.4 %
    # All vehicles below 40 m: median 0.55, p90 2.43, RMSE 1.63 m/s (11.8 at f5df590, when
    # three tracks parked 23 m to the right and cut by the image border diverged).
    assert f["all_med"] < 0.65
    assert f["all_p90"] < 2.9
    assert f["bin_0-20_rmse"] < 1.45  # measured 1.19
    assert f["bin_40-inf_rmse"] < 2.6  # measured 2.18
    assert f["all_rmse"] < 2.0


def test_lane_marking_horizon_on_kitti_raw(kitti_raw_dir):
    import cv2

    from vid2sim.detect.lanes.vanishing import HorizonEstimator

    camera = load_camera(kitti_raw_dir / "camera.yaml")
    est = HorizonEstimator(camera, every=5)
    cap = cv2.VideoCapture(str(kitti_raw_dir / "video.mp4"))
    try:
        while True:
            ok, image = cap.read()
            if not ok:
                break
            est.add_frame(image)
    finally:
        cap.release()
    row, votes = est.estimate()
    print(f"KITTI raw 0001 lane-marking horizon {row} px from {votes} frames; calibration "
          f"says {camera.horizon_y_px():.1f} px")
    assert votes >= 10
    # The rectified KITTI camera is level to within a few tenths of a degree (0.4 deg = 5 px).
    assert row == pytest.approx(camera.horizon_y_px(), abs=5.0)
