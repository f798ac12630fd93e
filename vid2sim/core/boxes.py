"""Axis-aligned box geometry shared by the detector, the tracker, the importers and scoring.

Boxes are (x1, y1, x2, y2) in pixels, x right, y down; arrays of boxes are (N, 4). This
module depends on numpy, scipy and OpenCV only, so any layer (detection, evaluation, sample
generation) may import it.
"""

from __future__ import annotations

import cv2
import numpy as np

UNMATCHED_COST = 1e6
"""Cost standing for "not allowed" in the assignment problems of :func:`match`: far above any
real cost (costs are 1 - IoU or normalised chi-squares, at most a few units)."""


BUFFER_SIGMAS = 2.0
"""Widening of both boxes in :func:`buffered_iou`, in standard deviations of the predicted
centre: about the 95 % interval of a Gaussian prediction (C-BIoU uses fixed buffers of a
similar size, Yang et al. WACV 2023)."""

WINDOW_CUT_MARGIN_PX = 2.0
"""A box edge this close to a window's inner edge counts as cut by it (the net's box of a
cut car stops at the window edge, give or take its localisation noise at the window's
scale)."""

FRAGMENT_INSIDE = 0.7
"""Share of a box's area inside a stronger box from which it may be a fragment of that box's
vehicle (see :func:`suppress_fragments`)."""

FRAGMENT_MIN_HEIGHT_RATIO = 0.6
"""A fragment is at least this share of the stronger box's height: a smaller box inside is
another, farther vehicle seen through a gap, not a part."""


def box_area(boxes_px: np.ndarray) -> np.ndarray:
    """Area of each box [px^2]; inverted boxes (x2 < x1 or y2 < y1) have area 0."""
    b = np.asarray(boxes_px, dtype=float).reshape(-1, 4)
    return np.clip(b[:, 2] - b[:, 0], 0, None) * np.clip(b[:, 3] - b[:, 1], 0, None)


