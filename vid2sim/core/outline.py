"""Vehicle outlines: the 3D points a camera sees of a vehicle, and the pixel box they span.

A detector's box hugs the visible vehicle, not a cuboid around it. Seen from behind, a car's
lowest visible points are its rear tyres where they meet the road (and the shadow under the
car), some 0.8 m ahead of the rear bumper, whose own lower edge is 0.3-0.5 m above the road;
its widest parts are the rear wheel arches, 0.8 m ahead of the rear face, and the mirrors,
2-3 m ahead of it; the rear face itself is narrower than the body (tail lamps and bumper
corners are drawn in). A camera 1.3-1.7 m above the road sees each of these at its own depth,
so the box of a car whose rear is at range Z reads neither Z at its bottom edge nor Z at its
sides: both cues read about Z + 0.8 m, and a cuboid model fitted to such boxes puts the car
too far away by that much (10-20 % at 4-8 m, negligible at 40 m).

:class:`OutlineShape` describes where those extremes lie relative to a vehicle's rear face and
size, per class (:data:`CLASS_SHAPES`, each number with its source); :func:`outline_points`
gives the points in the vehicle's own frame and :func:`outline_boxes` the pixel box of their
projection (the hull of what a camera sees), at any range, lateral offset and camera pitch.
The box's bottom is the lower of the tyre contact and the rear bumper's edge: the bumper hides
the contact exactly when its edge projects lower, so the hull needs no occlusion test.
:data:`CUBOID` is the old model (a box with its bottom at the rear face), kept for inputs that
are projected cuboids (KITTI label boxes) and for tests that show the difference.

Frames: the vehicle's own frame has x forward from its rear face, y left from its centre line,
z up from the road; it is placed in the ego's vehicle frame (x forward, y left, z up, origin on
the road below the camera) by the range of its rear face, the lateral offset of its centre and
its yaw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.core.records import VehicleCategory


@dataclass(frozen=True)
class OutlineShape:
    """Where a vehicle's visible extremes lie [m], relative to its rear face and body size.

    Parameters
    ----------
    rear_clearance_m : float
        Height of the rear face's lower edge above the road (bumper, underrun guard).
    rear_inset_m : float
        How much narrower the rear face is than the body on each side (tail lamps, rounded
        bumper corners).
    rear_top_frac : float
        Height of the rear face's top (boot lid, tailgate window base) as a share of the
        vehicle's height.
    contact_m : float
        Depth of the rear tyres' contact with the road ahead of the rear face (the rear
        overhang, ISO 612 dimension D, less half a contact patch).
    tyre_inset_m : float
        How far inside the body width the tyres' outer edges are, on each side.
    widest_m : float
        Depth of the widest body section (rear wheel arches, shoulders) ahead of the rear face.
    belt_frac : float
        Height of the widest section's top (the belt line) as a share of the height.
    roof_rear_m, roof_front_m : float
        The roof runs from ``roof_rear_m`` ahead of the rear face to ``roof_front_m`` behind
        the front end.
    roof_inset_m : float
        How much narrower the roof is than the body on each side (tumblehome).
    mirror_from_front_m, mirror_out_m, mirror_height_m : float
        Depth of the exterior mirrors behind the front end, how far they reach beyond the body
        width on each side, and their height above the road.
    front_contact_m : float
        Depth of the front tyres' contact behind the front end (front overhang).
    """

    rear_clearance_m: float
    rear_inset_m: float
    rear_top_frac: float
    contact_m: float
    tyre_inset_m: float
    widest_m: float
    belt_frac: float
    roof_rear_m: float
    roof_front_m: float
    roof_inset_m: float
    mirror_from_front_m: float
    mirror_out_m: float
    mirror_height_m: float
    front_contact_m: float

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not math.isfinite(v) or v < 0:
                raise ValueError(f"OutlineShape.{f.name} must be a finite value >= 0, got {v}")


# Sources of the class shapes (fleet means; one vehicle differs by the spreads noted):
# - Passenger cars. Rear overhang (ISO 612 "D", axle centre to rearmost point) of the
#   manufacturers' dimension sheets: small and compact hatchbacks 0.70-0.80 m (VW Polo VI,
#   VW Golf VIII, Toyota Yaris), saloons and estates 0.95-1.10 m (VW Passat B8, BMW 3 series
#   G20, Toyota Corolla saloon); the fleet mean is near 0.85 m, and the trailing edge of the
#   tyre's contact patch (about 0.15 m long) lies 0.07 m behind the axle, so the contact is
#   ~0.8 m ahead of the rear face. The widest section is the rear wheel arches, over the axle.
#   Body width excludes the mirrors, which add about 0.2 m in all (VW Golf VIII: 1.79 m,
#   2.07 m with mirrors; German fleet statistics of Dudenhoeffer, WiWo 2018: "about 20 cm on
#   top of every width"), sit at the A-pillar base ~1.6 m behind the front end and ~1.0 m
#   high. The rear face (tail lamp to tail lamp) is ~0.12 m narrower on each side: the VW
#   Polo cut out of KITTI tracking 0001/000010 shows a 1.45 m rear on a 1.68 m body. Rear
#   bumper lower edge 0.30-0.45 m above the road (departure angles of 15-25 deg over the
#   overhang); front overhang 0.85-0.95 m; roof from ~0.6 m (hatchback tailgate) behind to
#   ~1.6 m (bonnet and windscreen) before the ends, ~0.2 m narrower on each side.
# - Trucks (rigid delivery trucks and semi-trailers seen from behind): the box body is the
#   full 2.55 m legal width (EU 96/53/EC) and square; the rear underrun protection's lower
#   edge is at most 0.45-0.55 m above the road (UN ECE R58); the rear overhang behind the
#   last axle is 1.5-3 m (2 m taken); mirrors 0.25 m out at the cab, 2.2 m high.
# - Buses (12 m city buses, e.g. Mercedes Citaro, MAN Lion's City): rear overhang 3.2-3.6 m,
#   rear bumper 0.35 m, body 2.55 m nearly full width at the rear, mirrors 0.3 m out near
#   the front end at ~2.3 m height.
# - Trams (low-floor articulated trams: Siemens Avenio/Combino, Alstom Citadis, Bombardier
#   Flexity, the Karlsruhe NET 2012): the end car's face is full width (2.30-2.65 m) and
#   nearly full height, its lower edge ~0.35 m above the rail head; the first bogie sits
#   ~3.5 m behind each end; camera arms or mirrors reach ~0.25 m out at ~2.2 m.
# - Motorcycles: the rear wheel's contact ~0.25 m ahead of the rear fender, no bumper below
#   ~0.35 m, mirrors at the handlebar within the rider's width.
CAR_SHAPE = OutlineShape(rear_clearance_m=0.35, rear_inset_m=0.12, rear_top_frac=0.65,
                         contact_m=0.8, tyre_inset_m=0.05, widest_m=0.8, belt_frac=0.6,
                         roof_rear_m=0.6, roof_front_m=1.6, roof_inset_m=0.2,
                         mirror_from_front_m=1.6, mirror_out_m=0.1, mirror_height_m=1.0,
                         front_contact_m=0.9)
TRUCK_SHAPE = OutlineShape(rear_clearance_m=0.5, rear_inset_m=0.0, rear_top_frac=1.0,
                           contact_m=2.0, tyre_inset_m=0.05, widest_m=0.0, belt_frac=0.9,
                           roof_rear_m=0.0, roof_front_m=0.3, roof_inset_m=0.0,
                           mirror_from_front_m=0.8, mirror_out_m=0.25, mirror_height_m=2.2,
                           front_contact_m=1.4)
BUS_SHAPE = OutlineShape(rear_clearance_m=0.35, rear_inset_m=0.03, rear_top_frac=1.0,
                         contact_m=3.3, tyre_inset_m=0.05, widest_m=0.3, belt_frac=0.8,
                         roof_rear_m=0.1, roof_front_m=0.1, roof_inset_m=0.05,
                         mirror_from_front_m=0.2, mirror_out_m=0.3, mirror_height_m=2.3,
                         front_contact_m=2.7)
TRAM_SHAPE = OutlineShape(rear_clearance_m=0.35, rear_inset_m=0.05, rear_top_frac=1.0,
                          contact_m=3.5, tyre_inset_m=0.3, widest_m=0.0, belt_frac=0.85,
                          roof_rear_m=0.3, roof_front_m=0.3, roof_inset_m=0.15,
                          mirror_from_front_m=0.5, mirror_out_m=0.25, mirror_height_m=2.2,
                          front_contact_m=3.5)
MOTORCYCLE_SHAPE = OutlineShape(rear_clearance_m=0.35, rear_inset_m=0.1, rear_top_frac=0.7,
                                contact_m=0.25, tyre_inset_m=0.3, widest_m=0.6,
                                belt_frac=0.6, roof_rear_m=0.5, roof_front_m=0.7,
                                roof_inset_m=0.15, mirror_from_front_m=0.6, mirror_out_m=0.0,
                                mirror_height_m=1.1, front_contact_m=0.3)
#: A cuboid: bottom and full width at the rear face, top over the whole length.
CUBOID = OutlineShape(rear_clearance_m=0.0, rear_inset_m=0.0, rear_top_frac=1.0, contact_m=0.0,
                      tyre_inset_m=0.0, widest_m=0.0, belt_frac=1.0, roof_rear_m=0.0,
                      roof_front_m=0.0, roof_inset_m=0.0, mirror_from_front_m=0.0,
                      mirror_out_m=0.0, mirror_height_m=0.0, front_contact_m=0.0)

#: The outline of each detector class (a class not listed takes the car's).
CLASS_SHAPES: dict[VehicleCategory, OutlineShape] = {
    VehicleCategory.CAR: CAR_SHAPE, VehicleCategory.TRUCK: TRUCK_SHAPE,
    VehicleCategory.BUS: BUS_SHAPE, VehicleCategory.MOTORCYCLE: MOTORCYCLE_SHAPE,
    VehicleCategory.TRAM: TRAM_SHAPE,
}

_SHAPE_FIELDS = tuple(f.name for f in fields(OutlineShape))
#: Column of each :class:`OutlineShape` field in :func:`shape_matrix`'s rows.
OUTLINE_COLUMNS = {name: i for i, name in enumerate(_SHAPE_FIELDS)}


def shape_matrix(shapes: list[OutlineShape]) -> np.ndarray:
    """(N, F) matrix of the shapes' parameters, one row per vehicle, columns in the order of
    :class:`OutlineShape`'s fields (for vectorised outlines)."""
    return np.array([[getattr(s, k) for k in _SHAPE_FIELDS] for s in shapes],
                    dtype=float).reshape(-1, len(_SHAPE_FIELDS))


