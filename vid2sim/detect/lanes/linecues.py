"""Line evidence for camera self-calibration, measured in raw pixels of one frame.

Two kinds (the estimator, :mod:`vid2sim.calib`, undistorts and interprets them):

- **Road segments**: straight pieces leaning 15-75 deg from horizontal, found by Canny edges
  and probabilistic Hough lines (Matas et al., 2000) as in
  :mod:`vid2sim.detect.lanes.vanishing`: lane markings, kerbs and facades along the road.
  Their intersections are the road's vanishing point, which lies on the horizon (Hartley &
  Zisserman, Multiple View Geometry, 2nd ed., sec. 8.6).
- **Edge chains**: long runs of edge pixels whose gradient keeps one direction, straight up
  to the bow a lens's radial distortion gives them. A straight edge in the world is imaged
  as a straight line by a pinhole and as a curve through a distorting lens: the plumb-line
  method (Brown, "Close-range camera calibration", 1971; Devernay & Faugeras, "Straight
  lines have to be straight", MVA 2001). Edge pixels are grouped by connected components
  within overlapping 45 deg windows of the signed gradient direction, which splits the two
  edges of a painted line (opposite gradients) and breaks chains at corners.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from vid2sim.core.calibration import FrameLines


@dataclass(frozen=True, slots=True)
class LineCueConfig:
    """Settings of the line evidence.

    :param segment_max_width_px: frames are downscaled to at most this width for the Hough
        segments (as the lane vanishing point does)
    :param segment_top_frac: segments are sought below this fraction of the height (the
        sky and tree tops give no road lines)
    :param steep_deg: a road segment leans between these angles from horizontal
    :param chain_max_width_px: frames are downscaled to at most this width for edge chains
        (a lens's bow over a long edge is several pixels at 960 px)
    :param chain_min_length_frac: a chain spans at least this fraction of the image diagonal
        (the bow grows with the square of the length; short chains carry noise only)
    :param chain_max_thickness: largest ratio of a chain's spread across to along it
    :param chain_max_rms_px: largest RMS [px] of a chain about its best quadratic (a lens's
        bow is near-quadratic over a chain; texture and corners are not)
    :param chain_points: a chain is reduced to at most this many mean positions along it
    :param canny_low, canny_high: Canny hysteresis thresholds (grey levels)
    """

    segment_max_width_px: int = 640
    segment_top_frac: float = 0.25
    steep_deg: tuple[float, float] = (15.0, 75.0)
    chain_max_width_px: int = 960
    chain_min_length_frac: float = 0.08
    chain_max_thickness: float = 0.05
    chain_max_rms_px: float = 0.7
    chain_points: int = 40
    canny_low: int = 40
    canny_high: int = 120


def road_segments(image_bgr: np.ndarray, config: LineCueConfig | None = None) -> np.ndarray:
    """(M, 5) steep straight segments (x1, y1, x2, y2, length) [full-resolution px]."""
    cfg = config or LineCueConfig()
    grey = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY) if image_bgr.ndim == 3 else image_bgr
    scale = min(1.0, cfg.segment_max_width_px / grey.shape[1])
    if scale < 1.0:
        grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    hs, ws = grey.shape
    top = int(cfg.segment_top_frac * hs)
    edges = cv2.Canny(cv2.GaussianBlur(grey[top:], (5, 5), 0), 60, 160)
    segs = cv2.HoughLinesP(edges, 1, math.pi / 180, threshold=25,
                           minLineLength=max(10, int(0.04 * ws)), maxLineGap=8)
    if segs is None:
        return np.zeros((0, 5))
    s = segs.reshape(-1, 4).astype(float)
    s[:, [1, 3]] += top
    dx, dy = s[:, 2] - s[:, 0], s[:, 3] - s[:, 1]
    ang = np.abs(np.degrees(np.arctan2(dy, dx)))
    ang = np.where(ang > 90, 180 - ang, ang)
    lo, hi = cfg.steep_deg
    keep = (ang > lo) & (ang < hi)
    s = (s[keep] + 0.5) / scale - 0.5
    length = np.hypot(s[:, 2] - s[:, 0], s[:, 3] - s[:, 1])
    return np.column_stack((s, length))


def edge_chains(image_bgr: np.ndarray, config: LineCueConfig | None = None
                ) -> tuple[np.ndarray, ...]:
    """Long, nearly straight edge chains [full-resolution px], longest first."""
    cfg = config or LineCueConfig()
    grey = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2GRAY) if image_bgr.ndim == 3 else image_bgr
    scale = min(1.0, cfg.chain_max_width_px / grey.shape[1])
    if scale < 1.0:
        grey = cv2.resize(grey, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    smooth = cv2.GaussianBlur(grey, (5, 5), 1.0)
    gx = cv2.Sobel(smooth, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(smooth, cv2.CV_32F, 0, 1, ksize=3)
    edges = cv2.Canny(smooth, cfg.canny_low, cfg.canny_high) > 0
    direction = (np.degrees(np.arctan2(gy, gx)) + 360.0) % 360.0
    h, w = grey.shape
    min_len = cfg.chain_min_length_frac * math.hypot(w, h)
    candidates = _direction_components(edges, direction, min_len)
    used = np.zeros(edges.shape, dtype=bool)
    chains = []
    for pts in sorted(candidates, key=len, reverse=True):
        xi, yi = pts[:, 0].astype(int), pts[:, 1].astype(int)
        if used[yi, xi].mean() > 0.3:  # the same pixels seen in the neighbouring window
            continue
        chain = _straight_chain(pts, cfg)
        if chain is None:
            continue
        used[yi, xi] = True
        chains.append((chain + 0.5) / scale - 0.5)
    return tuple(chains)


def _direction_components(edges: np.ndarray, direction: np.ndarray, min_len: float
                          ) -> list[np.ndarray]:
    """Connected edge pixels within each 45 deg window of gradient direction (16 windows
    at 22.5 deg steps), as (K, 2) pixel arrays, those spanning at least ``min_len``."""
    out = []
    ys_all, xs_all = np.nonzero(edges)
    dir_all = direction[ys_all, xs_all]
    for b in range(16):
        inside = ((dir_all - 22.5 * b) % 360.0) < 45.0
        mask = np.zeros(edges.shape, np.uint8)
        mask[ys_all[inside], xs_all[inside]] = 1
        _, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        big = np.flatnonzero((stats[:, cv2.CC_STAT_AREA] >= 0.8 * min_len)
                             & (np.hypot(stats[:, 2], stats[:, 3]) >= min_len))
        big = big[big > 0]
        if big.size == 0:
            continue
        ys, xs = ys_all[inside], xs_all[inside]
        lab = labels[ys, xs]
        keep = np.isin(lab, big)
        ys, xs, lab = ys[keep], xs[keep], lab[keep]
        order = np.argsort(lab, kind="stable")
        ys, xs, lab = ys[order], xs[order], lab[order]
        cuts = np.flatnonzero(np.diff(lab)) + 1
        for yy, xx in zip(np.split(ys, cuts), np.split(xs, cuts), strict=True):
            out.append(np.column_stack((xx, yy)).astype(float))
    return out


def _straight_chain(pts: np.ndarray, cfg: LineCueConfig) -> np.ndarray | None:
    """A component reduced to mean positions along it, if it is a thin, near-quadratic
    curve; else None."""
    mean = pts.mean(axis=0)
    _, sv, vt = np.linalg.svd(pts - mean, full_matrices=False)
    if sv[0] <= 0 or sv[1] / sv[0] > cfg.chain_max_thickness:
        return None
    along, across = (pts - mean) @ vt[0], (pts - mean) @ vt[1]
    design = np.column_stack((np.ones_like(along), along, along * along))
    coef = np.linalg.lstsq(design, across, rcond=None)[0]
    if math.sqrt(float(np.mean((across - design @ coef) ** 2))) > cfg.chain_max_rms_px:
        return None
    n_bins = min(cfg.chain_points, max(8, len(pts) // 6))
    bins = np.minimum(((along - along.min()) / (np.ptp(along) + 1e-9) * n_bins).astype(int),
                      n_bins - 1)
    counts = np.bincount(bins, minlength=n_bins)
    sums = np.stack([np.bincount(bins, weights=pts[:, j], minlength=n_bins) for j in (0, 1)],
                    axis=1)
    good = counts >= 2
    return sums[good] / counts[good, None] if good.sum() >= 6 else None


def frame_lines(image_bgr: np.ndarray, frame: int, t_s: float, with_chains: bool,
                config: LineCueConfig | None = None) -> FrameLines:
    """The line evidence of one frame (edge chains only where ``with_chains``: they cost
    about 0.1 s a frame, and a dozen frames fix a lens)."""
    chains = edge_chains(image_bgr, config) if with_chains else ()
    return FrameLines(frame=int(frame), t_s=float(t_s), segments=road_segments(image_bgr, config),
                      chains=chains)
