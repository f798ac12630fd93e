"""The detectors' pure pre- and post-processing: YOLOX's letterbox, the YOLOX and PP-PicoDet
output decoders and the vehicle classes of COCO (see the project's MODELS.md for the upstream
exports they follow)."""

from __future__ import annotations

import functools

import cv2
import numpy as np

from vid2sim.core.records import VehicleCategory

COCO_VEHICLES: dict[int, VehicleCategory] = {
    2: VehicleCategory.CAR, 3: VehicleCategory.MOTORCYCLE, 5: VehicleCategory.BUS,
    6: VehicleCategory.TRAM, 7: VehicleCategory.TRUCK}
"""COCO class id (0-based) -> vehicle category. COCO's ``train`` (6) holds trains and trams,
and the only rail vehicle a road camera meets beside or on the street is a tram: it is its
own category, replayed on its own track (:mod:`vid2sim.detect.rail`)."""

NET_INPUT_PX = (416, 416)
"""(width, height) of the shared exports' fixed input (MODELS.md); a loaded model's own input
size overrides it."""
LETTERBOX_FILL = 114
"""Grey level of YOLOX's letterbox canvas (upstream preprocessing, MODELS.md)."""
LOGIT_CLIP = 10.0
"""Raw YOLOX size logits are clipped to +-this before exp(): a box e^10 strides wide is
already larger than any input, and the clip keeps exp() finite on garbage outputs."""
PICODET_TOP_K = 1000
"""Cells kept per PicoDet level before NMS, as upstream (MODELS.md)."""


# --------------------------------------------------------------------------- geometry


def letterbox(image_bgr: np.ndarray, size_px: tuple[int, int] = NET_INPUT_PX,
              fill: int = LETTERBOX_FILL, max_scale: float | None = None
              ) -> tuple[np.ndarray, float]:
    """Resize keeping the aspect ratio (at most ``max_scale``) and paste at the top-left of
    a filled canvas.

    Returns the canvas (``size_px`` = (width, height)) and the scale r (canvas px per image
    px); a canvas point (u, v) is the image point (u / r, v / r).
    """
    out_w, out_h = size_px
    h, w = image_bgr.shape[:2]
    r = min(out_h / h, out_w / w)
    if max_scale is not None:
        r = min(r, max_scale)
    # floor, as the upstream YOLOX demo does
    new_w, new_h = max(1, int(w * r)), max(1, int(h * r))
    canvas = np.full((out_h, out_w, 3), fill, dtype=np.uint8)
    canvas[:new_h, :new_w] = cv2.resize(image_bgr, (new_w, new_h),
                                        interpolation=cv2.INTER_LINEAR)
    return canvas, r


# --------------------------------------------------------------------------- decoders


