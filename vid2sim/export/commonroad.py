"""CommonRoad export (``scenario.xml``, format 2020a) with commonroad-io's own XML writer.

What the file holds:

- **lanelet network**: every lane of every road's cross-section
  (:meth:`vid2sim.core.scenario.Road.layout`) is one lanelet whose bounds are the
  centerline offset to the lane's edges (positive left, as in the cross-section). A lanelet's
  vertices run in its lane's direction, so a ``backward`` lane's are reversed and its left
  bound is the road's right edge of it. Neighbours are linked (``adjacentLeft``/
  ``adjacentRight`` with ``sameDirection``); consecutive roads whose ends meet and whose
  cross-sections agree are linked as predecessor/successor. Lane types: ``driving`` is the
  road's class (:data:`HIGHWAY_TYPES`), ``parking``, ``shoulder`` and ``border`` are
  CommonRoad's lanelet types of those names, ``rail`` (a track bed) is ``restricted`` with
  trains as its only users (CommonRoad has no rail type). Markings: broken between driving
  lanes of one direction, solid on the other edges of driving lanes, none elsewhere.
- **dynamic obstacles**: every actor (parked ones too, standing) with its category's
  :class:`ObstacleType` (:data:`OBSTACLE_TYPES`; a tram is a ``train``), a rectangle of its
  length and width centred on its position (the scenario's positions are the footprint's
  centre), and its trajectory on the scenario's time grid (:func:`time_grid`): position,
  orientation, velocity and acceleration interpolated from scenario.json at each step of
  its span. Obstacle ids follow the actors' order (``ids.json`` maps them).
- **planning problem**: the ego's logged first state (position, orientation, velocity,
  acceleration, yaw rate) and a goal region around its logged end (:class:`CommonRoadConfig`);
  with ``ego_as_obstacle`` the ego is also a dynamic obstacle with its log (what a
  criticality tool evaluates).
- **header**: benchmark id ``<country>_<map>-1_1_T-1``, author, affiliation, source (the
  tool and its inputs), tags (lanes, oncoming traffic, cut-ins, lane changes, the road's
  class), the location (the ENU origin and its PROJ string as geo-transformation).

Files are reproducible: the header date is ``SOURCE_DATE_EPOCH`` (default the Unix epoch).

commonroad-io pins protobuf 3.20.2, which vid2sim's own dependencies (onnx, onnxruntime, ray)
exclude; it is installed beside them without its dependencies (``docs/commonroad.md``). Only
its XML reader and writer are used here: they do not import protobuf.
"""

from __future__ import annotations

import functools
import json
import math
import os
import re
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from vid2sim import __version__
from vid2sim.base.errors import ImpossibleValueError, InconsistentInputError, InputError
from vid2sim.base.fileio import write_text_atomic
from vid2sim.core.enu import EnuFrame
from vid2sim.core.lanelayout import (
    BORDER,
    DRIVING,
    FORWARD,
    PARKING,
    RAIL,
    SHOULDER,
    CrossSection,
)
from vid2sim.core.polyline import signed_offsets
from vid2sim.core.records import EGO_ID
from vid2sim.core.scenario import Road, Scenario, Trajectory
from vid2sim.core.vocabulary import VehicleCategory

XML_NAME = "scenario.xml"
IDS_NAME = "ids.json"

#: vid2sim category -> CommonRoad ObstacleType value (a tram runs on rails: CommonRoad's
#: ``train``; vid2sim has no bicycle category, so CommonRoad's ``bicycle`` never occurs).
OBSTACLE_TYPES = {VehicleCategory.CAR: "car", VehicleCategory.TRUCK: "truck",
                  VehicleCategory.BUS: "bus", VehicleCategory.MOTORCYCLE: "motorcycle",
                  VehicleCategory.TRAM: "train"}
#: OSM highway class -> CommonRoad lanelet types of its driving lanes; other classes (primary,
#: secondary, ...: urban or rural, the map does not say) get ``unknown``.
HIGHWAY_TYPES = {"motorway": ("highway", "mainCarriageWay"), "motorway_link": ("highway",),
                 "trunk": ("highway", "mainCarriageWay"), "trunk_link": ("highway",),
                 "residential": ("urban",), "living_street": ("urban",),
                 "service": ("urban",)}
