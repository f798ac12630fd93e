"""Fast OpenCV renderer of a synthetic dash-cam frame: sky, ground, road, lane markings, vehicles.

Everything is drawn in the perspective of a :class:`vid2sim.core.camera.Camera` on a flat road
(z = 0 in ENU): geometry is built in the local ENU frame, moved into the ego's vehicle frame
(x forward, y left, z up, origin on the road below the camera), clipped against a near plane
in camera coordinates (so objects beside or behind the camera are cut, not smeared across
the image), projected with the pinhole model and filled with ``cv2.fillPoly`` / ``fillConvexPoly``
in painter's order (far to near). Vehicles are a few boxes each (wheels, body, cabin) with
back-face culling, shaded faces and decals (rear window, tail lights, plate, headlights) and
a soft shadow, which is enough for a COCO detector to call them cars without photorealism.

The renderer also returns, per vehicle, the pixel box of its full 3D box (exactly what
:meth:`Camera.project_box` gives when the box is wholly in front of the camera) and how much
of it is visible, for ground-truth annotations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.samples.vehicle_model import (
    GLASS_BGR,
    GLASS_SIDE_BGR,
    outward_normal,
    shade,
    vehicle_model,
)

# Fixed-point precision of polygon vertices handed to OpenCV (2**4 = 1/16 px): sub-pixel
# accurate edges without float support in fillPoly.
_SHIFT = 4
_SCALE = float(1 << _SHIFT)
# Near clipping plane [m along the optical axis]: nearer geometry is cut away. Must be > 0 so
# the perspective division stays finite; 0.3 m is well inside the bonnet.
NEAR_M = 0.3
# The road, its markings and the vehicles are drawn out to this distance ahead [m]; beyond it
# a 7 m road is under 30 px wide at the demo's focal length and fades into the horizon.
DRAW_RANGE_M = 150.0

# Colours (BGR).
SKY_TOP_BGR = (190, 140, 85)
SKY_HORIZON_BGR = (235, 220, 200)
GRASS_NEAR_BGR = (60, 110, 75)
GRASS_FAR_BGR = (120, 150, 135)
SIDEWALK_BGR = (150, 152, 155)
ASPHALT_BGR = (88, 88, 92)
MARKING_BGR = (230, 232, 235)
SHADOW_OUTER_BGR = (68, 68, 72)
SHADOW_INNER_BGR = (40, 40, 44)


@dataclass(frozen=True, slots=True)
class RoadGeometry:
    """A road with a centerline sampled along its length, for drawing.

    :param s_m: (N,) arc length of the samples [m], increasing
    :param xy_m: (N, 2) ENU centerline points [m]
    :param left_normal: (N, 2) unit normals pointing to the left of the travel direction
    :param width_m: total carriageway width [m] (all lanes, both directions)
    :param lane_width_m: width of one lane [m]; lane lines are drawn between lanes
    :param dash_length_m: length of a dash of the centre line [m]
    :param dash_period_m: dash plus gap [m] (Finnish practice: 3 m dash, 9 m gap)
    :param sidewalk_m: width of the pavement strip either side of the carriageway [m]
    :param parking_m: width of a parking strip along the right kerb [m] (0: none), drawn as
        asphalt between the carriageway and the right pavement
    """

    s_m: np.ndarray
    xy_m: np.ndarray
    left_normal: np.ndarray
    width_m: float
    lane_width_m: float
    dash_length_m: float = 3.0
    dash_period_m: float = 12.0
    sidewalk_m: float = 3.0
    parking_m: float = 0.0

    def points_at(self, s_m: np.ndarray, offset_m: float | np.ndarray) -> np.ndarray:
        """(N, 2) ENU points at arc lengths ``s_m`` and lateral offsets (positive left) [m]."""
        s = np.clip(np.asarray(s_m, float), self.s_m[0], self.s_m[-1])
        x = np.interp(s, self.s_m, self.xy_m[:, 0])
        y = np.interp(s, self.s_m, self.xy_m[:, 1])
        nx = np.interp(s, self.s_m, self.left_normal[:, 0])
        ny = np.interp(s, self.s_m, self.left_normal[:, 1])
        return np.column_stack((x + offset_m * nx, y + offset_m * ny))


@dataclass(frozen=True, slots=True)
class DrawnVehicle:
    """One vehicle to draw, in ENU.

    :param x_m, y_m: centre of the footprint [m]
    :param heading_rad: counter-clockwise from east [rad]
    :param style: "car" or "van" (body shape), ``color_bgr`` its paint
    """

    id: str
    x_m: float
    y_m: float
    heading_rad: float
    length_m: float
    width_m: float
    height_m: float
    color_bgr: tuple[int, int, int]
    style: str = "car"


@dataclass(frozen=True, slots=True)
class VehicleView:
    """What the camera sees of one vehicle in one frame.

    :param box_px: (x1, y1, x2, y2) of the drawn vehicle's projected outline (near-clipped),
        clipped to the image; None when nothing of it is in front of the camera and inside
        the image
    :param visible_fraction: share of its in-image silhouette not hidden by nearer vehicles
    :param in_image_fraction: share of its silhouette inside the image (1 = not truncated)
    :param range_m: longitudinal distance from the camera's ground point to its nearest
        footprint point along the ego x axis [m]
    :param lateral_m: ego-frame y of its centre [m], positive left
    :param in_front: all corners of its 3D box are in front of the camera (only then does
        :meth:`Camera.project_box` give a box)
    """

    id: str
    box_px: tuple[float, float, float, float] | None
    visible_fraction: float
    in_image_fraction: float
    range_m: float
    lateral_m: float
    in_front: bool = True


@dataclass(frozen=True, slots=True)
class Building:
    """A block of flats beside the road, for context (a detector judges a car partly by its
    surroundings, and facades give the scene texture and motion parallax).

    :param s0_m, s1_m: extent along the road [m]
    :param side: +1 left of the road, -1 right
    :param setback_m: distance of the facade from the road's centre line [m]
    :param depth_m, height_m: size [m]
    :param color_bgr: facade colour
    """

    s0_m: float
    s1_m: float
    side: float
    setback_m: float
    depth_m: float
    height_m: float
    color_bgr: tuple[int, int, int]


# --------------------------------------------------------------------------- clipping


def _clip_near(poly_cam: np.ndarray, z_near: float = NEAR_M) -> np.ndarray:
    """Sutherland-Hodgman clip of a (N, 3) camera-frame polygon to z >= ``z_near``."""
    z = poly_cam[:, 2]
    if (z >= z_near).all():
        return poly_cam
    if (z < z_near).all():
        return poly_cam[:0]
    out = []
    n = len(poly_cam)
    for i in range(n):
        a, b = poly_cam[i], poly_cam[(i + 1) % n]
        a_in, b_in = a[2] >= z_near, b[2] >= z_near
        if a_in:
            out.append(a)
        if a_in != b_in:
            t = (z_near - a[2]) / (b[2] - a[2])
            out.append(a + t * (b - a))
    return np.asarray(out) if out else poly_cam[:0]


# --------------------------------------------------------------------------- renderer


class SceneRenderer:
    """Draws frames of a flat road scene seen from a camera on the ego vehicle.

    Parameters
    ----------
    camera : Camera
        The dash-cam; its image size is the frame size. Distortion is ignored when drawing
        (edges are straight between projected vertices), so use an undistorted camera.
    road : RoadGeometry
        The road to draw (centerline, widths, marking pattern).
    buildings : list of Building, optional
        Facades along the road, drawn between the road and the vehicles.
    """

    def __init__(self, camera: Camera, road: RoadGeometry,
                 buildings: list[Building] | tuple[Building, ...] = ()):
        self.camera = camera
        self.road = road
        self._buildings = [self._building_quads(b) for b in buildings]
        self._w, self._h = camera.image_width, camera.image_height
        self._rot_veh_from_cam = camera.R_veh_from_cam
        self._cam_pos_veh = camera.position_veh_m
        self._background = self._make_background()
        self._models: dict[tuple, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}

    # ------------------------------------------------------------------ static layers

    def _make_background(self) -> np.ndarray:
        """Sky gradient above the horizon and grass below it (constant: the road is flat and
        the camera rigidly mounted, so the horizon never moves in the image)."""
        h, w = self._h, self._w
        horizon = self.camera.horizon_y_px()
        rows = np.arange(h, dtype=float)[:, None]
        sky_t = np.clip(rows / max(horizon, 1.0), 0.0, 1.0)
        sky = (np.array(SKY_TOP_BGR) * (1 - sky_t) + np.array(SKY_HORIZON_BGR) * sky_t)
        ground_t = np.clip((rows - horizon) / max(h - horizon, 1.0), 0.0, 1.0) ** 0.5
        ground = (np.array(GRASS_FAR_BGR) * (1 - ground_t) + np.array(GRASS_NEAR_BGR) * ground_t)
        col = np.where(rows < horizon, sky, ground)
        return np.ascontiguousarray(np.repeat(col[:, None, :], w, axis=1).astype(np.uint8))

    # ------------------------------------------------------------------ transforms

    def _enu_to_cam(self, pts_enu: np.ndarray, ego_xy: tuple[float, float],
                    ego_heading_rad: float) -> np.ndarray:
        """(N, 2 or 3) ENU points -> (N, 3) camera-frame points [m]."""
        p = np.asarray(pts_enu, float)
        if p.shape[-1] == 2:
            p = np.concatenate((p, np.zeros(p.shape[:-1] + (1,))), axis=-1)
        c, s = math.cos(ego_heading_rad), math.sin(ego_heading_rad)
        dx, dy = p[..., 0] - ego_xy[0], p[..., 1] - ego_xy[1]
        veh = np.stack((c * dx + s * dy, -s * dx + c * dy, p[..., 2]), axis=-1)
        # Row-vector form of R^T (p - t): camera coordinates of vehicle-frame points.
        return (veh - self._cam_pos_veh) @ self._rot_veh_from_cam

    def _project(self, p_cam: np.ndarray) -> np.ndarray:
        cam = self.camera
        z = p_cam[..., 2]
        return np.stack((cam.fx * p_cam[..., 0] / z + cam.cx,
                         cam.fy * p_cam[..., 1] / z + cam.cy), axis=-1)

    def _fill(self, img: np.ndarray, polys_cam: list[np.ndarray], color, convex: bool = False
              ) -> None:
        pts = []
        for poly in polys_cam:
            clipped = _clip_near(poly)
            if len(clipped) >= 3:
                pts.append(np.round(self._project(clipped) * _SCALE).astype(np.int32))
        if not pts:
            return
        color = tuple(int(c) for c in color)
        if convex and len(pts) == 1:
            cv2.fillConvexPoly(img, pts[0], color, cv2.LINE_AA, _SHIFT)
        else:
            cv2.fillPoly(img, pts, color, cv2.LINE_AA, shift=_SHIFT)

    # ------------------------------------------------------------------ road

    def _strip(self, s_m: np.ndarray, d0_m: float, d1_m: float, ego_xy, ego_heading
               ) -> np.ndarray:
        """Camera-frame polygon of the band between lateral offsets d0 and d1 along s."""
        a = self.road.points_at(s_m, d0_m)
        b = self.road.points_at(s_m[::-1], d1_m)
        return self._enu_to_cam(np.vstack((a, b)), ego_xy, ego_heading)

    def _draw_road(self, img: np.ndarray, ego_s_m: float, ego_xy, ego_heading: float) -> None:
        road = self.road
        s0 = max(road.s_m[0], ego_s_m - 10.0)
        s1 = min(road.s_m[-1], ego_s_m + DRAW_RANGE_M)
        if s1 <= s0:
            return
        # 1 m steps near the camera where curvature shows, coarser far away.
        s = np.unique(np.concatenate((np.arange(s0, min(s1, ego_s_m + 40.0), 1.0),
                                      np.arange(min(s1, ego_s_m + 40.0), s1, 3.0), [s1])))
        half = road.width_m / 2.0
        right = -half - road.parking_m
        self._fill(img, [self._strip(s, right - road.sidewalk_m, half + road.sidewalk_m,
                                     ego_xy, ego_heading)], SIDEWALK_BGR)
        self._fill(img, [self._strip(s, right, half, ego_xy, ego_heading)], ASPHALT_BGR)
        # Solid edge lines 0.3 m inside the kerbs, 0.15 m wide.
        for side in (-1.0, 1.0):
            d_out = side * (half - 0.3)
            d_in = side * (half - 0.45)
            self._fill(img, [self._strip(s, min(d_out, d_in), max(d_out, d_in), ego_xy,
                                         ego_heading)], MARKING_BGR)
        # Dashed lines between lanes, anchored to the road (they stream past as the ego moves,
        # which is what a vanishing-point or ego-motion estimator looks for).
        n_lanes = max(1, round(road.width_m / road.lane_width_m))
        offsets = [-half + k * road.lane_width_m for k in range(1, n_lanes)]
        k0 = math.floor(s0 / road.dash_period_m)
        k1 = math.ceil(s1 / road.dash_period_m)
        dashes = []
        for k in range(k0, k1 + 1):
            a = k * road.dash_period_m
            b = a + road.dash_length_m
            if b < s0 or a > s1:
                continue
            ds = np.array([max(a, s0), min(b, s1)])
            for d in offsets:
                dashes.append(self._strip(ds, d - 0.06, d + 0.06, ego_xy, ego_heading))
        self._fill(img, dashes, MARKING_BGR)

    # ------------------------------------------------------------------ buildings

    def _building_quads(self, b: Building) -> tuple[float, np.ndarray, np.ndarray, list]:
        """ENU quads of a building (facade, ends, windows) with normals and colours; the
        facade is straight between the road points at its two ends."""
        near = self.road.points_at(np.array([b.s0_m, b.s1_m]), b.side * b.setback_m)
        far = self.road.points_at(np.array([b.s0_m, b.s1_m]),
                                  b.side * (b.setback_m + b.depth_m))
        h = b.height_m

        def quad(p0, p1, z0, z1):
            return np.array([[p0[0], p0[1], z0], [p1[0], p1[1], z0],
                             [p1[0], p1[1], z1], [p0[0], p0[1], z1]])

        centre = np.array([*(near.mean(axis=0) + far.mean(axis=0)) / 2.0, h / 2.0])
        quads, colors = [], []
        quads.append(quad(near[0], near[1], 0.0, h))
        colors.append(shade(b.color_bgr, 0.9))
        quads.append(quad(near[0], far[0], 0.0, h))
        colors.append(shade(b.color_bgr, 0.7))
        quads.append(quad(near[1], far[1], 0.0, h))
        colors.append(shade(b.color_bgr, 0.7))
        # Windows: 1.4 m x 1.5 m every 3.2 m along the facade, one row per 3.3 m storey
        # above a ground floor of shop windows.
        facade = near[1] - near[0]
        length = float(np.hypot(*facade))
        unit = facade / max(length, 1e-9)
        normal_out = outward_normal(quads[0], centre)
        inset = 0.02 * normal_out[:2]
        n_win = int((length - 1.0) // 3.2)
        for storey in range(int((h - 1.0) // 3.3)):
            z0 = 1.0 + storey * 3.3 + (0.0 if storey == 0 else 0.6)
            z1 = z0 + (2.2 if storey == 0 else 1.5)
            for k in range(n_win):
                a = near[0] + unit * (1.0 + k * 3.2) + inset
                quads.append(quad(a, a + unit * (2.4 if storey == 0 else 1.4), z0, z1))
                colors.append(GLASS_BGR if (k + storey) % 3 else GLASS_SIDE_BGR)
        quads_arr = np.asarray(quads, float)
        normals = np.array([outward_normal(q, centre) for q in quads_arr[:3]]
                           + [normal_out] * (len(quads_arr) - 3))
        s_mid = (b.s0_m + b.s1_m) / 2.0
        return s_mid, quads_arr, normals, [tuple(int(c) for c in col) for col in colors]

    def _draw_buildings(self, img: np.ndarray, ego_s_m: float, ego_xy, ego_heading) -> None:
        visible = [bq for bq in self._buildings
                   if -60.0 < bq[0] - ego_s_m < DRAW_RANGE_M + 40.0]
        for _, quads, normals, colors in sorted(visible, key=lambda bq: -abs(bq[0] - ego_s_m)):
            self._draw_quads(img, quads, normals, colors, ego_xy, ego_heading, n_walls=3)

    def _draw_quads(self, img, quads_enu, normals_enu, colors, ego_xy, ego_heading,
                    n_walls: int | None = None) -> None:
        """Fill ENU quads in order with back-face culling and near clipping.

        ``colors`` is a list of BGR int tuples. Quads from index ``n_walls`` on (windows) must
        not overlap one another: they are filled in one ``fillPoly`` call per colour, which is
        what keeps a street of facades fast.
        """
        quads_cam = self._enu_to_cam(quads_enu, ego_xy, ego_heading)
        ce, se = math.cos(ego_heading), math.sin(ego_heading)
        n_veh = np.stack((ce * normals_enu[:, 0] + se * normals_enu[:, 1],
                          -se * normals_enu[:, 0] + ce * normals_enu[:, 1], normals_enu[:, 2]),
                         axis=-1)
        n_cam = n_veh @ self._rot_veh_from_cam
        # Back-face culling: a face is seen when the camera lies on its outer side, i.e. the
        # outward normal points against the ray from the camera to the face.
        facing = np.einsum("ij,ij->i", n_cam, quads_cam[:, 0, :]) < 0.0
        z_ok = quads_cam[..., 2] >= NEAR_M
        in_front = z_ok.all(axis=1)
        facing &= z_ok.any(axis=1)  # wholly behind the near plane: nothing to draw
        uv = np.zeros(quads_cam.shape[:2] + (2,), np.int32)
        if in_front.any():
            uv[in_front] = np.round(self._project(quads_cam[in_front]) * _SCALE
                                    ).astype(np.int32)
        n_walls = len(quads_cam) if n_walls is None else n_walls
        batches: dict[tuple[int, int, int], list[np.ndarray]] = {}
        for i in np.flatnonzero(facing):
            if i >= n_walls and in_front[i]:
                batches.setdefault(colors[i], []).append(uv[i])
            elif in_front[i]:
                cv2.fillConvexPoly(img, uv[i], colors[i], cv2.LINE_AA, _SHIFT)
            else:
                self._fill(img, [quads_cam[i]], colors[i], convex=True)
        for color, pts in batches.items():
            cv2.fillPoly(img, pts, color, cv2.LINE_AA, shift=_SHIFT)

    # ------------------------------------------------------------------ vehicles

    def _model(self, v: DrawnVehicle):
        key = (v.length_m, v.width_m, v.height_m, tuple(v.color_bgr), v.style)
        if key not in self._models:
            quads, normals, colors = vehicle_model(v.length_m, v.width_m, v.height_m,
                                                   v.color_bgr, v.style)
            self._models[key] = (quads, normals, [tuple(int(c) for c in col) for col in colors])
        return self._models[key]

    def _body_to_enu(self, v: DrawnVehicle, pts_body: np.ndarray) -> np.ndarray:
        c, s = math.cos(v.heading_rad), math.sin(v.heading_rad)
        x = v.x_m + c * pts_body[..., 0] - s * pts_body[..., 1]
        y = v.y_m + s * pts_body[..., 0] + c * pts_body[..., 1]
        return np.stack((x, y, pts_body[..., 2]), axis=-1)

    def _silhouette_px(self, v: DrawnVehicle, ego_xy, ego_heading
                       ) -> tuple[np.ndarray | None, bool]:
        """Projected vertices of the polygons drawn for the vehicle (its tyres, body and
        cabin: the outline a camera and an annotator see, not its 3D bounding box) after near
        clipping (None if nothing is in front), and whether its whole 3D box is in front of
        the camera."""
        quads, _, _ = self._model(v)
        hx, hy = v.length_m / 2.0, v.width_m / 2.0
        corners = np.array([[x, y, z] for x in (-hx, hx) for y in (-hy, hy)
                            for z in (0.0, v.height_m)])
        box_cam = self._enu_to_cam(self._body_to_enu(v, corners), ego_xy, ego_heading)
        whole = bool((box_cam[:, 2] >= NEAR_M).all())
        pts = []
        for quad in quads:
            cam = _clip_near(self._enu_to_cam(self._body_to_enu(v, quad), ego_xy, ego_heading))
            if len(cam):
                pts.append(self._project(cam))
        return (np.vstack(pts) if pts else None), whole

    def _draw_shadow(self, img: np.ndarray, v: DrawnVehicle, ego_xy, ego_heading) -> None:
        hx, hy = v.length_m / 2.0, v.width_m / 2.0
        for grow, color in ((0.28, SHADOW_OUTER_BGR), (0.06, SHADOW_INNER_BGR)):
            foot = np.array([[-hx - grow, -hy - grow, 0.0], [hx + grow, -hy - grow, 0.0],
                             [hx + grow, hy + grow, 0.0], [-hx - grow, hy + grow, 0.0]])
            cam = self._enu_to_cam(self._body_to_enu(v, foot), ego_xy, ego_heading)
            self._fill(img, [cam], color, convex=True)

    def _draw_vehicle(self, img: np.ndarray, v: DrawnVehicle, ego_xy, ego_heading) -> None:
        quads, normals, colors = self._model(v)
        c, s = math.cos(v.heading_rad), math.sin(v.heading_rad)
        n_enu = np.stack((c * normals[:, 0] - s * normals[:, 1],
                          s * normals[:, 0] + c * normals[:, 1], normals[:, 2]), axis=-1)
        self._draw_quads(img, self._body_to_enu(v, quads), n_enu, colors, ego_xy, ego_heading)

    # ------------------------------------------------------------------ frame

    def render(self, ego_xy: tuple[float, float], ego_heading_rad: float, ego_s_m: float,
               vehicles: list[DrawnVehicle], *, draw_road: bool = True,
               draw_shadows: bool = True) -> tuple[np.ndarray, list[VehicleView]]:
        """Draw one frame.

        Parameters
        ----------
        ego_xy : (float, float)
            ENU position of the ego's vehicle-frame origin (road point below the camera) [m].
        ego_heading_rad : float
            Ego heading, counter-clockwise from east [rad].
        ego_s_m : float
            Ego arc length along the road [m] (to choose which part of the road to draw).
        vehicles : list of DrawnVehicle
            Other vehicles in ENU.

        Returns
        -------
        image : (H, W, 3) uint8 BGR frame
        views : one :class:`VehicleView` per vehicle, in input order
        """
        img = self._background.copy()
        if draw_road:
            self._draw_road(img, ego_s_m, ego_xy, ego_heading_rad)
            self._draw_buildings(img, ego_s_m, ego_xy, ego_heading_rad)
        # Painter's order: far to near by distance from the camera's ground point.
        ce, se = math.cos(ego_heading_rad), math.sin(ego_heading_rad)
        info = []
        for v in vehicles:
            dx, dy = v.x_m - ego_xy[0], v.y_m - ego_xy[1]
            x_fwd, y_left = ce * dx + se * dy, -se * dx + ce * dy
            # Nearest footprint point along the ego x axis: the rear of a vehicle ahead.
            rel = v.heading_rad - ego_heading_rad
            half_extent_x = (abs(math.cos(rel)) * v.length_m + abs(math.sin(rel)) * v.width_m) / 2
            info.append((math.hypot(x_fwd, y_left), x_fwd, y_left, x_fwd - half_extent_x))
        # Half the vehicle's length inside the draw range still counts: its rear shows first.
        drawn = [i for i, v in enumerate(vehicles)
                 if info[i][1] > -v.length_m and info[i][0] < DRAW_RANGE_M + v.length_m]
        order = sorted(drawn, key=lambda i: -info[i][0])
        if draw_shadows:
            for i in order:
                self._draw_shadow(img, vehicles[i], ego_xy, ego_heading_rad)
        silhouettes: dict[int, np.ndarray] = {}
        whole: dict[int, bool] = {}
        for i in order:
            self._draw_vehicle(img, vehicles[i], ego_xy, ego_heading_rad)
            sil, whole[i] = self._silhouette_px(vehicles[i], ego_xy, ego_heading_rad)
            if sil is not None:
                silhouettes[i] = sil
        views = self._views(vehicles, info, order, silhouettes, whole)
        return img, views

    def _views(self, vehicles, info, order, silhouettes, whole) -> list[VehicleView]:
        """Pixel boxes and visibility from an id buffer of silhouettes at half resolution
        (occlusion shares need only a couple of per cent accuracy)."""
        w, h = self._w, self._h
        scale = 0.5
        ids = np.zeros((int(h * scale) + 1, int(w * scale) + 1), np.uint8)
        hulls: dict[int, np.ndarray] = {}
        for rank, i in enumerate(order, start=1):
            if i not in silhouettes:
                continue
            hull = cv2.convexHull(silhouettes[i].astype(np.float32)).reshape(-1, 2)
            hulls[i] = hull
            cv2.fillConvexPoly(ids, np.round(hull * scale * _SCALE).astype(np.int32), rank,
                               cv2.LINE_8, _SHIFT)
        counts = np.bincount(ids.ravel(), minlength=len(order) + 1)
        views = []
        rank_of = {i: r for r, i in enumerate(order, start=1)}
        for i, v in enumerate(vehicles):
            box = None
            visible = in_image = 0.0
            if i in hulls:
                sil = silhouettes[i]
                x1, y1 = sil.min(axis=0)
                x2, y2 = sil.max(axis=0)
                if not (x2 < 0 or y2 < 0 or x1 > w - 1 or y1 > h - 1):
                    box = (float(np.clip(x1, 0, w - 1)), float(np.clip(y1, 0, h - 1)),
                           float(np.clip(x2, 0, w - 1)), float(np.clip(y2, 0, h - 1)))
                    own = np.zeros_like(ids)
                    cv2.fillConvexPoly(own, np.round(hulls[i] * scale * _SCALE).astype(np.int32),
                                       1, cv2.LINE_8, _SHIFT)
                    n_own = int(own.sum())
                    visible = counts[rank_of[i]] / n_own if n_own else 0.0
                    full_area = float(cv2.contourArea(hulls[i].astype(np.float32)))
                    clipped = _clip_polygon_to_rect(hulls[i], w - 1, h - 1)
                    in_area = float(cv2.contourArea(clipped.astype(np.float32))) \
                        if len(clipped) >= 3 else 0.0
                    in_image = in_area / full_area if full_area > 0 else 0.0
            views.append(VehicleView(id=v.id, box_px=box,
                                     visible_fraction=min(1.0, visible),
                                     in_image_fraction=min(1.0, in_image),
                                     range_m=info[i][3], lateral_m=info[i][2],
                                     in_front=whole.get(i, False)))
        return views


def _clip_polygon_to_rect(poly: np.ndarray, x_max: float, y_max: float) -> np.ndarray:
    """Sutherland-Hodgman clip of a 2D polygon to [0, x_max] x [0, y_max]."""
    pts = [np.asarray(p, float) for p in poly]
    for axis, limit, keep_low in ((0, 0.0, False), (0, x_max, True), (1, 0.0, False),
                                  (1, y_max, True)):
        if not pts:
            break
        out = []
        n = len(pts)
        for k in range(n):
            a, b = pts[k], pts[(k + 1) % n]
            a_in = a[axis] <= limit if keep_low else a[axis] >= limit
            b_in = b[axis] <= limit if keep_low else b[axis] >= limit
            if a_in:
                out.append(a)
            if a_in != b_in:
                t = (limit - a[axis]) / (b[axis] - a[axis])
                out.append(a + t * (b - a))
        pts = out
    return np.asarray(pts) if pts else np.zeros((0, 2))
