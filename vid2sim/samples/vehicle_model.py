"""Vehicle models of the synthetic renderer: the faces of a car body, cabin, wheels and decals.

A vehicle is a few boxes and frusta (wheels, lower body, cabin) in its own frame (x forward
from the rear bumper, y left, z up from the road), with shading and decals (rear window, tail
lights, plate, headlights), which is enough for a COCO detector to call it a car.
"""

from __future__ import annotations

import numpy as np


def box_faces(x0: float, x1: float, y0: float, y1: float, z0: float, z1: float
               ) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The six faces of an axis-aligned box as (name, (4, 3) corners, outward normal)."""
    return [
        ("rear", np.array([[x0, y0, z0], [x0, y1, z0], [x0, y1, z1], [x0, y0, z1]]),
         np.array([-1.0, 0, 0])),
        ("front", np.array([[x1, y0, z0], [x1, y0, z1], [x1, y1, z1], [x1, y1, z0]]),
         np.array([1.0, 0, 0])),
        ("right", np.array([[x0, y0, z0], [x0, y0, z1], [x1, y0, z1], [x1, y0, z0]]),
         np.array([0, -1.0, 0])),
        ("left", np.array([[x0, y1, z0], [x1, y1, z0], [x1, y1, z1], [x0, y1, z1]]),
         np.array([0, 1.0, 0])),
        ("top", np.array([[x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]]),
         np.array([0, 0, 1.0])),
        ("bottom", np.array([[x0, y0, z0], [x0, y1, z0], [x1, y1, z0], [x1, y0, z0]]),
         np.array([0, 0, -1.0])),
    ]


# Shading by face orientation: light from above and slightly behind the camera, so tops are
# brightest, rears/fronts next, sides darkest (the classic three-tone look of a lit box).
_SHADE = {"top": 1.0, "rear": 0.82, "front": 0.82, "right": 0.62, "left": 0.62, "bottom": 0.3}
_TYRE_BGR = (28, 28, 30)
GLASS_BGR = (90, 80, 72)
GLASS_SIDE_BGR = (80, 68, 60)
_TAIL_LIGHT_BGR = (40, 40, 170)
_HEAD_LIGHT_BGR = (205, 235, 245)
_PLATE_BGR = (225, 228, 230)
# Car shape: beltline height as a share of the roof height; cabin setbacks [m] from the rear
# and front of the body at the beltline and at the roof, and the roof's inset from the sides.
_BELT_FRAC = 0.6
_CABIN = (0.3, 1.3, 1.0, 2.1, 0.28)
_BUMPER_BGR = (45, 45, 48)


def shade(color: tuple[int, int, int], factor: float) -> tuple[int, int, int]:
    return tuple(int(min(255, round(c * factor))) for c in color)  # type: ignore[return-value]


def _decal(face_x: float, sign: float, y0: float, y1: float, z0: float, z1: float
           ) -> tuple[np.ndarray, np.ndarray]:
    """A rectangle on the rear (sign -1) or front (sign +1) face at x = ``face_x``, pushed
    1 cm outwards so it is unambiguously in front of its face."""
    x = face_x + sign * 0.01
    corners = np.array([[x, y0, z0], [x, y1, z0], [x, y1, z1], [x, y0, z1]])
    return corners, np.array([sign, 0.0, 0.0])


def vehicle_model(length_m: float, width_m: float, height_m: float,
                  color_bgr: tuple[int, int, int], style: str = "car"
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Polygons of a simple vehicle in its body frame (x forward, y left, z up, origin at the
    centre of the footprint on the road), in drawing order.

    :return: (P, 4, 3) quad corners [m], (P, 3) outward normals, (P, 3) BGR colours
    """
    L, W, H = length_m, width_m, height_m
    hx, hy = L / 2.0, W / 2.0
    polys = _Polygons()
    clearance = 0.28 if style == "car" else 0.35
    # Wheels first: the body drawn afterwards hides their upper part, leaving the dark
    # tyres visible under the bumper and along the sills as on a real car.
    _add_wheels(polys, hx, hy, L, wheel_r=0.33 if style == "car" else 0.36)
    if style == "van":
        body_top = 0.97 * H
        polys.add_box(-hx, hx, -hy, hy, clearance, body_top, color_bgr)
        # Rear doors' windows high up, a dark windscreen band on the front.
        polys.add_decal(_decal(-hx, -1, -hy + 0.12, -0.04, 0.62 * H, 0.86 * H), GLASS_BGR)
        polys.add_decal(_decal(-hx, -1, 0.04, hy - 0.12, 0.62 * H, 0.86 * H), GLASS_BGR)
        polys.add_decal(_decal(hx, 1, -hy + 0.1, hy - 0.1, 0.58 * H, 0.9 * H), GLASS_BGR)
        light_z = (0.28 * H, 0.42 * H)
        plate_z = (0.22 * H, 0.28 * H)
    else:
        body_top = _BELT_FRAC * H
        polys.add_box(-hx, hx, -hy, hy, clearance, body_top, color_bgr)
        light_z = (body_top - 0.22, body_top - 0.06)
        plate_z = (clearance + 0.12, clearance + 0.26)
    _add_lights_and_plates(polys, hx, hy, clearance, light_z, plate_z)
    if style != "van":
        _add_cabin(polys, hx, hy, body_top, H, color_bgr)
    return (np.asarray(polys.quads, float), np.asarray(polys.normals, float),
            np.asarray(polys.colors, float))


