"""The reference line of an OpenDRIVE road: a polyline fitted with a continuous-curvature
chain of clothoids, written as ``line``, ``arc`` and ``spiral`` geometries.

The curvature is piecewise linear in ``s`` with knots every :data:`KNOT_SPACING_M` or closer
until the fit is within :data:`FIT_TOLERANCE_M` of the polyline (:func:`fit_reference_line`).
"""

from __future__ import annotations

import contextlib
import itertools
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

KNOT_SPACING_M = 20.0
MIN_KNOT_SPACING_M = 4.0
FIT_TOLERANCE_M = 0.2
_SMOOTHING = 0.05  # weight of the curvature-change penalty (dimensionless)
_FINE_STEP_M = 0.25  # integration step of the curvature model [m]
_MAX_GRID = 8000  # integration steps of a fit (memory: grid x knots doubles)
_MAX_KNOTS = 500  # knots of a fit at most (long roads get a coarser minimum spacing)
_LINE_CURVATURE = 1e-5  # |k| below this (radius > 100 km) is written as a line [1/m]
_ARC_DCURVATURE = 1e-6  # |k1 - k0| below this is written as an arc [1/m]


@dataclass(frozen=True)
class ReferenceLine:
    """A clothoid chain: start pose, knot arc lengths [m] and curvatures at the knots [1/m]."""

    x0_m: float
    y0_m: float
    heading0_rad: float
    knots_s_m: np.ndarray
    curvature_per_m: np.ndarray

    @property
    def length_m(self) -> float:
        return float(self.knots_s_m[-1])

    def sample(self, s_m: np.ndarray) -> np.ndarray:
        """(N, 2) points at arc lengths ``s_m`` (numerical integration of the curvature)."""
        return _integrate(self.x0_m, self.y0_m, self.heading0_rad, self.knots_s_m,
                          self.curvature_per_m, np.asarray(s_m, float))

    def pieces(self) -> list[tuple[str, float, float, float]]:
        """``(kind, curvature_start, curvature_end, length_m)``, one per knot interval, with
        runs of equal lines or arcs merged (repeating them is redundant information that the
        ASAM checker flags)."""
        out: list[tuple[str, float, float, float]] = []
        for i in range(len(self.knots_s_m) - 1):
            k0, k1 = float(self.curvature_per_m[i]), float(self.curvature_per_m[i + 1])
            length = float(self.knots_s_m[i + 1] - self.knots_s_m[i])
            kind = "line" if k0 == 0.0 and k1 == 0.0 else ("arc" if k0 == k1 else "spiral")
            if out and kind != "spiral" and out[-1][0] == kind and out[-1][1] == k0:
                out[-1] = (kind, k0, k1, out[-1][3] + length)
            else:
                out.append((kind, k0, k1, length))
        return out


def _integrate(x0, y0, h0, knots, kappa, s_query) -> np.ndarray:
    n = max(math.ceil(knots[-1] / _FINE_STEP_M), 1)
    s = np.linspace(0.0, knots[-1], n + 1)
    k = np.interp(s, knots, kappa)
    ds = np.diff(s)
    # heading: exact integral of the piecewise-linear curvature (trapezoid is exact here
    # when the grid contains the knots; off-knot error is O(ds^2 * dk))
    h = h0 + np.r_[0.0, np.cumsum(0.5 * (k[1:] + k[:-1]) * ds)]
    # position: midpoint heading per step (second-order accurate)
    hm = 0.5 * (h[1:] + h[:-1])
    x = x0 + np.r_[0.0, np.cumsum(np.cos(hm) * ds)]
    y = y0 + np.r_[0.0, np.cumsum(np.sin(hm) * ds)]
    return np.column_stack((np.interp(s_query, s, x), np.interp(s_query, s, y)))


