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

from pathlib import Path
from typing import Protocol, runtime_checkable

import cv2
import numpy as np

from vid2sim.base.errors import FormatError
from vid2sim.core.boxes import cut_by_window, iou_matrix, nms, suppress_fragments
from vid2sim.core.records import Detection
from vid2sim.detect.vehicles import models
from vid2sim.detect.vehicles._dynamic import dynamic_copy
from vid2sim.detect.vehicles.decode import (
    COCO_VEHICLES,
    NET_INPUT_PX,
    decode_picodet,
    decode_yolox,
    letterbox,
    vehicle_candidates,
)
from vid2sim.detect.vehicles.windows import (
    REFINE_CROP_SCALE,
    REFINE_MAX_BOXES,
    REFINE_MIN_IOU,
    REFINE_MIN_SIDE_PX,
    Look,
    full_look,
    refine_candidates,
    refine_crop,
)

CENTRE_MIN_SCORE = 0.5
"""Lowest score kept from the centre window (see :func:`tile_windows`), the tracker's score to
start a track: a car 30-45 m ahead scores about 0.65 there against 0.37 in the full frame, a
road shadow or a fragment of a partly hidden car 0.3-0.47."""


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


YOLOX_NMS_IOU = 0.45
"""Class-aware NMS IoU of YOLOX, as in the upstream demo (MODELS.md)."""

PICODET_NMS_IOU = 0.6
"""Class-aware NMS IoU of PicoDet, as in the upstream PaddleDetection deploy config
(MODELS.md)."""

SCORE_THRESHOLD = 0.3
"""Default lowest vehicle score kept by a detector built directly (MODELS.md: "score
threshold about 0.3"); the application layer passes the tracker's low score instead."""



FREE_SHAPE_STEP_PX = 32
"""Input sides of a free-shape run are multiples of this: the net's largest stride (YOLOX
downsamples by 32)."""

FREE_SHAPE_MARGIN_PX = 32
"""Grey margin kept below and beside the image in a free-shape run: the letterbox's fill is
context the net was trained with. On KITTI's six labelled frames (default settings): without
a margin recall 0.92 -> 0.88 and precision 0.85 -> 0.83 against the full 416x416 canvas;
with 32 px (or 64) the same counts as the full canvas (23/25 found, 7/48 false)."""



