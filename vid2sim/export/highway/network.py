"""Road network of the replay: ENU <-> highway-env frames, lanes, the ego's reference path.

Frames. The scenario is in ENU (x east, y north, heading counter-clockwise from east).
highway-env draws with the screen's y axis pointing DOWN, and its lane geometry
(``PolyLaneFixedWidth``) puts positive lateral offsets at ``(-sin h, cos h)``, i.e. to the
right of travel on screen. We map

    x_hw = x_enu,   y_hw = -y_enu,   heading_hw = -heading_enu

which is a reflection: a left turn in ENU (heading increasing) is a heading that decreases in
highway-env's numbers and still turns left on screen. Every conversion goes through
:func:`enu_to_hw` / :func:`hw_to_enu`.

Lane numbers. The project numbers lanes from the RIGHT: lane 0 is the rightmost lane in the
travel direction, counting leftwards (as the road stage does). highway-env numbers the lanes
of an edge in the order they were added and its ``LANE_RIGHT`` action means index + 1, so
inside the network the lanes are added left to right (highway-env index 0 = the leftmost).
:func:`project_lane` and :func:`hw_lane` convert at the boundary; everything the environment
reports (``info["ego_lane"]``, the sensor's lanes) uses the project's numbers.

Lane types. A road's cross-section (:meth:`vid2sim.core.scenario.Road.layout`) puts its forward
driving lanes on the edge ``road{i}:start -> road{i}:end`` (the lanes the ego and IDM/MOBIL
drivers use and the numbers above count), its backward driving lanes on their own edge drawn
in their travel direction, and every parking strip, shoulder, border and track bed on an edge
of its own, so that highway-env's lane changes and route planning never enter them while a
replayed vehicle standing in one is on a lane of the network. highway-env's lanes have no
type: :class:`ScenarioLane` carries ``lane_type`` and ``direction``.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
from highway_env.road.lane import LineType, PolyLaneFixedWidth
from highway_env.road.road import RoadNetwork

from vid2sim.core.lanelayout import BACKWARD, BORDER, DRIVING, FORWARD, PARKING, RAIL, CrossSection
from vid2sim.core.scenario import Road

ROAD_EXTENSION_M = 50.0
"""Straight extension of each road end in the simulation [m] (the scenario is unchanged)."""
LANE_SAMPLE_M = 1.0
"""Resampling step of lane polylines [m] (highway-env samples its curves at 1 m too)."""
_COARSE_STEP = 10  # samples between coarse search points of ScenarioLane
_WINDOW = 40  # fine search half-window of ScenarioLane [samples]


# --------------------------------------------------------------------------- frames


def enu_to_hw(x_m, y_m, heading_rad=None):
    """ENU -> highway-env coordinates (y axis down): ``(x, -y[, -heading])``."""
    if heading_rad is None:
        return np.asarray(x_m, float), -np.asarray(y_m, float)
    return np.asarray(x_m, float), -np.asarray(y_m, float), -np.asarray(heading_rad, float)


def hw_to_enu(x_m, y_m, heading_rad=None):
    """highway-env -> ENU coordinates; the reflection is its own inverse."""
    return enu_to_hw(x_m, y_m, heading_rad)


def project_lane(hw_index: int, lanes: int) -> int:
    """highway-env lane index (0 = leftmost) -> project lane number (0 = rightmost)."""
    return int(lanes) - 1 - int(hw_index)


def hw_lane(project_index: int, lanes: int) -> int:
    """Project lane number (0 = rightmost) -> highway-env lane index (0 = leftmost)."""
    return int(lanes) - 1 - int(project_index)


# --------------------------------------------------------------------------- lanes


class ScenarioLane(PolyLaneFixedWidth):
    """A ``PolyLaneFixedWidth`` whose world -> lane projection is vectorised.

    highway-env's own ``cartesian_to_frenet`` scans the 1 m curve samples in a Python loop from
    the end and takes the first with a non-negative projection, which costs O(length) Python
    steps per call (called for every vehicle, lane and step) and picks the wrong branch on
    curves that come back on themselves. Here the nearest sampled segment wins, in numpy.
    """

    def __init__(self, lane_points, width: float, line_types, speed_limit: float = 30.0,
                 lane_type: str = DRIVING, direction: str = FORWARD):
        super().__init__(lane_points, width=width, line_types=line_types,
                         speed_limit=speed_limit)
        #: the cross-section's lane type (``driving``, ``parking``, ``shoulder``, ``border``,
        #: ``rail``) and direction relative to its road's centerline
        self.lane_type, self.direction = lane_type, direction
        poses = self.curve.poses
        p = np.array([q.position for q in poses])  # (N, 2) sample positions, 1 m apart
        t = np.array([q.normal for q in poses])  # unit tangents
        self._px, self._py, self._tx, self._ty = p[:, 0], p[:, 1], t[:, 0], t[:, 1]
        self._s = np.asarray(self.curve.s_samples, float)
        # Segment i runs from sample i to sample i+1; the first extends backwards and the last
        # forwards without bound, matching highway-env's extrapolation beyond the ends.
        self._seg_len = np.append(np.diff(self._s), np.inf)
        self._coarse = np.arange(0, len(self._s), _COARSE_STEP)

    def local_coordinates(self, position: np.ndarray) -> tuple[float, float]:
        x, y = float(position[0]), float(position[1])
        # Coarse-to-fine: the nearest every-10th sample, then an exact search in a window
        # around it. The window (+-_WINDOW samples, 1 m each) covers points up to ~15 m off the
        # lane exactly; farther points (other roads) still get a nearby, consistent answer.
        c = self._coarse
        j = int(c[np.argmin((self._px[c] - x) ** 2 + (self._py[c] - y) ** 2)])
        lo, hi = max(j - _WINDOW, 0), min(j + _WINDOW + 1, len(self._s))
        dx, dy = x - self._px[lo:hi], y - self._py[lo:hi]
        tx, ty = self._tx[lo:hi], self._ty[lo:hi]
        along = dx * tx + dy * ty
        low = np.zeros_like(along)
        if lo == 0:
            low[0] = -np.inf
        clamped = np.minimum(np.maximum(along, low), self._seg_len[lo:hi])  # np.clip is slower
        # squared distance from the point to its clamped foot on each segment
        dist2 = dx * dx + dy * dy - 2 * clamped * along + clamped**2
        i = int(np.argmin(dist2))
        # lateral positive along (-t_y, t_x), the same side as PolyLaneFixedWidth.position()
        lat = -dx[i] * ty[i] + dy[i] * tx[i]
        return float(self._s[lo + i] + along[i]), float(lat)

    def heading_at(self, longitudinal: float) -> float:
        # the same piecewise-constant heading as highway-env's, found by bisection
        i = min(max(int(np.searchsorted(self._s, longitudinal, side="right")) - 1, 0),
                len(self._s) - 1)
        return float(math.atan2(self._ty[i], self._tx[i]))

    def pose_at(self, longitudinal: float) -> tuple[np.ndarray, float]:
        """Centre-line point and heading at ``longitudinal`` [m]: the point on the 1 m sampled
        polyline (straight beyond both ends) and a heading interpolated between the segments'
        headings at their midpoints, so a vehicle moved along the lane turns smoothly
        (``heading_at`` is piecewise constant, as highway-env's)."""
        if not hasattr(self, "_mid_s"):
            self._mid_s = self._s + 0.5 * np.append(np.diff(self._s), 1.0)
            self._heading_unwrapped = np.unwrap(np.arctan2(self._ty, self._tx))
        i = min(max(int(np.searchsorted(self._s, longitudinal, side="right")) - 1, 0),
                len(self._s) - 1)
        ds = longitudinal - self._s[i]
        point = np.array([self._px[i] + ds * self._tx[i], self._py[i] + ds * self._ty[i]])
        return point, float(np.interp(longitudinal, self._mid_s, self._heading_unwrapped))


def _resample_polyline(points_m: np.ndarray, step_m: float) -> np.ndarray:
    """Points along a polyline every ``step_m`` or less (ends kept; repeated points dropped)."""
    p = np.asarray(points_m, float).reshape(-1, 2)
    keep = np.r_[True, np.linalg.norm(np.diff(p, axis=0), axis=1) > 1e-6]
    p = p[keep]
    if len(p) < 2:
        raise ValueError("a centerline needs two distinct points")
    s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))]
    n = max(math.ceil(s[-1] / step_m), 1)
    s_new = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack((np.interp(s_new, s, p[:, 0]), np.interp(s_new, s, p[:, 1])))