def decode_yolox(output: np.ndarray, input_size_px: tuple[int, int] = NET_INPUT_PX,
                 strides: tuple[int, ...] = (8, 16, 32), min_objectness: float = 0.0
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Decode a raw YOLOX output [1, N, 5 + C] into boxes and class scores on the input canvas.

    Rows run over strides 8, 16, 32, each grid row-major; columns are tx, ty, tw, th,
    objectness, C class scores (sigmoid already applied in the export). Rows whose
    objectness is below ``min_objectness`` are left out (a class score, objectness times a
    probability, cannot exceed it): a detector's score threshold drops them anyway, and
    nearly every row of a frame is one.

    Returns
    -------
    boxes_px : (K, 4) array
        (x1, y1, x2, y2) on the network input canvas [px], in row order.
    class_scores : (K, C) array
        objectness * class probability.
    """
    pred = output.reshape(-1, output.shape[-1]).astype(np.float32)
    grid, stride = _yolox_grid(tuple(input_size_px), tuple(strides))
    if len(grid) != len(pred):
        raise ValueError(f"YOLOX output has {len(pred)} rows, expected {len(grid)} "
                         f"for input {input_size_px}")
    if min_objectness > 0:
        keep = pred[:, 4] >= min_objectness
        pred, grid, stride = pred[keep], grid[keep], stride[keep]
    centre = (pred[:, 0:2] + grid) * stride
    size = np.exp(np.clip(pred[:, 2:4], -LOGIT_CLIP, LOGIT_CLIP)) * stride
    boxes = np.concatenate([centre - size / 2, centre + size / 2], axis=1)
    return boxes, pred[:, 4:5] * pred[:, 5:]


@functools.lru_cache(maxsize=16)
def _yolox_grid(input_size_px: tuple[int, int], strides: tuple[int, ...]
                ) -> tuple[np.ndarray, np.ndarray]:
    """Cell (column, row) and stride of every YOLOX output row for one input size (cached:
    a run sees a handful of window sizes)."""
    in_w, in_h = input_size_px
    grids, scale = [], []
    for s in strides:
        gh, gw = in_h // s, in_w // s
        gy, gx = np.mgrid[0:gh, 0:gw]
        grids.append(np.column_stack([gx.ravel(), gy.ravel()]))
        scale.append(np.full(gh * gw, s, dtype=np.float32))
    grid = np.concatenate(grids).astype(np.float32)
    grid.flags.writeable = False
    stride = np.concatenate(scale)[:, None]
    stride.flags.writeable = False
    return grid, stride


def decode_picodet(class_outputs: list[np.ndarray], box_outputs: list[np.ndarray],
                   input_size_px: tuple[int, int] = NET_INPUT_PX,
                   strides: tuple[int, ...] = (8, 16, 32, 64), reg_max: int = 7,
                   top_k: int = PICODET_TOP_K) -> tuple[np.ndarray, np.ndarray]:
    """Decode PicoDet outputs (per stride: class scores [1, N, C], distances [1, N, 4*(reg_max+1)]).

    Each side (left, top, right, bottom) is a distribution over reg_max + 1 bins; its
    expectation times the stride is the distance from the cell centre ((col + 0.5) * s,
    (row + 0.5) * s). The best ``top_k`` cells per level (by max class score) are kept,
    as upstream does.

    Returns
    -------
    boxes_px : (M, 4) array
        (x1, y1, x2, y2) on the network input canvas [px].
    class_scores : (M, C) array
    """
    in_w, in_h = input_size_px
    bins = np.arange(reg_max + 1, dtype=np.float32)
    all_boxes, all_scores = [], []
    for s, cls, reg in zip(strides, class_outputs, box_outputs, strict=True):
        cls = cls.reshape(-1, cls.shape[-1]).astype(np.float32)
        reg = reg.reshape(-1, 4, reg_max + 1).astype(np.float32)
        gw = int(np.ceil(in_w / s))
        gh = int(np.ceil(in_h / s))
        if len(cls) != gw * gh:
            raise ValueError(f"PicoDet level stride {s} has {len(cls)} cells, expected {gw * gh}")
        if len(cls) > top_k:
            idx = np.argpartition(-cls.max(axis=1), top_k)[:top_k]
        else:
            idx = np.arange(len(cls))
        cls, reg = cls[idx], reg[idx]
        # softmax over the bins (shifted by the max for numerical safety)
        e = np.exp(reg - reg.max(axis=2, keepdims=True))
        dist = (e / e.sum(axis=2, keepdims=True)) @ bins * s  # (M, 4) l, t, r, b [px]
        cx = (idx % gw + 0.5) * s
        cy = (idx // gw + 0.5) * s
        all_boxes.append(np.column_stack([cx - dist[:, 0], cy - dist[:, 1],
                                          cx + dist[:, 2], cy + dist[:, 3]]))
        all_scores.append(cls)
    return np.concatenate(all_boxes), np.concatenate(all_scores)


def vehicle_candidates(boxes_px: np.ndarray, class_scores: np.ndarray, score_threshold: float
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Best vehicle class per row, keeping rows scoring >= ``score_threshold``.

    Returns boxes (K, 4), scores (K,), COCO class ids (K,).
    """
    ids = np.array(sorted(COCO_VEHICLES))
    vehicle_scores = class_scores[:, ids]
    best = vehicle_scores.argmax(axis=1)
    score = vehicle_scores[np.arange(len(best)), best]
    keep = score >= score_threshold
    return boxes_px[keep], score[keep], ids[best[keep]]