def _resample(points_m: np.ndarray, step_m: float) -> tuple[np.ndarray, np.ndarray]:
    p = np.asarray(points_m, float).reshape(-1, 2)
    keep = np.r_[True, np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-6]
    p = p[keep]
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    n = max(math.ceil(s[-1] / step_m), 1)
    s_new = np.linspace(0.0, s[-1], n + 1)
    return s_new, np.column_stack((np.interp(s_new, s, p[:, 0]), np.interp(s_new, s, p[:, 1])))


def _single_blas_thread():
    """One BLAS thread for the fit: the per-iteration SVD of a few-hundred-column Jacobian takes
    0.2 s on one thread but 10 s when OpenBLAS spreads it over busy cores (measured on the
    2-core CI machine)."""
    try:
        from threadpoolctl import threadpool_limits  # installed with scikit-learn
    except ImportError:  # pragma: no cover
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


class _ClothoidModel:
    """Positions of a clothoid chain at given arc lengths and their exact Jacobian.

    Parameters are ``[heading0, curvature at each knot]``. On a grid of at most
    :data:`_MAX_GRID` steps the heading is the trapezoid integral of the piecewise-linear
    curvature (``h = h0 + H @ k`` with ``H`` the integrated hat functions) and positions are
    sums of ``(cos, sin)`` of the midpoint headings, as in :func:`_integrate`. The Jacobian
    follows by the chain rule (``dx/dk = -sum sin(h_mid) H_mid ds``), so a fit costs a few
    matrix products per iteration instead of one integration per parameter.
    """

    def __init__(self, x0: float, y0: float, knots: np.ndarray, s_query: np.ndarray):
        self.x0, self.y0, self.knots = x0, y0, knots
        n = int(min(max(math.ceil(knots[-1] / _FINE_STEP_M), 1), _MAX_GRID))
        s = np.linspace(0.0, knots[-1], n + 1)
        self.ds = np.diff(s)
        i = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(knots) - 2)
        w = (s - knots[i]) / (knots[i + 1] - knots[i])
        hat = np.zeros((s.size, len(knots)))
        rows = np.arange(s.size)
        hat[rows, i] = 1.0 - w
        hat[rows, i + 1] += w
        h_of_k = np.vstack((np.zeros(len(knots)),
                            np.cumsum(0.5 * (hat[1:] + hat[:-1]) * self.ds[:, None], axis=0)))
        self.hm_of_k = 0.5 * (h_of_k[1:] + h_of_k[:-1])  # d(midpoint heading)/d(curvature)
        q = np.clip(np.searchsorted(s, s_query, side="right") - 1, 0, n - 1)
        self.q, self.qw = q, ((s_query - s[q]) / (s[q + 1] - s[q]))[:, None]

    def _at_query(self, grid: np.ndarray) -> np.ndarray:
        return (1.0 - self.qw) * grid[self.q] + self.qw * grid[self.q + 1]

    def _midpoint_heading(self, params: np.ndarray) -> np.ndarray:
        return params[0] + self.hm_of_k @ params[1:]

    def positions(self, params: np.ndarray) -> np.ndarray:
        hm = self._midpoint_heading(params)
        x = self.x0 + np.r_[0.0, np.cumsum(np.cos(hm) * self.ds)]
        y = self.y0 + np.r_[0.0, np.cumsum(np.sin(hm) * self.ds)]
        return np.column_stack((self._at_query(x[:, None])[:, 0], self._at_query(y[:, None])[:, 0]))

    def jacobian(self, params: np.ndarray) -> np.ndarray:
        """d(positions)/d(params), rows ordered like ``positions(...).ravel()``."""
        hm = self._midpoint_heading(params)
        dh = np.column_stack((np.ones_like(hm), self.hm_of_k))  # d(hm)/d(params)
        zero = np.zeros((1, dh.shape[1]))
        dx = np.vstack((zero, np.cumsum((-np.sin(hm) * self.ds)[:, None] * dh, axis=0)))
        dy = np.vstack((zero, np.cumsum((np.cos(hm) * self.ds)[:, None] * dh, axis=0)))
        jac = np.empty((2 * self.q.size, dh.shape[1]))
        jac[0::2], jac[1::2] = self._at_query(dx), self._at_query(dy)
        return jac


