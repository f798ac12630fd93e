"""The schema of ``scenario.json``: its limits and :func:`validate`, which checks a parsed
file (types, finite numbers, physical ranges, limits) before any exporter reads it. The
scenario model itself is :mod:`vid2sim.core.scenario`."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from vid2sim.base.errors import ScenarioError
from vid2sim.core.lanelayout import validate_cross_section
from vid2sim.core.records import EGO_ID, EVENT_TYPES, VEHICLE_CATEGORIES

SCHEMA = "vid2sim.scenario"
#: The format's version. Fields added since version 1 was first written (a road's
#: ``cross_section``, an actor's ``static``) are optional, so every version-1 file, older or
#: newer, still loads, and a reader that does not know them still reads the rest.
VERSION = 1

# Limits of a scenario (docs/limits.md). A scenario past them is refused on load and on save,
# before any exporter loops over it: `lanes: 1e9` made the highway-env export hang, and a
# 140 MB file of 2 million points took 3.4 GB to export.

#: Largest scenario.json [bytes]; an hour-long build writes 5-15 MB.
MAX_SCENARIO_BYTES = 64 * 1024 * 1024
#: Most trajectory points of all vehicles together: an hour of ego at 10 Hz is 36,000; a busy
#: hour adds a few hundred thousand actor points.
MAX_TRAJECTORY_POINTS = 1_000_000
#: Most centerline points of all roads together: 500 km at the road stage's 1 m spacing.
MAX_CENTERLINE_POINTS = 500_000
#: Most actors in one scenario.
MAX_ACTORS = 20_000
#: Most lanes of one carriageway: the widest roads in OpenStreetMap have about 13 lanes
#: across one carriageway; more is a tag or unit error.
MAX_LANES = 16
#: Range of a lane's width [m]: 2.0 m is an old-town lane, 7 m a wide single-lane road;
#: outside it the number is not a lane width.
LANE_WIDTH_RANGE_M = (1.5, 8.0)
#: Largest |x|, |y| of any ENU point [m]: 1,000 km, beyond which a flat local frame is
#: useless (and larger numbers are a unit error: degrees, millimetres).
MAX_COORDINATE_M = 1.0e6
#: Longest scenario [s]: a day.
MAX_DURATION_S = 86_400.0
#: Largest |t| of any trajectory point [s] (seconds from the first video frame).
MAX_TIME_S = 1.0e6
#: Fastest vehicle speed [m/s]: 720 km/h, twice the fastest road vehicle; more is a unit or
#: data error.
MAX_SPEED_MPS = 200.0
#: Largest vehicle length, width and height [m] (a road train is 53.5 m long).
MAX_BOX_M = {"length_m": 60.0, "width_m": 6.0, "height_m": 6.0}
#: Two consecutive centerline segments turning back by more than this [deg] make a spike
#: (the lane normals cancel): a digitising error, not a road.
MAX_TURN_DEG = 179.0
#: Most events in one scenario: each actor changes lanes a few times at most.
MAX_EVENTS = 100_000
#: An event lies within its vehicle's trajectory, give or take this [s] (the crossing is
#: interpolated between frames; hand-made files round).
EVENT_TIME_TOLERANCE_S = 0.5


#: Largest |ground height| of an actor off the ego's road plane [m]: kerbs, banks and crowns
#: reach a metre; beyond it a value is no road surface.
MAX_GROUND_M = 5.0
#: What found a static actor standing: the ranging's fit from the ego's motion, the
#: assembly's hold of a slow track, or the road layout's of a slow one off the lanes.
STATIC_BY = ("ranging", "assembly", "road layout")


def _require(d: Any, key: str, kind: type | tuple[type, ...], where: str, path) -> Any:
    if not isinstance(d, dict) or key not in d:
        raise ScenarioError(path, f"{where}{key}", "missing")
    value = d[key]
    if kind is float:
        kind = (int, float)
    if isinstance(value, bool) and kind is not bool:
        raise ScenarioError(path, f"{where}{key}", f"expected {_kind_name(kind)}, got bool")
    if not isinstance(value, kind):
        raise ScenarioError(
            path, f"{where}{key}", f"expected {_kind_name(kind)}, got {type(value).__name__}")
    return value


def _number(d: Any, key: str, where: str, path, lo: float = -math.inf, hi: float = math.inf,
            lo_open: bool = False) -> float:
    """A finite number in [lo, hi] (or (lo, hi]), else a ScenarioError naming the field."""
    v = _require(d, key, float, where, path)
    try:
        ok = math.isfinite(v)
    except OverflowError:  # an integer beyond any float
        ok = False
    if not ok:
        raise ScenarioError(path, f"{where}{key}", "not a finite number")
    if (v <= lo if lo_open else v < lo) or v > hi:
        left = "(" if lo_open else "["
        raise ScenarioError(path, f"{where}{key}", f"{v:g} outside {left}{lo:g}, {hi:g}]")
    return float(v)


def _kind_name(kind) -> str:
    if isinstance(kind, tuple):
        return "number" if set(kind) == {int, float} else "/".join(k.__name__ for k in kind)
    return kind.__name__


def _validate_trajectory(points: Any, where: str, path) -> int:
    """Check one trajectory; return its number of points."""
    if not isinstance(points, list) or not points:
        raise ScenarioError(path, where, "expected a non-empty list of points")
    last_t = -math.inf
    for i, p in enumerate(points):
        w = f"{where}[{i}]."
        t = _number(p, "t", w, path, -MAX_TIME_S, MAX_TIME_S)
        _number(p, "x", w, path, -MAX_COORDINATE_M, MAX_COORDINATE_M)
        _number(p, "y", w, path, -MAX_COORDINATE_M, MAX_COORDINATE_M)
        _number(p, "heading", w, path)
        speed = _require(p, "speed", float, w, path)
        if isinstance(speed, (int, float)) and speed < 0:
            raise ScenarioError(path, f"{w}speed", "must be >= 0")
        _number(p, "speed", w, path, 0.0, MAX_SPEED_MPS)
        if t <= last_t:
            raise ScenarioError(path, f"{w}t", "times must increase strictly")
        last_t = t
    if last_t - points[0]["t"] > MAX_DURATION_S:
        raise ScenarioError(path, where, f"lasts {last_t - points[0]['t']:.0f} s, more than the "
                            f"{MAX_DURATION_S:.0f} s limit")
    return len(points)


def _validate_box(d: dict, where: str, path) -> None:
    for k, hi in MAX_BOX_M.items():
        v = _require(d, k, float, where, path)
        if isinstance(v, (int, float)) and not v > 0:
            raise ScenarioError(path, f"{where}{k}", "must be > 0")
        _number(d, k, where, path, 0.0, hi, lo_open=True)


def _validate_centerline(line: Any, where: str, path) -> int:
    """Check a road centerline's geometry: [x, y] pairs of finite numbers within the frame,
    at least two distinct points, no spike; return its number of points."""
    if len(line) < 2 or not all(
        isinstance(p, list) and len(p) == 2
        and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in p)
        for p in line
    ):
        raise ScenarioError(path, where, "expected at least two [x, y] points")
    try:
        xy = np.asarray(line, dtype=float)
    except OverflowError:
        raise ScenarioError(path, where, "a coordinate is not a finite number") from None
    bad = ~np.isfinite(xy).all(axis=1)
    if bad.any():
        raise ScenarioError(path, f"{where}[{int(np.argmax(bad))}]", "not a finite number")
    far = (np.abs(xy) > MAX_COORDINATE_M).any(axis=1)
    if far.any():
        raise ScenarioError(path, f"{where}[{int(np.argmax(far))}]",
                            f"more than {MAX_COORDINATE_M / 1000:.0f} km from the origin")
    seg = np.diff(xy, axis=0)
    length = np.hypot(seg[:, 0], seg[:, 1])
    seg = seg[length > 1e-6]
    if len(seg) == 0:
        raise ScenarioError(path, where, "all points coincide: a road needs two distinct points")
    if len(seg) > 1:
        u = seg / np.hypot(seg[:, 0], seg[:, 1])[:, None]
        cos_turn = np.einsum("ij,ij->i", u[:-1], u[1:])
        back = cos_turn < math.cos(math.radians(MAX_TURN_DEG))
        if back.any():
            raise ScenarioError(path, where, f"turns back on itself (segment {int(np.argmax(back))}"
                                f" -> {int(np.argmax(back)) + 1}, more than {MAX_TURN_DEG:g} deg)")
    return len(line)


def _validate_events(events: list, spans: dict[str, tuple[float, float]], path) -> None:
    """Check ``events``: known types and vehicles, times within the vehicle's trajectory,
    whole lanes, and a type that fits the lanes (a cut-in ends in the ego lane, a cut-out
    starts there, the ego leaves lane 0)."""
    if len(events) > MAX_EVENTS:
        raise ScenarioError(path, "events", f"{len(events):,} events, more than the "
                            f"{MAX_EVENTS:,} limit")
    for i, ev in enumerate(events):
        w = f"events[{i}]."
        kind = _require(ev, "type", str, w, path)
        if kind not in EVENT_TYPES:
            raise ScenarioError(path, f"{w}type", f"expected one of {', '.join(EVENT_TYPES)}, "
                                f"got {kind!r}")
        actor = str(_require(ev, "actor", (str, int), w, path))
        if actor not in spans:
            raise ScenarioError(path, f"{w}actor", f"no actor {actor!r} in the scenario")
        t0, t1 = spans[actor]
        _number(ev, "t_s", w, path, t0 - EVENT_TIME_TOLERANCE_S, t1 + EVENT_TIME_TOLERANCE_S)
        lanes = [_require(ev, k, int, w, path) for k in ("from_lane", "to_lane")]
        for k, v in zip(("from_lane", "to_lane"), lanes, strict=True):
            if abs(v) > MAX_LANES:
                raise ScenarioError(path, f"{w}{k}", f"{v} is more than {MAX_LANES} lanes from "
                                    "the ego lane")
        a, b = lanes
        if a == b:
            raise ScenarioError(path, f"{w}to_lane", "a lane change must change the lane")
        problem = None
        if actor == EGO_ID and (kind != "lane_change" or a != 0):
            problem = "the ego's own event is a lane_change from lane 0"
        elif kind == "cut_in" and b != 0:
            problem = "a cut_in ends in the ego lane (to_lane 0)"
        elif kind == "cut_out" and a != 0:
            problem = "a cut_out starts in the ego lane (from_lane 0)"
        if problem:
            raise ScenarioError(path, f"{w}type", problem)


def _validate_roads(roads: list, path) -> None:
    """Each road's fields, lanes, widths, cross-section and centerline; the centerline limit."""
    n_line = 0
    for i, road in enumerate(roads):
        w = f"roads[{i}]."
        _require(road, "id", (str, int), w, path)
        _require(road, "name", str, w, path)
        _require(road, "highway", str, w, path)
        _require(road, "source", str, w, path)
        ways = _require(road, "osm_way_ids", list, w, path)
        if not all(isinstance(x, int) and not isinstance(x, bool) for x in ways):
            raise ScenarioError(path, f"{w}osm_way_ids", "expected a list of integers")
        lanes = _require(road, "lanes", int, w, path)
        if not 1 <= lanes <= MAX_LANES:
            raise ScenarioError(path, f"{w}lanes", f"must be 1-{MAX_LANES}, got {lanes}")
        width = _require(road, "lane_width_m", float, w, path)
        if isinstance(width, (int, float)) and not width > 0:
            raise ScenarioError(path, f"{w}lane_width_m", "must be > 0")
        _number(road, "lane_width_m", w, path, *LANE_WIDTH_RANGE_M)
        if road.get("cross_section") is not None:
            validate_cross_section(road["cross_section"], f"{w}cross_section", path, lanes,
                                   LANE_WIDTH_RANGE_M)
        n_line += _validate_centerline(_require(road, "centerline", list, w, path),
                                       f"{w}centerline", path)
        if n_line > MAX_CENTERLINE_POINTS:
            raise ScenarioError(path, f"{w}centerline", f"the roads have more than "
                                f"{MAX_CENTERLINE_POINTS:,} centerline points (the limit)")


