"""Synthetic road frames with lines of known ground-plane geometry, and lane observation
sequences of a known lateral motion (test tooling).

Every pixel below the horizon is back-projected onto the road plane with the camera model
(:meth:`vid2sim.core.camera.Camera.pixel_to_ground`) and painted by what lies at that ground
point: asphalt with grain, a painted line where ``|y - y_line(x)|`` is under half its width
(dashes by distance along x), or rough gravel beyond a road edge. Rendered at twice the size
and area-averaged down, so thin far lines are anti-aliased as a sensor would see them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import cv2
import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.core.records import LaneBoundary, LaneObservation
from vid2sim.detect.lanes.geometry import pick_ego_lane

KITTI_CAM = Camera(image_width=1242, image_height=375, fx=721.5377, fy=721.5377,
                   cx=609.5593, cy=172.854, height_m=1.65)
#: lane width [m] and frame rate [frames/s] of the synthetic observation sequences
W = 3.5
FPS = 10.0
DASHCAM = Camera(image_width=960, image_height=540, fx=560.0, fy=560.0, cx=479.5, cy=269.5,
                 height_m=1.35, pitch_deg=1.5)


@dataclass(frozen=True)
class Line:
    """A painted line ``y = offset + heading x + curvature x^2 / 2`` [m, rad, 1/m]; dashed
    with ``dash_m`` of paint every ``period_m`` when ``period_m`` is set."""

    offset_m: float
    heading_rad: float = 0.0
    curvature_inv_m: float = 0.0
    width_m: float = 0.12
    dash_m: float = 3.0
    period_m: float | None = None

    def y_at(self, x: np.ndarray) -> np.ndarray:
        return self.offset_m + self.heading_rad * x + 0.5 * self.curvature_inv_m * x * x


def render(camera: Camera, lines: list[Line], *, edge_right_m: float | None = None,
           edge_left_m: float | None = None, seed: int = 0, asphalt: int = 95,
           paint: int = 215, supersample: int = 2) -> np.ndarray:
    """A BGR frame of ``camera``'s size showing ``lines`` on asphalt; gravel right of
    ``edge_right_m`` / left of ``edge_left_m`` (lateral offsets at every x [m])."""
    rng = np.random.default_rng(seed)
    k = int(supersample)
    big = camera.scaled_to(k * camera.image_width, k * camera.image_height)
    # Pixel centres: big pixel j covers small pixel j / k, so its centre sits half a big
    # pixel off the scaled principal point.
    big = replace(big, cx=big.cx + (k - 1) / 2.0, cy=big.cy + (k - 1) / 2.0)
    h, w = big.image_height, big.image_width
    vv, uu = np.mgrid[0:h, 0:w]
    ground, below = big.pixel_to_ground(np.column_stack((uu.ravel(), vv.ravel())))
    x, y = np.nan_to_num(ground[:, 0]), np.nan_to_num(ground[:, 1])
    img = np.full(h * w, 205.0)  # sky
    img[below] = asphalt + rng.normal(0.0, 3.0, int(below.sum()))
    for ln in lines:
        on = below & (np.abs(y - ln.y_at(x)) <= ln.width_m / 2.0) & (x > 0.5)
        if ln.period_m:
            on &= np.mod(x, ln.period_m) < ln.dash_m
        img[on] = paint + rng.normal(0.0, 3.0, int(on.sum()))
    gravel = np.zeros(h * w, bool)
    if edge_right_m is not None:
        gravel |= below & (y < edge_right_m)
    if edge_left_m is not None:
        gravel |= below & (y > edge_left_m)
    # Gravel: stones of a few centimetres in light and shade (blocks on the ground grid).
    cells = (np.floor(x / 0.06).astype(np.int64) * 7919 + np.floor(y / 0.06).astype(np.int64))
    stone = (np.sin(cells[gravel] * 12.9898) * 43758.5453) % 1.0
    img[gravel] = 60.0 + 120.0 * stone
    grey = np.clip(img.reshape(h, w), 0, 255).astype(np.uint8)
    small = cv2.resize(grey, (camera.image_width, camera.image_height),
                       interpolation=cv2.INTER_AREA)
    return cv2.cvtColor(small, cv2.COLOR_GRAY2BGR)


def pitched(camera: Camera, delta_deg: float) -> Camera:
    """The same camera pitched ``delta_deg`` further down."""
    return replace(camera, pitch_deg=camera.pitch_deg + delta_deg)


def observations(lateral_m: np.ndarray, speed_mps: float = 12.0, noise_m: float = 0.0,
                 heading_noise: float = 0.0, outliers: float = 0.0, seed: int = 0,
                 width_m: float = W, missing: np.ndarray | None = None,
                 lanes: tuple[int, int] = (-3, 3)) -> list[LaneObservation]:
    """Lane observations (as :class:`~vid2sim.detect.lanes.markings.LaneMarkingDetector`
    would report them) of a camera at lateral position ``lateral_m`` (per frame at ``FPS``,
    positive left, 0 = middle of the first lane) on a straight road whose lanes
    ``lanes[0]..lanes[1]`` (0 = the first lane) have lines every ``width_m``: dashed between
    lanes, the road's edge on the right of the lowest lane, solid on the left of the highest.
    The heading against the lane follows the lateral motion (dL/dt = -v * heading)."""
    rng = np.random.default_rng(seed)
    t = np.arange(len(lateral_m)) / FPS
    heading = -np.gradient(lateral_m, t) / speed_mps
    out = []
    for i, (ti, lat, psi) in enumerate(zip(t, lateral_m, heading, strict=True)):
        if missing is not None and missing[i]:
            out.append(LaneObservation(frame=i, t_s=float(ti)))
            continue
        lines = []
        for k in range(lanes[0] - 1, lanes[1] + 1):
            c0 = (k + 0.5) * width_m - lat
            if abs(c0) > 8:
                continue
            kind = ("road_edge" if k == lanes[0] - 1 else "solid" if k == lanes[1]
                    else "dashed")
            h = psi + rng.normal(0.0, heading_noise)
            # The fit is good where the line is seen (6 m ahead): a heading error moves the
            # offset at x = 0 by 6 m times it.
            c0_meas = c0 + rng.normal(0.0, noise_m) - (h - psi) * 6.0
            lines.append(LaneBoundary(c0_meas, h, 0.0, kind, 0.9, 0.03, 5.0, 30.0, 12.0))
        if rng.random() < outliers:  # a car's shadow taken for a line
            lines.append(LaneBoundary(float(rng.uniform(-1.5, 1.5)), 0.0, 0.0, "unknown",
                                      0.95, 0.03, 5.0, 20.0, 10.0))
        left, right, fl, fr = pick_ego_lane(lines)
        width = left.offset_m - right.offset_m if left and right else math.nan
        offset = -0.5 * (left.offset_m + right.offset_m) if left and right else math.nan
        out.append(LaneObservation(frame=i, t_s=float(ti), left=left, right=right,
                                   lane_width_m=width, ego_offset_m=offset,
                                   lines_left=fl, lines_right=fr))
    return out