def shape_matrix_for(categories: list[str], shapes: dict[str, OutlineShape] | None = None
                     ) -> np.ndarray:
    """:func:`shape_matrix` of each category's shape (unknown categories: the car's)."""
    table = CLASS_SHAPES if shapes is None else shapes
    fallback = table.get(VehicleCategory.CAR, CAR_SHAPE)
    return shape_matrix([table.get(c, fallback) for c in categories])


def outline_points(width_m: np.ndarray, height_m: np.ndarray, length_m: np.ndarray,
                   shape_rows: np.ndarray) -> np.ndarray:
    """(N, P, 3) outline points [m] in each vehicle's own frame (x forward from the rear face,
    y left of the centre line, z up from the road).

    Per side (left and right): the rear face's lower and upper corners, the widest section at
    the road-clearance height and at the belt line, the rear and front tyres' contact, the
    roof's rear and front corners, the mirror, the widest section at the front and the front
    face's corners. Sizes are clipped so that no point lies outside the vehicle's length.
    """
    w = np.asarray(width_m, dtype=float)
    h = np.asarray(height_m, dtype=float)
    length = np.asarray(length_m, dtype=float)
    n = w.shape[0]
    shape = {k: shape_rows[:, i] for k, i in OUTLINE_COLUMNS.items()}
    half = w / 2
    c = np.minimum(shape["rear_clearance_m"], 0.5 * h)

    def lim(x: np.ndarray) -> np.ndarray:
        return np.clip(x, 0.0, length)

    front_wide = lim(length - shape["widest_m"])
    rows = [
        # (x, half-width, z) of one side's points
        (np.zeros(n), half - shape["rear_inset_m"], c),
        (np.zeros(n), half - shape["rear_inset_m"], np.maximum(shape["rear_top_frac"] * h, c)),
        (lim(shape["widest_m"]), half, c),
        (lim(shape["widest_m"]), half, shape["belt_frac"] * h),
        (lim(shape["contact_m"]), half - shape["tyre_inset_m"], np.zeros(n)),
        (lim(length - shape["front_contact_m"]), half - shape["tyre_inset_m"], np.zeros(n)),
        (lim(shape["roof_rear_m"]), half - shape["roof_inset_m"], h),
        (lim(length - shape["roof_front_m"]), half - shape["roof_inset_m"], h),
        (lim(length - shape["mirror_from_front_m"]), half + shape["mirror_out_m"],
         np.minimum(shape["mirror_height_m"], h)),
        (front_wide, half, c),
        (front_wide, half, shape["belt_frac"] * h),
        (length, half - shape["rear_inset_m"], c),
        (length, half - shape["rear_inset_m"], shape["belt_frac"] * h),
    ]
    xs = np.stack([r[0] for r in rows], axis=1)
    ys = np.stack([np.maximum(r[1], 0.0) for r in rows], axis=1)
    zs = np.stack([r[2] for r in rows], axis=1)
    pts = np.stack([np.concatenate([xs, xs], 1), np.concatenate([ys, -ys], 1),
                    np.concatenate([zs, zs], 1)], axis=-1)
    return pts


