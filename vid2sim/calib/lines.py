"""Line cues: the road's vanishing point from lane segments, and the plumb-line residuals.

Both are evaluated on undistorted coordinates, so they follow the current lens estimate:

- **Vanishing point.** Segments leaning left and right (lane markings and road edges on
  either side) are undistorted at their end points, and every left-right pair is
  intersected; the length-weighted median of a frame's intersections is its vanishing point,
  and the median over frames the road's (robust to curves and crossings). Straight ahead
  of the vehicle lies there: its row is the horizon (pitch), its column the mount's yaw.
- **Plumb lines.** A straight edge in the world is straight in the undistorted image: each
  chain's points are undistorted, a total-least-squares line fitted, and the distances to
  it, converted back to raw pixels by the lens's local magnification (so that shrinking the
  image cannot make lines straighter), are the residuals.
"""

from __future__ import annotations

import math

import numpy as np

from vid2sim.base.defaults import MAD_TO_SIGMA
from vid2sim.calib import cameramodel as geo
from vid2sim.core.calibration import FrameLines


def frame_vanishing_point(segments: np.ndarray, f: float, c: np.ndarray, k1: float,
                          k2: float) -> np.ndarray | None:
    """The vanishing point of one frame's road segments in undistorted pixels, or None.

    ``segments`` (M, 5): x1, y1, x2, y2, length [raw px]."""
    if len(segments) < 2:
        return None
    ends = np.concatenate((segments[:, :2], segments[:, 2:4]))
    und = geo.pixels_to_normalised(ends, f, c, k1, k2) * f + c
    a, b = und[:len(segments)], und[len(segments):]
    slope = (b[:, 1] - a[:, 1]) * (b[:, 0] - a[:, 0])
    left, right = slope < 0, slope > 0  # rising to the right: a line on the left
    if not left.any() or not right.any():
        return None
    hom = lambda p: np.column_stack((p, np.ones(len(p))))
    lines = np.cross(hom(a), hom(b))
    x = np.cross(lines[left][:, None, :], lines[right][None, :, :]).reshape(-1, 3)
    w = (segments[left, 4][:, None] * segments[right, 4][None, :]).reshape(-1)
    good = np.abs(x[:, 2]) > 1e-9
    if good.sum() < 2:
        return None
    pts, w = x[good, :2] / x[good, 2:3], w[good]
    near = np.all(np.abs(pts - c) < 2.0 * f, axis=1)  # within ~63 deg of the axis
    if near.sum() < 2:
        return None
    return np.array([_weighted_median(pts[near, 0], w[near]),
                     _weighted_median(pts[near, 1], w[near])])


def road_vanishing_point(lines: list[FrameLines], f: float, c: np.ndarray, k1: float,
                         k2: float, floor_px: float) -> tuple[np.ndarray, np.ndarray, int]:
    """Median vanishing point over frames [undistorted px], its one-sigma per axis (robust
    scatter over the frames / sqrt(n), plus ``floor_px``), and the number of frames."""
    vps = [vp for fl in lines if (vp := frame_vanishing_point(fl.segments, f, c, k1, k2))
           is not None]
    if not vps:
        return np.full(2, np.nan), np.full(2, np.inf), 0
    v = np.array(vps)
    med = np.median(v, axis=0)
    mad = MAD_TO_SIGMA * np.median(np.abs(v - med), axis=0)
    # frames far from the others looked at a bend or a crossing: drop them once
    keep = np.all(np.abs(v - med) <= 3.0 * np.maximum(mad, floor_px), axis=1)
    if keep.sum() >= 2:
        v = v[keep]
        med = np.median(v, axis=0)
        mad = MAD_TO_SIGMA * np.median(np.abs(v - med), axis=0)
    n = len(v)
    spread = np.maximum(mad, floor_px) if n > 2 else np.full(2, 10.0 * floor_px)
    return med, spread / math.sqrt(n) + floor_px, n


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    order = np.argsort(values)
    cw = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cw, cw[-1] / 2.0)])


# --------------------------------------------------------------------------- plumb lines