#: Longest piece of road fitted at once [m]. One least-squares fit costs about samples x
#: knots^2 per iteration, i.e. the cube of the length (a 6 km road: 40 s, 1.5 km: 5.6 s);
#: longer roads are fitted piece by piece, each piece starting at the previous one's end
#: pose and curvature, so the cost is linear in the length and the chain stays continuous.
FIT_PIECE_M = 500.0
# weight pinning a piece's start heading [rad] and curvature [1/m] to the previous piece's end
# (residuals are metres: 1e4 holds them to ~1e-6 while the positions are fitted)
_PIN_WEIGHT = 1e4


def fit_reference_line(centerline_m: np.ndarray, tolerance_m: float = FIT_TOLERANCE_M,
                       knot_spacing_m: float = KNOT_SPACING_M) -> tuple[ReferenceLine, float]:
    """Fit a continuous-curvature clothoid chain to a polyline.

    The start point is kept; start heading and knot curvatures are fitted by least squares on
    the positions (1 m samples; exact Jacobian), so heading errors do not accumulate into drift.
    Knot intervals holding samples farther than ``tolerance_m`` are halved and the fit repeated
    (warm-started) until all samples are within tolerance or the intervals reach
    :data:`MIN_KNOT_SPACING_M` (a sharp polyline corner cannot be followed by any curve of
    finite curvature). Roads longer than :data:`FIT_PIECE_M` are fitted in pieces of about that
    length, each continuing the chain (position, heading and curvature) where the previous one
    ends. Near-zero and near-constant curvatures are then snapped to lines and arcs if the fit
    stays within tolerance.

    Returns
    -------
    line : ReferenceLine
    max_error_m : float
        Largest distance between the fitted line and the 1 m samples of the polyline [m].
    """
    s_data, p_data = _resample(centerline_m, 1.0)
    length = float(s_data[-1])
    if length < 1e-3:
        raise ValueError("centerline has no length")
    n_pieces = max(1, round(length / FIT_PIECE_M))
    bounds = np.linspace(0, len(s_data) - 1, n_pieces + 1).round().astype(int)
    knots, kappa = [np.zeros(1)], []
    start: tuple[float, float, float, float] | None = None
    first: ReferenceLine | None = None
    for a, b in itertools.pairwise(bounds):
        piece = _fit_piece(s_data[a:b + 1] - s_data[a], p_data[a:b + 1], start, tolerance_m,
                           knot_spacing_m)
        first = first or piece
        knots.append(s_data[a] + piece.knots_s_m[1:])
        # the chain continues with the previous piece's end curvature (the new piece's first
        # knot is pinned to it)
        kappa.append(piece.curvature_per_m if start is None else piece.curvature_per_m[1:])
        end = piece.sample(np.array([piece.length_m]))[0]
        k = piece.curvature_per_m
        heading_end = piece.heading0_rad + float(np.sum(0.5 * (k[1:] + k[:-1])
                                                        * np.diff(piece.knots_s_m)))
        start = (float(end[0]), float(end[1]), heading_end, float(piece.curvature_per_m[-1]))
    line = ReferenceLine(first.x0_m, first.y0_m, first.heading0_rad, np.concatenate(knots),
                         np.concatenate(kappa))
    err = float(np.max(np.linalg.norm(line.sample(s_data) - p_data, axis=1)))
    snapped = _snap(line)
    snapped_err = float(np.max(np.linalg.norm(snapped.sample(s_data) - p_data, axis=1)))
    if snapped_err <= max(tolerance_m, err):
        return snapped, snapped_err
    return line, err


