"""Geometry of lane markings on the ground plane: the pure functions behind
:mod:`vid2sim.detect.lanes.markings` (arrays in, arrays out; no state).

Ground coordinates are the vehicle frame's: x forward, y left [m]. A line on the road is
``y(x) = c0 + c1 x + c2 x^2 / 2 + c3 x^3 / 6`` (offset [m], heading [rad], curvature [1/m],
curvature rate [1/m^2]).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import cv2
import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.core.records import LaneBoundary, LaneObservation, MarkingKind

# --------------------------------------------------------------------------- the grid


@dataclass(frozen=True, slots=True)
class BevGrid:
    """The ground grid of the bird's-eye view: row i is ``x_m[i]``, column j is ``y_m[j]``
    (x far to near, y left to right as in the image)."""

    x_m: np.ndarray
    y_m: np.ndarray

    @classmethod
    def make(cls, half_width_m: float, near_m: float, far_m: float, lateral_step_m: float,
             longitudinal_step_m: float) -> BevGrid:
        """A grid over ``|y| <= half_width_m`` and ``near_m <= x <= far_m``."""
        n_y = round(2 * half_width_m / lateral_step_m) + 1
        y = half_width_m - lateral_step_m * np.arange(n_y)
        n_x = round((far_m - near_m) / longitudinal_step_m) + 1
        x = far_m - longitudinal_step_m * np.arange(n_x)
        return cls(x_m=x, y_m=y)

    def column_of(self, y_m: float | np.ndarray) -> np.ndarray:
        """Fractional column of lateral offsets [m]."""
        return (self.y_m[0] - np.asarray(y_m, float)) / (self.y_m[0] - self.y_m[1])


def ground_to_pixel_maps(camera: Camera, grid: BevGrid) -> tuple[np.ndarray, np.ndarray]:
    """Pixel coordinates (u, v) of every ground grid point, NaN where behind the camera.

    Returns
    -------
    (map_u, map_v) : two (len(x_m), len(y_m)) float32 arrays [px]
    """
    xx, yy = np.meshgrid(grid.x_m, grid.y_m, indexing="ij")
    pts = np.column_stack((xx.ravel(), yy.ravel(), np.zeros(xx.size)))
    uv, _ = camera.project(pts)
    return (uv[:, 0].reshape(xx.shape).astype(np.float32),
            uv[:, 1].reshape(xx.shape).astype(np.float32))


# --------------------------------------------------------------------------- pure maths


def ridge_response(bev: np.ndarray, side_px: int) -> np.ndarray:
    """Relative contrast of a bright stripe against the asphalt on both sides.

    ``min(c - s(y - d), c - s(y + d)) / max(s, 20)`` with ``c`` the 3x3 mean at the pixel and
    ``s`` the 5-wide side means ``d = side_px`` columns away; 0 near the border.
    """
    img = bev.astype(np.float32, copy=False)
    centre = cv2.blur(img, (3, 3))
    side = cv2.blur(img, (5, 3))
    out = np.zeros_like(img)
    k = int(side_px)
    if img.shape[1] <= 2 * k:
        return out
    left, right = side[:, :-2 * k], side[:, 2 * k:]
    c = centre[:, k:-k]
    contrast = np.minimum(c - left, c - right)
    out[:, k:-k] = contrast / np.maximum(np.maximum(left, right), 20.0)
    return out


def hough_lines(x_m: np.ndarray, y_m: np.ndarray, weight: np.ndarray, *, x_ref_m: float,
                max_heading_rad: float, heading_step_rad: float, half_width_m: float,
                offset_bin_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted Hough accumulator over straight ground lines ``y = a + b (x - x_ref)``.

    Returns
    -------
    acc : (n_heading, n_offset) votes
    headings_rad : (n_heading,) the ``b`` of each row
    offsets_m : (n_offset,) the ``a`` of each column (offset at ``x_ref_m``)
    """
    headings = np.arange(-max_heading_rad, max_heading_rad + 1e-9, heading_step_rad)
    n_off = round(2 * half_width_m / offset_bin_m) + 1
    offsets = -half_width_m + offset_bin_m * np.arange(n_off)
    if len(x_m) == 0:
        return np.zeros((len(headings), n_off)), headings, offsets
    a = y_m[None, :] - headings[:, None] * (x_m[None, :] - x_ref_m)
    col = np.rint((a + half_width_m) / offset_bin_m).astype(np.int64)
    ok = (col >= 0) & (col < n_off)
    flat = (np.arange(len(headings))[:, None] * n_off + col)[ok]
    w = np.broadcast_to(weight[None, :], a.shape)[ok]
    acc = np.bincount(flat, weights=w, minlength=len(headings) * n_off)
    return acc.reshape(len(headings), n_off), headings, offsets