def _validate_actors(actors: list, n_points: int, path) -> None:
    """Each actor's id (unique), category, size and trajectory; the limits on actors and on
    trajectory points (``n_points`` already taken by the ego)."""
    if len(actors) > MAX_ACTORS:
        raise ScenarioError(path, "actors", f"{len(actors):,} actors, more than the "
                            f"{MAX_ACTORS:,} limit")
    seen: set[str] = set()
    for i, actor in enumerate(actors):
        w = f"actors[{i}]."
        actor_id = str(_require(actor, "id", (str, int), w, path))
        if actor_id in seen:
            raise ScenarioError(path, f"{w}id", f"duplicate actor id {actor_id!r}")
        seen.add(actor_id)
        category = _require(actor, "category", str, w, path)
        if category not in VEHICLE_CATEGORIES:
            raise ScenarioError(path, f"{w}category", f"unknown vehicle category {category!r} "
                                f"(one of {', '.join(VEHICLE_CATEGORIES)})")
        if "static" in actor:
            _require(actor, "static", bool, w, path)
        if "ground_m" in actor:
            _number(actor, "ground_m", w, path, -MAX_GROUND_M, MAX_GROUND_M)
        if "static_by" in actor and actor["static_by"] not in STATIC_BY:
            raise ScenarioError(path, f"{w}static_by", f"must be one of {', '.join(STATIC_BY)}")
        _validate_box(actor, w, path)
        traj = _require(actor, "trajectory", list, w, path)
        if n_points + len(traj) > MAX_TRAJECTORY_POINTS:
            raise ScenarioError(path, f"{w}trajectory", f"the vehicles have more than "
                                f"{MAX_TRAJECTORY_POINTS:,} trajectory points (the limit)")
        n_points += _validate_trajectory(traj, f"{w}trajectory", path)