def _fit_piece(s_data: np.ndarray, p_data: np.ndarray,
               start: tuple[float, float, float, float] | None, tolerance_m: float,
               knot_spacing_m: float) -> ReferenceLine:
    """The clothoid chain of one piece (arc lengths ``s_data`` from 0, points ``p_data``).

    ``start``: None for the road's first piece (start at its first point, heading fitted),
    else the (x, y, heading, curvature) it must continue from.
    """
    length = float(s_data[-1])
    x0, y0 = p_data[0] if start is None else start[:2]
    d = np.diff(p_data, axis=0)
    seg_h = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    if start is not None:  # unwrap onto the heading the chain arrives with
        seg_h += 2 * math.pi * round((start[2] - seg_h[0]) / (2 * math.pi))
    min_spacing = max(MIN_KNOT_SPACING_M, length / _MAX_KNOTS)
    n_int = max(math.ceil(length / max(knot_spacing_m, min_spacing)), 1)
    knots = np.linspace(0.0, length, n_int + 1)
    # initial guess: curvature from the heading slope between knots
    h_knots = np.interp(knots, 0.5 * (s_data[1:] + s_data[:-1]), seg_h)
    params = np.r_[seg_h[0], np.gradient(h_knots, knots) if n_int > 1 else np.zeros(2)]
    if start is not None:
        params[0], params[1] = start[2], start[3]
    best: tuple[ReferenceLine, float] | None = None
    while True:
        model = _ClothoidModel(float(x0), float(y0), knots, s_data)
        # a weak penalty on curvature changes [1/m] * (interval length [m])^2 -> metres: damps
        # the oscillation a free fit shows on straights next to curves
        w_smooth = _SMOOTHING * np.diff(knots) ** 2
        diff_op = np.diff(np.eye(len(knots)), axis=0)
        smooth_jac = np.column_stack((np.zeros(len(knots) - 1), w_smooth[:, None] * diff_op))
        pin_jac = np.zeros((0 if start is None else 2, len(knots) + 1))
        if start is not None:
            pin_jac[0, 0] = pin_jac[1, 1] = _PIN_WEIGHT

        def residual(params, model=model, w_smooth=w_smooth):
            pin = ([] if start is None else
                   [_PIN_WEIGHT * (params[0] - start[2]), _PIN_WEIGHT * (params[1] - start[3])])
            return np.r_[(model.positions(params) - p_data).ravel(),
                         w_smooth * np.diff(params[1:]), pin]

        def jacobian(params, model=model, smooth_jac=smooth_jac, pin_jac=pin_jac):
            return np.vstack((model.jacobian(params), smooth_jac, pin_jac))

        with _single_blas_thread():
            sol = least_squares(residual, params, jac=jacobian, method="trf", x_scale="jac")
        line = ReferenceLine(float(x0), float(y0), float(sol.x[0]), knots, sol.x[1:].copy())
        dev = np.linalg.norm(line.sample(s_data) - p_data, axis=1)
        err = float(dev.max())
        if best is None or err < best[1]:
            best = (line, err)
        # refine only where the fit misses: split the knot intervals holding bad samples
        bad = np.unique(np.clip(np.searchsorted(knots, s_data[dev > tolerance_m], "right") - 1,
                                0, len(knots) - 2))
        bad = bad[np.diff(knots)[bad] / 2.0 >= min_spacing]
        if err <= tolerance_m or bad.size == 0:
            break
        new_knots = np.sort(np.r_[knots, 0.5 * (knots[bad] + knots[bad + 1])])
        params = np.r_[sol.x[0], np.interp(new_knots, knots, sol.x[1:])]  # warm start
        knots = new_knots
    return best[0]


def _snap(line: ReferenceLine) -> ReferenceLine:
    k = line.curvature_per_m.copy()
    k[np.abs(k) < _LINE_CURVATURE] = 0.0
    for i in range(len(k) - 1):
        if k[i] != 0.0 and abs(k[i + 1] - k[i]) < _ARC_DCURVATURE:
            k[i + 1] = k[i]
    return ReferenceLine(line.x0_m, line.y0_m, line.heading0_rad, line.knots_s_m, k)

