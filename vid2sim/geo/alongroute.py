"""Positions along a matched route: the along-route smoother, trimming a route to its fixes,
signed lateral offsets from a polyline and joining edge geometries."""

from __future__ import annotations

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
    n = len(t_s)
    first = int(np.flatnonzero(np.isfinite(s_meas_m))[0])
    x = np.array([s_meas_m[first], 0.0])
    p = np.diag([sigma_m[first] ** 2, 15.0 ** 2])
    xs_f = np.zeros((n, 2))
    ps_f = np.zeros((n, 2, 2))
    xs_p = np.zeros((n, 2))
    ps_p = np.zeros((n, 2, 2))
    fs = np.zeros((n, 2, 2))
    q = accel_sigma_mps2 ** 2
    accepted = np.zeros(n, bool)
    for k in range(n):
        dt = float(t_s[k] - t_s[k - 1]) if k else 0.0
        f = np.array([[1.0, dt], [0.0, 1.0]])
        # white-acceleration process noise (Bar-Shalom, discretised continuous model)
        qm = q * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
        x = f @ x
        p = f @ p @ f.T + qm
        xs_p[k], ps_p[k], fs[k] = x, p, f
        z = s_meas_m[k]
        if np.isfinite(z):
            r = sigma_m[k] ** 2
            innov_var = p[0, 0] + r
            innov = z - x[0]
            if innov ** 2 <= GATE * innov_var:
                accepted[k] = True
                gain = p[:, 0] / innov_var
                x = x + gain * innov
                p = p - np.outer(gain, p[0, :])
        xs_f[k], ps_f[k] = x, p
    xs = xs_f.copy()
    for k in range(n - 2, -1, -1):
        c = ps_f[k] @ fs[k + 1].T @ np.linalg.inv(ps_p[k + 1])
        xs[k] = xs_f[k] + c @ (xs[k + 1] - xs_p[k + 1])
    return (xs[:, 0], accepted) if return_accepted else xs[:, 0]


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
