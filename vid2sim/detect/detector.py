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
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol, runtime_checkable

import cv2
import numpy as np

from vid2sim.detect import models
from vid2sim.errors import InputError
from vid2sim.records import Detection

CENTRE_MIN_SCORE = 0.5
"""Lowest score kept from the centre window (see :func:`tile_windows`), the tracker's score to
start a track: a car 30-45 m ahead scores about 0.65 there against 0.37 in the full frame, a
road shadow or a fragment of a partly hidden car 0.3-0.47."""

COCO_VEHICLES: dict[int, str] = {2: "car", 3: "motorcycle", 5: "bus", 7: "truck"}
"""COCO class id (0-based) -> vehicle category; train (6) is left out on purpose (trams)."""

DEFAULT_DETECTOR = models.DEFAULT_DETECTOR
CROSS_CLASS_IOU = 0.7
"""IoU above which boxes of different vehicle classes are taken for one vehicle."""


@runtime_checkable
class Detector(Protocol):
    """Anything that finds vehicles in one BGR image."""

    def detect(self, image_bgr: np.ndarray) -> list[Detection]:
        """Vehicles in ``image_bgr`` (HxWx3 uint8), boxes in that image's pixels."""
        ...


# --------------------------------------------------------------------------- geometry


def letterbox(image_bgr: np.ndarray, size_px: tuple[int, int] = (416, 416),
              fill: int = 114) -> tuple[np.ndarray, float]:
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


def tile_windows(width_px: int, height_px: int, overlap: float = 0.1, centre: bool = True
                 ) -> list[tuple[int, int, int, int]]:
    """Windows (x1, y1, x2, y2) [px] the detector runs on: the full frame, plus for a frame
    wider than 4:3 a left and a right tile: the two halves, each widened by ``overlap``
    (fraction of the half width) into the other, and at least as wide as the frame is high,
    so a car up to ``overlap`` half-widths wide in the middle is whole in one tile."""
    windows = [(0, 0, width_px, height_px)]
    if width_px <= 1.34 * height_px:
        return windows
    tile_w = int(min(width_px, max(height_px, round(width_px / 2 * (1.0 + overlap)))))
    windows.append((0, 0, tile_w, height_px))
    windows.append((width_px - tile_w, 0, width_px, height_px))
    if centre:
        windows.append(centre_window(width_px, height_px))
    return windows


def centre_window(width_px: int, height_px: int) -> tuple[int, int, int, int]:
    """A square of a third of the width (at most the height) about the image centre, where a
    forward camera sees the road ahead: a lead 30-45 m away is seen at about the net's own
    scale."""
    side = int(min(height_px, round(width_px / 3)))
    cx1, cy1 = (width_px - side) // 2, (height_px - side) // 2
    return cx1, cy1, cx1 + side, cy1 + side


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


def suppress_fragments(boxes_px: np.ndarray, scores: np.ndarray, inside: float = 0.7,
                       min_height_ratio: float = 0.6) -> np.ndarray:
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


# --------------------------------------------------------------------------- decoders


