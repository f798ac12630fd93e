"""Keyframe scoring: IoU, Hungarian matching of simulated to annotated boxes, counts and rates.

Two counting rules are reported side by side (``metrics.json`` states which is which):

- **standard** (the top-level ``tp``/``fp``/``fn``/``precision``/``recall``/``f1``): boxes are
  matched one-to-one by the Hungarian method maximising first the number of pairs with
  IoU >= 0.5, then their summed IoU; a pair is a TP, every unmatched simulated box a FP,
  every unmatched annotated box a FN. Simulated boxes lying mostly (>= 50 % of their area)
  inside an ignore region (KITTI DontCare, crowd, unmodelled vehicle classes) are not
  counted at all, as in the KITTI benchmark, nor are unmatched "hard" simulated boxes (ones
  an annotator may skip: tiny, mostly outside the image, partly behind the camera, largely
  hidden; see :mod:`vid2sim.evaluate.replay`).
- **reference_study** (the counting of the study this tool is compared with): Hungarian
  matching admitting pairs with IoU > 0.1; a pair with IoU >= 0.5 is a TP, a pair with
  0.1 < IoU < 0.5 a FP, an annotated box without a pair (IoU <= 0.1) a FN; simulated boxes
  without a pair are not counted. It is more lenient on precision than the standard rule.

``mean_iou`` is the mean IoU of the standard matched pairs (all >= 0.5), 0 without pairs; the
reference block carries the mean over its own pairs (> 0.1).

Every rate is a number (the metrics.json contract): where its denominator is zero it is 1.0
when nothing went wrong (no annotation and no simulated box: nothing to find, nothing
invented) and 0.0 otherwise (e.g. precision with annotations but no simulated boxes).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from vid2sim.core.boxes import box_area, intersection_matrix, iou_matrix
from vid2sim.core.records import AnnotatedBox, Keyframe, ProjectedBox

TP_IOU = 0.5
"""Minimum IoU of a true positive (both counting rules)."""
REFERENCE_MIN_IOU = 0.1
"""Reference study: pairs at or below this IoU are misses."""
IGNORE_OVERLAP = 0.5
"""Fraction of a simulated box's area inside an ignore region above which it is not counted."""


def match_boxes(pred_px: Sequence[Sequence[float]] | np.ndarray,
                gt_px: Sequence[Sequence[float]] | np.ndarray, *,
                min_iou: float = TP_IOU, strict: bool = False
                ) -> list[tuple[int, int, float]]:
    """One-to-one matching of predicted to annotated boxes (Hungarian, scipy).

    Pairs whose IoU is below ``min_iou`` (or at/below it when ``strict``) are not admissible.
    Among admissible assignments the one with the most pairs wins, ties broken by the
    largest summed IoU: a per-pair bonus larger than any IoU sum makes the count dominate.

    Parameters
    ----------
    pred_px, gt_px : array_like, shape (N, 4) and (M, 4)
        Boxes (x1, y1, x2, y2) in pixels.
    min_iou : float
        Admission threshold on IoU.
    strict : bool
        Require IoU > ``min_iou`` instead of >= (the reference study's 0.1 rule).

    Returns
    -------
    list of (pred_index, gt_index, iou)
        Sorted by ``pred_index``.
    """
    iou = iou_matrix(pred_px, gt_px)
    if iou.size == 0:
        return []
    ok = iou > min_iou if strict else iou >= min_iou
    if not ok.any():
        return []
    bonus = float(min(iou.shape)) + 1.0
    # linear_sum_assignment minimises: admissible pairs cost -(bonus + IoU), others 0, so
    # a solution never gains by using an inadmissible pair (dropped afterwards anyway).
    cost = np.where(ok, -(bonus + iou), 0.0)
    rows, cols = linear_sum_assignment(cost)
    pairs = [(int(r), int(c), float(iou[r, c])) for r, c in zip(rows, cols, strict=True) if ok[r, c]]
    return sorted(pairs)