def place_points(points: np.ndarray, range_m: np.ndarray, lateral_m: np.ndarray,
                 length_m: np.ndarray, yaw_rad: np.ndarray | float = 0.0,
                 z_m: np.ndarray | float = 0.0) -> np.ndarray:
    """Own-frame outline points -> ego vehicle frame [m].

    A vehicle aligned with the ego (``yaw_rad`` 0) has its rear face at x = ``range_m`` and its
    centre line at y = ``lateral_m``; a yawed one is turned about its footprint's centre,
    which stays at (``range_m`` + length / 2, ``lateral_m``). ``z_m`` lifts it (road height).
    """
    n = points.shape[0]
    yaw = np.broadcast_to(np.asarray(yaw_rad, dtype=float), (n,))
    cx = np.asarray(range_m, dtype=float) + np.asarray(length_m, dtype=float) / 2
    x = points[..., 0] - np.asarray(length_m, dtype=float)[:, None] / 2
    y = points[..., 1]
    cs, sn = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    out = np.empty_like(points)
    out[..., 0] = cx[:, None] + cs * x - sn * y
    out[..., 1] = np.asarray(lateral_m, dtype=float)[:, None] + sn * x + cs * y
    out[..., 2] = points[..., 2] + np.broadcast_to(np.asarray(z_m, dtype=float), (n,))[:, None]
    return out


