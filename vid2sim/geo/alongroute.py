"""Positions along a matched route: the along-route smoother, trimming a route to its fixes,
signed lateral offsets from a polyline and joining edge geometries."""

from __future__ import annotations

import math

import numpy as np

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


def signed_offsets(line_xy_m: np.ndarray, xy_m: np.ndarray,
                   expected_s_m: np.ndarray | None = None, window_m: float = 40.0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Arc length along ``line_xy_m`` and signed lateral offset (positive left) of points.

    With ``expected_s_m`` each point is projected only onto the part of the line within
    ``window_m`` of where it should be, so a route that passes a place twice (a loop round a
    block) does not project onto the wrong pass.

    Returns
    -------
    (s_m, offset_m) per point [m]
    """
    line = np.asarray(line_xy_m, float)
    pts = np.asarray(xy_m, float).reshape(-1, 2)
    a, d = line[:-1], np.diff(line, axis=0)
    seg_len = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    seg_s = np.concatenate([[0.0], np.cumsum(seg_len)])
    n_seg = len(a)
    if expected_s_m is None or not len(pts):
        first = np.zeros(len(pts), dtype=np.int64)
        width = n_seg
    else:
        exp = np.asarray(expected_s_m, float).reshape(-1)
        known = np.isfinite(exp)
        lo = np.where(known, np.searchsorted(seg_s, exp - window_m, side="right") - 1, 0)
        hi = np.where(known, np.searchsorted(seg_s, exp + window_m, side="left"), n_seg)
        first = np.clip(lo, 0, n_seg - 1)
        width = int(max(1, (np.clip(hi, 1, n_seg) - first).max()))
    s_out = np.full(len(pts), np.nan)
    off_out = np.full(len(pts), np.nan)
    chunk = max(1, 200_000 // max(width, 1))  # bounds the (points x segments) work arrays
    for k0 in range(0, len(pts), chunk):
        p = pts[k0:k0 + chunk]
        # candidate segments of each point: a window of ``width`` from ``first``
        j = np.minimum(first[k0:k0 + chunk, None] + np.arange(width)[None], n_seg - 1)
        rel0 = p[:, None, :] - a[j]
        u = np.clip((rel0 * d[j]).sum(-1) / seg_len[j] ** 2, 0.0, 1.0)
        foot = a[j] + u[..., None] * d[j]
        dist2 = ((p[:, None, :] - foot) ** 2).sum(-1)
        if expected_s_m is not None:
            exp_k = np.asarray(expected_s_m, float)[k0:k0 + chunk]
            far = np.abs(seg_s[j] + u * seg_len[j] - exp_k[:, None]) > window_m
            dist2 = np.where(far & np.isfinite(exp_k)[:, None] & (dist2 < np.inf), np.inf,
                             dist2)
            # no segment inside the window (an expectation off the line): take the nearest
            none = ~np.isfinite(dist2).any(axis=1)
            dist2[none] = ((p[none, None, :] - foot[none]) ** 2).sum(-1)
        best = np.argmin(dist2, axis=1)
        rows = np.arange(len(p))
        jj = j[rows, best]
        rel = p - foot[rows, best]
        cross = d[jj, 0] * rel[:, 1] - d[jj, 1] * rel[:, 0]
        s_out[k0:k0 + chunk] = seg_s[jj] + u[rows, best] * seg_len[jj]
        off_out[k0:k0 + chunk] = np.sign(cross) * np.sqrt(dist2[rows, best])
    return s_out, off_out


def join_xy(net: RoadNetwork, edges: list[int]) -> np.ndarray:
    """Edge geometries joined in travel order (the shared node written once) [m]."""
    return np.vstack([net.edge_xy[edges[0]]] + [net.edge_xy[e][1:] for e in edges[1:]])
