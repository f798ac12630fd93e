"""Lanes of an OSM carriageway from its tags: lane counts, lane width, parking lanes and
shoulders, and the cross-section they make (rightmost first in the travel direction)."""

from __future__ import annotations

import math
import re

from vid2sim.base.defaults import LANE_WIDTH_M
from vid2sim.core.lanelayout import (
    BACKWARD,
    DRIVING,
    FORWARD,
    PARKING,
    SHOULDER,
    CrossSection,
    LaneSpec,
)
from vid2sim.core.scenario import MAX_LANES

#: lane width of a road derived from the trajectory, and of unknown highway types [m]
DEFAULT_LANE_WIDTH_M = LANE_WIDTH_M  # the project's default (vid2sim.base.defaults)
#: Defaults where OSM has no ``lanes`` / ``width`` tag, per ``highway`` value:
#: (lanes of a two-way road, lanes of a one-way road, lane width [m]). Lane counts follow the
#: OSM wiki's assumptions (Key:lanes: two-way roads 2, one-way roads 1, motorways and trunks
#: 2 per direction); widths are typical European design values (motorway 3.75 m, urban main
#: roads 3.25-3.5 m, residential 3.0 m, service and living streets 2.75-3.0 m).
LANE_DEFAULTS: dict[str, tuple[int, int, float]] = {
    "motorway": (4, 2, 3.75),
    "motorway_link": (2, 1, 3.5),
    "trunk": (4, 2, 3.5),
    "trunk_link": (2, 1, 3.5),
    "primary": (2, 1, 3.5),
    "primary_link": (2, 1, 3.5),
    "secondary": (2, 1, 3.25),
    "secondary_link": (2, 1, 3.25),
    "tertiary": (2, 1, 3.25),
    "tertiary_link": (2, 1, 3.25),
    "unclassified": (2, 1, 3.0),
    "residential": (2, 1, 3.0),
    "living_street": (1, 1, 2.75),
    "service": (1, 1, 3.0),
    "road": (2, 1, 3.0),
}
#: lane widths outside this range in a ``width`` tag are taken as tagging errors [m]
LANE_WIDTH_RANGE_M = (2.5, 4.5)


# --------------------------------------------------------------------------- lanes


def _number(text: str | None) -> float | None:
    """First number in an OSM value ('7', '7.5 m', '3;2' -> 3), None if none."""
    if not text:
        return None
    m = re.search(r"\d+(?:\.\d+)?", str(text))
    return float(m.group()) if m else None


def lanes_from_tags(tags: dict[str, str], along_way: bool = True) -> tuple[int, int, float]:
    """Lanes of a carriageway from its OSM tags.

    Parameters
    ----------
    tags : OSM way tags (``highway``, ``lanes``, ``lanes:forward``, ``lanes:backward``,
        ``width``, ``oneway``)
    along_way : travel follows the way's node order (else ``lanes:backward`` applies)

    Returns
    -------
    (lanes_total, lanes_in_travel_direction, lane_width_m)
    """
    highway = tags.get("highway", "")
    two_way_default, one_way_default, width_default = LANE_DEFAULTS.get(
        highway, (2, 1, DEFAULT_LANE_WIDTH_M))
    oneway = tags.get("oneway", "") in ("yes", "true", "1", "-1", "reverse") or (
        tags.get("junction") in ("roundabout", "circular") and tags.get("oneway") != "no")
    # A lane count beyond any carriageway's (a tag typo, "lanes=99") is taken as no tag.
    lanes, fwd, bwd = (v if v is None or v <= MAX_LANES else None for v in (
        _number(tags.get("lanes")), _number(tags.get("lanes:forward")),
        _number(tags.get("lanes:backward"))))
    if oneway:
        total = int(lanes) if lanes and lanes >= 1 else one_way_default
        forward = total
    else:
        if lanes and lanes >= 1:
            total = int(lanes)
        elif fwd and bwd:
            total = int(fwd + bwd)
        else:
            total = two_way_default
        mine = fwd if along_way else bwd
        if mine and 1 <= mine <= total:
            forward = int(mine)
        else:
            # split evenly; an odd middle lane (turn lane, or one shared lane) counts for both
            forward = max(1, math.ceil(total / 2)) if total > 1 else 1
    width = _number(tags.get("width"))
    lane_width = width_default
    if width and total:
        per_lane = width / total
        if LANE_WIDTH_RANGE_M[0] <= per_lane <= LANE_WIDTH_RANGE_M[1]:
            lane_width = per_lane
    return total, forward, float(lane_width)


#: Width of a parking lane by how the cars stand [m] (RASt 06, the German street design
#: guideline, 6.1.5: parallel parking 2.00 m, at least 1.80 m, 2.50 m beside a bus route;
#: diagonal bays 4.15-4.50 m deep; perpendicular bays 5.00 m). ``parking:*:width`` wins.
PARKING_WIDTH_M = {"parallel": 2.3, "diagonal": 4.5, "perpendicular": 5.0}
#: Tag values (``parking:lane:<side>`` of the older scheme, ``parking:<side>`` of the 2022
#: one) that put standing cars beside the driving lanes; others (``no``, ``no_parking``,
#: ``no_stopping``, ``separate``, ``fire_lane``) do not.
PARKING_ON_ROAD = {"parallel", "diagonal", "perpendicular", "marked", "yes", "lane",
                   "street_side", "on_kerb", "half_on_kerb", "shoulder"}
