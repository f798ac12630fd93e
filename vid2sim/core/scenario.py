"""The scenario model: typed records and the versioned ``scenario.json`` (the project's hub).

Every exporter and evaluator reads this file; the field names are a contract:

- ``schema``: ``"vid2sim.scenario"``, ``version``: 1
- ``origin``: ``{lat, lon, alt}``, origin of the local ENU frame (x east, y north, z up, m)
- ``roads``: ``[{id, name, highway, source, osm_way_ids, lanes, lane_width_m, centerline}]``
  with ``centerline`` a list of ``[x, y]`` ENU points in travel order, and optionally
  ``cross_section``: ``{right_edge_m, lanes: [{type, direction, width_m}]}``, the lanes from
  right to left (:mod:`vid2sim.core.lanelayout`); without it the road's ``lanes`` are forward
  driving lanes of ``lane_width_m`` centred on the centerline
- ``ego``: ``{length_m, width_m, height_m, trajectory}``
- ``actors``: ``[{id, category, length_m, width_m, height_m, trajectory}]``, and
  ``static: true`` for a vehicle that stood still (parked) and is replayed standing, with
  ``static_by``: ``"ranging"`` (the ranging fitted its track as one standing vehicle seen
  from the ego's measured motion), ``"assembly"`` (its world speed stayed below a share of
  the ego's: the assembly's hold of a monocular range's scale error) or ``"road layout"``
  (off the driving lanes and slower than the ego: held by the road's cross-section); and
  ``ground_m``: the height of the ground the vehicle stands on above the ego's road plane
  (the ranging's measurement; absent: 0)
- trajectories: ``[{t, x, y, heading, speed}]`` with ``t`` seconds from the video's first
  frame, ``x``/``y`` ENU metres, ``heading`` radians counter-clockwise from east, ``speed`` m/s
- ``camera``: the camera record (see :mod:`vid2sim.core.camera`)
- ``source``: input names and sha256, tool version, options, assumptions, warnings
- ``events`` (optional; absent in files written before it, read as none):
  ``[{type, actor, t_s, from_lane, to_lane}]``, lane changes seen in the video: ``type``
  ``"cut_in"`` (a vehicle ahead entering the ego lane), ``"cut_out"`` (one ahead leaving
  it) or ``"lane_change"`` (any other); ``actor`` an actor's id or ``"ego"``; ``t_s`` the
  moment the vehicle's centre crossed the lane boundary; lanes relative to the ego lane
  at that moment (0 the ego lane, +1 the next to the left, -1 the next to the right; the
  ego's own change goes from 0 to +1 or -1)

Validation (:func:`validate`, on load and on save) also enforces physical ranges and the
size limits (``MAX_*`` below, README "Limits").

Output is canonical: sorted keys, floats rounded to fixed decimals, so the same inputs give
byte-identical files.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vid2sim.base.errors import ScenarioError
from vid2sim.base.fileio import parse_json, read_input_text, write_text_atomic
from vid2sim.core.lanelayout import CrossSection, uniform_cross_section, validate_cross_section
from vid2sim.core.records import EGO_ID, EVENT_TYPES, Event, Origin

SCHEMA = "vid2sim.scenario"
#: The format's version. Fields added since version 1 was first written (a road's
#: ``cross_section``, an actor's ``static``) are optional, so every version-1 file, older or
#: newer, still loads, and a reader that does not know them still reads the rest.
VERSION = 1

# Decimals kept per key when writing: 1e-9 deg is 0.1 mm; 1e-4 m and 1e-4 s are far below
# what a GPS or a monocular range can resolve, and keep files small and stable.
_DECIMALS_BY_KEY = {"lat": 9, "lon": 9}
_DEFAULT_DECIMALS = 4
_HEADING_DECIMALS = 6


@dataclass(slots=True)
class Trajectory:
    """Timed poses in ENU: arrays of one length, ``t`` strictly increasing [s]."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    speed: np.ndarray

    def __post_init__(self) -> None:
        for name in ("t", "x", "y", "heading", "speed"):
            setattr(self, name, np.asarray(getattr(self, name), dtype=float).reshape(-1))

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def duration_s(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0

    def state_at(self, t_s: float | np.ndarray) -> dict[str, np.ndarray]:
        """Linearly interpolated pose at ``t_s`` (heading unwrapped before interpolating)."""
        heading = np.unwrap(self.heading)
        return {
            "x": np.interp(t_s, self.t, self.x),
            "y": np.interp(t_s, self.t, self.y),
            "heading": np.interp(t_s, self.t, heading),
            "speed": np.interp(t_s, self.t, self.speed),
        }

    def to_json(self) -> list[dict[str, float]]:
        return [
            {"t": t, "x": x, "y": y, "heading": h, "speed": v}
            for t, x, y, h, v in zip(
                self.t.tolist(), self.x.tolist(), self.y.tolist(),
                self.heading.tolist(), self.speed.tolist(), strict=True,
            )
        ]

    @classmethod
    def from_json(cls, points: list[dict[str, float]]) -> Trajectory:
        cols = {k: [p[k] for p in points] for k in ("t", "x", "y", "heading", "speed")}
        return cls(**cols)


@dataclass(slots=True)
class Road:
    """One road of the scenario: a centerline in travel order with its lanes.

    :param source: ``"osm"`` (matched OpenStreetMap ways) or ``"trajectory"`` (derived
        from the ego path where no map was available)
    :param lanes: driving lanes (both directions)
    :param lane_width_m: width of a driving lane in the ego's direction [m]
    :param centerline: (N, 2) ENU points [m]
    :param cross_section: every lane from right to left with its type, direction and width;
        None: ``lanes`` forward driving lanes centred on the centerline (:meth:`layout`)
    """

    id: str
    name: str
    highway: str
    source: str
    osm_way_ids: list[int]
    lanes: int
    lane_width_m: float
    centerline: np.ndarray
    cross_section: CrossSection | None = None

    def __post_init__(self) -> None:
        self.centerline = np.asarray(self.centerline, dtype=float).reshape(-1, 2)

    def layout(self) -> CrossSection:
        """The road's lanes from right to left: its ``cross_section``, or what a road without
        one means."""
        if self.cross_section is not None:
            return self.cross_section
        return uniform_cross_section(self.lanes, self.lane_width_m)

    def to_json(self) -> dict[str, Any]:
        out = {
            "id": self.id, "name": self.name, "highway": self.highway, "source": self.source,
            "osm_way_ids": [int(w) for w in self.osm_way_ids], "lanes": int(self.lanes),
            "lane_width_m": float(self.lane_width_m), "centerline": self.centerline.tolist(),
        }
        if self.cross_section is not None:
            out["cross_section"] = self.cross_section.to_json()
        return out

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> Road:
        section = d.get("cross_section")
        return cls(
            id=str(d["id"]), name=d["name"], highway=d["highway"], source=d["source"],
            osm_way_ids=list(d["osm_way_ids"]), lanes=int(d["lanes"]),
            lane_width_m=float(d["lane_width_m"]), centerline=np.asarray(d["centerline"]),
            cross_section=None if section is None else CrossSection.from_json(section),
        )


@dataclass(slots=True)
class Ego:
    length_m: float
    width_m: float
    height_m: float
    trajectory: Trajectory

    def to_json(self) -> dict[str, Any]:
        return {"length_m": self.length_m, "width_m": self.width_m,
                "height_m": self.height_m, "trajectory": self.trajectory.to_json()}


#: Largest |ground height| of an actor off the ego's road plane [m]: kerbs, banks and crowns
#: reach a metre; beyond it a value is no road surface.
MAX_GROUND_M = 5.0
#: What found a static actor standing: the ranging's fit from the ego's motion, the
#: assembly's hold of a slow track, or the road layout's of a slow one off the lanes.
STATIC_BY = ("ranging", "assembly", "road layout")


@dataclass(slots=True)
class Actor:
    """A recorded vehicle. ``static``: it stood still (a parked car) and is replayed
    standing where it was seen; ``static_by``: what found it standing (:data:`STATIC_BY`)."""

    id: str
    category: str
    length_m: float
    width_m: float
    height_m: float
    trajectory: Trajectory
    static: bool = False
    static_by: str | None = None
    #: height of the ground it stands on above the ego's road plane [m] (the ranging's)
    ground_m: float = 0.0

    def to_json(self) -> dict[str, Any]:
        out = {"id": self.id, "category": self.category, "length_m": self.length_m,
               "width_m": self.width_m, "height_m": self.height_m,
               "trajectory": self.trajectory.to_json()}
        if self.static:
            out["static"] = True
            if self.static_by:
                out["static_by"] = self.static_by
        if self.ground_m:
            out["ground_m"] = self.ground_m
        return out


@dataclass(slots=True)
class Source:
    """Provenance: which inputs, which tool version and options, which assumptions, and the
    warnings of the run that made the scenario (what a user of the scenario should know:
    GPS gaps, corrupt frames skipped, a guessed camera)."""

    inputs: list[dict[str, str]] = field(default_factory=list)
    tool_version: str = ""
    options: dict[str, Any] = field(default_factory=dict)
    assumptions: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {"inputs": self.inputs, "tool_version": self.tool_version,
                "options": self.options, "assumptions": self.assumptions,
                "warnings": self.warnings}


@dataclass(slots=True)
class Scenario:
    origin: Origin
    roads: list[Road]
    ego: Ego
    actors: list[Actor]
    camera: dict[str, Any]
    source: Source
    events: list[Event] = field(default_factory=list)

    @property
    def duration_s(self) -> float:
        return self.ego.trajectory.duration_s

    def to_json(self) -> dict[str, Any]:
        return {
            "schema": SCHEMA,
            "version": VERSION,
            "origin": {"lat": self.origin.lat, "lon": self.origin.lon, "alt": self.origin.alt},
            "roads": [r.to_json() for r in self.roads],
            "ego": self.ego.to_json(),
            "actors": [a.to_json() for a in self.actors],
            "camera": dict(self.camera),
            "source": self.source.to_json(),
            "events": [e.to_json() for e in self.events],
        }


# --------------------------------------------------------------------------- canonical JSON


def _canonical(obj: Any, key: str | None = None) -> Any:
    if isinstance(obj, dict):
        return {str(k): _canonical(v, str(k)) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_canonical(v, key) for v in obj]
    if isinstance(obj, np.ndarray):
        return _canonical(obj.tolist(), key)
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        value = float(obj)
        if not math.isfinite(value):
            return None
        decimals = _DECIMALS_BY_KEY.get(key or "", _DEFAULT_DECIMALS)
        if key == "heading":
            decimals = _HEADING_DECIMALS
        rounded = round(value, decimals)
        return 0.0 if rounded == 0 else rounded  # no "-0.0" noise
    return obj


def dumps_canonical(data: dict[str, Any]) -> str:
    """Deterministic JSON text: sorted keys, fixed decimals, two-space indent, final newline."""
    return json.dumps(_canonical(data), sort_keys=True, indent=1, ensure_ascii=False) + "\n"


# --------------------------------------------------------------------------- validation

# Limits of a scenario (README "Limits"). A scenario past them is refused on load and on save,
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
    roads = _require(data, "roads", list, "", path)
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
    ego = _require(data, "ego", dict, "", path)
    _validate_box(ego, "ego.", path)
    n_points = _validate_trajectory(_require(ego, "trajectory", list, "ego.", path),
                                    "ego.trajectory", path)
    actors = _require(data, "actors", list, "", path)
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
        _require(actor, "category", str, w, path)
        if "static" in actor:
            _require(actor, "static", bool, w, path)
        if "ground_m" in actor:
            g = _require(actor, "ground_m", (int, float), w, path)
            if isinstance(g, bool) or not (math.isfinite(g) and abs(g) <= MAX_GROUND_M):
                raise ScenarioError(path, f"{w}ground_m", f"must be within +-{MAX_GROUND_M:g} m")
        if "static_by" in actor and actor["static_by"] not in STATIC_BY:
            raise ScenarioError(path, f"{w}static_by", f"must be one of {', '.join(STATIC_BY)}")
        _validate_box(actor, w, path)
        traj = _require(actor, "trajectory", list, w, path)
        if n_points + len(traj) > MAX_TRAJECTORY_POINTS:
            raise ScenarioError(path, f"{w}trajectory", f"the vehicles have more than "
                                f"{MAX_TRAJECTORY_POINTS:,} trajectory points (the limit)")
        n_points += _validate_trajectory(traj, f"{w}trajectory", path)
    _require(data, "camera", dict, "", path)
    if "events" in data:
        spans = {str(a["id"]): (a["trajectory"][0]["t"], a["trajectory"][-1]["t"])
                 for a in actors}
        spans[EGO_ID] = (ego["trajectory"][0]["t"], ego["trajectory"][-1]["t"])
        _validate_events(_require(data, "events", list, "", path), spans, path)
    src = _require(data, "source", dict, "", path)
    for key, kind in (("inputs", list), ("tool_version", str), ("options", dict),
                      ("assumptions", list), ("warnings", list)):
        if key in src:
            _require(src, key, kind, "source.", path)


# --------------------------------------------------------------------------- load / save


def from_json(data: dict[str, Any], path: str | Path | None = None) -> Scenario:
    validate(data, path)
    o = data["origin"]
    ego = data["ego"]
    src = data["source"]
    return Scenario(
        origin=Origin(float(o["lat"]), float(o["lon"]), float(o["alt"])),
        roads=[Road.from_json(r) for r in data["roads"]],
        ego=Ego(float(ego["length_m"]), float(ego["width_m"]), float(ego["height_m"]),
                Trajectory.from_json(ego["trajectory"])),
        actors=[
            Actor(str(a["id"]), a["category"], float(a["length_m"]), float(a["width_m"]),
                  float(a["height_m"]), Trajectory.from_json(a["trajectory"]),
                  static=bool(a.get("static", False)), static_by=a.get("static_by"),
                  ground_m=float(a.get("ground_m", 0.0)))
            for a in data["actors"]
        ],
        camera=dict(data["camera"]),
        source=Source(inputs=list(src.get("inputs", [])), tool_version=str(src.get("tool_version", "")),
                      options=dict(src.get("options", {})),
                      assumptions=list(src.get("assumptions", [])),
                      warnings=list(src.get("warnings", []))),
        events=[Event.from_json(e) for e in data.get("events", [])],
    )


def load(path: str | Path) -> Scenario:
    """Read and validate a scenario.json; errors name the file and the field.

    Files above :data:`MAX_SCENARIO_BYTES` are refused before they are read.
    """
    path = Path(path)
    text = read_input_text(path, max_bytes=MAX_SCENARIO_BYTES)
    return from_json(parse_json(text, path), path)


def save(scenario: Scenario, path: str | Path) -> None:
    """Validate and write canonical JSON atomically.

    The canonical (rounded) record is validated as it will be read back, and serialised
    once (no text round trip: a long scenario's text is tens of MB).
    """
    data = _canonical(scenario.to_json())
    validate(data, path)
    write_text_atomic(path, json.dumps(data, sort_keys=True, indent=1, ensure_ascii=False) + "\n")
