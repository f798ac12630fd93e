"""A vehicle's box in the image: its outline's hull, or its 3D box cut at a near plane where
it reaches behind the camera (what an annotator draws of a car alongside). Used by the replay
(:mod:`vid2sim.evaluate.replay`)."""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.core.outline import OutlineShape, vehicle_points

NEAR_PLANE_M = 0.1
"""Depth in front of the camera [m] at which 3D boxes are cut before projection."""

_BOX_EDGES = ((0, 1), (0, 2), (1, 3), (2, 3), (4, 5), (4, 6), (5, 7), (6, 7),
              (0, 4), (1, 5), (2, 6), (3, 7))


class BoxView(NamedTuple):
    """How a 3D box appears in the image.

    :param box_px: (x1, y1, x2, y2) clipped to the image [px]
    :param range_m: smallest forward (x) coordinate of the box [m]
    :param in_image_fraction: share of the unclipped image box inside the image
    :param behind_camera: part of the box lies behind the near plane (cut there)
    """

    box_px: tuple[float, float, float, float]
    range_m: float
    in_image_fraction: float
    behind_camera: bool


def project_box_clipped(camera: Camera, center_veh_m: np.ndarray, length_m: float,
                        width_m: float, height_m: float, yaw_rad: float,
                        near_m: float = NEAR_PLANE_M, outline: OutlineShape | None = None
                        ) -> BoxView | None:
    """Pixel box of a vehicle's ``outline`` (None: its 3D box), as its 3D box cut at a near
    plane in front of the camera where it reaches behind that plane.

    Parameters
    ----------
    camera : Camera
        The scenario camera.
    center_veh_m : array_like
        Footprint centre (x forward, y left[, z up]) in the vehicle frame [m].
    length_m, width_m, height_m : float
        Box size [m].
    yaw_rad : float
        Heading relative to the vehicle x axis, counter-clockwise [rad].
    near_m : float
        Depth of the cutting plane [m].

    Returns
    -------
    BoxView or None
        None when nothing of the box is in view.
    """
    seen = _visible_points_px(camera, center_veh_m, length_m, width_m, height_m, yaw_rad,
                              near_m, outline)
    if seen is None:
        return None
    uv, x_min, cut = seen
    x1, y1 = uv.min(axis=0)
    x2, y2 = uv.max(axis=0)
    w, h = camera.image_width - 1, camera.image_height - 1
    if x2 <= 0 or y2 <= 0 or x1 >= w or y1 >= h:
        return None
    full_area = max((x2 - x1) * (y2 - y1), 1e-9)
    x1, x2 = float(np.clip(x1, 0, w)), float(np.clip(x2, 0, w))
    y1, y2 = float(np.clip(y1, 0, h)), float(np.clip(y2, 0, h))
    if x2 - x1 < 1.0 or y2 - y1 < 1.0:
        return None
    return BoxView((x1, y1, x2, y2), x_min, float((x2 - x1) * (y2 - y1) / full_area), cut)


def _visible_points_px(camera: Camera, center_veh_m: np.ndarray, length_m: float,
                       width_m: float, height_m: float, yaw_rad: float, near_m: float,
                       outline: OutlineShape | None
                       ) -> tuple[np.ndarray, float, bool] | None:
    """The pixels a vehicle's image spans: its outline's points (its 3D box's corners without
    an outline, or where the outline reaches behind the near plane), the box cut at the near
    plane where it reaches behind it. ``(uv, nearest x [m], cut)`` or None when nothing is in
    front of the camera."""
    corners = camera.box_corners_veh(center_veh_m, length_m, width_m, height_m, yaw_rad)
    depth = camera.vehicle_to_camera(corners)[:, 2]
    front = depth > near_m
    if not front.any():
        return None
    pts = [corners[front]]
    if outline is not None and front.all():
        placed = vehicle_points(center_veh_m, length_m, width_m, height_m, yaw_rad, outline)
        if (camera.vehicle_to_camera(placed)[:, 2] > near_m).all():
            pts = [placed]
    if not front.all():
        # Where an edge crosses the near plane, keep the crossing point: the visible part of
        # the box ends there.
        for i, j in _BOX_EDGES:
            if front[i] != front[j]:
                s = (near_m - depth[i]) / (depth[j] - depth[i])
                pts.append((corners[i] + s * (corners[j] - corners[i]))[None, :])
    uv, ok = camera.project(np.vstack(pts))
    uv = uv[ok]
    if uv.size == 0:
        return None
    return uv, float(corners[:, 0].min()), bool(not front.all())


def project_hull(camera: Camera, center_veh_m: np.ndarray, length_m: float, width_m: float,
                 height_m: float, yaw_rad: float, near_m: float = NEAR_PLANE_M,
                 outline: OutlineShape | None = None) -> np.ndarray | None:
    """(K, 2) pixel polygon [px], the convex hull of the points whose bounding box
    :func:`project_box_clipped` returns (unclipped: it may reach beyond the image); None when
    nothing of the vehicle is in front of the camera."""
    seen = _visible_points_px(camera, center_veh_m, length_m, width_m, height_m, yaw_rad,
                              near_m, outline)
    if seen is None:
        return None
    uv = seen[0]
    if len(uv) < 3:
        return uv
    return cv2.convexHull(uv.astype(np.float32)).reshape(-1, 2).astype(float)