_OTHER_TYPES = {PARKING: "parking", SHOULDER: "shoulder", BORDER: "border", RAIL: "restricted"}


@dataclass(frozen=True)
class CommonRoadConfig:
    """Tuning of the CommonRoad export (sources in the comments)."""

    #: length of the goal rectangle along the ego's logged end heading [m]: two car
    #: lengths, the size of the goal areas of CommonRoad's recorded-data benchmarks
    #: (highD/inD conversions use lanelet-sized goals of tens of metres)
    goal_length_m: float = 10.0
    #: the goal time interval is the logged end +- this [s]: a planner may arrive a second
    #: early or late and still have driven the recorded route
    goal_time_tolerance_s: float = 1.0
    #: the goal orientation interval is the logged end heading +- this [rad] (about 11 deg:
    #: a lane change's heading, so a car still changing lanes at the end counts)
    goal_orientation_tolerance_rad: float = 0.2
    #: two road ends closer than this are joined (predecessor/successor) [m]: the road
    #: stage's 1 m centerline spacing
    join_tolerance_m: float = 1.0
    #: CommonRoad's country code of the benchmark id: ``ZAM`` (CommonRoad's code for maps
    #: without a country) -- vid2sim does not look up the country of the GPS origin
    country_id: str = "ZAM"
    author: str = "vid2sim"
    affiliation: str = ""


# --------------------------------------------------------------------------- time grid


@dataclass(frozen=True)
class TimeGrid:
    """CommonRoad's time steps: step ``k`` is scenario time ``t0_s + k * dt_s``."""

    t0_s: float
    dt_s: float
    steps: int

    def steps_within(self, traj: Trajectory) -> np.ndarray:
        """The steps inside a trajectory's span (the nearest one when none falls inside)."""
        a = (float(traj.t[0]) - self.t0_s) / self.dt_s
        b = (float(traj.t[-1]) - self.t0_s) / self.dt_s
        k0, k1 = math.ceil(a - 1e-6), math.floor(b + 1e-6)
        if k1 < k0:
            k0 = k1 = round((a + b) / 2.0)
        return np.arange(k0, k1 + 1)

    def times(self, steps: np.ndarray) -> np.ndarray:
        return self.t0_s + np.asarray(steps, float) * self.dt_s


def time_grid(scenario: Scenario) -> TimeGrid:
    """The scenario's rate: the median step of the ego's log (its first sample is step 0)."""
    t = scenario.ego.trajectory.t
    if len(t) < 2:
        raise InconsistentInputError(None, "the ego's log has a single sample",
                                     "CommonRoad needs a time step: build a longer clip")
    dt = float(round(float(np.median(np.diff(t))), 6))
    steps = math.floor((float(t[-1]) - float(t[0])) / dt + 1e-6) + 1
    return TimeGrid(float(t[0]), dt, steps)


def states_at(traj: Trajectory, times_s: np.ndarray) -> dict[str, np.ndarray]:
    """Position, orientation (unwrapped), velocity and acceleration of a log at ``times_s``
    (linear interpolation, as :meth:`Trajectory.state_at`; held at the log's ends)."""
    st = traj.state_at(times_s)
    speed = np.atleast_1d(st["speed"]).astype(float)
    t = np.atleast_1d(np.asarray(times_s, float))
    accel = np.gradient(speed, t) if len(t) > 1 else np.zeros_like(speed)
    return {"x": np.atleast_1d(st["x"]), "y": np.atleast_1d(st["y"]),
            "heading": np.atleast_1d(st["heading"]), "speed": speed, "accel": accel}


# --------------------------------------------------------------------------- lanelets


