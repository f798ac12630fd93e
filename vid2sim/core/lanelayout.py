"""A road's cross-section: its lanes from right to left, each with a type, a direction and a
width (the ``cross_section`` of a road in ``scenario.json``).

Frame: lateral offsets are measured from the road's centerline, positive to the LEFT of its
direction (the travel order of the centerline's points). Lanes are listed from the right
edge leftwards and touch (each lane's left edge is the next one's right edge), starting at
``right_edge_m``. Lane types follow OpenDRIVE 1.8's ``e_laneType`` names where one exists:

- ``driving``: a lane for moving traffic;
- ``parking``: a strip or bay where vehicles stand (parked cars along a kerb, a lay-by);
- ``shoulder``: a hard shoulder or verge vehicles may stop on (motorways, rural roads);
- ``border``: a strip between the others that nobody uses (a kerb with its verge, a hedge);
- ``rail``: a track bed with rails beside the road (a tram on its own bed).

``direction`` is ``forward`` (the centerline's direction) or ``backward``: the way traffic
moves in a driving lane, and the way a vehicle standing in any other lane faces (a parked
car faces the way of the driving lane beside it, StVO section 12(4) in Germany, the rule in
right-hand traffic generally).

Lane numbers (:data:`vid2sim.geo.roads.LANE_NUMBERING`) count only the forward ``driving``
lanes: lane 0 is the rightmost of them.

Pure records and geometry: no I/O; validation of the JSON form raises
:class:`~vid2sim.base.errors.ScenarioError` naming the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from vid2sim.base.errors import ScenarioError

DRIVING, PARKING, SHOULDER, BORDER, RAIL = "driving", "parking", "shoulder", "border", "rail"
#: Lane types of a cross-section (OpenDRIVE 1.8 names).
LANE_TYPES = (DRIVING, PARKING, SHOULDER, BORDER, RAIL)
#: Lane types a road vehicle may stand in (the on-lane measure's "on the road").
ROAD_LANE_TYPES = (DRIVING, PARKING, SHOULDER)
FORWARD, BACKWARD = "forward", "backward"
DIRECTIONS = (FORWARD, BACKWARD)

#: Most lanes of a cross-section: 16 driving lanes (``scenario.MAX_LANES``) plus parking,
#: shoulders, borders and tracks on both sides.
MAX_CROSS_SECTION_LANES = 32
#: Widths of a non-driving lane [m]: a kerb's border is a few decimetres; the widest
#: parking strip (perpendicular bays, RASt 06: 5.0 m) with its manoeuvring space stays
#: under 12 m. (Driving lanes are held to ``scenario.LANE_WIDTH_RANGE_M``.)
OTHER_LANE_WIDTH_RANGE_M = (0.1, 12.0)
#: Largest |offset| of any lane edge from the centerline [m]: the widest urban streets with
#: service roads and tracks span about 100 m.
MAX_CROSS_SECTION_M = 100.0


@dataclass(frozen=True, slots=True)
class LaneSpec:
    """One lane of a cross-section: ``type`` (:data:`LANE_TYPES`), ``direction``
    (:data:`DIRECTIONS`) and ``width_m`` [m]."""

    type: str
    direction: str
    width_m: float

    def to_json(self) -> dict[str, Any]:
        return {"type": self.type, "direction": self.direction, "width_m": float(self.width_m)}


@dataclass(frozen=True, slots=True)
class CrossSection:
    """The lanes of a road from right to left (see the module docstring).

    :param right_edge_m: offset of the rightmost lane's right edge from the centerline,
        positive left [m]
    :param lanes: the lanes, rightmost first
    """

    right_edge_m: float
    lanes: tuple[LaneSpec, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "lanes", tuple(self.lanes))

    def __len__(self) -> int:
        return len(self.lanes)

    @property
    def edges_m(self) -> np.ndarray:
        """Offsets of the lane edges from the centerline [m], right to left (n + 1 values)."""
        widths = np.array([lane.width_m for lane in self.lanes], float)
        return self.right_edge_m + np.concatenate(([0.0], np.cumsum(widths)))

    @property
    def centres_m(self) -> np.ndarray:
        """Offset of each lane's middle from the centerline [m], right to left."""
        e = self.edges_m
        return 0.5 * (e[:-1] + e[1:])

    @property
    def width_m(self) -> float:
        """Total width [m]."""
        return float(sum(lane.width_m for lane in self.lanes))

    def indices(self, lane_type: str | None = None, direction: str | None = None) -> list[int]:
        """Positions (0 = rightmost) of the lanes of a type and direction (None: any)."""
        return [i for i, lane in enumerate(self.lanes)
                if (lane_type is None or lane.type == lane_type)
                and (direction is None or lane.direction == direction)]

    @property
    def n_driving(self) -> int:
        """Driving lanes in both directions."""
        return len(self.indices(DRIVING))

    def forward_driving(self) -> list[int]:
        """Positions of the forward driving lanes, rightmost first: lane number k of the
        project's numbering is ``forward_driving()[k]``."""
        return self.indices(DRIVING, FORWARD)

    def lane_at(self, offset_m: float | np.ndarray) -> np.ndarray:
        """Position of the lane holding each offset from the centerline [m]; -1 outside."""
        e = self.edges_m
        d = np.asarray(offset_m, float)
        k = np.searchsorted(e, d, side="right") - 1
        inside = np.isfinite(d) & (d >= e[0]) & (d <= e[-1])
        return np.where(inside, np.clip(k, 0, len(self.lanes) - 1), -1)

    def to_json(self) -> dict[str, Any]:
        return {"right_edge_m": float(self.right_edge_m),
                "lanes": [lane.to_json() for lane in self.lanes]}

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> CrossSection:
        return cls(float(d["right_edge_m"]),
                   tuple(LaneSpec(str(x["type"]), str(x["direction"]), float(x["width_m"]))
                         for x in d["lanes"]))