def fit_line(x_m: np.ndarray, y_m: np.ndarray, weight: np.ndarray, *,
             curvature_prior_inv_m: float = 0.01, sigma_m: float = 0.05
             ) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares fit of ``y = c0 + c1 x + c2 x^2 / 2`` with a zero-mean prior of
    one-sigma ``curvature_prior_inv_m`` on ``c2`` (ridge regression, so a short straight piece
    does not invent a bend).

    Parameters
    ----------
    x_m, y_m : points on the ground [m]
    weight : relative weights (one point of weight 1 has one-sigma ``sigma_m``)

    Returns
    -------
    coef : (3,) c0 [m], c1 [rad], c2 [1/m]
    cov : (3, 3) covariance of ``coef`` for a point scatter of ``sigma_m``
    """
    coef, cov = fit_lines(np.asarray(x_m, float), np.asarray(y_m, float)[None, :],
                          np.asarray(weight, float)[None, :],
                          curvature_prior_inv_m=curvature_prior_inv_m, sigma_m=sigma_m)
    return coef[0], cov[0]


def fit_lines(x_m: np.ndarray, y_m: np.ndarray, weight: np.ndarray, *,
              curvature_prior_inv_m: float = 0.01, sigma_m: float = 0.05
              ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fit_line` for K lines sampled at the same ``x_m`` at once (weight 0 where a
    line has no point).

    Parameters
    ----------
    x_m : (R,) abscissae [m]; y_m, weight : (K, R)

    Returns
    -------
    coef : (K, 3); cov : (K, 3, 3)
    """
    x = np.asarray(x_m, float)
    w = np.asarray(weight, float) / sigma_m ** 2
    design = np.column_stack((np.ones_like(x), x, 0.5 * x * x))
    normal = np.einsum("kr,ri,rj->kij", w, design, design)
    normal[:, 2, 2] += 1.0 / curvature_prior_inv_m ** 2
    # Lines with fewer than two points get a weak prior on c0 and c1 too (no singular solve).
    normal[:, 0, 0] += 1e-9
    normal[:, 1, 1] += 1e-9
    rhs = np.einsum("kr,ri->ki", w * np.asarray(y_m, float), design)
    cov = np.linalg.inv(normal)
    return np.einsum("kij,kj->ki", cov, rhs), cov