def offset_polyline(line_m: np.ndarray, offset_m: float) -> np.ndarray:
    """The polyline moved ``offset_m`` to its left (negative: right), vertex by vertex (the
    mitred offset: each vertex on the offset lines of both its segments; repeated points
    dropped first)."""
    p = np.asarray(line_m, float)
    keep = np.r_[True, np.hypot(*np.diff(p, axis=0).T) > 1e-6]
    p = p[keep]
    d = np.diff(p, axis=0)
    n = np.column_stack((-d[:, 1], d[:, 0])) / np.hypot(d[:, 0], d[:, 1])[:, None]
    vn = np.vstack((n[:1], n[:-1] + n[1:], n[-1:]))
    vn /= np.maximum(np.hypot(vn[:, 0], vn[:, 1]), 1e-12)[:, None]
    seg_n = np.vstack((n[:1], n))  # the segment before each vertex (the first: after)
    cos_half = np.clip(np.einsum("ij,ij->i", vn, seg_n), 0.5, 1.0)  # mitre at most 2x
    return p + vn * (offset_m / cos_half)[:, None]


def unique_points(line_m: np.ndarray) -> np.ndarray:
    p = np.asarray(line_m, float)
    return p[np.r_[True, np.hypot(*np.diff(p, axis=0).T) > 1e-6]]


