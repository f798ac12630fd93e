"""Ranging truth from KITTI tracking labels (lidar-annotated 3D boxes) and its figures.

The truth of a labelled vehicle is its rear distance, Z - l/2 (Z the labelled box centre's
depth in the rectified camera, l its length); the truth range RATE is the slope of a quadratic
fitted over 1.1 s of it (:func:`kitti_rate_truth`). :func:`kitti_label_boxes` turns a
sequence's labels into tracked boxes for the ranging, :func:`kitti_rate_rows` joins the ranging
result with the truth, :func:`kitti_rate_figures` scores it. Used by
``tests/detect/test_ranging_real.py`` and ``benchmarks/bench_ranging.py --kitti-rate``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.signal import savgol_filter

from vid2sim.core.records import RangedBox, TrackedBox, VehicleCategory
from vid2sim.detect.vehicles.external import KittiLabel, read_kitti_tracking_labels

# What a detector would call each labelled class (COCO has no van: a van is a "car").
KITTI_CATEGORY = {"Car": VehicleCategory.CAR, "Van": VehicleCategory.CAR,
                  "Truck": VehicleCategory.TRUCK}
KITTI_DT_S = 0.1  # the tracking benchmark's frame interval (10 Hz)
# Truth rate: a quadratic fitted over 11 frames (1.1 s) of the labelled rear distance. Raw
# frame differences of the lidar labels carry ~0.45 m/s of noise; the fit's derivative has
# ~1 x the labels' own position noise per m/s (sqrt(1/110) / 0.1 s), a few cm/s.
RATE_TRUTH_WINDOW = 11
MIN_BOX_PX = 25.0  # boxes lower than this are not scored (as in tests/detect/test_ranging_real)
LEAD_HALF_LANE_M = 1.8  # labelled ego-lane lead: |X| below this ...
LEAD_MAX_RANGE_M = 60.0  # ... nearer than this, box >= MIN_BOX_PX high
RATE_BINS_M = ((0.0, 20.0), (20.0, 40.0), (40.0, math.inf))


def rear_distance_m(label: KittiLabel) -> float:
    """Distance of a labelled vehicle's rear face [m]: the box centre's depth minus half its
    length (a vehicle seen from behind; for one seen from the side it is its near end)."""
    return label.location_m[2] - label.size_hwl_m[2] / 2


def kitti_rate_truth(frames: np.ndarray, rear_m: np.ndarray, window: int = RATE_TRUTH_WINDOW,
                     dt_s: float = KITTI_DT_S) -> tuple[np.ndarray, np.ndarray]:
    """Truth range rate [m/s] of one track and the fit's residual [m], NaN where unknown.

    ``frames`` and ``rear_m`` are the track's labelled frames and rear distances (any order).
    On each run of consecutive frames at least ``window`` long, a quadratic is fitted over a
    sliding window (Savitzky-Golay); its slope at the centre is the truth. The first and last
    ``window // 2`` frames of a run (where the window would be one-sided) get NaN, as do runs
    too short: a gap in the labels is no evidence of how the vehicle moved.
    """
    frames = np.asarray(frames)
    rear_m = np.asarray(rear_m, dtype=float)
    rate = np.full(len(frames), np.nan)
    resid = np.full(len(frames), np.nan)
    order = np.argsort(frames, kind="stable")
    half = window // 2
    for run in np.split(order, np.flatnonzero(np.diff(frames[order]) != 1) + 1):
        if run.size < window:
            continue
        r = rear_m[run]
        inner = run[half:run.size - half]
        rate[inner] = savgol_filter(r, window, 2, deriv=1, delta=dt_s)[half:run.size - half]
        resid[inner] = (r - savgol_filter(r, window, 2))[half:run.size - half]
    return rate, resid


def kitti_label_boxes(label_path: Path) -> tuple[list[KittiLabel], list[TrackedBox]]:
    """The labelled vehicles (Car, Van, Truck) of one KITTI tracking sequence, in frame
    order, and the same as tracked boxes at 10 Hz (the label's 2D box, its track id)."""
    labels = read_kitti_tracking_labels(label_path)
    objs = [o for f in sorted(labels) for o in labels[f] if o.type in KITTI_CATEGORY]
    boxes = [TrackedBox(o.frame, o.frame * KITTI_DT_S, o.track_id, KITTI_CATEGORY[o.type], 1.0,
                        *o.box_px) for o in objs]
    return objs, boxes


def kitti_rate_rows(objs: list[KittiLabel], ranged: list[RangedBox]) -> dict[str, np.ndarray]:
    """Join the ranging of :func:`kitti_label_boxes`' boxes with the labels' truth.

    Returns per labelled box arrays: ``frame``, ``track``, ``rear_m`` (truth Z - l/2), ``x_m``
    (labelled lateral centre, right positive), ``box_h_px``, ``rate_true`` and ``resid_m``
    (:func:`kitti_rate_truth`), the estimates ``range_m``, ``rate_m_s`` and ``is_lead``, and
    ``true_lead`` (the labelled lead of its frame: the nearest vehicle with |X| < 1.8 m and a
    rear nearer than 60 m, if its box is at least 25 px high).
    """
    if len(objs) != len(ranged):
        raise ValueError(f"{len(objs)} labels but {len(ranged)} ranged boxes")
    rows = {
        "frame": np.array([o.frame for o in objs], dtype=int),
        "track": np.array([o.track_id for o in objs], dtype=int),
        "rear_m": np.array([rear_distance_m(o) for o in objs]),
        "x_m": np.array([o.location_m[0] for o in objs]),
        "box_h_px": np.array([o.box_px[3] - o.box_px[1] for o in objs]),
        "range_m": np.array([b.range_m for b in ranged]),
        "rate_m_s": np.array([b.range_rate_mps for b in ranged]),
        "is_lead": np.array([b.is_lead for b in ranged], dtype=bool),
    }
    n = len(objs)
    rows["rate_true"], rows["resid_m"] = np.full(n, np.nan), np.full(n, np.nan)
    for tid in np.unique(rows["track"]):
        m = np.flatnonzero(rows["track"] == tid)
        rows["rate_true"][m], rows["resid_m"][m] = kitti_rate_truth(rows["frame"][m],
                                                                    rows["rear_m"][m])
    # The nearest ego-lane vehicle is the lead whatever its size; a frame whose lead is under
    # 25 px is not scored (taking the nearest of the boxes >= 25 px instead would call a car
    # 20 m behind a small lead "the lead", and count the right choice as a miss).
    cand = ((np.abs(rows["x_m"]) < LEAD_HALF_LANE_M) & (rows["rear_m"] > 0)
            & (rows["rear_m"] < LEAD_MAX_RANGE_M))
    rows["true_lead"] = np.zeros(n, dtype=bool)
    for f in np.unique(rows["frame"][cand]):
        c = np.flatnonzero(cand & (rows["frame"] == f))
        lead = c[np.argmin(rows["rear_m"][c])]
        rows["true_lead"][lead] = rows["box_h_px"][lead] >= MIN_BOX_PX
    return rows


def _rms(x: np.ndarray) -> float:
    return math.sqrt(float(np.mean(np.square(x)))) if x.size else math.nan


def _median_abs(x: np.ndarray) -> float:
    return float(np.median(np.abs(x))) if x.size else math.nan


def kitti_rate_figures(rows: dict[str, np.ndarray]) -> dict[str, float]:
    """Range-rate and lead figures of :func:`kitti_rate_rows` (one sequence or several joined
    with :func:`join_rows`).

    ``lead_*`` are over the frames with a labelled lead: rate RMSE / median |error| [m/s]
    where the truth rate is known, median |relative range error|, ``lead_same`` the share of
    those frames where that vehicle is the one marked ``is_lead``, ``lead_any`` where some
    vehicle is. ``all_*`` are over all vehicles >= 25 px with a rear nearer than 40 m;
    ``bin_*`` per range bin; ``all_p90`` the 90th percentile of |error|. ``truth_resid_m``: RMS residual of the truth fit (the labels'
    own position noise); ``truth_rate_floor``: that noise carried into the truth's slope.
    """
    ok = (np.isfinite(rows["rate_true"]) & np.isfinite(rows["rate_m_s"])
          & (rows["box_h_px"] >= MIN_BOX_PX))
    err = rows["rate_m_s"] - rows["rate_true"]
    lead = rows["true_lead"]
    rear = rows["rear_m"]
    out: dict[str, float] = {"lead_frames": int(lead.sum()), "lead_n": int((ok & lead).sum())}
    out["lead_rmse"] = _rms(err[ok & lead])
    out["lead_med"] = _median_abs(err[ok & lead])
    out["lead_range_rel"] = _median_abs((rows["range_m"][lead] - rear[lead]) / rear[lead])
    out["lead_same"] = float(np.mean(rows["is_lead"][lead])) if lead.any() else math.nan
    lead_frames = set(rows["frame"][lead].tolist()) if "seq" not in rows else set(
        zip(rows["seq"][lead].tolist(), rows["frame"][lead].tolist(), strict=True))
    flagged = set(rows["frame"][rows["is_lead"]].tolist()) if "seq" not in rows else set(
        zip(rows["seq"][rows["is_lead"]].tolist(), rows["frame"][rows["is_lead"]].tolist(),
            strict=True))
    out["lead_any"] = len(lead_frames & flagged) / len(lead_frames) if lead_frames else math.nan
    near = ok & (rear < 40)
    out["all_n"] = int(near.sum())
    out["all_rmse"], out["all_med"] = _rms(err[near]), _median_abs(err[near])
    # The RMSE hangs on a few diverged tracks; the 90th percentile shows the bulk.
    out["all_p90"] = float(np.percentile(np.abs(err[near]), 90)) if near.any() else math.nan
    for lo, hi in RATE_BINS_M:
        m = ok & (rear >= lo) & (rear < hi)
        key = f"bin_{lo:g}-{hi:g}"
        out[key + "_n"] = int(m.sum())
        out[key + "_rmse"], out[key + "_med"] = _rms(err[m]), _median_abs(err[m])
    # The fit leaves 3 of the window's degrees of freedom unused; white noise of spread s then
    # gives a slope spread of s sqrt(12 / (w (w^2 - 1))) / dt at the centre.
    w = RATE_TRUTH_WINDOW
    res = rows["resid_m"][np.isfinite(rows["resid_m"]) & (rows["box_h_px"] >= MIN_BOX_PX)]
    s = _rms(res) * math.sqrt(w / (w - 3))
    out["truth_resid_m"] = _rms(res)
    out["truth_rate_floor"] = s * math.sqrt(12.0 / (w * (w * w - 1))) / KITTI_DT_S
    return out


def join_rows(per_seq: dict[str, dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """The rows of several sequences as one set (with a ``seq`` column)."""
    keys = next(iter(per_seq.values())).keys()
    out = {k: np.concatenate([r[k] for r in per_seq.values()]) for k in keys}
    out["seq"] = np.concatenate([np.full(len(r["frame"]), int(s)) for s, r in per_seq.items()])
    return out
