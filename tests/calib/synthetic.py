"""A drive seen through a known camera, rendered as the cues the detect wings measure.

Road points and straight 3D edges are projected with :class:`vid2sim.core.camera.Camera`
(OpenCV's projection, not the fit's own numpy model), the ego drives a gentle S-bend at
a changing speed with a small body pitch, and every pixel gets Gaussian noise.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from vid2sim.core.calibration import EgoMotionSample, FlowPair, FrameLines
from vid2sim.core.camera import Camera

TRUTH = Camera(image_width=1280, image_height=720, fx=900.0, fy=900.0, cx=639.5, cy=359.5,
               dist=(-0.15, 0.015, 0.0, 0.0, 0.0), height_m=1.4, pitch_deg=1.0,
               yaw_deg=-0.5, roll_deg=0.3)


def _moved(points: np.ndarray, s: float, dpsi: float) -> np.ndarray:
    """World points in the earlier vehicle frame -> the later one (arc of length s)."""
    dx = points[:, 0] - s * math.cos(dpsi / 2)
    dy = points[:, 1] - s * math.sin(dpsi / 2)
    c, sn = math.cos(dpsi), math.sin(dpsi)
    return np.column_stack((c * dx + sn * dy, -sn * dx + c * dy, points[:, 2]))


def drive(camera: Camera = TRUTH, n_pairs: int = 40, noise_px: float = 0.3, seed: int = 0,
          dt: float = 0.1) -> tuple[list[FlowPair], list[EgoMotionSample]]:
    """Flow pairs (road points within 1.2 m of the path, 4-40 m ahead) and their motion."""
    rng = np.random.default_rng(seed)
    pairs, motion = [], []
    for k in range(n_pairs):
        t = 0.25 * k
        speed = 12.0 + 3.0 * math.sin(0.4 * t)
        yaw_rate = 0.06 * math.sin(0.5 * t)
        s, dpsi = speed * dt, yaw_rate * dt
        body = replace(camera, pitch_deg=camera.pitch_deg + 0.2 * math.sin(1.7 * t))
        later = replace(body, pitch_deg=body.pitch_deg + 0.05 * math.cos(1.3 * t))
        pts = np.column_stack((rng.uniform(4, 40, 300), rng.uniform(-1.2, 1.2, 300),
                               np.zeros(300)))
        a, ok_a = body.project(pts)
        b, ok_b = later.project(_moved(pts, s, dpsi))
        inside = ok_a & ok_b & np.all((a >= 0) & (a < [camera.image_width, camera.image_height])
                                      & (b >= 0) & (b < [camera.image_width,
                                                         camera.image_height]), axis=1)
        a = a[inside] + rng.normal(0, noise_px, (inside.sum(), 2))
        b = b[inside] + rng.normal(0, noise_px, (inside.sum(), 2))
        pairs.append(FlowPair(2 * k, 2 * k + 1, t, t + dt, a, b))
        motion.append(EgoMotionSample(2 * k, s, dpsi, 0.01 * s + 0.015, 0.002 * dt))
    return pairs, motion


def _line(camera: Camera, p0, p1, n: int, rng, noise_px: float) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)[:, None]
    pts = np.asarray(p0, float) + t * (np.asarray(p1, float) - np.asarray(p0, float))
    uv, ok = camera.project(pts)
    uv = uv[ok]
    inside = np.all((uv >= 0) & (uv < [camera.image_width, camera.image_height]), axis=1)
    return uv[inside] + rng.normal(0, noise_px, (inside.sum(), 2))


def lines(camera: Camera = TRUTH, n_frames: int = 12, seed: int = 0, noise_px: float = 0.3
          ) -> list[FrameLines]:
    """Lane-marking segments (lines 1.75 m either side) and straight edges (poles, eaves
    and kerbs across the view) seen in a few frames."""
    rng = np.random.default_rng(seed + 1)
    out = []
    for i in range(n_frames):
        segs = []
        for y in (1.75, -1.75, 5.25, -5.25):
            for x0 in (6.0, 12.0, 20.0):
                uv = _line(camera, (x0, y, 0), (x0 + 4, y, 0), 2, rng, noise_px)
                if len(uv) == 2:
                    segs.append([*uv[0], *uv[1], float(np.hypot(*(uv[1] - uv[0])))])
        chains = []
        for _ in range(10):
            x, y = rng.uniform(8, 25), rng.choice([-1, 1]) * rng.uniform(4, 9)
            kind = rng.integers(3)
            if kind == 0:  # a pole
                ch = _line(camera, (x, y, 0.2), (x, y, 5.0), 40, rng, noise_px)
            elif kind == 1:  # an eave along the road
                ch = _line(camera, (x, y, 4.0), (x + 15, y, 4.0), 40, rng, noise_px)
            else:  # a crossing's edge across the road
                ch = _line(camera, (x, -8, 0.0), (x, 8, 0.0), 40, rng, noise_px)
            if len(ch) >= 12:
                chains.append(ch)
        out.append(FrameLines(frame=i, t_s=0.5 * i, segments=np.array(segs),
                              chains=tuple(chains)))
    return out
