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
size limits (``MAX_*`` below, docs/limits.md).

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

from vid2sim.base.fileio import atomic_open, parse_json, read_input_text
from vid2sim.core._scenario_schema import (  # noqa: F401  the schema's limits, re-exported
    LANE_WIDTH_RANGE_M,
    MAX_ACTORS,
    MAX_CENTERLINE_POINTS,
    MAX_LANES,
    MAX_SCENARIO_BYTES,
    MAX_TRAJECTORY_POINTS,
    SCHEMA,
    STATIC_BY,
    VERSION,
    validate,
)
from vid2sim.core.lanelayout import CrossSection, uniform_cross_section
from vid2sim.core.records import (
    Event,
    Origin,
    VehicleCategory,
)

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


@dataclass(slots=True)
class Actor:
    """A recorded vehicle. ``static``: it stood still (a parked car) and is replayed
    standing where it was seen; ``static_by``: what found it standing (:data:`STATIC_BY`);
    ``ground_m``: the height of the ground it stands on above the ego's road plane [m] (the
    ranging's)."""

    id: str
    category: VehicleCategory
    length_m: float
    width_m: float
    height_m: float
    trajectory: Trajectory
    static: bool = False
    static_by: str | None = None
    ground_m: float = 0.0

    def __post_init__(self) -> None:
        self.category = VehicleCategory(self.category)  # a ValueError for an unknown one

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
    #: the whole settings tree the scenario was made with (``vid2sim settings`` prints the
    #: format; numbers kept exact, not rounded like the trajectories)
    settings: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        out = {"inputs": self.inputs, "tool_version": self.tool_version,
               "options": self.options, "assumptions": self.assumptions,
               "warnings": self.warnings}
        if self.settings:
            out["settings"] = self.settings
        return out


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
    if key == "settings" and isinstance(obj, dict):
        return _exact(obj)  # settings keep every digit: a rounded 1e-5 would read as 0
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


def _exact(obj: Any) -> Any:
    """JSON-ready data with string keys and numbers as they are (non-finite -> None)."""
    if isinstance(obj, dict):
        return {str(k): _exact(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_exact(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def dumps_canonical(data: dict[str, Any]) -> str:
    """Deterministic JSON text: sorted keys, fixed decimals, two-space indent, final newline."""
    return json.dumps(_canonical(data), sort_keys=True, indent=1, ensure_ascii=False) + "\n"


# --------------------------------------------------------------------------- loading

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
            Actor(str(a["id"]), VehicleCategory(a["category"]), float(a["length_m"]),
                  float(a["width_m"]),
                  float(a["height_m"]), Trajectory.from_json(a["trajectory"]),
                  static=bool(a.get("static", False)), static_by=a.get("static_by"),
                  ground_m=float(a.get("ground_m", 0.0)))
            for a in data["actors"]
        ],
        camera=dict(data["camera"]),
        source=Source(inputs=list(src.get("inputs", [])), tool_version=str(src.get("tool_version", "")),
                      options=dict(src.get("options", {})),
                      assumptions=list(src.get("assumptions", [])),
                      warnings=list(src.get("warnings", [])),
                      settings=dict(src.get("settings", {}))),
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
    once (no text round trip: a long scenario's text is tens of MB), streamed into the file:
    ``json.dumps`` of an indented record first holds every one of its small pieces (about
    12 bytes of text each) and then their join, some 60 MB for a 10-minute drive; the text
    is the same.
    """
    data = _canonical(scenario.to_json())
    validate(data, path)
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        json.dump(data, fh, sort_keys=True, indent=1, ensure_ascii=False)
        fh.write("\n")
