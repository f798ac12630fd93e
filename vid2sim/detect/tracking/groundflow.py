"""Sparse optical flow of the lower image between two nearby frames: the road's motion.

For camera self-calibration (:mod:`vid2sim.calib`): the road below the horizon moves, for a
camera at height ``h`` and a forward speed ``v``, as ``dy/dt = (y - y0)^2 v / (f h)``
(row ``y``, horizon row ``y0``, focal length ``f``), so its flow measures ``f h``; a turn
adds ``f * yaw rate`` to every point alike. This module only measures pixels: corners
(Shi-Tomasi, ``cv2.goodFeaturesToTrack``) in the lower part of the LATER frame, followed back
into the earlier one by pyramidal Lucas-Kanade and forward again (Kalal et al., ICPR 2010:
forward-backward error). Tracking backwards keeps every point inside both images: a road
point near the bottom of the later frame was higher up in the earlier one, while forward
tracking would push the nearest road out of the picture. Which points lie on the road is
decided by the estimator with its camera model, not here.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from vid2sim.core.calibration import FlowPair


@dataclass(frozen=True, slots=True)
class GroundFlowConfig:
    """Settings of the lower-image flow.

    :param max_width_px: frames are downscaled to at most this width first (the flow of
        road texture 10-40 m ahead is 1-20 px a frame at 960 px; finer costs time)
    :param top_frac: corners are sought below this fraction of the image height (dash-cam
        horizons lie at 0.35-0.55 of the height; rows above the estimated horizon are
        dropped by the estimator)
    :param bottom_frac: and above this fraction (the lowest rows of many dash-cams see the
        bonnet)
    :param max_points: corners per pair (a few hundred fill the road triangle)
    :param grid: corners are picked in this many columns and rows of cells, each its share
        (the road's weak texture would otherwise lose to trees and car edges)
    :param min_corner_ratio: a corner's smaller structure-tensor eigenvalue is at least this
        share of the larger one (over ``corner_block_px``): points on a straight edge (a
        lane line, a kerb) are dropped, whose motion along the edge cannot be seen (on the
        rendered demo they were most points, and read the ego as standing still)
    :param quality: Shi-Tomasi quality relative to a cell's best corner (asphalt is weak
        texture beside lane markings; the forward-backward check removes bad tracks)
    :param min_distance_frac: corners at least this fraction of the width apart
    :param window_px: Lucas-Kanade window side [px, downscaled]
    :param levels: pyramid levels: 4 follows up to ~16 windows' motion (a road point 6 m
        ahead of a 10 fps camera at 14 m/s moves 40 px)
    :param max_fb_error_px: forward-backward round trip allowed [px, downscaled]
    :param homography_tolerance_px: inlier distance of the road's homography that guides
        the second tracking [px, downscaled]
    :param plane_tolerance_px, plane_tolerance_frac: a point whose first track lies within
        this distance (or share of its motion) of the homography's prediction moves with
        the road and is tracked again against the warped frame [px, downscaled]
    :param warped_levels: pyramid levels of the second tracking, against the warped frame
        (what is left to follow is a few pixels)
    """

    max_width_px: int = 960
    top_frac: float = 0.3
    bottom_frac: float = 0.97
    max_points: int = 400
    min_corner_ratio: float = 0.15
    corner_block_px: int = 7
    grid: tuple[int, int] = (8, 3)
    quality: float = 0.003
    min_distance_frac: float = 0.008
    window_px: int = 15
    levels: int = 4
    max_fb_error_px: float = 0.5
    homography_tolerance_px: float = 2.0
    warped_levels: int = 2
    plane_tolerance_px: float = 3.0
    plane_tolerance_frac: float = 0.25


def grey_small(image_bgr: np.ndarray, max_width_px: int) -> tuple[np.ndarray, float]:
    """The frame in grey, downscaled to at most ``max_width_px``; and the scale used."""
    grey = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY) if image_bgr.ndim == 3 else image_bgr
    scale = min(1.0, max_width_px / grey.shape[1])
    if scale < 1.0:
        grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return grey, scale


def lower_image_flow(image_a: np.ndarray, image_b: np.ndarray, frame_a: int, frame_b: int,
                     t_a_s: float, t_b_s: float, config: GroundFlowConfig | None = None
                     ) -> FlowPair:
    """Points of the lower image tracked between frame a (earlier) and frame b (later).

    Corners are picked in b, tracked back to a, and kept when tracking a -> b returns within
    ``max_fb_error_px``. Pixels are full-resolution raw pixels.
    """
    cfg = config or GroundFlowConfig()
    ga, scale = grey_small(image_a, cfg.max_width_px)
    gb, _ = grey_small(image_b, cfg.max_width_px)
    h, w = gb.shape
    pb = _corners(gb, cfg)
    empty = np.zeros((0, 2))
    if len(pb) < 4:
        return FlowPair(frame_a, frame_b, t_a_s, t_b_s, empty, empty)
    lk = {"winSize": (cfg.window_px, cfg.window_px), "maxLevel": cfg.levels}
    pa, ok = _track(gb, ga, pb, None, lk, cfg.max_fb_error_px)
    if ok.sum() >= 8:
        pa, ok = _on_the_road_plane(ga, gb, pb, pa, ok, lk, cfg)
    pa, pb = pa.reshape(-1, 2)[ok], pb.reshape(-1, 2)[ok]
    inside = ((pa[:, 0] >= 0) & (pa[:, 0] <= w - 1) & (pa[:, 1] >= 0) & (pa[:, 1] <= h - 1))
    return FlowPair(frame_a, frame_b, t_a_s, t_b_s, _full_pixels(pa[inside], scale),
                    _full_pixels(pb[inside], scale))


def _on_the_road_plane(ga: np.ndarray, gb: np.ndarray, pb: np.ndarray, pa: np.ndarray,
                       ok: np.ndarray, lk: dict, cfg: GroundFlowConfig
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Track again, against frame a warped onto frame b by the road's homography, the
    points that move as the road does.

    The road is a plane, so its motion between the frames is a homography (Hartley &
    Zisserman, sec. 13.1): the dominant one of the first tracks. Against the warped frame
    what remains of a road point's motion is a small shift without the growth that
    Lucas-Kanade (a translation model) cannot follow (the near road of a 10 fps camera at
    speed grows by a fifth, and its first tracks lag by several per cent). Points off the
    plane (facades, trees, cars) keep their first tracks: the warp means nothing for them.
    """
    hom, _ = cv2.findHomography(pb[ok], pa[ok], cv2.RANSAC, cfg.homography_tolerance_px)
    if hom is None or not np.all(np.isfinite(hom)) or abs(np.linalg.det(hom)) < 1e-6:
        return pa, ok
    h, w = gb.shape
    warped = cv2.warpPerspective(ga, hom, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                 borderMode=cv2.BORDER_REPLICATE)
    fine = {"winSize": lk["winSize"], "maxLevel": cfg.warped_levels}
    q, ok2 = _track(gb, warped, pb, None, fine, cfg.max_fb_error_px)
    on_plane = cv2.perspectiveTransform(pb.reshape(-1, 1, 2).astype(np.float64), hom)
    again = cv2.perspectiveTransform(q.reshape(-1, 1, 2).astype(np.float64), hom)
    motion = np.linalg.norm((on_plane - pb).reshape(-1, 2), axis=1)
    near = np.linalg.norm((on_plane - pa).reshape(-1, 2), axis=1) <= np.maximum(
        cfg.plane_tolerance_px, cfg.plane_tolerance_frac * motion)
    road = ok2 & (near | ~ok)  # on the plane by its first track, or lost without the warp
    out = np.where(road[:, None, None], again.astype(np.float32), pa)
    return out, np.where(road, True, ok)


