"""Boxes carried from frame to frame by sparse optical flow (between detector keyframes).

Median flow (Kalal, Mikolajczyk & Matas, "Forward-Backward Error", ICPR 2010): corners are
picked inside each box (Shi-Tomasi, ``cv2.goodFeaturesToTrack``), followed into the next frame
by pyramidal Lucas-Kanade (``cv2.calcOpticalFlowPyrLK``) and back again; points whose
round trip misses their start by more than ``max_fb_error_px`` are dropped. The box moves by
the median displacement and scales by the median ratio of point-pair distances, so a car
approached by the ego grows as its texture spreads. All boxes' points go through one
OpenCV call each way, on a grey image downscaled to at most ``max_width_px``.

A box whose points are too few, or disagree (the scale's spread), is reported as not
carried: the tracker then only predicts it, and the detection schedule asks for a keyframe.
"""

from __future__ import annotations

import functools
import threading
from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True, slots=True)
class FlowConfig:
    """Median-flow settings.

    :param max_width_px: frames are downscaled to at most this width before the flow [px]
        (on KITTI raw 0001, 1242 px wide, boxes of the next frame's detections carried: 236
        of 361 at 640 px, 326 at 960, 330 at full width; median IoU with the next detection
        0.89 in each case)
    :param max_points: corners picked per box (20-30 in the median-flow paper)
    :param min_points: a box with fewer surviving points is not carried (4: the median of
        the pair ratios needs a few pairs)
    :param corner_quality: Shi-Tomasi quality level relative to the box's best corner
        (0.001, below OpenCV's example 0.01: small boxes on grey, compressed video have
        weak corners, and the forward-backward check removes the bad ones)
    :param inner_margin: corners are picked in the box shrunk by this fraction per side,
        away from the background at its edges
    :param window_px: Lucas-Kanade window side [px, downscaled image] (OpenCV's default 21
        is coarse for a 12 px far car)
    :param levels: pyramid levels (0-based maximum level): 3 follows motion up to about
        8 x window/2 px per frame (a parked car passed at 10 m/s moves 50-100 px a frame)
    :param max_fb_error_px: forward-backward round-trip error above which a point is dropped
        [px, downscaled image] (median flow uses the median; a fixed pixel bound is simpler)
    :param max_scale_spread: a box is not carried when the interquartile range of its point
        pairs' scale ratios exceeds this (points on two objects, or on a moving background;
        0.06 refused half of KITTI's boxes, 0.15 a third as many)
    :param min_box_px: boxes smaller than this on either side [px, downscaled image] are not
        carried (too few pixels for corners)
    """

    max_width_px: int = 960
    max_points: int = 24
    min_points: int = 4
    corner_quality: float = 0.001
    inner_margin: float = 0.1
    window_px: int = 15
    levels: int = 3
    max_fb_error_px: float = 2.0
    max_scale_spread: float = 0.15
    min_box_px: float = 4.0