class _Polygons:
    """A vehicle's quads, outward normals and colours, in drawing order."""

    def __init__(self) -> None:
        self.quads: list[np.ndarray] = []
        self.normals: list[np.ndarray] = []
        self.colors: list[tuple[int, int, int]] = []

    def add(self, corners: np.ndarray, normal: np.ndarray, color: tuple[int, int, int]) -> None:
        self.quads.append(corners)
        self.normals.append(normal)
        self.colors.append(color)

    def add_box(self, x0, x1, y0, y1, z0, z1, color) -> None:
        """A box's faces shaded by orientation (its bottom is never seen from above)."""
        for name, corners, n in box_faces(x0, x1, y0, y1, z0, z1):
            if name != "bottom":
                self.add(corners, n, shade(color, _SHADE[name]))

    def add_decal(self, corners_normal: tuple[np.ndarray, np.ndarray], color) -> None:
        self.add(corners_normal[0], corners_normal[1], color)


def _add_wheels(polys: _Polygons, hx: float, hy: float, length_m: float,
                wheel_r: float) -> None:
    """Four tyres, their axles ``min(0.85 m, 20 % of the length)`` in from the bumpers."""
    axle = min(0.85, 0.2 * length_m)
    for ax in (-hx + axle, hx - axle):
        for side in (-1.0, 1.0):
            y_out = side * (hy - 0.02)
            y_in = side * (hy - 0.27)
            polys.add_box(ax - wheel_r, ax + wheel_r, min(y_out, y_in), max(y_out, y_in),
                          0.0, 2 * wheel_r, _TYRE_BGR)


def _add_lights_and_plates(polys: _Polygons, hx: float, hy: float, clearance: float,
                           light_z: tuple[float, float], plate_z: tuple[float, float]) -> None:
    """Rear: bumper band, tail lights at the outer corners, a light plate in the middle;
    front: headlights and a dark grille band."""
    polys.add_decal(_decal(-hx, -1, -hy + 0.02, hy - 0.02, clearance, clearance + 0.12),
                    _BUMPER_BGR)
    for side in (-1.0, 1.0):
        y_a, y_b = side * (hy - 0.04), side * (hy - 0.38)
        polys.add_decal(_decal(-hx, -1, min(y_a, y_b), max(y_a, y_b), *light_z),
                        _TAIL_LIGHT_BGR)
        polys.add_decal(_decal(hx, 1, min(y_a, y_b), max(y_a, y_b), *light_z),
                        _HEAD_LIGHT_BGR)
    polys.add_decal(_decal(-hx, -1, -0.26, 0.26, *plate_z), _PLATE_BGR)
    polys.add_decal(_decal(hx, 1, -0.42, 0.42, plate_z[0], light_z[1] - 0.04), _BUMPER_BGR)