#: Width of a shoulder without a ``shoulder:width`` tag [m]: the hard shoulder of German
#: motorways (RAA 2008: 2.50-3.00 m) and of rural roads (1.5 m) by road class.
SHOULDER_WIDTH_M = {"motorway": 2.5, "motorway_link": 2.5, "trunk": 2.5}
SHOULDER_WIDTH_OTHER_M = 1.5


def _side_value(tags: dict[str, str], prefix: str, side: str) -> str | None:
    """The tag ``<prefix>:<side>``, or ``<prefix>:both``."""
    for key in (f"{prefix}:{side}", f"{prefix}:both"):
        if tags.get(key):
            return str(tags[key]).strip().lower()
    return None


def _parking_side(tags: dict[str, str], side: str) -> float | None:
    """Width of the parking lane on one side of the way (``left``/``right`` of its node
    order) from ``parking:lane:*`` or ``parking:*`` tags [m], None without one."""
    old = _side_value(tags, "parking:lane", side)
    new = _side_value(tags, "parking", side)
    value = old or new
    if value is None or value not in PARKING_ON_ROAD:
        return None
    orientation = (value if value in PARKING_WIDTH_M else
                   _side_value(tags, "parking", f"{side}:orientation") or "parallel")
    width = (_number(tags.get(f"parking:{side}:width") or tags.get(f"parking:lane:{side}:width")
                     or tags.get("parking:both:width")))
    if width and 1.5 <= width <= 12.0:
        return float(width)
    return PARKING_WIDTH_M.get(orientation, PARKING_WIDTH_M["parallel"])


def _shoulder_sides(tags: dict[str, str]) -> set[str]:
    value = str(tags.get("shoulder", "")).strip().lower()
    sides = {"both": {"left", "right"}, "yes": {"right"}, "right": {"right"},
             "left": {"left"}}.get(value, set())
    sides |= {s for s in ("left", "right") if tags.get(f"shoulder:{s}") == "yes"}
    return sides


def cross_section_from_tags(tags: dict[str, str], along_way: bool = True) -> CrossSection:
    """A carriageway's lanes from its OSM tags, rightmost first in the travel direction.

    Driving lanes come from :func:`lanes_from_tags` (``lanes``, ``lanes:forward``,
    ``lanes:backward``, ``width``, ``oneway``): on a two-way road the travel direction's
    lanes lie right of the centerline (the way's geometry) and the others left of it, the
    rule by which :func:`vid2sim.geo.lateral.fuse_lateral` places the ego; a one-way road's
    lanes are centred on it. Parking lanes (``parking:lane:<side>``, ``parking:<side>`` with
    its ``:orientation`` and ``:width``) and shoulders (``shoulder``, ``shoulder:width``) go
    outside the driving lanes on their side; a way drawn against the travel direction has
    its sides swapped. Parked cars face the way of the driving lane beside them.
    """
    total, forward, width = lanes_from_tags(tags, along_way)
    backward = total - forward
    oneway = backward <= 0 or tags.get("oneway", "") in ("yes", "true", "1", "-1", "reverse")
    if oneway:
        forward, backward = total, 0
    right_edge = -forward * width if backward else -total * width / 2.0
    lanes = [LaneSpec(DRIVING, FORWARD, width) for _ in range(forward)]
    lanes += [LaneSpec(DRIVING, BACKWARD, width) for _ in range(backward)]
    # sides in the travel direction: a way drawn against it has its left on our right
    right, left = ("right", "left") if along_way else ("left", "right")
    shoulder_w = _number(tags.get("shoulder:width"))
    shoulder_w = (shoulder_w if shoulder_w and 0.5 <= shoulder_w <= 5.0 else
                  SHOULDER_WIDTH_M.get(tags.get("highway", ""), SHOULDER_WIDTH_OTHER_M))
    shoulders = _shoulder_sides(tags)
    left_dir = BACKWARD if backward else FORWARD
    park_right, park_left = _parking_side(tags, right), _parking_side(tags, left)
    outer_right: list[LaneSpec] = []
    if park_right:
        outer_right.append(LaneSpec(PARKING, FORWARD, park_right))
    if right in shoulders:
        outer_right.append(LaneSpec(SHOULDER, FORWARD, shoulder_w))
    outer_left: list[LaneSpec] = []
    if park_left:
        outer_left.append(LaneSpec(PARKING, left_dir, park_left))
    if left in shoulders:
        outer_left.append(LaneSpec(SHOULDER, left_dir, shoulder_w))
    right_edge -= sum(lane.width_m for lane in outer_right)
    return CrossSection(right_edge, tuple(outer_right[::-1] + lanes + outer_left))


def with_driving_width(section: CrossSection, width_m: float) -> CrossSection:
    """The cross-section with every driving lane ``width_m`` wide, laid out by the rule of
    :func:`cross_section_from_tags` (two-way: the travel direction's lanes right of the
    centerline; one-way: centred on it)."""
    lanes = tuple(LaneSpec(lane.type, lane.direction, width_m) if lane.type == DRIVING
                  else lane for lane in section.lanes)
    forward = len(section.indices(DRIVING, FORWARD))
    backward = len(section.indices(DRIVING, BACKWARD))
    first = next(i for i, lane in enumerate(lanes) if lane.type == DRIVING)
    edge = -forward * width_m if backward else -(forward + backward) * width_m / 2.0
    return CrossSection(edge - sum(lane.width_m for lane in lanes[:first]), lanes)