@runtime_checkable
class Detector(Protocol):
    """Anything that finds vehicles in one BGR image."""

    def detect(self, image_bgr: np.ndarray) -> list[Detection]:
        """Vehicles in ``image_bgr`` (HxWx3 uint8), boxes in that image's pixels."""
        ...


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

    def _prepare(self, image_bgr: np.ndarray, max_scale: float | None = None
                 ) -> tuple[np.ndarray, tuple[float, float]]:
        """Network input (3, H, W) float32 for one window, and the (x, y) scale from input
        to window pixels; ``max_scale`` caps the net pixels per window pixel where the net
        takes inputs smaller than its own (a crop seen at another window's scale)."""
        raise NotImplementedError

    def _decode(self, outputs: list[np.ndarray], input_size_px: tuple[int, int]
                ) -> tuple[np.ndarray, np.ndarray]:
        """Boxes on the network input [px] and class scores of one batch item."""
        raise NotImplementedError

    def _raw_many(self, images: list[np.ndarray], caps: list[float | None] | None = None
                  ) -> list[tuple[np.ndarray, np.ndarray]]:
        """:meth:`_raw` of several windows, inputs of one shape in one onnxruntime call."""
        caps = caps or [None] * len(images)
        prepared = [self._prepare(im) if cap is None else self._prepare(im, cap)
                    for im, cap in zip(images, caps, strict=True)]
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

    def _raw(self, image_bgr: np.ndarray, cap: float | None = None
             ) -> tuple[np.ndarray, np.ndarray]:
        """Boxes (in ``image_bgr`` pixels) and class scores before thresholds and NMS."""
        blob, (sx, sy) = (self._prepare(image_bgr) if cap is None
                          else self._prepare(image_bgr, cap))
        outputs = self.session.run(None, {self.input_name: blob[None]})
        self.n_calls = getattr(self, "n_calls", 0) + 1
        boxes, scores = self._decode(outputs, (blob.shape[2], blob.shape[1]))
        return boxes * [sx, sy, sx, sy], scores

    def _window(self, image_bgr: np.ndarray, cap: float | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Vehicle boxes (window px), scores and COCO ids of one window after NMS."""
        raw = self._raw(image_bgr) if cap is None else self._raw(image_bgr, cap)
        return self._postprocess(image_bgr.shape, *raw)

    def _windows(self, images: list[np.ndarray], caps: list[float | None] | None = None
                 ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """:meth:`_window` of several windows (batched when the weights allow); ``caps``
        as ``max_scale`` of :meth:`_prepare`, per window."""
        caps = caps or [None] * len(images)
        if not self.batch_windows or len(images) < 2:
            return [self._window(im) if cap is None else self._window(im, cap)
                    for im, cap in zip(images, caps, strict=True)]
        raws = self._raw_many(images) if not any(caps) else self._raw_many(images, caps)
        return [self._postprocess(im.shape, *raw)
                for im, raw in zip(images, raws, strict=True)]

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

    def full_look(self, width_px: int, height_px: int) -> Look:
        """Every window this detector runs on a frame of this size (:func:`full_look`)."""
        return full_look(width_px, height_px, tiles=self.small_object_mode)

    def detect(self, image_bgr: np.ndarray, look: Look | None = None) -> list[Detection]:
        """Vehicles in one BGR image, boxes in its pixels, best score first.

        ``look`` chooses the windows (:class:`~vid2sim.detect.vehicles.windows.Look`, e.g.
        cut to a band about the horizon); by default every window of :meth:`full_look`.
        """
        h, w = image_bgr.shape[:2]
        look = look or self.full_look(w, h)
        windows = list(look.windows)
        if not windows:
            return []
        crops = [image_bgr[y1:y2, x1:x2] for x1, y1, x2, y2 in windows]
        results = (self._windows(crops) if look.caps is None
                   else self._windows(crops, list(look.caps)))
        parts = [self._window_boxes(window, found, look.centre, w, h)
                 for window, found in zip(windows, results, strict=True)]
        boxes = np.concatenate([p[0] for p in parts])
        scores = np.concatenate([p[1] for p in parts])
        ids = np.concatenate([p[2] for p in parts])
        if len(windows) > 1:
            # The same car seen in two windows may be called car in one and truck in the
            # other: merge without regard to class.
            keep = nms(boxes, scores, self.nms_iou)
            boxes, scores, ids = boxes[keep], scores[keep], ids[keep]
        order = suppress_fragments(boxes, scores)
        boxes, scores, ids = boxes[order], scores[order], ids[order]
        if self.refine_max_boxes > 0 and look.refine:
            boxes = self.refine(image_bgr, boxes)
        return [Detection(box_px=tuple(float(v) for v in boxes[i]), score=float(scores[i]),
                          category=COCO_VEHICLES[int(ids[i])]) for i in range(len(boxes))]

    @staticmethod
    def _window_boxes(window: tuple[int, int, int, int],
                      found: tuple[np.ndarray, np.ndarray, np.ndarray],
                      centre: tuple[int, int, int, int] | None, width_px: int, height_px: int
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One window's boxes in frame pixels, with the centre window's weak boxes and the
        boxes a window's inner edge cut dropped."""
        x1, y1, x2, y2 = window
        boxes, scores, ids = found
        boxes = boxes + [x1, y1, x1, y1]
        if window == centre:
            # The centre window sees far cars at the net's scale, and with them more of
            # what only looks like one (shadows, fragments): only its confident boxes.
            keep = scores >= CENTRE_MIN_SCORE
            boxes, scores, ids = boxes[keep], scores[keep], ids[keep]
        if (x2 - x1, y2 - y1) != (width_px, height_px):
            # A car cut by a tile's inner edge gets a truncated box there; the full frame
            # or the neighbouring tile sees it whole, so the cut box is dropped.
            cut = cut_by_window(boxes, window, width_px, height_px)
            boxes, scores, ids = boxes[~cut], scores[~cut], ids[~cut]
        return boxes, scores, ids


class YoloxDetector(OnnxDetector):
    """YOLOX exported with the decode head off (raw tx, ty, tw, th; sigmoid scores)."""

    decoder = "yolox"

    def _expected_cells(self, width_px: int, height_px: int) -> int:
        return sum((width_px // s) * (height_px // s) for s in (8, 16, 32))

    def _prepare(self, image_bgr: np.ndarray, max_scale: float | None = None
                 ) -> tuple[np.ndarray, tuple[float, float]]:
        size = self.input_size_px
        if not self.free_shape:
            max_scale = None  # a fixed input: the window fills it
        if self.free_shape:
            # the letterbox canvas cut after the image, rounded up to the net's largest
            # stride: the same pixels at the same scale, without computing the padding (the
            # axis that sets the scale keeps its full side, so the scale is unchanged)
            w, h = self.input_size_px
            r = min(h / image_bgr.shape[0], w / image_bgr.shape[1], max_scale or np.inf)
            step = FREE_SHAPE_STEP_PX
            size = (min(w, step * -(-max(1, int(image_bgr.shape[1] * r)) // step)
                        + FREE_SHAPE_MARGIN_PX),
                    min(h, step * -(-max(1, int(image_bgr.shape[0] * r)) // step)
                        + FREE_SHAPE_MARGIN_PX))
        canvas, r = letterbox(image_bgr, size, max_scale=max_scale)
        blob = canvas.transpose(2, 0, 1).astype(np.float32)  # BGR, 0-255, no norm
        return blob, (1.0 / r, 1.0 / r)

    def _decode(self, outputs: list[np.ndarray], input_size_px: tuple[int, int]
                ) -> tuple[np.ndarray, np.ndarray]:
        return decode_yolox(outputs[0], input_size_px, min_objectness=self.score_threshold)


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

    def _prepare(self, image_bgr: np.ndarray, max_scale: float | None = None
                 ) -> tuple[np.ndarray, tuple[float, float]]:
        # the input is resized to the net's fixed size whatever ``max_scale``
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