def _add_cabin(polys: _Polygons, hx: float, hy: float, body_top: float, height_m: float,
               color_bgr: tuple[int, int, int]) -> None:
    """The cabin (greenhouse): a frustum on the body, its rear window and windscreen raked and
    its sides drawn in (tumblehome), glass all round, roof in body colour. A box here reads as
    a pickup's cab; the rake is what makes the outline a saloon's."""
    bottom = (-hx + _CABIN[0], hx - _CABIN[1], hy - 0.08, body_top)
    top = (-hx + _CABIN[2], hx - _CABIN[3], hy - _CABIN[4], height_m)
    glass = {"rear": GLASS_BGR, "front": GLASS_BGR, "right": GLASS_SIDE_BGR,
             "left": GLASS_SIDE_BGR}
    inside = np.array([0.0, 0.0, (body_top + height_m) / 2])
    for name, corners in _frustum_faces(bottom, top):
        n = outward_normal(corners, inside)
        polys.add(corners, n, shade(color_bgr, _SHADE[name]))
        if name in glass:
            # The window inset in its frame: body-coloured pillars and roof edge around
            # dark glass are much of what makes a rear view read as a car.
            polys.add(_inset(corners, 0.14 if name in ("rear", "front") else 0.08, 0.12)
                      + 0.01 * n, n, glass[name])


def _frustum_faces(bottom: tuple[float, float, float, float],
                   top: tuple[float, float, float, float]) -> list[tuple[str, np.ndarray]]:
    """Rear, front, right, left and top quads of a solid between two centred rectangles,
    each given as (x_rear, x_front, half_width, z)."""
    def ring(r):
        x0, x1, hw, z = r
        return np.array([[x0, -hw, z], [x0, hw, z], [x1, hw, z], [x1, -hw, z]])

    b, t = ring(bottom), ring(top)
    return [
        ("rear", np.array([b[0], b[1], t[1], t[0]])),
        ("front", np.array([b[3], t[3], t[2], b[2]])),
        ("right", np.array([b[0], t[0], t[3], b[3]])),
        ("left", np.array([b[1], b[2], t[2], t[1]])),
        ("top", np.array([t[0], t[1], t[2], t[3]])),
    ]


def _inset(quad: np.ndarray, side_frac: float, top_frac: float) -> np.ndarray:
    """A face quad (two corners at its bottom, two at its top) shrunk towards its centre:
    ``side_frac`` of its width from each side, ``top_frac`` of its height from the top and
    a thin sill at the bottom; the winding is kept."""
    zs = quad[:, 2]
    ib = np.argsort(zs, kind="stable")[:2]
    it = np.array([k for k in range(4) if k not in ib])
    # Pair each bottom corner with the top corner on its side (the nearer one).
    if (np.linalg.norm(quad[ib[0]] - quad[it[0]])
            > np.linalg.norm(quad[ib[0]] - quad[it[1]])):
        it = it[::-1]
    out = quad.copy()
    for k in range(2):
        o = 1 - k
        b = quad[ib[k]] + side_frac * (quad[ib[o]] - quad[ib[k]])
        t = quad[it[k]] + side_frac * (quad[it[o]] - quad[it[k]])
        out[ib[k]] = b + 0.06 * (t - b)
        out[it[k]] = t + top_frac * (b - t)
    return out


def outward_normal(quad: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """Unit normal of a planar quad, oriented away from a point inside the solid."""
    n = np.cross(quad[1] - quad[0], quad[2] - quad[0])
    n = n / np.linalg.norm(n)
    return n if np.dot(n, quad[0] - inside) > 0 else -n
