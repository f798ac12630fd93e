"""Plane polylines in metres: resampling at equal spacing and signed offsets of points from
a line (positive left of its direction).

Core geometry shared by the stages (the map matcher's route, the lane-layout of a built
scene, the road exporters): pure numpy, no I/O.
"""

from __future__ import annotations

import math

import numpy as np


def resample_polyline(xy_m: np.ndarray, step_m: float = 1.0) -> np.ndarray:
    """Resample a polyline at equal spacing <= ``step_m``, keeping both ends.

    Repeated points are dropped first, so standing still or a way join never creates a
    zero-length step (the source of heading flips and zig-zags).
    """
    xy = np.asarray(xy_m, float).reshape(-1, 2)
    if len(xy) < 2:
        return xy.copy()
    seg = np.hypot(*np.diff(xy, axis=0).T)
    xy = xy[np.concatenate([[True], seg > 1e-6])]
    if len(xy) < 2:
        return xy[:1].copy()
    s = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(xy, axis=0).T))])
    n = max(1, math.ceil(s[-1] / step_m - 1e-9))
    grid = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack([np.interp(grid, s, xy[:, 0]), np.interp(grid, s, xy[:, 1])])


#: Points x segments above which a point's nearest segment is found through a spatial index
#: (shapely's STRtree) instead of against every segment: the all-pairs search is quadratic in
#: a drive's length (a 6,000-frame build's actors on its 6 km road: 40 s against 2.7 s for a
#: quarter of it); below this the all-pairs arrays are cheaper than building the tree.
INDEXED_PAIRS = 2_000_000


def _nearest_by_index(a: np.ndarray, d: np.ndarray, seg_len: np.ndarray, seg_s: np.ndarray,
                      pts: np.ndarray, s_out: np.ndarray, off_out: np.ndarray) -> None:
    """:func:`signed_offsets` without an expected place: each point's nearest segment from
    an STRtree (all equally near ones, the first kept, as the all-pairs search does), its
    foot, arc length and signed offset written into ``s_out`` and ``off_out``."""
    import shapely

    segs = shapely.linestrings(np.stack((a, a + d), axis=1))
    finite = np.isfinite(pts).all(axis=1)
    idx = np.flatnonzero(finite)
    pairs = shapely.STRtree(segs).query_nearest(shapely.points(pts[idx]), all_matches=True)
    p_i, j = pairs
    if not len(p_i):
        return
    order = np.lexsort((j, p_i))
    p_i, j = p_i[order], j[order]
    rel0 = pts[idx[p_i]] - a[j]
    u = np.clip((rel0 * d[j]).sum(-1) / seg_len[j] ** 2, 0.0, 1.0)
    foot = a[j] + u[:, None] * d[j]
    dist2 = ((pts[idx[p_i]] - foot) ** 2).sum(-1)
    # per point, the smallest distance, ties to the lowest segment (as np.argmin)
    best = np.lexsort((j, dist2, p_i))
    keep = best[np.concatenate([[True], np.diff(p_i[best]) != 0])]
    k, jj = idx[p_i[keep]], j[keep]
    rel = pts[k] - foot[keep]
    cross = d[jj, 0] * rel[:, 1] - d[jj, 1] * rel[:, 0]
    s_out[k] = seg_s[jj] + u[keep] * seg_len[jj]
    off_out[k] = np.sign(cross) * np.sqrt(dist2[keep])


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
    raw_len = np.hypot(d[:, 0], d[:, 1])
    seg_len = np.maximum(raw_len, 1e-9)
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
    # the index answers as the all-pairs search does where no segment has zero length (a
    # repeated point ties its neighbours with an offset of sign 0)
    if expected_s_m is None and len(pts) * n_seg > INDEXED_PAIRS and n_seg \
            and np.all(raw_len > 1e-9) and np.isfinite(line).all():
        _nearest_by_index(a, d, seg_len, seg_s, pts, s_out, off_out)
        return s_out, off_out
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