def pack_chains(lines: list[FrameLines], max_points: int) -> tuple[np.ndarray, np.ndarray]:
    """All frames' chains as one (n, K, 2) array padded with copies of the last point, and
    its (n, K) mask of real points."""
    chains = [ch[:max_points] for fl in lines for ch in fl.chains if len(ch) >= 6]
    if not chains:
        return np.zeros((0, max_points, 2)), np.zeros((0, max_points), bool)
    k = max(len(ch) for ch in chains)
    pts = np.zeros((len(chains), k, 2))
    mask = np.zeros((len(chains), k), bool)
    for i, ch in enumerate(chains):
        pts[i, :len(ch)] = ch
        pts[i, len(ch):] = ch[-1]
        mask[i, :len(ch)] = True
    return pts, mask


def plumb_residuals(pts: np.ndarray, mask: np.ndarray, f: float, c: np.ndarray, k1: float,
                    k2: float) -> np.ndarray:
    """(n, K) distances [raw px] of chain points from their chain's straight line in the
    undistorted image (0 at padding)."""
    if len(pts) == 0:
        return np.zeros((0, pts.shape[1] if pts.ndim == 3 else 0))
    n, k, _ = pts.shape
    xn = geo.pixels_to_normalised(pts.reshape(-1, 2), f, c, k1, k2).reshape(n, k, 2)
    w = mask.astype(float)
    cnt = w.sum(axis=1, keepdims=True)
    mean = (xn * w[..., None]).sum(axis=1, keepdims=True) / cnt[..., None]
    d = (xn - mean) * w[..., None]
    cov = np.einsum("nki,nkj->nij", d, d)
    _, vecs = np.linalg.eigh(cov)
    normal = vecs[:, :, 0]  # smallest eigenvalue: across the line
    dist = np.einsum("nki,ni->nk", xn - mean, normal)
    # Back to raw pixels: the smallest raw displacement that puts the point on the line is
    # e / |J^-1 n|, J the lens's Jacobian of x -> x (1 + k1 r^2 + k2 r^4), g I + a x x^T
    # (symmetric; its inverse by Sherman-Morrison).
    r2 = np.sum(xn * xn, axis=-1)
    g = 1.0 + k1 * r2 + k2 * r2 * r2
    a = 2.0 * (k1 + 2.0 * k2 * r2)
    xdotn = np.einsum("nki,ni->nk", xn, normal)
    jin = (normal[:, None, :] - (a * xdotn / (g + a * r2))[..., None] * xn) / g[..., None]
    return dist / np.linalg.norm(jin, axis=-1) * f * w


def non_radial_chains(pts: np.ndarray, mask: np.ndarray, towards: np.ndarray,
                      min_angle_deg: float) -> np.ndarray:
    """Mask of chains that do not point at ``towards`` (the road's vanishing point) within
    ``min_angle_deg``.

    A line through the centre of distortion is imaged straight by any radial lens, so a chain
    pointing at the vanishing point (near the image centre) says little about the lens; but
    such chains are lane markings, kerbs and facades along the road, which bend with it: on
    a curve they would read as distortion. (On KITTI raw 0001, which bends 8 deg in its
    first six seconds, keeping them put k1 at +0.1 to +0.4 on a pinhole.)"""
    if len(pts) == 0:
        return np.zeros(0, bool)
    first = np.array([p[m][0] for p, m in zip(pts, mask, strict=True)])
    last = np.array([p[m][-1] for p, m in zip(pts, mask, strict=True)])
    d, to = last - first, towards - 0.5 * (first + last)
    cos = np.abs(np.sum(d * to, axis=1)) / np.maximum(
        np.linalg.norm(d, axis=1) * np.linalg.norm(to, axis=1), 1e-9)
    return np.degrees(np.arccos(np.clip(cos, 0.0, 1.0))) > min_angle_deg


def chain_rms(pts: np.ndarray, mask: np.ndarray, f: float, c: np.ndarray, k1: float,
              k2: float) -> np.ndarray:
    """Each chain's RMS distance from its straight line [raw px] under the lens."""
    r = plumb_residuals(pts, mask, f, c, k1, k2)
    return np.sqrt((r ** 2).sum(axis=1) / np.maximum(mask.sum(axis=1), 1))