def decode_yolox(output: np.ndarray, input_size_px: tuple[int, int] = (416, 416),
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
    in_w, in_h = input_size_px
    grids, scale = [], []
    for s in strides:
        gh, gw = in_h // s, in_w // s
        gy, gx = np.mgrid[0:gh, 0:gw]
        grids.append(np.column_stack([gx.ravel(), gy.ravel()]))
        scale.append(np.full(gh * gw, s, dtype=np.float32))
    grid = np.concatenate(grids).astype(np.float32)
    stride = np.concatenate(scale)[:, None]
    if len(grid) != len(pred):
        raise ValueError(f"YOLOX output has {len(pred)} rows, expected {len(grid)} "
                         f"for input {input_size_px}")
    centre = (pred[:, 0:2] + grid) * stride
    size = np.exp(np.clip(pred[:, 2:4], -10.0, 10.0)) * stride
    boxes = np.concatenate([centre - size / 2, centre + size / 2], axis=1)
    return boxes, pred[:, 4:5] * pred[:, 5:]


def decode_picodet(class_outputs: list[np.ndarray], box_outputs: list[np.ndarray],
                   input_size_px: tuple[int, int] = (416, 416),
                   strides: tuple[int, ...] = (8, 16, 32, 64), reg_max: int = 7,
                   top_k: int = 1000) -> tuple[np.ndarray, np.ndarray]:
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
    """

    decoder = ""
    input_size_px = (416, 416)

    def __init__(self, model_path: Path, *, score_threshold: float = 0.3,
                 nms_iou: float = 0.45, small_object_mode: bool = False, threads: int = 2):
        import onnxruntime as ort

        self.model_path = Path(model_path)
        self.score_threshold = float(score_threshold)
        self.nms_iou = float(nms_iou)
        self.small_object_mode = bool(small_object_mode)
        options = ort.SessionOptions()
        options.intra_op_num_threads = int(threads)
        options.inter_op_num_threads = 1
        # PicoDet exports list initializers as inputs; ORT warns about each one (harmless).
        options.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(str(self.model_path), sess_options=options,
                                                providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own Fail/InvalidGraph types
            raise InputError(self.model_path, f"onnxruntime cannot load the model: {exc}",
                             "is this an ONNX file of the chosen detector?") from exc
        self.input_name = self.session.get_inputs()[0].name
        shape = self.session.get_inputs()[0].shape
        if isinstance(shape[2], int) and isinstance(shape[3], int):
            self.input_size_px = (int(shape[3]), int(shape[2]))

    def _raw(self, image_bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Boxes (in ``image_bgr`` pixels) and class scores before thresholds and NMS."""
        raise NotImplementedError

    def _window(self, image_bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        boxes, class_scores = self._raw(image_bgr)
        boxes, scores, ids = vehicle_candidates(boxes, class_scores, self.score_threshold)
        h, w = image_bgr.shape[:2]
        boxes = np.clip(boxes, 0, [w, h, w, h])
        keep = nms(boxes, scores, self.nms_iou, ids)
        boxes, scores, ids = boxes[keep], scores[keep], ids[keep]
        # Class-aware NMS leaves a car and a truck box on one vehicle (near-identical boxes,
        # the net unsure of the class): one vehicle must give one box.
        keep = nms(boxes, scores, CROSS_CLASS_IOU)
        return boxes[keep], scores[keep], ids[keep]

    def detect(self, image_bgr: np.ndarray) -> list[Detection]:
        """Vehicles in one BGR image, boxes in its pixels, best score first."""
        h, w = image_bgr.shape[:2]
        windows = tile_windows(w, h) if self.small_object_mode else [(0, 0, w, h)]
        centre = centre_window(w, h)
        parts_b, parts_s, parts_c = [], [], []
        for x1, y1, x2, y2 in windows:
            boxes, scores, ids = self._window(image_bgr[y1:y2, x1:x2])
            boxes = boxes + [x1, y1, x1, y1]
            if len(windows) > 1 and (x1, y1, x2, y2) == centre:
                # The centre window sees far cars at the net's scale, and with them more of
                # what only looks like one (shadows, fragments): only its confident boxes.
                keep = scores >= CENTRE_MIN_SCORE
                boxes, scores, ids = boxes[keep], scores[keep], ids[keep]
            if (x2 - x1, y2 - y1) != (w, h):
                # A car cut by a tile's inner edge gets a truncated box there; the full frame
                # or the neighbouring tile sees it whole, so the cut box is dropped.
                margin = 2.0
                cut = np.zeros(len(boxes), dtype=bool)
                if x1 > 0:
                    cut |= boxes[:, 0] <= x1 + margin
                if x2 < w:
                    cut |= boxes[:, 2] >= x2 - margin
                if y1 > 0:
                    cut |= boxes[:, 1] <= y1 + margin
                if y2 < h:
                    cut |= boxes[:, 3] >= y2 - margin
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
        return [Detection(box_px=tuple(float(v) for v in boxes[i]), score=float(scores[i]),
                          category=COCO_VEHICLES[int(ids[i])]) for i in order]


class YoloxDetector(OnnxDetector):
    """YOLOX exported with the decode head off (raw tx, ty, tw, th; sigmoid scores)."""

    decoder = "yolox"

    def _raw(self, image_bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        canvas, r = letterbox(image_bgr, self.input_size_px)
        blob = canvas.transpose(2, 0, 1)[None].astype(np.float32)  # BGR, 0-255, no norm
        (output,) = self.session.run(None, {self.input_name: blob})
        boxes, class_scores = decode_yolox(output, self.input_size_px)
        return boxes / r, class_scores


class PicodetDetector(OnnxDetector):
    """PP-PicoDet exported without NMS (4 score and 4 distance tensors)."""

    decoder = "picodet"
    MEAN_RGB = np.array([0.485, 0.456, 0.406], dtype=np.float32)
    STD_RGB = np.array([0.229, 0.224, 0.225], dtype=np.float32)

    def __init__(self, model_path: Path, *, score_threshold: float = 0.3,
                 nms_iou: float = 0.6, small_object_mode: bool = False, threads: int = 2):
        super().__init__(model_path, score_threshold=score_threshold, nms_iou=nms_iou,
                         small_object_mode=small_object_mode, threads=threads)

    def _raw(self, image_bgr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h, w = image_bgr.shape[:2]
        in_w, in_h = self.input_size_px
        resized = cv2.resize(image_bgr, (in_w, in_h), interpolation=cv2.INTER_LINEAR)
        rgb = resized[:, :, ::-1].astype(np.float32) / 255.0
        blob = ((rgb - self.MEAN_RGB) / self.STD_RGB).transpose(2, 0, 1)[None]
        outputs = self.session.run(None, {self.input_name: np.ascontiguousarray(blob)})
        n = len(outputs) // 2
        boxes, class_scores = decode_picodet(outputs[:n], outputs[n:], self.input_size_px)
        return boxes * [w / in_w, h / in_h, w / in_w, h / in_h], class_scores


DETECTOR_CLASSES: dict[str, type[OnnxDetector]] = {"yolox": YoloxDetector,
                                                   "picodet": PicodetDetector}


def load_detector(name_or_path: str | Path = DEFAULT_DETECTOR, model_dir: Path | None = None,
                  *, score_threshold: float = 0.3, nms_iou: float | None = None,
                  small_object_mode: bool = True, threads: int = 2,
                  decoder: str | None = None) -> OnnxDetector:
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
    """
    path = models.resolve_model(name_or_path, model_dir)
    spec = models.MODELS.get(str(name_or_path)) or models.spec_for_path(path)
    kind = decoder or (spec.decoder if spec else None)
    if kind is None:
        import onnxruntime as ort

        options = ort.SessionOptions()
        options.log_severity_level = 3
        try:
            n_out = len(ort.InferenceSession(str(path), sess_options=options,
                                             providers=["CPUExecutionProvider"]).get_outputs())
        except Exception as exc:  # onnxruntime raises its own Fail/InvalidGraph types
            raise InputError(path, f"onnxruntime cannot load the model: {exc}",
                             "is this an ONNX file of a YOLOX or PicoDet export?") from exc
        # YOLOX exports one decoded-head tensor; PicoDet 4 score + 4 distance tensors
        kind = "yolox" if n_out == 1 else "picodet"
    if kind not in DETECTOR_CLASSES:
        raise InputError(path, f"unknown decoder '{kind}'", "use yolox or picodet")
    cls = DETECTOR_CLASSES[kind]
    kwargs = {"score_threshold": score_threshold, "small_object_mode": small_object_mode,
              "threads": threads}
    if nms_iou is not None:
        kwargs["nms_iou"] = nms_iou
    return cls(path, **kwargs)