def _extend_ends(points_m: np.ndarray, extension_m: float, step_m: float,
                 extension_end_m: float | None = None) -> np.ndarray:
    """Prolong a polyline straight along its end tangents by ``extension_m`` at the start and
    ``extension_end_m`` (default the same) at the end."""
    p = points_m
    ext_end = extension_m if extension_end_m is None else extension_end_m
    n0 = max(math.ceil(extension_m / step_m), 1)
    n1 = max(math.ceil(ext_end / step_m), 1)
    k0 = np.linspace(extension_m, 0.0, n0 + 1)[:-1, None]
    k1 = np.linspace(0.0, ext_end, n1 + 1)[1:, None]
    t0 = (p[1] - p[0]) / np.linalg.norm(p[1] - p[0])
    t1 = (p[-1] - p[-2]) / np.linalg.norm(p[-1] - p[-2])
    return np.vstack((p[0] - k0 * t0, p, p[-1] + k1 * t1))


def _left_normals(points_m: np.ndarray) -> np.ndarray:
    """Unit normals pointing to the LEFT of travel in ENU: the tangent rotated +90 deg."""
    tangent = np.gradient(points_m, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    return np.column_stack((-tangent[:, 1], tangent[:, 0]))


def layout_centerlines_enu(road: Road, extension_m: float = ROAD_EXTENSION_M
                           ) -> list[np.ndarray]:
    """Centre polylines in ENU [m] of every lane of a road's cross-section, rightmost first
    (:meth:`Road.layout`), each in the direction of the road's centerline."""
    centre = _resample_polyline(road.centerline, LANE_SAMPLE_M)
    if extension_m > 0:
        centre = _extend_ends(centre, extension_m, LANE_SAMPLE_M)
    normal = _left_normals(centre)
    return [centre + offset_left_m * normal for offset_left_m in road.layout().centres_m]


def lane_centerlines_enu(road: Road, extension_m: float = ROAD_EXTENSION_M) -> list[np.ndarray]:
    """Centre polylines of a road's forward driving lanes in ENU [m], indexed by the project's
    lane number (element 0 is the rightmost lane in the travel direction).

    Without a cross-section the lanes lie symmetrically about the road centerline.
    """
    every = layout_centerlines_enu(road, extension_m)
    return [every[i] for i in road.layout().forward_driving()]


def _line_types(k_hw: int, lanes: int) -> tuple[int, int]:
    # (left, right) in travel direction for highway-env lane k_hw (0 = leftmost):
    # highway-env draws line_types[0] at lateral -w/2, which after the y flip is the ENU left
    # side. Dashed lines are drawn once, on the right of a lane. Solid edges are CONTINUOUS
    # (drawn piecewise along the curve): CONTINUOUS_LINE is drawn as one straight segment and
    # cuts across curved roads.
    left = LineType.CONTINUOUS if k_hw == 0 else LineType.NONE
    right = LineType.CONTINUOUS if k_hw == lanes - 1 else LineType.STRIPED
    return left, right


#: How the edges of the lanes other than the forward driving ones are drawn (left, right in
#: the lane's own direction): parking strips and shoulders end at a kerb line, track beds
#: show their rails as striped lines, borders nothing.
_OTHER_LINES = {PARKING: (LineType.NONE, LineType.CONTINUOUS),
                RAIL: (LineType.STRIPED, LineType.STRIPED),
                BORDER: (LineType.NONE, LineType.NONE)}


def _hw_lane(points_enu: np.ndarray, width_m: float, line_types, lane_type: str,
             direction: str) -> ScenarioLane:
    pts = points_enu[::-1] if direction == BACKWARD else points_enu
    x_hw, y_hw = enu_to_hw(pts[:, 0], pts[:, 1])
    return ScenarioLane(list(zip(x_hw.tolist(), y_hw.tolist(), strict=True)), width=width_m,
                        line_types=line_types, lane_type=lane_type, direction=direction)


def build_network(roads: list[Road]) -> RoadNetwork:
    """A highway-env road network of the roads' cross-sections (see the module docstring).

    Edge ``road{i}:start -> road{i}:end`` holds road ``i``'s forward driving lanes in
    highway-env's order (index 0 = the leftmost; :func:`project_lane` converts); its backward
    driving lanes are on ``road{i}:back:start -> road{i}:back:end`` (leftmost in their own
    direction first); each other lane ``k`` of the cross-section (rightmost 0) is on
    ``road{i}:{type}{k}:start -> ...:end``. Every edge has nodes of its own, so no route
    leads from one to another.
    """
    net = RoadNetwork()
    for i, road in enumerate(roads):
        layout: CrossSection = road.layout()
        lines = layout_centerlines_enu(road)
        forward = layout.forward_driving()
        for k_hw in range(len(forward)):
            k = forward[hw_lane(k_hw, len(forward))]
            net.add_lane(f"road{i}:start", f"road{i}:end", _hw_lane(
                lines[k], layout.lanes[k].width_m, _line_types(k_hw, len(forward)), DRIVING,
                FORWARD))
        backward = layout.indices(DRIVING, BACKWARD)  # rightmost first = leftmost for them
        for k_hw, k in enumerate(backward):
            net.add_lane(f"road{i}:back:start", f"road{i}:back:end", _hw_lane(
                lines[k], layout.lanes[k].width_m, _line_types(k_hw, len(backward)), DRIVING,
                BACKWARD))
        for k, spec in enumerate(layout.lanes):
            if spec.type == DRIVING:
                continue
            net.add_lane(f"road{i}:{spec.type}{k}:start", f"road{i}:{spec.type}{k}:end",
                         _hw_lane(lines[k], spec.width_m,
                                  _OTHER_LINES.get(spec.type, _OTHER_LINES[PARKING]),
                                  spec.type, spec.direction))
    return net


def nearby_lane_index(network: RoadNetwork, lane_index, position: np.ndarray,
                      heading: float | None = None):
    """The lane a vehicle last known on ``lane_index`` is on now: that lane if it is still on
    it, else the lane of the same road its lateral offset points to (the outer lane when it is
    at most a lane width beyond the road's edge), else highway-env's search over every lane.

    ``(lane_index, lane)``. One projection in the common case instead of one per lane of the
    network (the dominant cost of a step with many vehicles).
    """
    if lane_index is None:
        index = network.get_closest_lane_index(position, heading)
        return index, network.get_lane(index)
    lane = network.get_lane(lane_index)
    s, lat = lane.local_coordinates(position)
    width = lane.width_at(s)
    inside = -lane.VEHICLE_LENGTH <= s <= lane.length + lane.VEHICLE_LENGTH
    if inside and abs(lat) <= width / 2.0:
        return lane_index, lane
    _from, _to, k = lane_index
    lanes = network.graph[_from][_to]
    # highway-env's lateral is positive to the right, where its lane indices grow
    k_new = min(max(k + round(lat / width), 0), len(lanes) - 1)
    other = lanes[k_new]
    s2, lat2 = other.local_coordinates(position)
    if inside and abs(lat2) <= other.width_at(s2) / 2.0 + width:
        return (_from, _to, k_new), other
    index = network.get_closest_lane_index(position, heading)
    return index, network.get_lane(index)


def _roads_key(roads: list[Road]) -> tuple:
    return tuple((r.lanes, float(r.lane_width_m), r.centerline.tobytes(), r.cross_section)
                 for r in roads)


@lru_cache(maxsize=8)
def _cached_network(key: tuple) -> RoadNetwork:
    roads = [Road(str(i), "", "", "", [], lanes, width,
                  np.frombuffer(points, dtype=float).reshape(-1, 2), cross_section=section)
             for i, (lanes, width, points, section) in enumerate(key)]
    return build_network(roads)


def network_for(roads: list[Road]) -> RoadNetwork:
    """:func:`build_network`, cached on the roads' geometry: variations of one scenario (and
    every episode of a campaign) share the network, which nobody mutates."""
    return _cached_network(_roads_key(roads))


# --------------------------------------------------------------------------- ego path


def path_lane(x_hw: np.ndarray, y_hw: np.ndarray, heading0_hw: float, width_m: float,
              ahead_m: float, behind_m: float = ROAD_EXTENSION_M) -> ScenarioLane:
    """The ego's logged path as a lane (highway-env frame): the reference line of the ego's
    longitudinal-only mode and of its lead search.

    The path is the logged positions resampled every :data:`LANE_SAMPLE_M`, prolonged straight
    by ``behind_m`` before its start and ``ahead_m`` beyond its end (a policy may drive farther
    than the log). A log that does not move (a camera-relative scenario) becomes a straight
    line along its first heading.
    """
    p = np.column_stack((np.asarray(x_hw, float), np.asarray(y_hw, float)))
    step = np.linalg.norm(np.diff(p, axis=0), axis=1)
    keep = np.r_[True, step > 1e-3]
    p = p[keep]
    if len(p) < 2 or float(np.sum(np.linalg.norm(np.diff(p, axis=0), axis=1))) < 0.5:
        direction = np.array([math.cos(heading0_hw), math.sin(heading0_hw)])
        p = np.vstack((p[0], p[0] + LANE_SAMPLE_M * direction))
    points = _extend_ends(_resample_polyline(p, LANE_SAMPLE_M), behind_m, LANE_SAMPLE_M,
                          extension_end_m=ahead_m)
    lane = ScenarioLane([tuple(q) for q in points.tolist()], width=width_m,
                        line_types=(LineType.NONE, LineType.NONE))
    lane.start_offset_m = float(behind_m)  # arc length of the log's first point on the lane
    return lane
