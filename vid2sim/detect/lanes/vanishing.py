"""Horizon row from the vanishing point of lane markings, collected while a video streams.

Lane markings and road edges are parallel on the road, so their images meet at the vanishing
point of the road direction, which lies on the horizon (the vanishing line of the road plane;
Hartley & Zisserman, Multiple View Geometry, 2nd ed., sec. 8.6). Per sampled frame: Canny
edges below the expected horizon, probabilistic Hough segments (Matas et al., 2000), keep the
steep ones leaning left and right, and take the length-weighted median of the intersections
of left- with right-leaning segments. Over the clip the median of those rows is robust to
frames where a curve, a crossing or a vehicle produced a wrong point.
"""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np

from vid2sim.core.camera import Camera


class HorizonEstimator:
    """Collects per-frame lane-marking vanishing points; cheap enough to run on every frame.

    Parameters
    ----------
    camera : Camera
        Gives the image size and the expected horizon (the search window is centred on it).
    every : int
        Look at every N-th frame given to :meth:`add_frame` (consecutive frames repeat).
    max_width_px : int
        Frames are downscaled to at most this width before edge detection.
    search_band_frac : float
        Vanishing points farther than this fraction of the image height from the expected
        horizon are discarded (a 90 deg lens at +-0.2 of the height is about +-10 deg pitch).
    """

    def __init__(self, camera: Camera, every: int = 5, max_width_px: int = 640,
                 search_band_frac: float = 0.2):
        self.camera = camera
        self.every = max(1, int(every))
        self.max_width_px = int(max_width_px)
        self.search_band_frac = float(search_band_frac)
        self._seen = 0
        self.rows_px: list[float] = []
        self.frames: list[int] = []  # frame index of each row (the call count without one)
        self.columns_px: list[float] = []

    def add_frame(self, image_bgr: np.ndarray | None, index: int | None = None) -> float | None:
        """Look at one frame (every N-th call does work); return its horizon row [px] if found.

        Frames of another size than the camera's are scaled to the camera's pixels. ``index``
        is the frame's index in the video, kept with its row (default: the count of calls).
        """
        if image_bgr is None:
            return None
        self._seen += 1
        index = self._seen - 1 if index is None else int(index)
        if (self._seen - 1) % self.every:
            return None
        found = self._vanishing_point(image_bgr)
        if found is None:
            return None
        u, v = found
        self.columns_px.append(u)
        self.rows_px.append(v)
        self.frames.append(index)
        return v

    def estimate(self) -> tuple[float | None, int]:
        """(median horizon row [px] over frames with a vanishing point, or None; n frames)."""
        if not self.rows_px:
            return None, 0
        return float(np.median(self.rows_px)), len(self.rows_px)

    def estimate_column(self) -> tuple[float | None, int]:
        """(median column [px] of the lane vanishing point, or None; n frames): where the
        road ahead points in the image, i.e. the camera's yaw against the driving direction
        (see :func:`yaw_for_vanishing_column`)."""
        if not self.columns_px:
            return None, 0
        return float(np.median(self.columns_px)), len(self.columns_px)

    # ----------------------------------------------------------------- one frame

    def _vanishing_point(self, image_bgr: np.ndarray) -> tuple[float, float] | None:
        w_img = image_bgr.shape[1]
        scale = min(1.0, self.max_width_px / w_img)
        small = cv2.resize(image_bgr, None, fx=scale, fy=scale,
                           interpolation=cv2.INTER_AREA) if scale < 1 else image_bgr
        gray = cv2.cvtColor(small, cv2.COLOR_BGR2GRAY) if small.ndim == 3 else small
        hs, ws = gray.shape
        # Expected horizon in this frame's pixels, and the band where the VP may lie.
        to_small = hs / self.camera.image_height
        h_exp = self.camera.horizon_y_px() * to_small
        band = self.search_band_frac * hs
        top = int(max(0, h_exp - band * 0.25))
        # Skip the bottom 5 %: a dash-cam often sees its own bonnet there.
        bottom = int(hs * 0.95)
        if bottom - top < 10:
            return None
        roi = cv2.GaussianBlur(gray[top:bottom], (5, 5), 0)
        edges = cv2.Canny(roi, 60, 160)
        segs = cv2.HoughLinesP(edges, 1, math.pi / 180, threshold=25,
                               minLineLength=max(10, int(0.04 * ws)), maxLineGap=8)
        if segs is None:
            return None
        s = segs.reshape(-1, 4).astype(float)
        s[:, [1, 3]] += top
        dx, dy = s[:, 2] - s[:, 0], s[:, 3] - s[:, 1]
        ang = np.degrees(np.arctan2(dy, dx))
        ang = np.where(ang > 90, ang - 180, np.where(ang < -90, ang + 180, ang))
        length = np.hypot(dx, dy)
        # Markings of the ego and next lanes appear 15-75 deg from horizontal; flatter lines
        # are stop lines, shadows and car edges, steeper ones poles and car sides.
        steep = (np.abs(ang) > 15) & (np.abs(ang) < 75)
        left = s[steep & (ang < 0)]  # rising to the right: a marking on the left
        right = s[steep & (ang > 0)]
        wl, wr = length[steep & (ang < 0)], length[steep & (ang > 0)]
        if len(left) == 0 or len(right) == 0:
            return None
        pts, wts = _intersections(left, right, wl, wr)
        if pts is None:
            return None
        ok = (np.abs(pts[:, 1] - h_exp) < band) & (pts[:, 0] > -0.25 * ws) & (
            pts[:, 0] < 1.25 * ws)
        # A marking must reach below the VP: its lower end is under the intersection.
        if ok.sum() < 2:
            return None
        u = _weighted_median(pts[ok, 0], wts[ok])
        v = _weighted_median(pts[ok, 1], wts[ok])
        return u / scale if scale < 1 else u, v / to_small