def lane_bounds(road: Road, k: int, where: str, path=None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Left, centre and right vertices of lane ``k`` of the road in the lane's own direction;
    :class:`ImpossibleValueError` when the lane's outline is degenerate (folds over itself
    where a curve is tighter than the lane's offset from the centerline)."""
    from shapely.geometry import Polygon  # the export's alone: the video commands skip it

    section = road.layout()
    e = section.edges_m
    right, left = offset_polyline(road.centerline, e[k]), offset_polyline(road.centerline,
                                                                          e[k + 1])
    centre = 0.5 * (right + left)
    outline = Polygon(np.vstack((right, left[::-1])))
    if len(right) < 2 or not outline.is_valid or outline.area < 1e-3:
        raise ImpossibleValueError(
            path, f"{where}: lane {k} ({section.lanes[k].type}, {e[k]:+.2f} to {e[k + 1]:+.2f} m"
            " from the centerline) has a degenerate outline",
            "a curve tighter than the lane's offset, or a centerline too short for lanes")
    if section.lanes[k].direction != FORWARD:
        return right[::-1], centre[::-1], left[::-1]
    return left, centre, right


def _marking(section: CrossSection, k: int, j: int) -> str:
    """CommonRoad line marking between lane ``k`` and its neighbour ``j`` (or the road edge)."""
    lane = section.lanes[k]
    if lane.type != DRIVING:
        return "no_marking"
    beside = section.lanes[j] if 0 <= j < len(section.lanes) else None
    if beside is not None and beside.type == DRIVING and beside.direction == lane.direction:
        return "dashed"
    return "solid"


def road_lanelets(road: Road, first_id: int, where: str, path=None) -> list:
    """The lanelets of one road (ids ``first_id``, ``first_id + 1``, ... from right to
    left)."""
    from commonroad.common.common_lanelet import LaneletType, LineMarking, RoadUser
    from commonroad.scenario.lanelet import Lanelet

    section = road.layout()
    n = len(section.lanes)
    out = []
    for k, lane in enumerate(section.lanes):
        left, centre, right = lane_bounds(road, k, where, path)
        fwd = lane.direction == FORWARD
        # in the lane's own direction, "left" is the road's left for forward lanes
        lk, rk = (k + 1, k - 1) if fwd else (k - 1, k + 1)
        kw = {}
        for side, j in (("left", lk), ("right", rk)):
            if 0 <= j < n:
                kw[f"adjacent_{side}"] = first_id + j
                kw[f"adjacent_{side}_same_direction"] = section.lanes[j].direction == \
                    lane.direction
        types = (HIGHWAY_TYPES.get(road.highway, ("unknown",)) if lane.type == DRIVING
                 else (_OTHER_TYPES[lane.type],))
        users = {RoadUser.TRAIN} if lane.type == RAIL else (
            {RoadUser.VEHICLE} if lane.type in (DRIVING, PARKING, SHOULDER) else set())
        out.append(Lanelet(
            left, centre, right, first_id + k,
            line_marking_left_vertices=LineMarking(_marking(section, k, lk)),
            line_marking_right_vertices=LineMarking(_marking(section, k, rk)),
            lanelet_type={LaneletType(t) for t in types}, user_one_way=users or None, **kw))
    return out


def _join_roads(roads: list[Road], lanelets: list[list], tolerance_m: float) -> None:
    """Predecessor/successor links between consecutive roads whose ends meet and whose
    cross-sections agree (same lanes, types and directions)."""
    for a, b, la, lb in zip(roads, roads[1:], lanelets, lanelets[1:], strict=False):
        sa, sb = a.layout(), b.layout()
        if [(x.type, x.direction) for x in sa.lanes] != [(x.type, x.direction) for x in sb.lanes]:
            continue
        if np.hypot(*(unique_points(a.centerline)[-1] - unique_points(b.centerline)[0])) \
                > tolerance_m:
            continue
        for k, lane in enumerate(sa.lanes):
            first, second = (la[k], lb[k]) if lane.direction == FORWARD else (lb[k], la[k])
            first.add_successor(second.lanelet_id)
            second.add_predecessor(first.lanelet_id)


# --------------------------------------------------------------------------- obstacles


def _state(cls, k: int, st: dict[str, np.ndarray], i: int, **extra):
    return cls(time_step=int(k), position=np.array([float(st["x"][i]), float(st["y"][i])]),
               orientation=float(st["heading"][i]), velocity=float(st["speed"][i]),
               acceleration=float(st["accel"][i]), **extra)


def dynamic_obstacle(obstacle_id: int, category: VehicleCategory, length_m: float, width_m: float,
                     traj: Trajectory, grid: TimeGrid):
    """A CommonRoad DynamicObstacle replaying ``traj`` on ``grid``."""
    from commonroad.geometry.obstacle_shapes.rect_obstacle_shape import RectObstacleShape
    from commonroad.prediction.prediction import TrajectoryPrediction
    from commonroad.scenario.obstacle import DynamicObstacle, ObstacleType
    from commonroad.scenario.state import CustomState, InitialState
    from commonroad.scenario.trajectory import Trajectory as CrTrajectory

    steps = grid.steps_within(traj)
    st = states_at(traj, grid.times(steps))
    shape = RectObstacleShape(width=float(width_m), length=float(length_m))
    initial = _state(InitialState, steps[0], st, 0, yaw_rate=_yaw_rate(st, grid.dt_s, 0),
                     slip_angle=0.0)
    prediction = None
    if len(steps) > 1:
        states = [_state(CustomState, k, st, i) for i, k in enumerate(steps) if i > 0]
        prediction = TrajectoryPrediction(CrTrajectory(int(steps[1]), states), shape)
    kind = ObstacleType(OBSTACLE_TYPES[VehicleCategory(category)])
    return DynamicObstacle(obstacle_id, kind, shape, initial, prediction)


def _yaw_rate(st: dict[str, np.ndarray], dt_s: float, i: int) -> float:
    h = st["heading"]
    return float(np.gradient(h, dt_s)[i]) if len(h) > 1 else 0.0


def planning_problem(problem_id: int, scenario: Scenario, grid: TimeGrid,
                     config: CommonRoadConfig, lane_width_m: float):
    """The ego's planning problem: its logged first state, a goal region around its logged
    end (a rectangle ``goal_length_m`` long along the end heading and a lane wide, the end
    time and heading within their tolerances)."""
    import shapely
    from commonroad.common.util import AngleInterval, Interval, make_valid_orientation
    from commonroad.geometry.occupancy.rect_occupancy import RectOccupancy
    from commonroad.planning.goal import GoalRegion
    from commonroad.planning.planning_problem import PlanningProblem
    from commonroad.scenario.state import CustomState, InitialState

    traj = scenario.ego.trajectory
    steps = grid.steps_within(traj)
    st = states_at(traj, grid.times(steps))
    initial = _state(InitialState, steps[0], st, 0, yaw_rate=_yaw_rate(st, grid.dt_s, 0),
                     slip_angle=0.0)
    end_x, end_y, end_h = (float(st[k][-1]) for k in ("x", "y", "heading"))
    tol_steps = max(1, round(config.goal_time_tolerance_s / grid.dt_s))
    last = int(steps[-1])
    tol_h = config.goal_orientation_tolerance_rad
    goal = CustomState(
        time_step=Interval(max(last - tol_steps, int(steps[0]) + 1), last + tol_steps),
        position=RectOccupancy(shapely.Point(end_x, end_y), width=float(lane_width_m),
                               length=config.goal_length_m,
                               orientation=make_valid_orientation(end_h)),
        orientation=AngleInterval(end_h - tol_h, end_h + tol_h))
    return PlanningProblem(problem_id, initial, GoalRegion([goal]))


# --------------------------------------------------------------------------- the scenario


def _map_name(scenario: Scenario) -> str:
    """CommonRoad's map name (letters and digits): the first input's file stem."""
    names = [str(i.get("name", "")) for i in scenario.source.inputs if i.get("name")]
    stem = Path(names[0]).stem if names else "scenario"
    return "Vid2sim" + (re.sub(r"[^A-Za-z0-9]", "", stem.title()) or "Scenario")[:40]


def scenario_tags(scenario: Scenario) -> set[str]:
    """CommonRoad tag values that describe the scenario (what its map and log show)."""
    tags: set[str] = set()
    sections = [r.layout() for r in scenario.roads]
    forward = max(len(s.indices(DRIVING, FORWARD)) for s in sections)
    oncoming = any(len(s.indices(DRIVING)) > len(s.indices(DRIVING, FORWARD)) for s in sections)
    tags.add("single_lane" if forward == 1 else ("two_lane" if forward == 2 else "multi_lane"))
    tags.add("oncoming_traffic" if oncoming else "no_oncoming_traffic")
    if any(r.highway.startswith(("motorway", "trunk")) for r in scenario.roads):
        tags.add("highway")
    elif any(r.highway in ("residential", "living_street", "service") for r in scenario.roads):
        tags.add("urban")
    kinds = {(e.type, e.actor == EGO_ID) for e in scenario.events}
    if any(k == "cut_in" for k, _ in kinds):
        tags.add("cut_in")
    if any(k == "lane_change" for k, _ in kinds):
        tags.add("lane_change")
    if not scenario.events:
        tags.add("lane_following")
    return tags


def _source_text(scenario: Scenario) -> str:
    inputs = ", ".join(f"{i.get('name', '?')}" + (f" (sha256 {str(i['sha256'])[:12]})"
                                                   if i.get("sha256") else "")
                       for i in scenario.source.inputs)
    made = f"vid2sim {scenario.source.tool_version or __version__}"
    return f"{made} from {inputs}" if inputs else made


def check_expressible(scenario: Scenario, path=None) -> None:
    """:class:`InputError` subclasses for a scenario CommonRoad cannot hold (before any work):
    no road (a lanelet network is the map every CommonRoad scenario has)."""
    if not scenario.roads:
        raise InconsistentInputError(path, "the scenario has no road: CommonRoad needs a "
                                     "lanelet network", "build it with a map or GPS so the "
                                     "road stage derives a road")


@dataclass
class CommonRoadExport:
    """What :func:`build_commonroad` made: the commonroad-io objects and the id map."""

    scenario: object
    planning_problems: object
    tags: set
    ids: dict
    grid: TimeGrid


def build_commonroad(scenario: Scenario, config: CommonRoadConfig | None = None,
                     ego_as_obstacle: bool = False, path=None) -> CommonRoadExport:
    """The scenario as commonroad-io objects (see the module docstring)."""
    from commonroad.common.common_scenario import GeoTransformation, Location, ScenarioID
    from commonroad.planning.planning_problem import PlanningProblemSet
    from commonroad.scenario.scenario import Scenario as CrScenario
    from commonroad.scenario.scenario import Tag

    cfg = config or CommonRoadConfig()
    check_expressible(scenario, path)
    grid = time_grid(scenario)
    sid = ScenarioID(country_id=cfg.country_id, map_name=_map_name(scenario), map_id=1,
                     configuration_id=1, obstacle_behavior="T", prediction_id=1)
    tags = {Tag(t) for t in sorted(scenario_tags(scenario))}
    cr = CrScenario(grid.dt_s, sid, tags=tags)
    frame = EnuFrame(scenario.origin)
    cr.lanelet_network.location = Location(
        gps_latitude=scenario.origin.lat, gps_longitude=scenario.origin.lon,
        geo_transformation=GeoTransformation(geo_reference=frame.proj_string()))
    ids: dict = {"lanelets": {}, "actors": {}, "ego": None}
    next_id, per_road = 1, []
    for i, road in enumerate(scenario.roads):
        lanelets = road_lanelets(road, next_id, f"roads[{i}] ({road.id})", path)
        ids["lanelets"][road.id] = [ln.lanelet_id for ln in lanelets]
        per_road.append(lanelets)
        next_id += len(lanelets)
    _join_roads(scenario.roads, per_road, cfg.join_tolerance_m)
    for lanelets in per_road:
        for ln in lanelets:
            cr.lanelet_network.add_lanelet(ln)
    if ego_as_obstacle:
        ego = scenario.ego
        cr.add_objects(dynamic_obstacle(next_id, VehicleCategory.CAR, ego.length_m, ego.width_m,
                                        ego.trajectory, grid))
        ids["ego"], next_id = next_id, next_id + 1
    for actor in scenario.actors:
        cr.add_objects(dynamic_obstacle(next_id, actor.category, actor.length_m, actor.width_m,
                                        actor.trajectory, grid))
        ids["actors"][actor.id] = next_id
        next_id += 1
    width = _ego_lane_width(scenario)
    problems = PlanningProblemSet([planning_problem(next_id, scenario, grid, cfg, width)])
    ids["planning_problem"] = next_id
    return CommonRoadExport(cr, problems, tags, ids, grid)


def _ego_lane_width(scenario: Scenario) -> float:
    """Width of the driving lane nearest the ego's last position [m] (the goal's width)."""
    traj = scenario.ego.trajectory
    end = np.array([[traj.x[-1], traj.y[-1]]])
    best = (math.inf, scenario.roads[0].lane_width_m)
    for road in scenario.roads:
        _, d = signed_offsets(road.centerline, end)
        section = road.layout()
        k = int(section.lane_at(float(d[0])))
        dist = abs(float(d[0]))
        if k >= 0 and section.lanes[k].type == DRIVING and dist < best[0]:
            best = (dist, section.lanes[k].width_m)
    return float(best[1])


# --------------------------------------------------------------------------- writing


@functools.cache
def _writer_class():
    """commonroad-io's XML writer with a reproducible header date (its own writes today's)."""
    from commonroad.common.writer.file_writer_xml import XMLFileWriter

    class _Writer(XMLFileWriter):
        def _write_header(self):
            super()._write_header()
            self._root_node.set("date", header_date())

    return _Writer


def header_date() -> str:
    """``SOURCE_DATE_EPOCH`` (the reproducible-builds convention) as a date, else 1970-01-01."""
    epoch_s = int(os.environ.get("SOURCE_DATE_EPOCH", "0") or 0)
    return datetime.fromtimestamp(epoch_s, tz=UTC).strftime("%Y-%m-%d")


def require_commonroad() -> None:
    """:class:`InputError` (one line) when commonroad-io is not installed."""
    try:
        import commonroad.common.writer.file_writer_xml  # noqa: F401
    except ImportError:
        raise InputError(None, "--format commonroad needs commonroad-io, which is not "
                         "installed", "see docs/commonroad.md: pip install --no-deps "
                         "commonroad-io==2026.1 ...") from None


def write_commonroad(scenario: Scenario, out_dir: Path, config: CommonRoadConfig | None = None,
                     ego_as_obstacle: bool = False, path=None) -> CommonRoadExport:
    """Write ``out_dir/scenario.xml`` (checked against CommonRoad's XSD by commonroad-io) and
    ``out_dir/ids.json`` (vid2sim ids -> CommonRoad ids)."""
    from commonroad.common.writer.file_writer_interface import OverwriteExistingFile

    require_commonroad()
    cfg = config or CommonRoadConfig()
    export = build_commonroad(scenario, cfg, ego_as_obstacle, path)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    writer = _writer_class()(export.scenario, export.planning_problems, author=cfg.author,
                             affiliation=cfg.affiliation, source=_source_text(scenario),
                             tags=export.tags)
    writer.write_to_file(str(out_dir / XML_NAME), OverwriteExistingFile.ALWAYS,
                         check_validity=True)
    ids = dict(export.ids, dt_s=export.grid.dt_s, t0_s=export.grid.t0_s)
    write_text_atomic(out_dir / IDS_NAME, json.dumps(ids, indent=1, sort_keys=True) + "\n")
    return export
