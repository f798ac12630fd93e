"""The traffic around the ego, measured exactly along the ego's reference line.

The reference line is the ego's logged path (longitudinal-only control and log replay) or the
lane the ego is in (lane following, lateral control). Every other vehicle is located on it by
arc length and lateral offset; the lead is the nearest vehicle ahead whose centre lies within
half a lane width of the line (the ego's path corridor). The environment's ``info`` and the
sensor model of :mod:`vid2sim.adas.sensor` both read this snapshot.

Signs follow ENU and the project: lateral offsets and curvatures are positive to the LEFT,
headings counter-clockwise; lanes are numbered from the right (lane 0 = the rightmost).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from highway_env import utils

from vid2sim.core.lead import in_ego_corridor, lead_of
from vid2sim.export.highway.network import project_lane

CURVATURE_LOOKAHEAD_M = 10.0
"""Arc length over which the lane's curvature ahead of the ego is measured [m] (the distance
at which a camera's lane model is fitted best)."""


@dataclass(frozen=True, slots=True)
class ObjectState:
    """One vehicle relative to the ego, on the ego's reference line."""

    id: str
    along_m: float
    """Centre-to-centre distance along the reference line [m], positive ahead."""
    gap_m: float
    """Bumper-to-bumper distance along the line [m]: for a vehicle ahead (``along_m`` > 0)
    from the ego's front to its rear, negative when the two overlap; for one behind, minus the
    distance from its front to the ego's rear."""
    lateral_m: float
    """Offset of the vehicle's centre from the line [m], positive left."""
    speed_along_mps: float
    """Its velocity along the line's direction at its position [m/s] (negative: oncoming)."""
    lane: int
    """Its lane, project numbering (0 = rightmost of its road)."""
    lane_offset: int
    """Lanes to the left of the ego's lane (negative: to the right)."""
    length_m: float
    width_m: float
    in_path: bool
    """Its centre lies within half a lane width of the reference line."""


@dataclass(frozen=True, slots=True)
class EgoState:
    """The ego's own motion and its place on the map's lane."""

    speed_mps: float
    speed_along_mps: float
    """Speed projected on the reference line's direction [m/s]."""
    lane: int
    """Project lane number (0 = rightmost)."""
    lane_offset_m: float
    """Offset of the ego's centre from its lane's centre [m], positive left."""
    heading_error_rad: float
    """Ego heading minus lane heading [rad], counter-clockwise positive."""
    lane_curvature_per_m: float
    """Curvature of the lane over the next :data:`CURVATURE_LOOKAHEAD_M` [1/m], left
    positive."""
    lane_width_m: float
    length_m: float
    width_m: float


@dataclass(frozen=True, slots=True)
class Traffic:
    """The ego and every other vehicle on the road, sorted by |along|."""

    ego: EgoState
    objects: tuple[ObjectState, ...]
    lead: ObjectState | None


def lanes_on_edge(network, lane_index) -> int:
    """How many lanes the network edge of ``lane_index`` has."""
    return len(network.graph[lane_index[0]][lane_index[1]])


def measure(ego, others, reference, network) -> Traffic:
    """Locate ``others`` relative to ``ego`` on ``reference`` (a lane object).

    Parameters
    ----------
    ego : highway-env Vehicle
        The ego (its ``lane`` is the map lane it is in).
    others : iterable of Vehicle
        The other vehicles on the road (with ``vehicle_id``).
    reference : AbstractLane
        The ego's reference line, in highway-env's frame (lateral positive to the right).
    network : RoadNetwork
        For lane counts.
    """
    s_ego, _ = reference.local_coordinates(ego.position)
    ref_heading = reference.heading_at(s_ego)
    half_width = reference.width_at(s_ego) / 2.0
    # the ego on its map lane (highway-env's lateral is positive to the right: negate)
    lane = ego.lane
    s_lane, lat_lane = lane.local_coordinates(ego.position)
    lane_heading = lane.heading_at(s_lane)
    lane_ahead = lane.heading_at(s_lane + CURVATURE_LOOKAHEAD_M)
    ego_lanes = lanes_on_edge(network, ego.lane_index)
    ego_lane = project_lane(ego.lane_index[2], ego_lanes)
    ego_state = EgoState(
        speed_mps=float(ego.speed),
        speed_along_mps=float(ego.speed * math.cos(utils.wrap_to_pi(ego.heading - ref_heading))),
        lane=ego_lane,
        lane_offset_m=float(-lat_lane),
        heading_error_rad=float(-utils.wrap_to_pi(ego.heading - lane_heading)),
        lane_curvature_per_m=float(-utils.wrap_to_pi(lane_ahead - lane_heading)
                                   / CURVATURE_LOOKAHEAD_M),
        lane_width_m=float(lane.width_at(s_lane)),
        length_m=float(ego.LENGTH), width_m=float(ego.WIDTH))
    objects = []
    for v in others:
        s, lat = reference.local_coordinates(v.position)
        along = s - s_ego
        half_lengths = (ego.LENGTH + v.LENGTH) / 2.0
        gap = along - half_lengths if along > 0.0 else along + half_lengths
        heading_at = reference.heading_at(s)
        v_along = float(v.speed * math.cos(utils.wrap_to_pi(v.heading - heading_at)))
        v_lane = project_lane(v.lane_index[2], lanes_on_edge(network, v.lane_index))
        if v.lane_index[:2] == ego.lane_index[:2]:
            offset = v_lane - ego_lane
        else:  # another edge (oncoming lanes, a parking strip, another road): count lane
            # widths from the ego's lane
            _, lat_v = lane.local_coordinates(v.position)
            offset = round(-lat_v / max(ego_state.lane_width_m, 0.1))
            if v.lane_index[0].split(":")[0] == ego.lane_index[0].split(":")[0]:
                v_lane = ego_lane + offset  # the ego's road: its numbers count driving lanes
        objects.append(ObjectState(
            id=str(getattr(v, "vehicle_id", "")), along_m=float(along), gap_m=float(gap),
            lateral_m=float(-lat), speed_along_mps=v_along, lane=v_lane, lane_offset=offset,
            length_m=float(v.LENGTH), width_m=float(v.WIDTH),
            in_path=bool(in_ego_corridor(lat, 2.0 * half_width))))
    objects.sort(key=lambda o: abs(o.along_m))
    # the lead (vid2sim.core.lead): the nearest vehicle ahead in the ego's corridor, nearest
    # by the bumper-to-bumper gap
    k = lead_of(np.array([o.along_m for o in objects]),
                np.array([o.lateral_m for o in objects]), 2.0 * half_width,
                nearness_m=np.array([o.gap_m for o in objects])) if objects else -1
    return Traffic(ego_state, tuple(objects), objects[k] if k >= 0 else None)