def _intersections(a: np.ndarray, b: np.ndarray, wa: np.ndarray, wb: np.ndarray
                   ) -> tuple[np.ndarray | None, np.ndarray]:
    """All intersections of segments ``a`` with segments ``b`` (as infinite lines), with the
    product of their lengths as weight; pairs at nearly the same angle are dropped."""
    pa = np.cross(np.column_stack((a[:, :2], np.ones(len(a)))),
                  np.column_stack((a[:, 2:], np.ones(len(a)))))
    pb = np.cross(np.column_stack((b[:, :2], np.ones(len(b)))),
                  np.column_stack((b[:, 2:], np.ones(len(b)))))
    x = np.cross(pa[:, None, :], pb[None, :, :]).reshape(-1, 3)
    w = (wa[:, None] * wb[None, :]).reshape(-1)
    good = np.abs(x[:, 2]) > 1e-9
    if not good.any():
        return None, w
    pts = x[good, :2] / x[good, 2:3]
    return pts, w[good]


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    order = np.argsort(values)
    cw = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cw, cw[-1] / 2.0)])


def yaw_for_vanishing_column(camera: Camera, column_px: float) -> float:
    """Camera yaw [deg, positive looks left] that puts the vanishing point of the vehicle's
    forward axis at image column ``column_px`` (pitch and roll kept).

    A dash-cam is rarely aimed exactly along the car: 1 deg of yaw shifts a vehicle 50 m
    ahead by 0.9 m sideways, enough to put it in the wrong lane. Over a clip the lane
    markings' vanishing point shows where straight ahead is.
    """
    def column(yaw_deg: float) -> float:
        cam = replace(camera, yaw_deg=yaw_deg)
        uv, ok = cam.project(np.array([[1e5, 0.0, camera.height_m]]))
        return float(uv[0, 0]) if ok[0] else float("nan")

    yaw = camera.yaw_deg - math.degrees(math.atan((column_px - camera.cx) / camera.fx))
    for _ in range(3):  # Newton: exact with distortion and pitch
        c0, c1 = column(yaw), column(yaw + 1e-3)
        if not (np.isfinite(c0) and np.isfinite(c1)) or c1 == c0:
            break
        yaw += (column_px - c0) * 1e-3 / (c1 - c0)
    return float(yaw)
