"""The road's image motion between two frames: the ground-plane model of the flow.

A road point seen at pixel ``p_a`` in the earlier frame is back-projected onto the road
plane (camera ``h`` above it, mounted at pitch, yaw, roll, lens ``f``, ``k1``, ``k2``), moved
by the ego's motion between the frames (forward ``s``, sideways ``s tan(dpsi / 2) + slip``
for a car on an arc, heading change ``dpsi``) and projected into the later frame, whose
body pitch differs by ``dpitch``. For a level pinhole this is the textbook relation: a
point at row ``y`` moves by ``dy = (y - y0)^2 s / (f h)``, a turn shifts every point by
``f dpsi`` whatever its distance, so the flow of the road measures ``s / h`` and ``f``
(given a GPS yaw change), the horizon ``y0`` and the lens's bow at the image's edges.

Parameters are held in two arrays: the 7 globals of :data:`GLOBALS` (logs of the focal
length and height, so that both stay positive) and a (K, 5) array of the per-pair motion
:data:`PAIR_PARAMS`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vid2sim.calib import cameramodel as geo
from vid2sim.core.calibration import FlowPair

#: Global parameters, in the order of the parameter vector.
GLOBALS = ("log_f", "k1", "k2", "pitch", "yaw", "roll", "log_h")
G = {name: i for i, name in enumerate(GLOBALS)}
#: Per-pair motion: forward [m], heading change [rad], sideways slip [m], body pitch of the
#: earlier frame about the mount's [rad], body pitch change to the later frame [rad].
PAIR_PARAMS = ("s", "dpsi", "slip", "eps", "dpitch")
P = {name: i for i, name in enumerate(PAIR_PARAMS)}


@dataclass(slots=True)
class PairSet:
    """Flow pairs packed for the fits: all points in two arrays with their pair's index."""

    points_a: np.ndarray  # (N, 2) raw px
    points_b: np.ndarray  # (N, 2)
    pair: np.ndarray  # (N,) index into the per-pair arrays
    dt_s: np.ndarray  # (K,)
    t_mid_s: np.ndarray  # (K,)
    frame_a: np.ndarray  # (K,)
    frame_b: np.ndarray  # (K,)

    @property
    def n_pairs(self) -> int:
        return len(self.dt_s)

    def subset_points(self, keep: np.ndarray) -> PairSet:
        return PairSet(self.points_a[keep], self.points_b[keep], self.pair[keep], self.dt_s,
                       self.t_mid_s, self.frame_a, self.frame_b)


def pack_pairs(pairs: list[FlowPair]) -> PairSet:
    """The pairs' points in one :class:`PairSet` (pairs without points keep their slot)."""
    pa = [p.points_a for p in pairs]
    pb = [p.points_b for p in pairs]
    idx = [np.full(len(p.points_a), k) for k, p in enumerate(pairs)]
    cat = (lambda xs, w: np.concatenate(xs) if xs else np.zeros((0, w)))
    return PairSet(points_a=cat(pa, 2).reshape(-1, 2), points_b=cat(pb, 2).reshape(-1, 2),
                   pair=np.concatenate(idx).astype(int) if idx else np.zeros(0, int),
                   dt_s=np.array([p.dt_s for p in pairs], float),
                   t_mid_s=np.array([0.5 * (p.t_a_s + p.t_b_s) for p in pairs], float),
                   frame_a=np.array([p.frame_a for p in pairs], int),
                   frame_b=np.array([p.frame_b for p in pairs], int))


def unpack(g: np.ndarray) -> tuple[float, float, float, float, float, float, float]:
    """(f, k1, k2, pitch, yaw, roll, h) of a global vector."""
    return (math.exp(g[G["log_f"]]), float(g[G["k1"]]), float(g[G["k2"]]),
            float(g[G["pitch"]]), float(g[G["yaw"]]), float(g[G["roll"]]),
            math.exp(g[G["log_h"]]))


def _lens(g: np.ndarray) -> dict:
    return {"f": math.exp(g[G["log_f"]]), "k1": float(g[G["k1"]]), "k2": float(g[G["k2"]])}


