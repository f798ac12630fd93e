"""Positions along a matched route: the along-route smoother, trimming a route to its fixes,
signed lateral offsets from a polyline, cutting a polyline to a span and joining edge
geometries."""

from __future__ import annotations

import math

import numpy as np

from vid2sim.core.polyline import signed_offsets  # noqa: F401 - its old home, still imported here
from vid2sim.geo.osm import RoadNetwork

#: innovations beyond 4 sigma (16 = 4^2 in variance) are rejected by the along-route filter
GATE = 16.0


def rts_along(t_s: np.ndarray, s_meas_m: np.ndarray, sigma_m: np.ndarray,
              accel_sigma_mps2: float, return_accepted: bool = False
              ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
    """Constant-velocity Kalman filter + Rauch-Tung-Striebel smoother of along-route position.

    NaN measurements (skipped outliers) are predicted through; innovations beyond 4 sigma are
    rejected. Returns the smoothed positions [m], and with ``return_accepted`` also which
    measurements the filter used.
    """
    # scalar arithmetic on the 2x2 state: numpy's per-call overhead would dominate at 10 Hz
    n = len(t_s)
    ts = np.asarray(t_s, float).tolist()
    zs = np.asarray(s_meas_m, float).tolist()
    rs = (np.asarray(sigma_m, float) ** 2).tolist()
    first = int(np.flatnonzero(np.isfinite(s_meas_m))[0])
    x0, x1 = zs[first], 0.0
    p00, p01, p11 = rs[first], 0.0, 15.0 ** 2
    q = accel_sigma_mps2 ** 2
    filt = [(0.0, 0.0, 0.0, 0.0, 0.0)] * n   # filtered x0, x1, p00, p01, p11
    pred = [(0.0, 0.0, 0.0, 0.0, 0.0)] * n   # predicted, the same
    dts = [0.0] * n
    accepted = np.zeros(n, bool)
    for k in range(n):
        dt = ts[k] - ts[k - 1] if k else 0.0
        dts[k] = dt
        # x <- F x, P <- F P F' + Q (white acceleration, Bar-Shalom's discretised model)
        x0 = x0 + dt * x1
        p00, p01, p11 = (p00 + 2 * dt * p01 + dt * dt * p11 + q * dt ** 3 / 3,
                         p01 + dt * p11 + q * dt ** 2 / 2, p11 + q * dt)
        pred[k] = (x0, x1, p00, p01, p11)
        z = zs[k]
        if not math.isnan(z):
            innov_var = p00 + rs[k]
            innov = z - x0
            if innov * innov <= GATE * innov_var:
                accepted[k] = True
                g0, g1 = p00 / innov_var, p01 / innov_var
                x0, x1 = x0 + g0 * innov, x1 + g1 * innov
                p00, p01, p11 = p00 - g0 * p00, p01 - g0 * p01, p11 - g1 * p01
        filt[k] = (x0, x1, p00, p01, p11)
    out = [0.0] * n
    s0, s1 = filt[n - 1][0], filt[n - 1][1]
    out[n - 1] = s0
    for k in range(n - 2, -1, -1):
        f0, f1, f00, f01, f11 = filt[k]
        q0, q1, q00, q01, q11 = pred[k + 1]
        dt = dts[k + 1]
        # C = P_f F' inv(P_p)
        a00, a01 = f00 + dt * f01, f01
        a10, a11 = f01 + dt * f11, f11
        det = q00 * q11 - q01 * q01
        i00, i01, i11 = q11 / det, -q01 / det, q00 / det
        c00, c01 = a00 * i00 + a01 * i01, a00 * i01 + a01 * i11
        c10, c11 = a10 * i00 + a11 * i01, a10 * i01 + a11 * i11
        d0, d1 = s0 - q0, s1 - q1
        s0, s1 = f0 + c00 * d0 + c01 * d1, f1 + c10 * d0 + c11 * d1
        out[k] = s0
    xs = np.asarray(out)
    return (xs, accepted) if return_accepted else xs


def trim_route(net: RoadNetwork, piece: list[int], s_m: np.ndarray, min_cover_m: float
               ) -> tuple[list[int], np.ndarray]:
    """Drop route edges before the first / after the last fix position, and a first or last
    edge covered by less than ``min_cover_m``; shift positions to the trimmed start."""
    lengths = net.edge_length_m[piece]
    ends = np.cumsum(lengths)
    starts = ends - lengths
    lo, hi = float(np.nanmin(s_m)), float(np.nanmax(s_m))
    first = int(np.searchsorted(ends, lo, side="right"))
    last = int(np.searchsorted(starts, hi, side="left")) - 1
    first, last = min(first, len(piece) - 1), max(last, 0)
    if last > first and ends[first] - lo < min_cover_m:
        first += 1
    if last > first and hi - starts[last] < min_cover_m:
        last -= 1
    last = max(last, first)
    return piece[first:last + 1], s_m - starts[first]


def sub_polyline(xy_m: np.ndarray, start_m: float, end_m: float) -> np.ndarray:
    """The part of a polyline from arc length ``start_m`` to ``end_m`` (clamped to the line),
    its two ends interpolated on the line; a single point where the part has no length."""
    xy = np.asarray(xy_m, float).reshape(-1, 2)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    start = float(np.clip(start_m, 0.0, s[-1]))
    end = float(np.clip(end_m, start, s[-1]))

    def at(v: float) -> np.ndarray:
        return np.array([np.interp(v, s, xy[:, 0]), np.interp(v, s, xy[:, 1])])

    if end <= start:
        return at(start)[None, :]
    inner = xy[(s > start) & (s < end)]
    return np.vstack([at(start), inner, at(end)])


def join_xy(net: RoadNetwork, edges: list[int]) -> np.ndarray:
    """Edge geometries joined in travel order (the shared node written once) [m]."""
    return np.vstack([net.edge_xy[edges[0]]] + [net.edge_xy[e][1:] for e in edges[1:]])