def uniform_cross_section(lanes: int, lane_width_m: float) -> CrossSection:
    """What a road without a ``cross_section`` means (the scenario format before it): its
    ``lanes`` lanes, all forward driving lanes of ``lane_width_m``, centred on the
    centerline."""
    n = max(int(lanes), 1)
    return CrossSection(-n * float(lane_width_m) / 2.0,
                        tuple(LaneSpec(DRIVING, FORWARD, float(lane_width_m)) for _ in range(n)))


def validate_cross_section(d: Any, where: str, path: str | Path | None, lanes: int,
                           driving_width_range_m: tuple[float, float]) -> None:
    """Check the JSON form of a cross-section; raise :class:`ScenarioError` naming the field.

    ``lanes`` is the road's ``lanes`` (the driving lanes the cross-section must hold);
    ``driving_width_range_m`` the plausible widths of a driving lane [m].
    """
    if not isinstance(d, dict):
        raise ScenarioError(path, where, "expected an object")
    edge = d.get("right_edge_m")
    if isinstance(edge, bool) or not isinstance(edge, (int, float)) or not _finite(edge) \
            or abs(edge) > MAX_CROSS_SECTION_M:
        raise ScenarioError(path, f"{where}.right_edge_m",
                            f"expected a number within +-{MAX_CROSS_SECTION_M:g} m")
    items = d.get("lanes")
    if not isinstance(items, list) or not 1 <= len(items) <= MAX_CROSS_SECTION_LANES:
        raise ScenarioError(path, f"{where}.lanes",
                            f"expected a list of 1-{MAX_CROSS_SECTION_LANES} lanes")
    total = 0.0
    n_driving = 0
    for i, lane in enumerate(items):
        w = f"{where}.lanes[{i}]"
        if not isinstance(lane, dict):
            raise ScenarioError(path, w, "expected an object")
        if lane.get("type") not in LANE_TYPES:
            raise ScenarioError(path, f"{w}.type",
                                f"expected one of {', '.join(LANE_TYPES)}, got {lane.get('type')!r}")
        if lane.get("direction") not in DIRECTIONS:
            raise ScenarioError(path, f"{w}.direction", f"expected one of "
                                f"{', '.join(DIRECTIONS)}, got {lane.get('direction')!r}")
        width = lane.get("width_m")
        lo, hi = (driving_width_range_m if lane["type"] == DRIVING
                  else OTHER_LANE_WIDTH_RANGE_M)
        if isinstance(width, bool) or not isinstance(width, (int, float)) \
                or not _finite(width) or not lo <= width <= hi:
            raise ScenarioError(path, f"{w}.width_m", f"expected a number in [{lo:g}, {hi:g}] m "
                                f"for a {lane['type']} lane, got {width!r}")
        total += float(width)
        n_driving += lane["type"] == DRIVING
    if abs(edge) + total > 2 * MAX_CROSS_SECTION_M or abs(edge + total) > MAX_CROSS_SECTION_M:
        raise ScenarioError(path, f"{where}.lanes", f"the lanes reach more than "
                            f"{MAX_CROSS_SECTION_M:g} m from the centerline")
    if n_driving != lanes:
        raise ScenarioError(path, f"{where}.lanes", f"{n_driving} driving lane(s), but the "
                            f"road's 'lanes' says {lanes}")


def _finite(value: float) -> bool:
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer beyond any float
        return False