def fit_parallel_lines(x_m: np.ndarray, y_m: np.ndarray, weight: np.ndarray,
                       offset_guess_m: np.ndarray, *, curvature_prior_inv_m: float = 0.01,
                       curvature_rate_prior_inv_m2: float = 5e-4,
                       pitch_bias_prior_inv_m: float = 0.006, sigma_m: float = 0.05
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Joint fit of K lines of one road: each its own offset, all one shape.

    ``y_k(x) = c0_k + (c1 + b o_k) x + c2 x^2 / 2 + c3 x^3 / 6``: lines on a road are
    parallel, so a dashed line seen as two dashes borrows its direction from a solid line
    beside it. ``c3`` (the clothoid's curvature rate) lets the curvature grow into a bend
    without pulling the offsets at x = 0; ``b`` absorbs a camera pitch error, which turns
    lines by ``b * offset`` in the warped view (``b`` = pitch error / camera height;
    ``o_k`` = ``offset_guess_m``, the lines' own offsets, keeps the model linear). ``c2``,
    ``c3`` and ``b`` have zero-mean priors of the given one-sigmas (0.5 deg of pitch at
    1.5 m height is 0.006 /m).

    Parameters
    ----------
    x_m : (R,) abscissae [m]; y_m, weight : (K, R) points (weight 0 where a line has none)
    offset_guess_m : (K,) approximate offsets of the lines [m]

    Returns
    -------
    coef : (K, 4) per line c0 [m], heading c1 + b * o_k [rad], curvature c2 [1/m],
        curvature rate c3 [1/m^2]
    offset_std_m : (K,) one-sigma of each c0 for a point scatter of ``sigma_m``
    """
    x = np.asarray(x_m, float)
    w = np.asarray(weight, float) / sigma_m ** 2
    y = np.asarray(y_m, float)
    o = np.asarray(offset_guess_m, float)
    k = w.shape[0]
    # Unknowns: c0_1..c0_K, then c1, c2, c3, b. Shared columns of line i at each x:
    # [x, x^2 / 2, x^3 / 6, o_i x].
    base = np.column_stack((x, 0.5 * x * x, x ** 3 / 6.0))
    moments = np.einsum("kr,ri,rj->kij", w, base, base)  # (K, 3, 3)
    wx = w @ x  # (K,)
    first = w @ base  # (K, 3)
    normal = np.zeros((k + 4, k + 4))
    normal[np.arange(k), np.arange(k)] = w.sum(axis=1) + 1e-9  # no point: still solvable
    cross = np.column_stack((first, o * wx))  # (K, 4): c0_i with the shared unknowns
    normal[:k, k:] = cross
    normal[k:, :k] = cross.T
    shared = np.zeros((4, 4))
    shared[:3, :3] = moments.sum(axis=0)
    shared[:3, 3] = shared[3, :3] = np.einsum("kr,ri,r,k->i", w, base, x, o)
    shared[3, 3] = float(np.einsum("kr,r,k->", w, x * x, o * o))
    normal[k:, k:] = shared
    normal[k + 1, k + 1] += 1.0 / curvature_prior_inv_m ** 2
    normal[k + 2, k + 2] += 1.0 / curvature_rate_prior_inv_m2 ** 2
    normal[k + 3, k + 3] += 1.0 / pitch_bias_prior_inv_m ** 2
    wy = w * y
    rhs = np.concatenate((wy.sum(axis=1), (wy @ base).sum(axis=0), [float(o @ (wy @ x))]))
    cov = np.linalg.inv(normal)
    theta = cov @ rhs
    c1, c2, c3, b = theta[k:]
    coef = np.column_stack((theta[:k], c1 + b * o, np.full(k, c2), np.full(k, c3)))
    return coef, np.sqrt(np.maximum(np.diag(cov)[:k], 0.0))


def pattern_kind(painted: np.ndarray, step_m: float, *, solid_coverage: float = 0.75,
                 min_gap_m: float = 1.5, min_seen_m: float = 2.0) -> MarkingKind:
    """Solid, dashed or unknown from where paint was found along a line.

    Parameters
    ----------
    painted : (n,) bool, along the line at ``step_m`` spacing, only where the line is visible
        (in the image and not hidden), near to far or far to near
    """
    p = np.asarray(painted, bool)
    if p.size == 0 or p.sum() * step_m < min_seen_m:
        return MarkingKind.UNKNOWN
    if p.mean() >= solid_coverage:
        return MarkingKind.SOLID
    # Runs of paint and of gaps, single-sample holes closed (a worn spot is not a gap).
    closed = p.copy()
    closed[1:-1] |= p[:-2] & p[2:]
    edges = np.flatnonzero(np.diff(np.concatenate(([0], closed.astype(np.int8), [0]))))
    starts, ends = edges[::2], edges[1::2]
    if len(starts) < 2:
        return MarkingKind.UNKNOWN
    gaps = (starts[1:] - ends[:-1]) * step_m
    if (gaps >= min_gap_m).sum() >= 1 and closed.mean() < solid_coverage:
        return MarkingKind.DASHED
    return MarkingKind.UNKNOWN


def pick_ego_lane(lines: list[LaneBoundary], *, width_range_m: tuple[float, float] = (2.2, 4.5),
                  max_offset_m: float = 4.0, min_confidence: float = 0.3
                  ) -> tuple[LaneBoundary | None, LaneBoundary | None,
                             tuple[LaneBoundary, ...], tuple[LaneBoundary, ...]]:
    """The ego lane's boundaries among the lines of a frame, and the further lines.

    The nearest line on each side (by offset at x = 0) is the boundary. When both are found
    but do not make a plausible lane (width outside ``width_range_m``), the one with the
    lower confidence is dropped (the other side then has no boundary). Lines below
    ``min_confidence`` are ignored (a faint short streak is more often a crack or a shadow's
    border than paint), and lines beyond a road edge are not part of the road.

    Returns
    -------
    left, right : the boundaries or None
    further_left, further_right : the other lines, nearest first
    """
    lines = [ln for ln in lines if ln.confidence >= min_confidence]
    left_side = sorted((ln for ln in lines if ln.offset_m > 0), key=lambda ln: ln.offset_m)
    right_side = sorted((ln for ln in lines if ln.offset_m <= 0), key=lambda ln: -ln.offset_m)
    left = left_side[0] if left_side and left_side[0].offset_m <= max_offset_m else None
    right = right_side[0] if right_side and -right_side[0].offset_m <= max_offset_m else None
    if left is not None and right is not None:
        width = left.offset_m - right.offset_m
        if not width_range_m[0] <= width <= width_range_m[1]:
            if left.confidence >= right.confidence:
                right = None
            else:
                left = None

    def beyond(side: list[LaneBoundary], boundary: LaneBoundary | None) -> tuple:
        out = []
        start = side.index(boundary) + 1 if boundary is not None else 0
        if boundary is not None and boundary.kind == MarkingKind.ROAD_EDGE.value:
            return ()
        for ln in side[start:]:
            out.append(ln)
            if ln.kind == MarkingKind.ROAD_EDGE.value:
                break
        return tuple(out)

    return left, right, beyond(left_side, left), beyond(right_side, right)



def weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The value at half the total weight (values sorted ascending)."""
    order = np.argsort(values)
    cw = np.cumsum(weights[order])
    return float(values[order][np.searchsorted(cw, cw[-1] / 2.0)])


def with_yaw_correction(obs: LaneObservation, delta_yaw_rad: float) -> LaneObservation:
    """An observation measured with a camera yaw that was later corrected by
    ``delta_yaw_rad`` (new minus old, positive left): headings turn by the same amount."""
    if delta_yaw_rad == 0.0:
        return obs

    def turn(ln: LaneBoundary | None) -> LaneBoundary | None:
        return None if ln is None else replace(ln, heading_rad=ln.heading_rad + delta_yaw_rad)

    return replace(obs, left=turn(obs.left), right=turn(obs.right),
                   lines_left=tuple(turn(ln) for ln in obs.lines_left),
                   lines_right=tuple(turn(ln) for ln in obs.lines_right))
