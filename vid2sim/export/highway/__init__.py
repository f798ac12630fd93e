"""highway-env environment that replays a vid2sim scenario (registered as ``vid2sim/Replay-v0``).

Modules: :mod:`~vid2sim.export.highway.network` (frames, lanes, the ego's path),
:mod:`~vid2sim.export.highway.vehicles` (replayed, reactive and ego vehicles),
:mod:`~vid2sim.export.highway.traffic` (gaps and the lead along the ego's path),
:mod:`~vid2sim.export.highway.observation` (the Kinematics observation without pandas),
:mod:`~vid2sim.export.highway.env` (the environment).

Frames. ENU in the scenario and in everything the environment reports (``vehicle_states``,
``info``); highway-env's own frame (y down, headings mirrored) inside, converted by
:func:`enu_to_hw` / :func:`hw_to_enu`. ``tests/export/test_highway.py`` checks that right-hand
traffic stays right-hand and that left turns stay left turns.

Lanes. Lane 0 is the RIGHTMOST lane in the travel direction, counting leftwards (the project's
convention, as the road stage's); ``info["ego_lane"]`` uses it. highway-env's internal lane
indices run the other way (0 = leftmost, so its ``LANE_RIGHT`` = index + 1 holds);
:func:`project_lane` / :func:`hw_lane` convert at the boundary.

Road. Each scenario road becomes one edge of a highway-env ``RoadNetwork`` with one lane per
scenario lane, laid out symmetrically about the centerline, all in the travel direction, with
solid outer edges and dashed lines between lanes. Both ends are extended straight by
:data:`ROAD_EXTENSION_M`. Scenarios without roads get
:func:`vid2sim.export.assemble.straight_road_for` the ego.

Vehicles. Actors replay their logged trajectories (linear interpolation of the scenario
samples, present only within their time span). With ``config={"reactive": True}`` (reactive
replay, off by default) an actor leaves its log when the ego's deviation makes the log
implausible: when the simulated ego is in its path, ahead of it, closer than
:class:`HandoverRule` allows (gap, time headway or TTC) and the logged ego at the same time
was not; it then continues from its logged state as highway-env's ``IDMVehicle`` (IDM car
following, MOBIL lane changes) until the episode ends. ``env.handovers`` lists
``Handover(actor_id, t_s, reason)``; ``info["handovers"]`` counts them.

The ego either replays its own log (``ego_mode="log"``, the action is ignored; the evaluator
uses this) or follows the policy (``ego_mode="policy"``). In policy mode:

- longitudinal only (the default): the action is the acceleration and the ego drives along
  its logged path (the recorded positions, prolonged straight beyond both ends), so the cars
  in its path are the ones the recorded driver had in front of the car whatever the map's
  lane geometry; ``config={"ego_path": "lane"}`` makes it steer along its map lane instead
  (highway-env's lane-following controller);
- ``config={"lateral_control": True}``: the action is acceleration and steering, integrated by
  highway-env's kinematic bicycle model (a lane-keeping function steers).

Observation (highway-env ``Kinematics``, not normalised; computed without pandas): an array
``(vehicles_count, 7)``, float32, rows = the ego then the nearest vehicles sorted by distance
along the lane (zero rows when fewer are present), columns ``presence, x, y, vx, vy, cos_h,
sin_h``. The ego row is absolute, other rows are relative to the ego, all in highway-env's
frame: metres and m/s with ``y`` pointing SOUTH (``y_hw = -y_enu``) and
``sin_h = -sin(heading_enu)``. :mod:`vid2sim.adas.sensor` wraps the environment with what a
camera would report instead.

Action: ``Box(-1, 1, (1,))`` mapped linearly to a longitudinal acceleration in
``config["acceleration_range_mps2"]`` (default [-8, 8] m/s^2, so 0 means no acceleration; the
ego never reverses); with lateral control ``Box(-1, 1, (2,))``, the second value mapped to a
front-wheel angle in ``config["steering_range_rad"]`` (default +-pi/4). Positive steers to the
RIGHT (highway-env's frame is mirrored; ISO 8855 would call left positive).

Reward: ``clip(v / v_ref, 0, 1) - 1 if crashed - 0.5 if time headway < 1 s`` (``v_ref`` = the
largest logged ego speed, at least 5 m/s); a simple progress-versus-safety trade-off.

Info (every step; finite numbers or ``inf``, never NaN or None, so that
``gymnasium.utils.env_checker.check_env`` can compare them): ``t_s`` scenario time [s],
``ego_mode``, ``ego_speed_mps``, ``ego_accel_mps2`` (over the last step), ``ego_lane`` (project
numbering), ``lane_offset_m`` (ego centre from its lane's centre, positive left),
``lane_width_m``, ``crashed``, ``collision_with`` (id of the vehicle hit first, "" before),
``offroad``, ``handovers`` (count so far), and the lead, the nearest vehicle ahead whose centre
is within half a lane width of the ego's path: ``has_lead``; ``lead_id`` ("" without a lead);
``gap_m`` bumper-to-bumper along the path [m] (``inf`` without a lead); ``lead_speed_mps`` and
``closing_speed_mps`` (ego minus lead, positive when closing) along the path [m/s] (0.0 without
a lead: read ``has_lead`` first); ``ttc_s`` time to collision [s] and ``time_headway_s`` [s]
(``inf`` where undefined).

Episode: scenario duration (``floor(duration * policy_frequency)`` steps). Terminated when the
ego collides or goes off the road in policy mode (on its logged path only the road's ends
count: the recorded car drove there, so a lateral offset from the map's lanes is the map's
error); in log mode the log is what happened, so the episode always runs to its end and
collisions are only reported in ``info["crashed"]``.
"""

from __future__ import annotations

from vid2sim.export.highway.env import (
    EGO_MODES,
    EGO_PATHS,
    ENV_ID,
    Handover,
    ReplayEnv,
    VehicleState,
)
from vid2sim.export.highway.network import (
    LANE_SAMPLE_M,
    ROAD_EXTENSION_M,
    ScenarioLane,
    build_network,
    enu_to_hw,
    hw_lane,
    hw_to_enu,
    lane_centerlines_enu,
    layout_centerlines_enu,
    project_lane,
)
from vid2sim.export.highway.traffic import EgoState, ObjectState, Traffic
from vid2sim.export.highway.vehicles import (
    HandoverRule,
    LaneFollowingEgo,
    PathEgo,
    ReactiveVehicle,
    ReplayVehicle,
    SteeredEgo,
)

__all__ = [
    "EGO_MODES", "EGO_PATHS", "ENV_ID", "LANE_SAMPLE_M", "ROAD_EXTENSION_M", "EgoState",
    "Handover", "HandoverRule", "LaneFollowingEgo", "ObjectState", "PathEgo", "ReactiveVehicle",
    "ReplayEnv", "ReplayVehicle", "ScenarioLane", "SteeredEgo", "Traffic", "VehicleState",
    "build_network", "enu_to_hw", "hw_lane", "hw_to_enu", "lane_centerlines_enu",
    "layout_centerlines_enu",
    "project_lane",
]