def intersection_matrix(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """Pairwise intersection area [px^2] of two sets of boxes, shape (len(a), len(b))."""
    a = np.asarray(boxes_a, dtype=float).reshape(-1, 4)
    b = np.asarray(boxes_b, dtype=float).reshape(-1, 4)
    x1 = np.maximum(a[:, None, 0], b[None, :, 0])
    y1 = np.maximum(a[:, None, 1], b[None, :, 1])
    x2 = np.minimum(a[:, None, 2], b[None, :, 2])
    y2 = np.minimum(a[:, None, 3], b[None, :, 3])
    return np.clip(x2 - x1, 0, None) * np.clip(y2 - y1, 0, None)


def iou_matrix(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """Intersection over union of every box in ``boxes_a`` with every box in ``boxes_b``.

    Parameters
    ----------
    boxes_a, boxes_b : array_like, shape (N, 4) and (M, 4)
        Boxes (x1, y1, x2, y2) [px].

    Returns
    -------
    ndarray, shape (N, M)
        IoU in [0, 1]; 0 where the union is empty (degenerate boxes give no NaN).
    """
    a = np.asarray(boxes_a, dtype=float).reshape(-1, 4)
    b = np.asarray(boxes_b, dtype=float).reshape(-1, 4)
    inter = intersection_matrix(a, b)
    union = box_area(a)[:, None] + box_area(b)[None, :] - inter
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(union > 0, inter / union, 0.0)


def xyxy_to_xyah(box: np.ndarray) -> np.ndarray:
    """(x1, y1, x2, y2) -> (cx, cy, w/h, h) [px, px, -, px]."""
    x1, y1, x2, y2 = box
    h = max(y2 - y1, 1e-6)
    return np.array([(x1 + x2) / 2, (y1 + y2) / 2, (x2 - x1) / h, h])


def xyah_to_xyxy(state: np.ndarray) -> np.ndarray:
    """(cx, cy, w/h, h, ...) -> (x1, y1, x2, y2) [px]."""
    cx, cy, a, h = state[:4]
    w = a * h
    return np.array([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2])


def buffered_iou(box_px: np.ndarray, std_px: tuple[float, float], boxes_px: np.ndarray,
                 n_sigma: float = BUFFER_SIGMAS) -> np.ndarray:
    """IoU of one predicted box with many boxes, all grown by the prediction's uncertainty.

    Both sides are widened by ``n_sigma`` standard deviations of the predicted centre in x
    and y (the "buffered IoU" idea of C-BIoU, Yang et al. WACV 2023, with the buffer taken
    from the Kalman covariance instead of a fixed ratio). A track predicted over several
    frames (``--detect-every N``, a short occlusion, a new track with unknown velocity) thus
    still overlaps the car's new box, while a well-tracked box keeps a tight gate.
    """
    bx, by = n_sigma * std_px[0], n_sigma * std_px[1]
    grow = np.array([-bx, -by, bx, by])
    return iou_matrix((np.asarray(box_px, float) + grow)[None], np.asarray(boxes_px) + grow)[0]


def border_cut(boxes_px: np.ndarray, image_size_px: tuple[int, int] | None,
               margin_px: float) -> np.ndarray:
    """Which edges (x1, y1, x2, y2) of each box lie on the image border, shape (n, 4)."""
    b = np.asarray(boxes_px, dtype=float).reshape(-1, 4)
    if image_size_px is None:
        return np.zeros(b.shape, dtype=bool)
    w, h = image_size_px
    return np.stack([b[:, 0] <= margin_px, b[:, 1] <= margin_px,
                     b[:, 2] >= w - margin_px, b[:, 3] >= h - margin_px], axis=1)


def cut_by_window(boxes_px: np.ndarray, window: tuple[int, int, int, int], width_px: int,
                  height_px: int, margin_px: float = WINDOW_CUT_MARGIN_PX) -> np.ndarray:
    """Mask of boxes (frame px, Nx4) touching an edge of ``window`` that lies inside the
    image: the window cut that car, so its box there is truncated. An edge on the image
    border cuts nothing (the image itself ends there)."""
    x1, y1, x2, y2 = window
    cut = np.zeros(len(boxes_px), dtype=bool)
    if x1 > 0:
        cut |= boxes_px[:, 0] <= x1 + margin_px
    if x2 < width_px:
        cut |= boxes_px[:, 2] >= x2 - margin_px
    if y1 > 0:
        cut |= boxes_px[:, 1] <= y1 + margin_px
    if y2 < height_px:
        cut |= boxes_px[:, 3] >= y2 - margin_px
    return cut


def match(cost: np.ndarray, max_cost: float) -> tuple[list[tuple[int, int]], list[int], list[int]]:
    """Min-cost one-to-one assignment, rejecting pairs costlier than ``max_cost``.

    Returns matched (row, col) pairs, unmatched rows, unmatched columns.
    """
    n_rows, n_cols = cost.shape
    if n_rows == 0 or n_cols == 0:
        return [], list(range(n_rows)), list(range(n_cols))
    # Leaving a row or a column unmatched costs half the gate, so a pair is made only if it
    # is cheaper than leaving both sides alone, and pairs beyond the gate never steer the
    # solution: the square problem [[cost, unmatched rows], [unmatched columns, 0]].
    half = max_cost / 2.0
    full = np.full((n_rows + n_cols, n_cols + n_rows), UNMATCHED_COST)
    full[:n_rows, :n_cols] = np.where(cost <= max_cost, cost, UNMATCHED_COST)
    full[:n_rows, n_cols:][np.diag_indices(n_rows)] = half
    full[n_rows:, :n_cols][np.diag_indices(n_cols)] = half
    full[n_rows:, n_cols:] = 0.0
    # scipy.optimize costs 0.7 s to import: loaded on the first assignment, not by every
    # command that only parses its options (`vid2sim batch` on a finished manifest).
    from scipy.optimize import linear_sum_assignment

    rows, cols = linear_sum_assignment(full)
    pairs = [(int(r), int(c)) for r, c in zip(rows, cols, strict=True)
             if r < n_rows and c < n_cols and cost[r, c] <= max_cost]
    used_r = {r for r, _ in pairs}
    used_c = {c for _, c in pairs}
    return (pairs, [r for r in range(n_rows) if r not in used_r],
            [c for c in range(n_cols) if c not in used_c])


def nms(boxes_px: np.ndarray, scores: np.ndarray, iou_threshold: float,
        class_ids: np.ndarray | None = None) -> np.ndarray:
    """Indices kept by non-maximum suppression (class-aware when ``class_ids`` is given),
    best score first. ``boxes_px`` is Nx4 (x1, y1, x2, y2)."""
    if len(boxes_px) == 0:
        return np.zeros(0, dtype=np.int64)
    xywh = np.column_stack([boxes_px[:, 0], boxes_px[:, 1], boxes_px[:, 2] - boxes_px[:, 0],
                            boxes_px[:, 3] - boxes_px[:, 1]]).astype(np.float64)
    if class_ids is None:
        keep = cv2.dnn.NMSBoxes(xywh.tolist(), scores.astype(float).tolist(), 0.0,
                                float(iou_threshold))
    else:
        keep = cv2.dnn.NMSBoxesBatched(xywh.tolist(), scores.astype(float).tolist(),
                                       class_ids.astype(int).tolist(), -np.inf,
                                       float(iou_threshold))
    keep = np.asarray(keep, dtype=np.int64).reshape(-1)
    return keep[np.argsort(-scores[keep], kind="stable")]


def suppress_fragments(boxes_px: np.ndarray, scores: np.ndarray,
                       inside: float = FRAGMENT_INSIDE,
                       min_height_ratio: float = FRAGMENT_MIN_HEIGHT_RATIO) -> np.ndarray:
    """Indices of boxes that are not fragments of a stronger box, best score first.

    A box with at least ``inside`` of its area within a higher-scoring box and at least
    ``min_height_ratio`` of that box's height is taken for a part of the same vehicle (a
    wheel arch, a bonnet cut by a tile or by an occluder): NMS keeps it because the IoU of a
    part with the whole is low. A smaller box inside a big one (a far car seen through the
    gap) keeps its place since its height differs. Cost: a car almost hidden behind another
    at the same range is dropped, which the tracker bridges.
    """
    order = np.argsort(-scores, kind="stable")
    kept: list[int] = []
    for i in order:
        x1, y1, x2, y2 = boxes_px[i]
        area = max((x2 - x1) * (y2 - y1), 1e-9)
        fragment = False
        for j in kept:
            a1, b1, a2, b2 = boxes_px[j]
            iw = max(0.0, min(x2, a2) - max(x1, a1))
            ih = max(0.0, min(y2, b2) - max(y1, b1))
            if iw * ih / area >= inside and (y2 - y1) >= min_height_ratio * (b2 - b1):
                fragment = True
                break
        if not fragment:
            kept.append(int(i))
    return np.asarray(kept, dtype=np.int64)