def _ignored_predictions(pred: np.ndarray, ignore: np.ndarray, unmatched: list[int]) -> set[int]:
    """Unmatched predictions lying mostly inside one ignore region."""
    if not unmatched or ignore.size == 0:
        return set()
    sub = pred[unmatched]
    inter = intersection_matrix(sub, ignore)
    area = box_area(sub)[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        frac = np.where(area > 0, inter / area, 0.0)
    return {unmatched[i] for i in np.flatnonzero((frac >= IGNORE_OVERLAP).any(axis=1))}


def _prf(tp: int, fp: int, fn: int) -> dict[str, float]:
    """Precision, recall and F1; empty denominators per the module docstring."""
    perfect = 1.0 if tp + fp + fn == 0 else 0.0
    precision = tp / (tp + fp) if tp + fp else perfect
    recall = tp / (tp + fn) if tp + fn else perfect
    f1 = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else 1.0
    return {"precision": float(precision), "recall": float(recall), "f1": float(f1)}


@dataclass(slots=True)
class _FrameScore:
    tp: int
    fp: int
    fn: int
    ious: list[float]
    ref_tp: int
    ref_fp: int
    ref_fn: int
    ref_ious: list[float]
    ignored: int
    matches: list[dict]
    false_positives: list[str]
    missed: list[str | None]
    range_errors_m: list[float]
    range_pairs: list[tuple[float, float]]


def score_frame(pred: Sequence[ProjectedBox], gt: Sequence[AnnotatedBox]) -> _FrameScore:
    """Score one keyframe's simulated boxes against its annotated boxes (both rules)."""
    care = [b for b in gt if not b.ignore]
    ignore = np.array([b.box_px for b in gt if b.ignore], dtype=float).reshape(-1, 4)
    pred_px = np.array([p.box_px for p in pred], dtype=float).reshape(-1, 4)
    gt_px = np.array([b.box_px for b in care], dtype=float).reshape(-1, 4)

    pairs = match_boxes(pred_px, gt_px, min_iou=TP_IOU)
    matched_pred = {i for i, _, _ in pairs}
    unmatched = [i for i in range(len(pred)) if i not in matched_pred]
    ignored = _ignored_predictions(pred_px, ignore, unmatched)
    ignored |= {i for i in unmatched if pred[i].hard}
    tp = len(pairs)
    fp = len(unmatched) - len(ignored)
    fn = len(care) - tp

    matches, errors, range_pairs = [], [], []
    for i, j, iou in pairs:
        p, g = pred[i], care[j]
        entry = {"actor_id": p.actor_id, "annotation_id": g.id, "iou": iou, "hard": p.hard,
                 "range_m_simulated": p.range_m, "range_m_annotated": g.range_m}
        if g.range_m is not None and math.isfinite(p.range_m):
            entry["range_error_m"] = p.range_m - g.range_m
            errors.append(p.range_m - g.range_m)
            range_pairs.append((g.range_m, p.range_m))
        matches.append(entry)

    ref_pairs = match_boxes(pred_px, gt_px, min_iou=REFERENCE_MIN_IOU, strict=True)
    ref_tp = sum(1 for _, _, v in ref_pairs if v >= TP_IOU)
    ref_fp = len(ref_pairs) - ref_tp
    ref_fn = len(care) - len(ref_pairs)
    return _FrameScore(tp=tp, fp=fp, fn=fn, ious=[v for _, _, v in pairs],
                       ref_tp=ref_tp, ref_fp=ref_fp, ref_fn=ref_fn,
                       ref_ious=[v for _, _, v in ref_pairs], ignored=len(ignored),
                       matches=matches,
                       false_positives=[pred[i].actor_id for i in unmatched if i not in ignored],
                       missed=[care[j].id for j in range(len(care))
                               if j not in {jj for _, jj, _ in pairs}],
                       range_errors_m=errors, range_pairs=range_pairs)


def _mean(values: list[float]) -> float:
    return float(np.mean(values)) if values else 0.0


def range_error_summary(errors_m: list[float], pairs: list[tuple[float, float]]
                        ) -> dict[str, float | int | None]:
    """Signed and absolute range error statistics of matched pairs [m]; relative error is
    |simulated - annotated| / annotated over pairs more than 1 m away."""
    e = np.asarray(errors_m, dtype=float)
    rel = [abs(s - a) / a for a, s in pairs if a > 1.0]
    if e.size == 0:
        return {"pairs": 0, "mean_abs_m": None, "median_abs_m": None, "rmse_m": None,
                "mean_signed_m": None, "mean_abs_rel": None}
    return {"pairs": int(e.size), "mean_abs_m": float(np.mean(np.abs(e))),
            "median_abs_m": float(np.median(np.abs(e))),
            "rmse_m": float(np.sqrt(np.mean(e ** 2))), "mean_signed_m": float(np.mean(e)),
            "mean_abs_rel": float(np.mean(rel)) if rel else None}


DEFINITIONS = {
    "tp_fp_fn": "standard: Hungarian one-to-one matching, a pair needs IoU >= 0.5; every "
                "unmatched simulated box is a FP (unless >= 50% inside an ignore region or "
                "'hard': under 10 px high, under half in the image, partly behind the camera "
                "or >= 70% hidden), every unmatched annotated vehicle a FN",
    "precision": "tp / (tp + fp)",
    "recall": "tp / (tp + fn)",
    "f1": "2 tp / (2 tp + fp + fn)",
    "mean_iou": "mean IoU of the standard matched pairs (IoU >= 0.5)",
    "reference_study": "matching admits IoU > 0.1; TP IoU >= 0.5, FP 0.1 < IoU < 0.5, FN = "
                       "annotated vehicle without a pair (IoU <= 0.1); unpaired simulated "
                       "boxes not counted",
    "range_error": "simulated minus annotated range to the vehicle's near face [m], over "
                   "standard matched pairs whose annotation carries 3D (KITTI)",
    "empty": "a rate whose denominator is zero is 1.0 when there was nothing to find and "
             "nothing simulated, else 0.0; mean IoU without pairs is 0.0",
}


def score_keyframes(keyframes: Sequence[Keyframe],
                    predictions: dict[float, list[ProjectedBox]] | Sequence[list[ProjectedBox]]
                    ) -> dict:
    """Score simulated boxes against annotated keyframes, per keyframe and overall.

    Parameters
    ----------
    keyframes : sequence of Keyframe
        Annotated frames.
    predictions : dict or sequence
        Simulated boxes per keyframe: a dict keyed by the keyframe's ``t_s`` (as returned by
        :func:`vid2sim.evaluate.replay.replay_boxes`) or a list parallel to ``keyframes``.

    Returns
    -------
    dict
        The ``metrics.json`` contract: ``keyframes, tp, fp, fn, precision, recall, f1,
        mean_iou, per_keyframe`` plus ``reference_study``, ``range_error``, ``definitions``.
    """
    if isinstance(predictions, dict):
        preds = [predictions.get(k.t_s, []) for k in keyframes]
    else:
        preds = list(predictions)
        if len(preds) != len(keyframes):
            raise ValueError(f"{len(preds)} prediction lists for {len(keyframes)} keyframes")
    per_keyframe = []
    tp = fp = fn = ref_tp = ref_fp = ref_fn = ignored = 0
    ious: list[float] = []
    ref_ious: list[float] = []
    errors: list[float] = []
    range_pairs: list[tuple[float, float]] = []
    for kf, pred in zip(keyframes, preds, strict=True):
        s = score_frame(pred, kf.boxes)
        tp, fp, fn = tp + s.tp, fp + s.fp, fn + s.fn
        ref_tp, ref_fp, ref_fn = ref_tp + s.ref_tp, ref_fp + s.ref_fp, ref_fn + s.ref_fn
        ignored += s.ignored
        ious += s.ious
        ref_ious += s.ref_ious
        errors += s.range_errors_m
        range_pairs += s.range_pairs
        per_keyframe.append({
            "name": kf.name, "frame": kf.frame, "t_s": kf.t_s,
            "annotated": sum(1 for b in kf.boxes if not b.ignore),
            "ignore_regions": sum(1 for b in kf.boxes if b.ignore),
            "simulated": len(pred), "ignored_simulated": s.ignored,
            "tp": s.tp, "fp": s.fp, "fn": s.fn, **_prf(s.tp, s.fp, s.fn),
            "mean_iou": _mean(s.ious),
            "reference_study": {"tp": s.ref_tp, "fp": s.ref_fp, "fn": s.ref_fn,
                                **_prf(s.ref_tp, s.ref_fp, s.ref_fn)},
            "range_error": range_error_summary(s.range_errors_m, s.range_pairs),
            "matches": s.matches,
            "false_positive_actors": s.false_positives, "missed_annotations": s.missed,
        })
    return {
        "keyframes": len(keyframes), "tp": tp, "fp": fp, "fn": fn, **_prf(tp, fp, fn),
        "mean_iou": _mean(ious), "ignored_simulated": ignored,
        "reference_study": {"tp": ref_tp, "fp": ref_fp, "fn": ref_fn,
                            **_prf(ref_tp, ref_fp, ref_fn), "mean_iou": _mean(ref_ious)},
        "range_error": range_error_summary(errors, range_pairs),
        "definitions": DEFINITIONS,
        "per_keyframe": per_keyframe,
    }