def _corners(grey: np.ndarray, cfg: GroundFlowConfig) -> np.ndarray:
    """Corners of the lower image, picked cell by cell (a grid of ``grid`` columns and rows)
    so that the asphalt's weak texture gets its share beside trees and car edges."""
    h, w = grey.shape
    top, bottom = int(cfg.top_frac * h), int(cfg.bottom_frac * h)
    cols, rows = cfg.grid
    per_cell = max(1, cfg.max_points // (cols * rows))
    out = []
    for i in range(rows):
        r0 = top + (bottom - top) * i // rows
        r1 = top + (bottom - top) * (i + 1) // rows
        for j in range(cols):
            c0, c1 = w * j // cols, w * (j + 1) // cols
            found = cv2.goodFeaturesToTrack(grey[r0:r1, c0:c1], per_cell, cfg.quality,
                                            max(2.0, cfg.min_distance_frac * w))
            if found is not None:
                out.append(found.reshape(-1, 2) + (c0, r0))
    if not out:
        return np.zeros((0, 1, 2), np.float32)
    pts = np.concatenate(out)
    # Not on an edge: along a painted line or a kerb the motion cannot be seen (the
    # aperture problem) and Lucas-Kanade reports none; a corner's structure tensor has two
    # comparable eigenvalues, an edge's one.
    xi = np.clip(np.rint(pts[:, 0]).astype(int), 0, w - 1)
    yi = np.clip(np.rint(pts[:, 1]).astype(int), 0, h - 1)
    big, small = _tensor_eigenvalues(grey, xi, yi, cfg.corner_block_px)
    keep = small >= cfg.min_corner_ratio * np.maximum(big, 1e-12)
    return pts[keep].reshape(-1, 1, 2).astype(np.float32)


def _tensor_eigenvalues(grey: np.ndarray, xi: np.ndarray, yi: np.ndarray, block: int
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The larger and smaller eigenvalue of the structure tensor (3x3 Sobel gradients
    summed over a ``block`` square, borders reflected) at pixels (``xi``, ``yi``): what
    ``cv2.cornerEigenValsAndVecs`` gives there, up to a common scale, from a small patch
    about each point instead of every pixel's 2x2 eigenproblem (a third of the flow's
    time at 960 px)."""
    half = block // 2 + 1
    padded = cv2.copyMakeBorder(grey, half, half, half, half, cv2.BORDER_REFLECT_101)
    off = np.arange(-half, half + 1)
    patch = padded[(yi + half)[:, None, None] + off[None, :, None],
                   (xi + half)[:, None, None] + off[None, None, :]].astype(np.float64)
    dx = (patch[:, :-2, 2:] - patch[:, :-2, :-2]) + 2 * (patch[:, 1:-1, 2:] - patch[:, 1:-1, :-2]) \
        + (patch[:, 2:, 2:] - patch[:, 2:, :-2])
    dy = (patch[:, 2:, :-2] - patch[:, :-2, :-2]) + 2 * (patch[:, 2:, 1:-1] - patch[:, :-2, 1:-1]) \
        + (patch[:, 2:, 2:] - patch[:, :-2, 2:])
    a, b, c = ((m * n).sum(axis=(1, 2)) for m, n in ((dx, dx), (dx, dy), (dy, dy)))
    mean, root = 0.5 * (a + c), np.sqrt((0.5 * (a - c)) ** 2 + b * b)
    return mean + root, mean - root


def _track(grey_from: np.ndarray, grey_to: np.ndarray, pts: np.ndarray,
           guess: np.ndarray | None, lk: dict, max_fb_px: float
           ) -> tuple[np.ndarray, np.ndarray]:
    """Lucas-Kanade from ``grey_from`` to ``grey_to`` (from ``guess`` if given) and back;
    the tracked points and the mask of those whose round trip closes."""
    if guess is None:
        out, st1, _ = cv2.calcOpticalFlowPyrLK(grey_from, grey_to, pts, None, **lk)
    else:
        out, st1, _ = cv2.calcOpticalFlowPyrLK(grey_from, grey_to, pts, guess.copy(),
                                               flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)
    back, st2, _ = cv2.calcOpticalFlowPyrLK(grey_to, grey_from, out, pts.copy(),
                                            flags=cv2.OPTFLOW_USE_INITIAL_FLOW, **lk)
    ok = ((st1.ravel() == 1) & (st2.ravel() == 1)
          & (np.linalg.norm((back - pts).reshape(-1, 2), axis=1) <= max_fb_px))
    return out, ok


def _full_pixels(small_px: np.ndarray, scale: float) -> np.ndarray:
    """Downscaled pixel coordinates -> full-resolution ones (an area-averaged pixel i
    covers full pixels i / scale .. (i + 1) / scale)."""
    return (np.asarray(small_px, dtype=float) + 0.5) / scale - 0.5