def vehicle_points(center_veh_m: np.ndarray, length_m: float, width_m: float, height_m: float,
                   yaw_rad: float, shape: OutlineShape) -> np.ndarray:
    """(P, 3) outline points of one vehicle in the ego vehicle frame [m], its footprint
    centred at ``center_veh_m`` (x, y[, z]) and yawed ``yaw_rad`` (as
    :meth:`Camera.box_corners_veh` places a cuboid)."""
    c = np.asarray(center_veh_m, dtype=float)
    local = outline_points(np.array([width_m]), np.array([height_m]), np.array([length_m]),
                           shape_matrix([shape]))
    return place_points(local, np.array([c[0] - length_m / 2]), np.array([c[1]]),
                        np.array([length_m]), yaw_rad, c[2] if c.size > 2 else 0.0)[0]


def outline_boxes(camera: Camera, range_m: np.ndarray, lateral_m: np.ndarray,
                  width_m: np.ndarray, height_m: np.ndarray, length_m: np.ndarray,
                  shape_rows: np.ndarray, yaw_rad: np.ndarray | float = 0.0,
                  z_m: np.ndarray | float = 0.0) -> np.ndarray:
    """(N, 4) pixel boxes (u1, v1, u2, v2) spanned by the vehicles' outlines (unclipped; NaN
    where a point lies behind the camera); ``shape_rows`` from :func:`shape_matrix`; ``z_m``
    the height of the ground each vehicle stands on above the ego's road plane [m]."""
    pts = place_points(outline_points(width_m, height_m, length_m, shape_rows), range_m,
                       lateral_m, length_m, yaw_rad, z_m)
    n, p, _ = pts.shape
    if any(camera.dist):
        uv, _ = camera.project(pts.reshape(-1, 3))
        u, v = uv[:, 0].reshape(n, p), uv[:, 1].reshape(n, p)
    else:
        # The pinhole written out on the (N, P) grid: the ranging's fit calls this for every
        # box and parameter of every Gauss-Newton step.
        q = (pts - camera.position_veh_m) @ camera.R_veh_from_cam
        z = q[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(z > 1e-6, 1.0 / z, np.nan)
        u = camera.fx * q[..., 0] * inv + camera.cx
        v = camera.fy * q[..., 1] * inv + camera.cy
    with np.errstate(invalid="ignore"):
        return np.stack([u.min(1), v.min(1), u.max(1), v.max(1)], axis=1)


def project_outline(camera: Camera, range_m: float, lateral_m: float, width_m: float,
                    height_m: float, length_m: float, shape: OutlineShape = CAR_SHAPE,
                    yaw_rad: float = 0.0, clip: bool = True
                    ) -> tuple[float, float, float, float] | None:
    """Pixel box (x1, y1, x2, y2) of one vehicle's outline (as :meth:`Camera.project_box`
    for a cuboid): None if any point is behind the camera or the box lies wholly outside the
    image; clipped to the image unless ``clip`` is False."""
    box = outline_boxes(camera, np.array([range_m]), np.array([lateral_m]), np.array([width_m]),
                        np.array([height_m]), np.array([length_m]), shape_matrix([shape]),
                        yaw_rad)[0]
    if not np.all(np.isfinite(box)):
        return None
    x1, y1, x2, y2 = (float(v) for v in box)
    if x2 < 0 or y2 < 0 or x1 > camera.image_width - 1 or y1 > camera.image_height - 1:
        return None
    if clip:
        x1, x2 = np.clip([x1, x2], 0, camera.image_width - 1)
        y1, y2 = np.clip([y1, y2], 0, camera.image_height - 1)
    return float(x1), float(y1), float(x2), float(y2)