class MedianFlow:
    """Carries boxes from the previous frame to the current one.

    Call :meth:`carry` once per frame with the boxes (frame pixels) to carry from the frame
    given to the previous call; every call also keeps the current frame for the next one.
    """

    def __init__(self, config: FlowConfig | None = None):
        self.config = config or FlowConfig()
        self._prev: np.ndarray | None = None
        self._scale = 1.0
        self._ready: dict[int, np.ndarray] = {}  # frame index -> grey image, from prepare()
        self._ready_lock = threading.Lock()  # prepare() may run in another thread

    def reset(self) -> None:
        """Forget the previous frame (e.g. after a frame was not decoded)."""
        self._prev = None

    def _grey(self, image_bgr: np.ndarray) -> np.ndarray:
        """The frame as the flow sees it: grey, downscaled to ``max_width_px`` at most."""
        scale = min(1.0, self.config.max_width_px / image_bgr.shape[1])
        grey = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY) if image_bgr.ndim == 3 else image_bgr
        if scale < 1.0:
            grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        return grey

    def prepare(self, index: int, image_bgr: np.ndarray) -> None:
        """Make frame ``index``'s grey image ahead of its :meth:`carry`, e.g. in the decoding
        thread: the conversion and the area resize (2.5-3 ms a 720p frame) then overlap the
        detector and the tracker (OpenCV releases the GIL). Frames are taken in order; a
        frame never carried is dropped when a later one is."""
        grey = self._grey(image_bgr)
        with self._ready_lock:
            self._ready[index] = grey

    def carry(self, image_bgr: np.ndarray, boxes_px: np.ndarray, index: int | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
        """Boxes of the previous frame moved into ``image_bgr``.

        Parameters
        ----------
        image_bgr : ndarray (H, W, 3)
            The current frame.
        boxes_px : ndarray (n, 4)
            Boxes (x1, y1, x2, y2) in the previous frame [px].
        index : int, optional
            The frame's index, if its grey image may have been made by :meth:`prepare`.

        Returns
        -------
        boxes : ndarray (n, 4)
            The carried boxes [px] (rows of not carried boxes are unchanged).
        ok : ndarray (n,) of bool
            Which boxes were carried.
        """
        grey = self._take_prepared(index) if index is not None else None
        if grey is None:
            grey = self._grey(image_bgr)
        self._scale = min(1.0, self.config.max_width_px / image_bgr.shape[1])
        prev, self._prev = self._prev, grey
        boxes = np.asarray(boxes_px, dtype=float).reshape(-1, 4)
        ok = np.zeros(len(boxes), dtype=bool)
        if prev is None or prev.shape != grey.shape or len(boxes) == 0:
            return boxes.copy(), ok
        s = self._scale
        small = boxes * s
        p0, who = self._corners(prev, small)
        if p0 is None:
            return boxes.copy(), ok
        cfg = self.config
        lk = {"winSize": (cfg.window_px, cfg.window_px), "maxLevel": cfg.levels}
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(prev, grey, p0, None, **lk)
        p0b, st2, _ = cv2.calcOpticalFlowPyrLK(grey, prev, p1, None, **lk)
        good = ((st1.ravel() == 1) & (st2.ravel() == 1)
                & (np.linalg.norm(p0b - p0, axis=1) <= cfg.max_fb_error_px))
        out = boxes.copy()
        for i in np.unique(who):
            sel = good & (who == i)
            moved = self._moved_box(p0[sel], p1[sel], small[i])
            if moved is not None:
                out[i] = moved / s
                ok[i] = True
        return out, ok

    def _take_prepared(self, index: int) -> np.ndarray | None:
        """Frame ``index``'s grey image from :meth:`prepare`, if made; older ones dropped."""
        with self._ready_lock:
            for old in [k for k in self._ready if k < index]:
                del self._ready[old]
            return self._ready.pop(index, None)

    def _corners(self, prev: np.ndarray, small: np.ndarray
                 ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Shi-Tomasi corners inside each box (downscaled px) of the previous frame, and the
        box each belongs to; None when no box has enough."""
        cfg = self.config
        points, owner = [], []
        h_img, w_img = prev.shape
        for i, (x1, y1, x2, y2) in enumerate(small):
            bw, bh = x2 - x1, y2 - y1
            if bw < cfg.min_box_px or bh < cfg.min_box_px:
                continue
            mx, my = cfg.inner_margin * bw, cfg.inner_margin * bh
            c1, r1 = int(max(0, x1 + mx)), int(max(0, y1 + my))
            c2, r2 = int(min(w_img, x2 - mx)), int(min(h_img, y2 - my))
            if c2 - c1 < 3 or r2 - r1 < 3:
                continue
            corners = cv2.goodFeaturesToTrack(
                prev[r1:r2, c1:c2], cfg.max_points, cfg.corner_quality,
                max(1.0, min(c2 - c1, r2 - r1) / 8.0))
            if corners is None or len(corners) < cfg.min_points:
                continue
            pts = corners.reshape(-1, 2) + [c1, r1]
            points.append(pts)
            owner.append(np.full(len(pts), i))
        if not points:
            return None, None
        return np.concatenate(points).astype(np.float32), np.concatenate(owner)

    def _moved_box(self, before: np.ndarray, after: np.ndarray, box: np.ndarray
                   ) -> np.ndarray | None:
        """The box (downscaled px) moved by its points' median shift and scaled by the median
        ratio of their pair distances; None when too few points survive or they disagree."""
        cfg = self.config
        if len(before) < cfg.min_points:
            return None
        a, b = before.astype(float), after.astype(float)
        shift = np.median(b - a, axis=0)
        ia, ib = _pairs(len(a))
        d0 = np.linalg.norm(a[ia] - a[ib], axis=1)
        d1 = np.linalg.norm(b[ia] - b[ib], axis=1)
        keep = d0 > 1.0  # pairs closer than a pixel give no scale
        if keep.sum() < cfg.min_points:
            return None
        ratios = d1[keep] / d0[keep]
        q1, scale, q3 = np.percentile(ratios, [25, 50, 75])
        if q3 - q1 > cfg.max_scale_spread:
            return None
        x1, y1, x2, y2 = box
        cx, cy = (x1 + x2) / 2 + shift[0], (y1 + y2) / 2 + shift[1]
        hw, hh = scale * (x2 - x1) / 2, scale * (y2 - y1) / 2
        return np.array([cx - hw, cy - hh, cx + hw, cy + hh])


@functools.lru_cache(maxsize=64)
def _pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Index arrays of every pair of ``n`` points (``np.triu_indices(n, k=1)``), kept: the
    same few point counts recur frame after frame."""
    return np.triu_indices(n, k=1)