def validate(data: Any, path: str | Path | None = None) -> None:
    """Check a parsed scenario.json; raise :class:`ScenarioError` naming the offending field.

    Beyond the schema: every number finite and in its physical range (coordinates, times,
    speeds, vehicle sizes, lane widths and counts), road geometry a road can have (two
    distinct points, no spike) and the size limits above.
    """
    if not isinstance(data, dict):
        raise ScenarioError(path, "<root>", "expected a JSON object")
    if data.get("schema") != SCHEMA:
        raise ScenarioError(path, "schema", f"expected '{SCHEMA}', got {data.get('schema')!r}")
    version = _require(data, "version", int, "", path)
    if version != VERSION:
        raise ScenarioError(path, "version", f"unsupported version {version} (this tool reads {VERSION})")
    origin = _require(data, "origin", dict, "", path)
    for k, lo, hi in (("lat", -90, 90), ("lon", -180, 180), ("alt", -1e4, 1e5)):
        _number(origin, k, "origin.", path, lo, hi)
    _validate_roads(_require(data, "roads", list, "", path), path)
    ego = _require(data, "ego", dict, "", path)
    _validate_box(ego, "ego.", path)
    n_points = _validate_trajectory(_require(ego, "trajectory", list, "ego.", path),
                                    "ego.trajectory", path)
    actors = _require(data, "actors", list, "", path)
    _validate_actors(actors, n_points, path)
    _require(data, "camera", dict, "", path)
    if "events" in data:
        spans = {str(a["id"]): (a["trajectory"][0]["t"], a["trajectory"][-1]["t"])
                 for a in actors}
        spans[EGO_ID] = (ego["trajectory"][0]["t"], ego["trajectory"][-1]["t"])
        _validate_events(_require(data, "events", list, "", path), spans, path)
    src = _require(data, "source", dict, "", path)
    for key, kind in (("inputs", list), ("tool_version", str), ("options", dict),
                      ("assumptions", list), ("warnings", list), ("settings", dict)):
        if key in src:
            _require(src, key, kind, "source.", path)


# --------------------------------------------------------------------------- load / save
