"""Vehicle detectors over onnxruntime: YOLOX and PP-PicoDet decoders behind one protocol.

Pre- and post-processing follow the upstream exports (see the project's MODELS.md):
YOLOX takes a BGR 0-255 image letterboxed at the top-left of a 416x416 canvas of 114s;
PicoDet takes an RGB image plainly resized to 416x416 and ImageNet-normalised, and predicts
distance distributions (GFL, reg_max 7) per side.

Small-car measure (``small_object_mode``): both nets see a fixed 416x416 input, so a wide
1242x375 KITTI frame is shrunk by 3x and a 25 px car becomes 8 px, near the limit of the
stride-8 head. With the mode on, the frame is also cut into two overlapping, nearly square
tiles (left and right) run at ~1.8x the full-frame scale, and a centre window of a third of
the width, where a forward camera sees the road ahead, at ~3.3x (a lead 30-45 m away, which
scores about 0.37 in the full frame, scores about 0.65 there; only its boxes scoring
``CENTRE_MIN_SCORE`` or more are kept, since it also sees shadows and fragments at that
scale). Window boxes cut by a window's inner edge are dropped (another window sees that car
whole) and everything is merged by NMS.

Crop refinement (``refine_max_boxes``, on with the small-object mode): the few vehicles that
may be the lead (see :func:`refine_candidates`) are detected again on a crop about their box,
``REFINE_CROP_SCALE`` times their larger side (at least ``REFINE_MIN_SIDE_PX``), seen by the
net at a larger scale, and their box is replaced by the crop's box that overlaps it best.
Range comes from box edges, so their frame-to-frame jitter becomes range-rate noise; see
:meth:`OnnxDetector.refine` for the measured gain.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Protocol, runtime_checkable

import cv2
import numpy as np

from vid2sim.base.errors import FormatError
from vid2sim.core.boxes import cut_by_window, iou_matrix, nms, suppress_fragments
from vid2sim.core.records import Detection, VehicleCategory
from vid2sim.detect.vehicles import models
from vid2sim.detect.vehicles._dynamic import dynamic_copy
from vid2sim.detect.vehicles.windows import (
    REFINE_CROP_SCALE,
    REFINE_MAX_BOXES,
    REFINE_MIN_IOU,
    REFINE_MIN_SIDE_PX,
    centre_window,
    refine_candidates,
    refine_crop,
    tile_windows,
)

CENTRE_MIN_SCORE = 0.5
"""Lowest score kept from the centre window (see :func:`tile_windows`), the tracker's score to
start a track: a car 30-45 m ahead scores about 0.65 there against 0.37 in the full frame, a
road shadow or a fragment of a partly hidden car 0.3-0.47."""

COCO_VEHICLES: dict[int, VehicleCategory] = {
    2: VehicleCategory.CAR, 3: VehicleCategory.MOTORCYCLE, 5: VehicleCategory.BUS,
    6: VehicleCategory.TRAM, 7: VehicleCategory.TRUCK}
"""COCO class id (0-based) -> vehicle category. COCO's ``train`` (6) holds trains and trams,
and the only rail vehicle a road camera meets beside or on the street is a tram: it is its
own category, replayed on its own track (:mod:`vid2sim.detect.rail`)."""

DEFAULT_DETECTOR = models.DEFAULT_DETECTOR

ORT_SPINNING = False
"""Whether onnxruntime's worker threads spin (busy-wait) between runs, its default. They spin
for a while after every run, and the frames' other work (decoding in the prefetch thread,
optical flow, lane markings, OpenCV's own threads) then waits for the CPU they burn: on this
2-core machine with a second process busy, ``detect_and_range`` on KITTI raw 0001 took
9.9-10.7 s wall and 9.3-10.6 s CPU spinning against 5.0-5.7 s and 5.1-6.3 s not; with the
machine quiet 5.5 s against 4.8 s mean wall, 10.3 s against 7.2 s CPU (4-5 runs each,
alternating). A batch worker shares its machine with other workers: spinning steals from
them too."""

CROSS_CLASS_IOU = 0.7
"""IoU above which boxes of different vehicle classes are taken for one vehicle."""

NET_INPUT_PX = (416, 416)
"""(width, height) of the shared exports' fixed input (MODELS.md); a loaded model's own input
size overrides it."""

YOLOX_NMS_IOU = 0.45
"""Class-aware NMS IoU of YOLOX, as in the upstream demo (MODELS.md)."""

PICODET_NMS_IOU = 0.6
"""Class-aware NMS IoU of PicoDet, as in the upstream PaddleDetection deploy config
(MODELS.md)."""

SCORE_THRESHOLD = 0.3
"""Default lowest vehicle score kept by a detector built directly (MODELS.md: "score
threshold about 0.3"); the application layer passes the tracker's low score instead."""

LETTERBOX_FILL = 114
"""Grey level of YOLOX's letterbox canvas (upstream preprocessing, MODELS.md)."""

LOGIT_CLIP = 10.0
"""Raw YOLOX size logits are clipped to +-this before exp(): a box e^10 strides wide is
already larger than any input, and the clip keeps exp() finite on garbage outputs."""

FREE_SHAPE_STEP_PX = 32
"""Input sides of a free-shape run are multiples of this: the net's largest stride (YOLOX
downsamples by 32)."""

FREE_SHAPE_MARGIN_PX = 32
"""Grey margin kept below and beside the image in a free-shape run: the letterbox's fill is
context the net was trained with. On KITTI's six labelled frames (default settings): without
a margin recall 0.92 -> 0.88 and precision 0.85 -> 0.83 against the full 416x416 canvas;
with 32 px (or 64) the same counts as the full canvas (23/25 found, 7/48 false)."""

PICODET_TOP_K = 1000
"""Cells kept per PicoDet level before NMS, as upstream (MODELS.md)."""


@runtime_checkable
class Detector(Protocol):
    """Anything that finds vehicles in one BGR image."""

    def detect(self, image_bgr: np.ndarray) -> list[Detection]:
        """Vehicles in ``image_bgr`` (HxWx3 uint8), boxes in that image's pixels."""
        ...


# --------------------------------------------------------------------------- geometry


def letterbox(image_bgr: np.ndarray, size_px: tuple[int, int] = NET_INPUT_PX,
              fill: int = LETTERBOX_FILL) -> tuple[np.ndarray, float]:
    """Resize keeping the aspect ratio and paste at the top-left of a filled canvas.

    Returns the canvas (``size_px`` = (width, height)) and the scale r (canvas px per image
    px); a canvas point (u, v) is the image point (u / r, v / r).
    """
    out_w, out_h = size_px
    h, w = image_bgr.shape[:2]
    r = min(out_h / h, out_w / w)
    # floor, as the upstream YOLOX demo does
    new_w, new_h = max(1, int(w * r)), max(1, int(h * r))
    canvas = np.full((out_h, out_w, 3), fill, dtype=np.uint8)
    canvas[:new_h, :new_w] = cv2.resize(image_bgr, (new_w, new_h),
                                        interpolation=cv2.INTER_LINEAR)
    return canvas, r


# --------------------------------------------------------------------------- decoders


def decode_yolox(output: np.ndarray, input_size_px: tuple[int, int] = NET_INPUT_PX,
                 strides: tuple[int, ...] = (8, 16, 32)) -> tuple[np.ndarray, np.ndarray]:
    """Decode a raw YOLOX output [1, N, 5 + C] into boxes and class scores on the input canvas.

    Rows run over strides 8, 16, 32, each grid row-major; columns are tx, ty, tw, th,
    objectness, C class scores (sigmoid already applied in the export).

    Returns
    -------
    boxes_px : (N, 4) array
        (x1, y1, x2, y2) on the network input canvas [px].
    class_scores : (N, C) array
        objectness * class probability.
    """
    pred = output.reshape(-1, output.shape[-1]).astype(np.float32)
    grid, stride = _yolox_grid(tuple(input_size_px), tuple(strides))
    if len(grid) != len(pred):
        raise ValueError(f"YOLOX output has {len(pred)} rows, expected {len(grid)} "
                         f"for input {input_size_px}")
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


# --------------------------------------------------------------------------- detectors


class OnnxDetector:
    """Shared machinery: session, windows (full frame and optional tiles), merging.

    Parameters
    ----------
    model_path : Path
        ONNX weights.
    score_threshold : float
        Minimum vehicle score kept.
    nms_iou : float
        IoU above which the weaker of two boxes of one class is suppressed.
    small_object_mode : bool
        Also run on two overlapping tiles (see the module docstring).
    threads : int
        onnxruntime intra-op threads.
    refine_max_boxes : int
        Lead candidates refined on a crop per frame (0 = off; see :meth:`refine`).
    refine_scale : float
        Crop side over the box's larger side.
    refine_min_side_px : float
        Smallest crop side [px].
    """

    decoder = ""
    input_size_px = NET_INPUT_PX
    # Set by __init__ when the dynamic copy of the weights loads (see vid2sim.detect.vehicles._dynamic);
    # off for detectors built another way (tests build them with a fake session).
    batch_windows = False  # several windows per onnxruntime call
    free_shape = False  # the input may have another height and width than input_size_px

    def __init__(self, model_path: Path, *, score_threshold: float = SCORE_THRESHOLD,
                 nms_iou: float = YOLOX_NMS_IOU, small_object_mode: bool = False, threads: int = 2,
                 refine_max_boxes: int = 0, refine_scale: float = REFINE_CROP_SCALE,
                 refine_min_side_px: float = REFINE_MIN_SIDE_PX, dynamic: bool = True):
        import onnxruntime as ort  # heavy native library: loaded only when a detector is built

        self.model_path = Path(model_path)
        self.score_threshold = float(score_threshold)
        self.nms_iou = float(nms_iou)
        self.small_object_mode = bool(small_object_mode)
        self.refine_max_boxes = int(refine_max_boxes)
        self.refine_scale = float(refine_scale)
        self.refine_min_side_px = float(refine_min_side_px)
        options = ort.SessionOptions()
        options.intra_op_num_threads = int(threads)
        options.inter_op_num_threads = 1
        if not ORT_SPINNING:
            options.add_session_config_entry("session.intra_op.allow_spinning", "0")
        # PicoDet exports list initializers as inputs; ORT warns about each one (harmless).
        options.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(str(self.model_path), sess_options=options,
                                                providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own Fail/InvalidGraph types
            raise FormatError(self.model_path, f"onnxruntime cannot load the model: {exc}",
                              "is this an ONNX file of the chosen detector?") from exc
        self.input_name = self.session.get_inputs()[0].name
        shape = self.session.get_inputs()[0].shape
        if isinstance(shape[2], int) and isinstance(shape[3], int):
            self.input_size_px = (int(shape[3]), int(shape[2]))
        copy = dynamic_copy(self.model_path) if dynamic else None
        if copy is not None:
            self.session = ort.InferenceSession(str(copy), sess_options=options,
                                                providers=["CPUExecutionProvider"])
            self.batch_windows = True
            self.free_shape = self._accepts_free_shape()
        self.n_calls = 0  # onnxruntime calls made (for benchmarks)

    def _accepts_free_shape(self) -> bool:
        """Whether the net runs on an input of another height (a fully convolutional graph
        whose reshapes do not fix the spatial size)."""
        w = self.input_size_px[0]
        probe = np.zeros((1, 3, FREE_SHAPE_STEP_PX, w), np.float32)
        try:
            outputs = self.session.run(None, {self.input_name: probe})
        except Exception:  # noqa: BLE001 - onnxruntime's own error types: the size is fixed
            return False
        return self._cells(outputs) == self._expected_cells(w, FREE_SHAPE_STEP_PX)

    @staticmethod
    def _cells(outputs: list[np.ndarray]) -> int:
        return int(sum(o.shape[1] for o in outputs if o.ndim == 3 and o.shape[-1] > 4))

    def _expected_cells(self, width_px: int, height_px: int) -> int:
        return -1

    def _prepare(self, image_bgr: np.ndarray) -> tuple[np.ndarray, tuple[float, float]]:
        """Network input (3, H, W) float32 for one window, and the (x, y) scale from input
        to window pixels."""
        raise NotImplementedError

    def _decode(self, outputs: list[np.ndarray], input_size_px: tuple[int, int]
                ) -> tuple[np.ndarray, np.ndarray]:
        """Boxes on the network input [px] and class scores of one batch item."""
        raise NotImplementedError

    def _raw_many(self, images: list[np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        """:meth:`_raw` of several windows, inputs of one shape in one onnxruntime call."""
        prepared = [self._prepare(im) for im in images]
        out: list[tuple[np.ndarray, np.ndarray] | None] = [None] * len(images)
        groups: dict[tuple[int, ...], list[int]] = {}
        for i, (blob, _) in enumerate(prepared):
            groups.setdefault(blob.shape, []).append(i)
        for shape, members in groups.items():
            batch = np.stack([prepared[i][0] for i in members])
            outputs = self.session.run(None, {self.input_name: batch})
            self.n_calls += 1
            size = (shape[2], shape[1])
            for k, i in enumerate(members):
                boxes, scores = self._decode([o[k:k + 1] for o in outputs], size)
                sx, sy = prepared[i][1]
                out[i] = boxes * [sx, sy, sx, sy], scores
        return out

    def _raw(self, image_bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Boxes (in ``image_bgr`` pixels) and class scores before thresholds and NMS."""
        blob, (sx, sy) = self._prepare(image_bgr)
        outputs = self.session.run(None, {self.input_name: blob[None]})
        self.n_calls = getattr(self, "n_calls", 0) + 1
        boxes, scores = self._decode(outputs, (blob.shape[2], blob.shape[1]))
        return boxes * [sx, sy, sx, sy], scores

    def _window(self, image_bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vehicle boxes (window px), scores and COCO ids of one window after NMS."""
        return self._postprocess(image_bgr.shape, *self._raw(image_bgr))

    def _windows(self, images: list[np.ndarray]
                 ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """:meth:`_window` of several windows (batched when the weights allow)."""
        if not self.batch_windows or len(images) < 2:
            return [self._window(im) for im in images]
        return [self._postprocess(im.shape, *raw)
                for im, raw in zip(images, self._raw_many(images), strict=True)]

    def _postprocess(self, shape: tuple[int, ...], boxes: np.ndarray, class_scores: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        boxes, scores, ids = vehicle_candidates(boxes, class_scores, self.score_threshold)
        h, w = shape[:2]
        boxes = np.clip(boxes, 0, [w, h, w, h])
        keep = nms(boxes, scores, self.nms_iou, ids)
        boxes, scores, ids = boxes[keep], scores[keep], ids[keep]
        # Class-aware NMS leaves a car and a truck box on one vehicle (near-identical boxes,
        # the net unsure of the class): one vehicle must give one box.
        keep = nms(boxes, scores, CROSS_CLASS_IOU)
        return boxes[keep], scores[keep], ids[keep]

    def refine(self, image_bgr: np.ndarray, boxes_px: np.ndarray) -> np.ndarray:
        """Boxes (Nx4, frame px) with up to ``refine_max_boxes`` lead candidates re-detected
        on a crop about each (see :func:`refine_candidates`, :func:`refine_crop`).

        Each candidate's crop is run through the net like a window; crop boxes cut by a crop
        edge inside the image are dropped (:func:`cut_by_window`), and the crop box that
        overlaps the candidate best replaces it if their IoU is ``REFINE_MIN_IOU`` or more.
        Other boxes are returned unchanged; scores and classes are left to the caller (the
        original ones are kept, so which tracks start does not change).

        Why: a car 10-45 m ahead is a 25-120 px box, which the net sees at a third of its
        size in a wide full frame and 0.6x in a tile; range comes from its bottom edge and
        size, so box jitter is range-rate noise. On the composite clips (a real car pasted
        with a known box, 646 frames of seeds 0-5, errors in true box widths) the lead's box
        with 2 refined per frame, crop
        5x (at least 96 px): width bias +0.059 -> +0.046, frame-to-frame jitter of the width
        0.040 -> 0.023, of the bottom edge 0.022 -> 0.009, of the top edge 0.036 -> 0.016;
        lead range-rate RMSE 1.00 -> 0.85 m/s (benchmarks/bench_composite.py). The parked
        cars of KITTI raw 0001 stand at the kerb, mostly not candidates: their range-rate
        error is unchanged (median 2.50 m/s). Cost: 10.0 -> 8.0 frames/s with the tiles.
        """
        boxes_px = np.array(boxes_px, dtype=float).reshape(-1, 4)
        h, w = image_bgr.shape[:2]
        chosen = refine_candidates(boxes_px, w, self.refine_max_boxes)
        crops = [refine_crop(boxes_px[i], w, h, self.refine_scale, self.refine_min_side_px)
                 for i in chosen]
        results = self._windows([image_bgr[y1:y2, x1:x2] for x1, y1, x2, y2 in crops])
        for i, (x1, y1, x2, y2), (found, _, _) in zip(chosen, crops, results, strict=True):
            found = found + [x1, y1, x1, y1]
            found = found[~cut_by_window(found, (x1, y1, x2, y2), w, h)]
            if len(found) == 0:
                continue
            overlap = iou_matrix(boxes_px[i], found)[0]
            best = int(overlap.argmax())
            if overlap[best] >= REFINE_MIN_IOU:
                boxes_px[i] = found[best]
        return boxes_px

    def detect(self, image_bgr: np.ndarray) -> list[Detection]:
        """Vehicles in one BGR image, boxes in its pixels, best score first."""
        h, w = image_bgr.shape[:2]
        windows = tile_windows(w, h) if self.small_object_mode else [(0, 0, w, h)]
        centre = centre_window(w, h)
        parts_b, parts_s, parts_c = [], [], []
        results = self._windows([image_bgr[y1:y2, x1:x2] for x1, y1, x2, y2 in windows])
        for (x1, y1, x2, y2), (boxes, scores, ids) in zip(windows, results, strict=True):
            boxes = boxes + [x1, y1, x1, y1]
            if len(windows) > 1 and (x1, y1, x2, y2) == centre:
                # The centre window sees far cars at the net's scale, and with them more of
                # what only looks like one (shadows, fragments): only its confident boxes.
                keep = scores >= CENTRE_MIN_SCORE
                boxes, scores, ids = boxes[keep], scores[keep], ids[keep]
            if (x2 - x1, y2 - y1) != (w, h):
                # A car cut by a tile's inner edge gets a truncated box there; the full frame
                # or the neighbouring tile sees it whole, so the cut box is dropped.
                cut = cut_by_window(boxes, (x1, y1, x2, y2), w, h)
                boxes, scores, ids = boxes[~cut], scores[~cut], ids[~cut]
            parts_b.append(boxes)
            parts_s.append(scores)
            parts_c.append(ids)
        boxes = np.concatenate(parts_b)
        scores = np.concatenate(parts_s)
        ids = np.concatenate(parts_c)
        if len(windows) > 1:
            # The same car seen in two windows may be called car in one and truck in the
            # other: merge without regard to class.
            keep = nms(boxes, scores, self.nms_iou)
            boxes, scores, ids = boxes[keep], scores[keep], ids[keep]
        order = suppress_fragments(boxes, scores)
        boxes, scores, ids = boxes[order], scores[order], ids[order]
        if self.refine_max_boxes > 0:
            boxes = self.refine(image_bgr, boxes)
        return [Detection(box_px=tuple(float(v) for v in boxes[i]), score=float(scores[i]),
                          category=COCO_VEHICLES[int(ids[i])]) for i in range(len(boxes))]


class YoloxDetector(OnnxDetector):
    """YOLOX exported with the decode head off (raw tx, ty, tw, th; sigmoid scores)."""

    decoder = "yolox"

    def _expected_cells(self, width_px: int, height_px: int) -> int:
        return sum((width_px // s) * (height_px // s) for s in (8, 16, 32))

    def _prepare(self, image_bgr: np.ndarray) -> tuple[np.ndarray, tuple[float, float]]:
        size = self.input_size_px
        if self.free_shape:
            # the letterbox canvas cut after the image, rounded up to the net's largest
            # stride: the same pixels at the same scale, without computing the padding (the
            # axis that sets the scale keeps its full side, so the scale is unchanged)
            w, h = self.input_size_px
            r = min(h / image_bgr.shape[0], w / image_bgr.shape[1])
            step = FREE_SHAPE_STEP_PX
            size = (min(w, step * -(-max(1, int(image_bgr.shape[1] * r)) // step)
                        + FREE_SHAPE_MARGIN_PX),
                    min(h, step * -(-max(1, int(image_bgr.shape[0] * r)) // step)
                        + FREE_SHAPE_MARGIN_PX))
        canvas, r = letterbox(image_bgr, size)
        blob = canvas.transpose(2, 0, 1).astype(np.float32)  # BGR, 0-255, no norm
        return blob, (1.0 / r, 1.0 / r)

    def _decode(self, outputs: list[np.ndarray], input_size_px: tuple[int, int]
                ) -> tuple[np.ndarray, np.ndarray]:
        return decode_yolox(outputs[0], input_size_px)


class PicodetDetector(OnnxDetector):
    """PP-PicoDet exported without NMS (4 score and 4 distance tensors)."""

    decoder = "picodet"
    # ImageNet mean and standard deviation, as the PaddleDetection export expects (MODELS.md)
    MEAN_RGB = np.array([0.485, 0.456, 0.406], dtype=np.float32)
    STD_RGB = np.array([0.229, 0.224, 0.225], dtype=np.float32)

    def __init__(self, model_path: Path, *, score_threshold: float = SCORE_THRESHOLD,
                 nms_iou: float = PICODET_NMS_IOU, small_object_mode: bool = False,
                 threads: int = 2,
                 **refine_options):
        super().__init__(model_path, score_threshold=score_threshold, nms_iou=nms_iou,
                         small_object_mode=small_object_mode, threads=threads, **refine_options)

    def _prepare(self, image_bgr: np.ndarray) -> tuple[np.ndarray, tuple[float, float]]:
        h, w = image_bgr.shape[:2]
        in_w, in_h = self.input_size_px
        resized = cv2.resize(image_bgr, (in_w, in_h), interpolation=cv2.INTER_LINEAR)
        rgb = resized[:, :, ::-1].astype(np.float32) / 255.0
        blob = ((rgb - self.MEAN_RGB) / self.STD_RGB).transpose(2, 0, 1)
        return np.ascontiguousarray(blob), (w / in_w, h / in_h)

    def _decode(self, outputs: list[np.ndarray], input_size_px: tuple[int, int]
                ) -> tuple[np.ndarray, np.ndarray]:
        n = len(outputs) // 2
        return decode_picodet(outputs[:n], outputs[n:], input_size_px)


DETECTOR_CLASSES: dict[str, type[OnnxDetector]] = {"yolox": YoloxDetector,
                                                   "picodet": PicodetDetector}


def load_detector(name_or_path: str | Path = DEFAULT_DETECTOR, model_dir: Path | None = None,
                  *, score_threshold: float = SCORE_THRESHOLD, nms_iou: float | None = None,
                  small_object_mode: bool = True, threads: int = 2,
                  decoder: str | None = None, refine_max_boxes: int | None = None
                  ) -> OnnxDetector:
    """Build a detector from a registry name or an .onnx path.

    Parameters
    ----------
    name_or_path : str or Path
        "yolox-nano", "picodet-s", or a path to weights (the decoder is taken from the
        registry file name, else from ``decoder``, else guessed from the output count).
    model_dir : Path, optional
        Folder searched first for registry weights.
    score_threshold : float
        Minimum vehicle score.
    nms_iou : float, optional
        NMS IoU (default 0.45 for YOLOX, 0.6 for PicoDet, as upstream).
    small_object_mode : bool
        Add two overlapping tiles and a centre window for distant cars (default on; see the
        module docstring).
    threads : int
        onnxruntime intra-op threads.
    decoder : str, optional
        "yolox" or "picodet", for weights under an unknown file name.
    refine_max_boxes : int, optional
        Lead candidates re-detected on a crop per frame, 0 = off (default
        ``REFINE_MAX_BOXES`` with the small-object mode, else 0; see
        :meth:`OnnxDetector.refine`).
    """
    path = models.resolve_model(name_or_path, model_dir)
    spec = models.MODELS.get(str(name_or_path)) or models.spec_for_path(path)
    kind = decoder or (spec.decoder if spec else None)
    if kind is None:
        import onnxruntime as ort  # heavy native library: only for weights of unknown kind

        options = ort.SessionOptions()
        options.log_severity_level = 3
        try:
            n_out = len(ort.InferenceSession(str(path), sess_options=options,
                                             providers=["CPUExecutionProvider"]).get_outputs())
        except Exception as exc:  # onnxruntime raises its own Fail/InvalidGraph types
            raise FormatError(path, f"onnxruntime cannot load the model: {exc}",
                              "is this an ONNX file of a YOLOX or PicoDet export?") from exc
        # YOLOX exports one decoded-head tensor; PicoDet 4 score + 4 distance tensors
        kind = "yolox" if n_out == 1 else "picodet"
    if kind not in DETECTOR_CLASSES:
        raise FormatError(path, f"unknown decoder '{kind}'", "use yolox or picodet")
    cls = DETECTOR_CLASSES[kind]
    if refine_max_boxes is None:
        refine_max_boxes = REFINE_MAX_BOXES if small_object_mode else 0
    kwargs = {"score_threshold": score_threshold, "small_object_mode": small_object_mode,
              "threads": threads, "refine_max_boxes": refine_max_boxes}
    if nms_iou is not None:
        kwargs["nms_iou"] = nms_iou
    return cls(path, **kwargs)