def back_project(g: np.ndarray, c: np.ndarray, px: np.ndarray, body_pitch: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Raw pixels -> road-plane points in the vehicle frame (and the below-horizon mask),
    each with its frame's body pitch about the mount [rad]."""
    f, k1, k2, pitch, yaw, roll, h = unpack(g)
    xn = geo.pixels_to_normalised(px, f, c, k1, k2)
    rot = geo.rotations(pitch + body_pitch, yaw, roll)
    return geo.ground_points(xn, rot, h)


def move(points: np.ndarray, s: np.ndarray, dpsi: np.ndarray, slip: np.ndarray) -> np.ndarray:
    """Road points in the earlier vehicle frame -> the later one, after driving forward ``s``
    on an arc turning by ``dpsi`` (sideways ``s tan(dpsi / 2)``) plus ``slip`` sideways."""
    dx = points[:, 0] - s
    dy = points[:, 1] - (s * np.tan(0.5 * dpsi) + slip)
    cs, sn = np.cos(dpsi), np.sin(dpsi)
    return np.column_stack((cs * dx + sn * dy, -sn * dx + cs * dy, np.zeros(len(points))))


def predict_b(g: np.ndarray, m: np.ndarray, ps: PairSet, c: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """Predicted raw pixels of every point in the later frame, and the mask of points
    whose prediction exists (on the road ahead in both frames)."""
    f, k1, k2, pitch, yaw, roll, h = unpack(g)
    mp = m[ps.pair]
    xa = geo.pixels_to_normalised(ps.points_a, f, c, k1, k2)
    rot_a = geo.rotations(pitch + m[:, P["eps"]], yaw, roll)[ps.pair]
    ground, down = geo.ground_points(xa, rot_a, h)
    moved = move(ground, mp[:, P["s"]], mp[:, P["dpsi"]], mp[:, P["slip"]])
    rot_b = geo.rotations(pitch + m[:, P["eps"]] + m[:, P["dpitch"]], yaw, roll)[ps.pair]
    xn, ahead = geo.project_normalised(geo.camera_points(moved, h, rot_b))
    pred = geo.normalised_to_pixels(xn, f, c, k1, k2)
    ok = down & ahead & np.isfinite(pred).all(axis=1)
    return np.where(ok[:, None], pred, ps.points_b), ok


def road_points(g: np.ndarray, c: np.ndarray, ps: PairSet, range_h: tuple[float, float],
                half_width_h: float) -> np.ndarray:
    """Mask of points whose earlier pixel lies on the road region: ``range_h`` camera
    heights ahead and within ``half_width_h`` beside the camera.

    Distances in camera heights depend on the focal length only through ``x / h = f /
    (y - y0)``; the sideways one, ``y / h = -(u - u0) / (y - y0)``, on the horizon and the
    vanishing column alone: a provisional camera selects the road well."""
    ground, down = geo.ground_points(
        geo.pixels_to_normalised(ps.points_a, c=c, **_lens(g)),
        geo.rotations(g[G["pitch"]], g[G["yaw"]], g[G["roll"]])[0], math.exp(g[G["log_h"]]))
    h = math.exp(g[G["log_h"]])
    x, y = ground[:, 0] / h, ground[:, 1] / h
    with np.errstate(invalid="ignore"):
        return down & (x >= range_h[0]) & (x <= range_h[1]) & (np.abs(y) <= half_width_h)


def initial_motion(g: np.ndarray, c: np.ndarray, ps: PairSet, road: np.ndarray) -> np.ndarray:
    """Per-pair forward motion from the road points' median change of distance (the
    camera as given), other motion zero: a starting point for the fit."""
    m = np.zeros((ps.n_pairs, len(PAIR_PARAMS)))
    if not road.any():
        return m
    ga, _ = back_project(g, c, ps.points_a[road], np.zeros(road.sum()))
    gb, _ = back_project(g, c, ps.points_b[road], np.zeros(road.sum()))
    step = ga[:, 0] - gb[:, 0]
    for k in range(ps.n_pairs):
        sel = ps.pair[road] == k
        if sel.sum() >= 3:
            m[k, P["s"]] = float(np.median(step[sel]))
    return m


def growth(g: np.ndarray, m: np.ndarray, ps: PairSet, c: np.ndarray) -> np.ndarray:
    """How much each road point's image grows between the frames, ``x_a / x_b - 1``
    (distance ahead before and after the pair's forward motion; inf above the horizon).

    Lucas-Kanade follows translation, not scale: beyond ~12 % growth (the near road of a
    10 fps camera at speed) its tracks lag the motion or stick to compression blocks."""
    ground, down = back_project(g, c, ps.points_a, m[ps.pair, P["eps"]])
    ahead = np.where(down, ground[:, 0], np.nan) - m[ps.pair, P["s"]]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(down & (ahead > 0), m[ps.pair, P["s"]] / ahead, np.inf)
    return np.abs(out)

