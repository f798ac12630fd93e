"""A bird's-eye view of a scenario at one instant, drawn with OpenCV from ``scenario.json``.

The picture is turned so that the ego drives up it (ego-up), the ego a fixed point near the
bottom. The roads come from the scenario: each lane of a road's cross-section
(:mod:`vid2sim.core.lanelayout`) is a band beside the centerline, filled by its type
(driving, parking, shoulder, border, rail), with the markings a reader expects between them:
dashed between driving lanes of one direction, solid at the edges of the carriageway and
between the directions, the two rails of a track bed. Vehicles are their footprints
(length x width about their trajectory point, turned by their heading), each labelled with
its id; the lead is drawn red, a "ghost" (the recorded ego beside a policy's) as an outline.
A metres scale bar and a legend of the lane types shown stay in the corners.

No display and no highway-env: one ``numpy`` transform per polyline and OpenCV fills, so a
frame costs about a millisecond at video sizes (``benchmarks/bench_render.py``).

Frames: ENU metres in (x east, y north, heading counter-clockwise from east); a point's
offset (dx, dy) from the ego goes to ``forward = cos(h) dx + sin(h) dy``,
``left = -sin(h) dx + cos(h) dy`` and to the pixel ``(u0 - S left, v0 - S forward)`` with S
the scale [px/m].
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from vid2sim.core.lanelayout import BORDER, DRIVING, PARKING, RAIL, SHOULDER
from vid2sim.core.polyline import resample_polyline
from vid2sim.core.scenario import Road
from vid2sim.evaluate.replayconfig import BirdsEyeConfig

#: Fixed-point bits of the pixel coordinates handed to OpenCV (sub-pixel, anti-aliased lines).
_SHIFT = 4
_ONE = 1 << _SHIFT

#: Lane fills by type (BGR): asphalt grey for driving lanes, a bluer grey for parking, a
#: lighter one for shoulders, verge green for borders, ballast brown for track beds.
LANE_BGR = {DRIVING: (78, 78, 78), PARKING: (112, 98, 84), SHOULDER: (100, 104, 108),
            BORDER: (66, 104, 72), RAIL: (70, 92, 118)}
_GROUND_BGR = (52, 64, 52)
_WHITE = (235, 235, 235)
_YELLOW = (40, 200, 235)
_KERB = (150, 150, 150)
_RAIL_BGR = (190, 190, 200)
EGO_BGR = (70, 200, 70)
ACTOR_BGR = (220, 160, 70)
STATIC_BGR = (160, 140, 125)
LEAD_BGR = (60, 60, 235)
GHOST_BGR = (255, 255, 255)
DETECTED_BGR = (0, 165, 255)
#: Half the standard rail gauge (1435 mm) [m]: where the two rails of a track bed lie.
RAIL_HALF_GAUGE_M = 0.7175


@dataclass(frozen=True, slots=True)
class Mark:
    """A vehicle to draw: ENU pose of its footprint's centre [m, rad] and its size [m].

    ``kind``: ``ego``, ``actor``, ``static`` (a parked car), ``lead`` or ``ghost``.
    """

    id: str
    x_m: float
    y_m: float
    heading_rad: float
    length_m: float
    width_m: float
    kind: str = "actor"


def _left_normals(xy: np.ndarray) -> np.ndarray:
    """Unit normals to the left of a polyline's direction at each point."""
    d = np.gradient(xy, axis=0)
    n = np.hypot(d[:, 0], d[:, 1])
    n[n < 1e-9] = 1.0
    return np.column_stack((-d[:, 1] / n, d[:, 0] / n))


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, end) index pairs of the runs of True in ``mask`` (end exclusive)."""
    m = np.concatenate(([False], mask, [False])).astype(np.int8)
    d = np.diff(m)
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(),
                    strict=True))


@dataclass(slots=True)
class _RoadGeometry:
    """One road's lane edges in ENU: ``edges[k]`` the (N, 2) polyline of edge k (right to
    left), ``s_m`` the arc length of its points, lane types and the style of every edge."""

    centre: np.ndarray
    normal: np.ndarray
    edges_m: np.ndarray
    edges: np.ndarray
    s_m: np.ndarray
    lane_types: list[str]
    edge_styles: list[str]
    rails: list[np.ndarray]


def _edge_style(right, left) -> str:
    """How the edge between two lanes (LaneSpec or None beyond the road) is marked."""
    drive_r = right is not None and right.type == DRIVING
    drive_l = left is not None and left.type == DRIVING
    if drive_r and drive_l:
        return "dashed" if right.direction == left.direction else "centre"
    if drive_r or drive_l:
        return "solid"
    if right is None or left is None:
        return "kerb"
    return "none" if BORDER in (right.type, left.type) else "kerb"


def road_geometry(road: Road, sample_m: float) -> _RoadGeometry:
    """The lane edges, types, markings and rails of one road (see :class:`_RoadGeometry`)."""
    centre = resample_polyline(road.centerline, sample_m)
    normal = _left_normals(centre)
    layout = road.layout()
    edges = np.stack([centre + off * normal for off in layout.edges_m])
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(centre, axis=0).T))))
    lanes = list(layout.lanes)
    styles = [_edge_style(lanes[k - 1] if k > 0 else None, lanes[k] if k < len(lanes) else None)
              for k in range(len(lanes) + 1)]
    rails = [centre + (c + side * RAIL_HALF_GAUGE_M) * normal
             for c, lane in zip(layout.centres_m, lanes, strict=True) if lane.type == RAIL
             for side in (-1.0, 1.0)]
    return _RoadGeometry(centre, normal, np.asarray(layout.edges_m, float), edges, s,
                         [lane.type for lane in lanes], styles, rails)


def lane_edges_at(roads: Sequence[_RoadGeometry], x_m: float, y_m: float
                  ) -> tuple[np.ndarray, np.ndarray] | None:
    """The (N, 2) ENU polylines of the right and left edge of the lane holding the point
    (x, y) [m] on the nearest road, or None when the point lies on no lane of it."""
    best = None
    for geo in roads:
        d2 = (geo.centre[:, 0] - x_m) ** 2 + (geo.centre[:, 1] - y_m) ** 2
        i = int(np.argmin(d2))
        if best is None or d2[i] < best[0]:
            best = (float(d2[i]), geo, i)
    if best is None:
        return None
    _, geo, i = best
    offset = float(np.dot(np.array([x_m, y_m]) - geo.centre[i], geo.normal[i]))
    k = int(np.searchsorted(geo.edges_m, offset, side="right")) - 1
    if not 0 <= k < len(geo.lane_types):
        return None
    return geo.edges[k], geo.edges[k + 1]


def nice_length_m(max_m: float) -> float:
    """The largest 1, 2 or 5 x 10^k metres not above ``max_m`` (the scale bar's length)."""
    if not max_m > 0:
        return 1.0
    k = math.floor(math.log10(max_m))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0 ** k <= max_m:
            return m * 10.0 ** k
    return 10.0 ** k


class BirdsEye:
    """Draws the scene from above, ego-up, into pictures of ``width_px`` x ``height_px``.

    The roads are laid out once (:func:`road_geometry`); :meth:`draw` then costs one
    transform of the points near the ego per frame.
    """

    def __init__(self, roads: Sequence[Road], width_px: int, height_px: int,
                 config: BirdsEyeConfig | None = None):
        self.config = cfg = config or BirdsEyeConfig()
        self.width, self.height = int(width_px), int(height_px)
        margin = 0.04 * self.height
        self.scale = (self.height - 2 * margin) / (cfg.ahead_m + cfg.behind_m)
        self.origin_px = (self.width / 2.0, self.height - margin - cfg.behind_m * self.scale)
        # every point within this distance of the ego may be in the picture [m]
        self.reach_m = math.hypot(self.width / 2.0, self.height) / self.scale + 5.0
        self.roads = [road_geometry(r, cfg.sample_m) for r in roads]
        self.font = max(0.35, self.height / 1100.0)
        self._legend = sorted({t for g in self.roads for t in g.lane_types},
                              key=list(LANE_BGR).index)

    # ------------------------------------------------------------------ transform

    def _matrix(self, ego: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
        """(2, 2) matrix and offset taking ENU points to fixed-point pixels."""
        x, y, h = ego
        c, s, k = math.cos(h), math.sin(h), self.scale * _ONE
        m = np.array([[k * s, -k * c], [-k * c, -k * s]])
        u0, v0 = self.origin_px
        return m, np.array([u0 * _ONE, v0 * _ONE]) - np.array([x, y]) @ m

    def to_px(self, ego: tuple[float, float, float], xy_m: np.ndarray) -> np.ndarray:
        """ENU points (N, 2) [m] -> pixel coordinates (N, 2) [px, float] for the ego pose."""
        m, b = self._matrix(ego)
        return (np.asarray(xy_m, float) @ m + b) / _ONE

    # ------------------------------------------------------------------ drawing

    def draw(self, ego: tuple[float, float, float], marks: Sequence[Mark],
             detected: Sequence[tuple[float, float]] = (), title: str = "") -> np.ndarray:
        """The picture (BGR, ``height x width``) with the ego pose ``(x, y, heading)`` [m, rad]
        at its fixed point, the vehicles ``marks`` and, as small crosses, ``detected``
        positions given in the ego's vehicle frame (forward, left) [m]."""
        img = np.full((self.height, self.width, 3), _GROUND_BGR, np.uint8)
        m, b = self._matrix(ego)
        for geo in self.roads:
            self._draw_road(img, geo, ego, m, b)
        for mark in sorted(marks, key=lambda k: ("ghost", "static", "actor", "lead",
                                                 "ego").index(k.kind)
                           if k.kind in ("ghost", "static", "actor", "lead", "ego") else 2):
            self._draw_vehicle(img, mark, m, b)
        self._draw_detected(img, detected)
        self._draw_scale_bar(img)
        self._draw_legend(img, title)
        return img

    def _draw_road(self, img: np.ndarray, geo: _RoadGeometry, ego, m, b) -> None:
        near = np.hypot(*(geo.centre - np.array(ego[:2])).T) < self.reach_m + 0.5 * float(
            np.abs(geo.edges[[0, -1]] - geo.centre).max(initial=0.0))
        for a, e in _runs(near):
            if e - a < 2:
                continue
            px = [np.round(edge[a:e] @ m + b).astype(np.int32) for edge in geo.edges]
            for k, lane_type in enumerate(geo.lane_types):
                poly = np.vstack((px[k], px[k + 1][::-1]))
                cv2.fillPoly(img, [poly], LANE_BGR[lane_type], cv2.LINE_AA, _SHIFT)
            for rail in geo.rails:
                cv2.polylines(img, [np.round(rail[a:e] @ m + b).astype(np.int32)], False,
                              _RAIL_BGR, 1, cv2.LINE_AA, _SHIFT)
            for k, style in enumerate(geo.edge_styles):
                self._draw_edge(img, px[k], geo.s_m[a:e], style)

    def _draw_edge(self, img: np.ndarray, px: np.ndarray, s_m: np.ndarray, style: str) -> None:
        thick = max(1, round(0.15 * self.scale))  # a 12-15 cm line
        if style == "none":
            return
        if style == "dashed":
            cfg = self.config
            on = np.mod(s_m, cfg.dash_period_m) < cfg.dash_on_m
            dashes = [px[a:e + 1] for a, e in _runs(on) if e - a >= 1]
            cv2.polylines(img, dashes, False, _WHITE, thick, cv2.LINE_AA, _SHIFT)
            return
        colour = {"solid": _WHITE, "centre": _YELLOW, "kerb": _KERB}[style]
        cv2.polylines(img, [px], False, colour, thick if style != "kerb" else 1, cv2.LINE_AA,
                      _SHIFT)

    def _draw_vehicle(self, img: np.ndarray, mark: Mark, m, b) -> None:
        c, s = math.cos(mark.heading_rad), math.sin(mark.heading_rad)
        fwd, left = np.array([c, s]), np.array([-s, c])
        hl, hw = mark.length_m / 2.0, mark.width_m / 2.0
        centre = np.array([mark.x_m, mark.y_m])
        corners = np.array([centre + fl * hl * fwd + sl * hw * left
                            for fl, sl in ((1, 1), (1, -1), (-1, -1), (-1, 1))])
        poly = np.round(corners @ m + b).astype(np.int32)
        if mark.kind == "ghost":
            cv2.polylines(img, [poly], True, GHOST_BGR, 1, cv2.LINE_AA, _SHIFT)
        else:
            colour = {"ego": EGO_BGR, "lead": LEAD_BGR, "static": STATIC_BGR}.get(mark.kind,
                                                                                  ACTOR_BGR)
            cv2.fillConvexPoly(img, poly, colour, cv2.LINE_AA, _SHIFT)
            # the windscreen side: a dark bar across the front third
            front = np.round(np.array([centre + 0.45 * hl * fwd + sl * hw * 0.9 * left
                                       for sl in (1, -1)]) @ m + b).astype(np.int32)
            cv2.polylines(img, [front], False, (30, 30, 30), 1, cv2.LINE_AA, _SHIFT)
            if mark.kind == "lead":
                cv2.polylines(img, [poly], True, (255, 255, 255), 2, cv2.LINE_AA, _SHIFT)
        if mark.kind in ("ego", "ghost"):
            label = "ego" if mark.kind == "ego" else "log"
        else:
            label = mark.id + (" LEAD" if mark.kind == "lead" else "")
        u = int(poly[:, 0].max() / _ONE) + 3
        v = int(poly[:, 1].mean() / _ONE) + 4
        if -40 < u < self.width and 0 < v < self.height + 10:
            outlined_text(img, label, (u, v), self.font, (255, 255, 255))

    def _draw_detected(self, img: np.ndarray, detected: Sequence[tuple[float, float]]) -> None:
        u0, v0 = self.origin_px
        r = max(3, round(0.6 * self.scale))
        for fwd, left in detected:
            if not (math.isfinite(fwd) and math.isfinite(left)):
                continue
            u, v = round(u0 - self.scale * left), round(v0 - self.scale * fwd)
            if 0 <= u < self.width and 0 <= v < self.height:
                cv2.drawMarker(img, (u, v), DETECTED_BGR, cv2.MARKER_TILTED_CROSS, 2 * r, 2,
                               cv2.LINE_AA)

    def _draw_scale_bar(self, img: np.ndarray) -> None:
        metres = nice_length_m(self.config.scale_bar_share * self.width / self.scale)
        length = round(metres * self.scale)
        x0, y0 = 12, self.height - 14
        cv2.rectangle(img, (x0 - 4, y0 - 22), (x0 + length + 60, y0 + 8), (30, 30, 30),
                      cv2.FILLED)
        cv2.line(img, (x0, y0), (x0 + length, y0), _WHITE, 2)
        for x in (x0, x0 + length):
            cv2.line(img, (x, y0 - 5), (x, y0 + 4), _WHITE, 2)
        outlined_text(img, f"{metres:g} m", (x0 + length + 6, y0 + 4), self.font, _WHITE)

    def _draw_legend(self, img: np.ndarray, title: str) -> None:
        y = 6
        if title:
            outlined_text(img, title, (8, y + 14), self.font * 1.1, _WHITE)
            y += 22
        for lane_type in self._legend:
            cv2.rectangle(img, (8, y + 2), (24, y + 14), LANE_BGR[lane_type], cv2.FILLED)
            cv2.rectangle(img, (8, y + 2), (24, y + 14), (200, 200, 200), 1)
            outlined_text(img, lane_type, (30, y + 13), self.font, _WHITE)
            y += 17


def outlined_text(img: np.ndarray, text: str, org: tuple[int, int], scale: float,
                  colour: tuple[int, int, int], outline: tuple[int, int, int] = (15, 15, 15)
                  ) -> None:
    """Text with a dark outline, legible on any background. The outline is the same glyphs
    shifted by a pixel each way (a thicker stroke would advance wider and drift)."""
    x, y = int(org[0]), int(org[1])
    for dx, dy in ((-1, -1), (1, -1), (-1, 1), (1, 1)):
        cv2.putText(img, text, (x + dx, y + dy), cv2.FONT_HERSHEY_SIMPLEX, scale, outline, 1,
                    cv2.LINE_AA)
    cv2.putText(img, text, (x, y), cv2.FONT_HERSHEY_SIMPLEX, scale, colour, 1, cv2.LINE_AA)
