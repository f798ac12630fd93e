"""OpenDRIVE 1.8 (``road.xodr``) with scenariogeneration: the scenario's roads with their
cross-sections.

Each scenario road becomes one road whose reference line is the scenario centerline, fitted
as a clothoid chain (:mod:`vid2sim.export.refline`). Its lanes are the road's cross-section
(:meth:`vid2sim.core.scenario.Road.layout`) with their OpenDRIVE types (``driving``, ``parking``,
``shoulder``, ``border``, ``rail``): in right-hand traffic OpenDRIVE's right lanes (ids -1,
-2, ...) run in the reference line's direction and its left lanes against it, so the centre
lane (id 0) is put on the boundary left of the leftmost forward driving lane, by a
``laneOffset`` from the reference line; lanes right of it are right lanes, the others left
lanes. Lines between driving lanes of one direction are broken, the outer lines of the
driving lanes solid; the centre lane's line is solid (the centre line, or the road's left
edge on a one-way road). The scenario carries no heights, so elevation is one flat record.
The header's ``geoReference`` is the PROJ string of the scenario's ENU frame, so OpenDRIVE
x/y are scenario ENU metres.

scenariogeneration ships OpenDRIVE 1.7 schemas; the road file uses only elements common to
1.7 and 1.8 (the ASAM checker validates it against 1.8).
"""

from __future__ import annotations

import logging
import xml.etree.ElementTree as ET

import numpy as np

from vid2sim.core.enu import EnuFrame
from vid2sim.core.lanelayout import DRIVING, FORWARD, CrossSection
from vid2sim.core.scenario import Road, Scenario
from vid2sim.export.assemble import straight_road_for
from vid2sim.export.refline import FIT_TOLERANCE_M, fit_reference_line

log = logging.getLogger(__name__)

#: Road mark widths [m]: 0.15 m for a solid edge or centre line, 0.12 m for a lane line
#: (German RMS 2019: narrow lines 0.12 m, broad 0.25 m; 0.15 m is the common OpenDRIVE value).
SOLID_MARK_M, BROKEN_MARK_M = 0.15, 0.12
#: Broken line dash and gap [m]: 3 m dashes, 6 m gaps (RMS 2019 lane lines in towns; 6 m
#: and 12 m on rural roads)
DASH_M, GAP_M = 3.0, 6.0


def centre_split(section: CrossSection) -> int:
    """How many lanes (from the right) are OpenDRIVE right lanes: every lane up to the
    leftmost forward driving lane (all lanes when none runs forward)."""
    forward = section.indices(DRIVING, FORWARD)
    return (forward[-1] + 1) if forward else len(section.lanes)


def _mark(xodr, section: CrossSection, k: int, outward: int):
    """The road mark on lane ``k``'s outer edge (``outward``: -1 right, +1 left), or None."""
    lane = section.lanes[k]
    if lane.type != DRIVING:
        return None
    j = k + outward
    beside = section.lanes[j] if 0 <= j < len(section.lanes) else None
    if beside is not None and beside.type == DRIVING and beside.direction == lane.direction:
        return xodr.RoadMark(xodr.RoadMarkType.broken, BROKEN_MARK_M, length=DASH_M,
                             space=GAP_M)
    return xodr.RoadMark(xodr.RoadMarkType.solid, SOLID_MARK_M)


def _xodr_lane(xodr, section: CrossSection, k: int, outward: int):
    spec = section.lanes[k]
    lane = xodr.Lane(lane_type=getattr(xodr.LaneType, spec.type), a=float(spec.width_m))
    mark = _mark(xodr, section, k, outward)
    if mark is not None:
        lane.add_roadmark(mark)
    return lane


def _xodr_road(road: Road, road_id: int):
    from scenariogeneration import xodr

    line, err_m = fit_reference_line(road.centerline)
    if err_m > FIT_TOLERANCE_M:
        log.warning("road %s: reference line within %.2f m of the centerline (sharp corners); "
                    "tolerance %.2f m", road.id, err_m, FIT_TOLERANCE_M)
    planview = xodr.PlanView(line.x0_m, line.y0_m, line.heading0_rad)
    for kind, k0, k1, length in line.pieces():
        if kind == "line":
            planview.add_geometry(xodr.Line(length))
        elif kind == "arc":
            planview.add_geometry(xodr.Arc(k0, length=length))
        else:
            planview.add_geometry(xodr.Spiral(k0, k1, length=length))

    layout = road.layout()
    split = centre_split(layout)
    centre = xodr.Lane(a=0)
    centre.add_roadmark(xodr.RoadMark(xodr.RoadMarkType.solid, SOLID_MARK_M))
    section = xodr.LaneSection(0, centre)
    for k in range(split - 1, -1, -1):  # right lanes from the centre outwards
        section.add_right_lane(_xodr_lane(xodr, layout, k, -1))
    for k in range(split, len(layout.lanes)):  # left lanes from the centre outwards
        section.add_left_lane(_xodr_lane(xodr, layout, k, +1))
    lanes = xodr.Lanes()
    lanes.add_lanesection(section)
    # the centre lane sits left of the forward lanes: move it off the reference line
    lanes.add_laneoffset(xodr.LaneOffset(0, float(layout.edges_m[split])))
    xroad = xodr.Road(road_id, planview, lanes, name=road.name or None)
    xroad.add_elevation(0, 0, 0, 0, 0)
    return xroad


def build_opendrive(scenario: Scenario, name: str = "vid2sim"):
    """The scenario's roads as a scenariogeneration ``OpenDrive`` (revision 1.8)."""
    from scenariogeneration import xodr

    roads = scenario.roads or [straight_road_for(scenario.ego)]
    odr = xodr.OpenDrive(name, revMajor="1", revMinor="8",
                         geo_reference=EnuFrame(scenario.origin).proj_string())
    for i, road in enumerate(roads, start=1):
        odr.add_road(_xodr_road(road, i))
    odr.adjust_roads_and_lanes()
    return odr


def set_header_bounds(root: ET.Element, roads: list[Road]) -> None:
    """OpenDRIVE's header north/south/east/west bound the road data in inertial (ENU)
    metres; scenariogeneration writes zeros."""
    pts = np.vstack([r.centerline for r in roads])
    margin = max(max(r.lanes * r.lane_width_m, float(np.max(np.abs(r.layout().edges_m))))
                 for r in roads)
    header = root.find("header")
    header.set("north", format(float(pts[:, 1].max() + margin), ".6f"))
    header.set("south", format(float(pts[:, 1].min() - margin), ".6f"))
    header.set("east", format(float(pts[:, 0].max() + margin), ".6f"))
    header.set("west", format(float(pts[:, 0].min() - margin), ".6f"))

