"""highway-env environment that replays a vid2sim scenario (registered as ``vid2sim/Replay-v0``).

Frames. The scenario is in ENU (x east, y north, heading counter-clockwise from east). highway-env
draws with the screen's y axis pointing DOWN, and its lane geometry (``PolyLaneFixedWidth``) puts
positive lateral offsets at ``(-sin h, cos h)``, i.e. to the right of travel on screen. We map

    x_hw = x_enu,   y_hw = -y_enu,   heading_hw = -heading_enu

which is a reflection: a left turn in ENU (heading increasing) is a heading that decreases in
highway-env's numbers and still turns left on screen, and a lane to the right of travel in ENU
is a lane with a larger index (highway-env's ``LANE_RIGHT`` = index + 1). Every conversion goes
through :func:`enu_to_hw` / :func:`hw_to_enu`; ``tests/export/test_highway.py`` checks that
right-hand traffic stays right-hand and that left turns stay left turns.

Road. Each scenario road becomes one edge of a highway-env ``RoadNetwork`` with one
``PolyLaneFixedWidth`` per lane, laid out symmetrically about the centerline (lane 0 the leftmost
in the travel direction), all in the travel direction, with explicit line types (solid outer
edges, dashed between lanes). Both ends are extended straight by :data:`ROAD_EXTENSION_M` so a
log that starts or ends at the road's end does not count as leaving the road. Scenarios without
roads get :func:`vid2sim.export.assemble.straight_road_for` the ego.

Vehicles. Actors replay their logged trajectories (linear interpolation of the scenario samples,
present only within their time span), they do not run IDM. The ego either follows the policy
(``ego_mode="policy"``: the action is a longitudinal acceleration, lateral control is
highway-env's lane-following steering controller on the ego's lane) or replays its own log
(``ego_mode="log"``, the action is ignored; the evaluator uses this).

Observation (highway-env ``Kinematics``, not normalised): an array ``(vehicles_count, 7)``,
float32, rows = the ego then the nearest vehicles sorted by distance along the lane (zero rows
when fewer are present), columns ``presence, x, y, vx, vy, cos_h, sin_h``. The ego row is absolute,
other rows are relative to the ego, all in highway-env's frame: metres and m/s with ``y`` pointing
SOUTH (``y_hw = -y_enu``) and ``sin_h = -sin(heading_enu)``.

Action: ``Box(-1, 1, (1,))`` mapped linearly to a longitudinal acceleration in
``config["acceleration_range_mps2"]`` (default [-8, 8] m/s^2, so 0 means no
acceleration; the ego never reverses).

Reward: ``clip(v / v_ref, 0, 1) - 1 if crashed - 0.5 if time headway < 1 s`` (``v_ref`` = the
largest logged ego speed, at least 5 m/s); a simple progress-versus-safety trade-off.

Info (every step): ``t_s`` scenario time [s], ``ego_speed_mps``, ``lead_id`` (None without a
lead), ``gap_m`` bumper-to-bumper gap to the lead along the ego lane [m], ``lead_speed_mps``,
``closing_speed_mps`` (positive when closing), ``ttc_s`` time to collision [s],
``time_headway_s`` [s] (``inf`` where undefined), ``crashed``, ``offroad``, ``ego_mode``.

Episode: scenario duration (``floor(duration * policy_frequency)`` steps). Terminated when the
ego collides or leaves the road in policy mode; in log mode the log is what happened, so the
episode always runs to its end and collisions are only reported in ``info["crashed"]``.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

import numpy as np
from highway_env import utils
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.road.lane import LineType, PolyLaneFixedWidth
from highway_env.road.road import Road as HwRoad
from highway_env.road.road import RoadNetwork
from highway_env.vehicle.controller import ControlledVehicle
from highway_env.vehicle.kinematics import Vehicle

from vid2sim import scenario as scenario_io
from vid2sim.errors import InputError
from vid2sim.scenario import Road, Scenario, Trajectory

ENV_ID = "vid2sim/Replay-v0"
ROAD_EXTENSION_M = 50.0
"""Straight extension of each road end in the simulation [m] (the scenario is unchanged)."""
LANE_SAMPLE_M = 1.0
"""Resampling step of lane polylines [m] (highway-env samples its curves at 1 m too)."""
EGO_MODES = ("policy", "log")
_COARSE_STEP = 10  # samples between coarse search points of ScenarioLane
_WINDOW = 40  # fine search half-window of ScenarioLane [samples]
_EGO_COLOR = (50, 200, 0)  # RGB, highway-env's ego green
_ACTOR_COLOR = (100, 200, 255)  # RGB, highway-env's traffic blue


# --------------------------------------------------------------------------- frames


def enu_to_hw(x_m, y_m, heading_rad=None):
    """ENU -> highway-env coordinates (y axis down): ``(x, -y[, -heading])``."""
    if heading_rad is None:
        return np.asarray(x_m, float), -np.asarray(y_m, float)
    return np.asarray(x_m, float), -np.asarray(y_m, float), -np.asarray(heading_rad, float)


def hw_to_enu(x_m, y_m, heading_rad=None):
    """highway-env -> ENU coordinates; the reflection is its own inverse."""
    return enu_to_hw(x_m, y_m, heading_rad)


class VehicleState(NamedTuple):
    """One vehicle at one instant, in ENU (box centre on the road, heading CCW from east)."""

    id: str
    x_m: float
    y_m: float
    heading_rad: float
    length_m: float
    width_m: float
    height_m: float
    speed_mps: float


# --------------------------------------------------------------------------- lanes


class ScenarioLane(PolyLaneFixedWidth):
    """A ``PolyLaneFixedWidth`` whose world -> lane projection is vectorised.

    highway-env's own ``cartesian_to_frenet`` scans the 1 m curve samples in a Python loop from
    the end and takes the first with a non-negative projection, which costs O(length) Python
    steps per call (called for every vehicle, lane and step) and picks the wrong branch on
    curves that come back on themselves. Here the nearest sampled segment wins, in numpy.
    """

    def __init__(self, lane_points, width: float, line_types, speed_limit: float = 30.0):
        super().__init__(lane_points, width=width, line_types=line_types,
                         speed_limit=speed_limit)
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
        clamped = np.clip(along, low, self._seg_len[lo:hi])
        # squared distance from the point to its clamped foot on each segment
        dist2 = dx * dx + dy * dy - 2 * clamped * along + clamped**2
        i = int(np.argmin(dist2))
        # lateral positive along (-t_y, t_x), the same side as PolyLaneFixedWidth.position()
        lat = -dx[i] * ty[i] + dy[i] * tx[i]
        return float(self._s[lo + i] + along[i]), float(lat)

    def heading_at(self, longitudinal: float) -> float:
        # the same piecewise-constant heading as highway-env's, found by bisection
        i = int(np.clip(np.searchsorted(self._s, longitudinal, side="right") - 1,
                        0, len(self._s) - 1))
        return float(math.atan2(self._ty[i], self._tx[i]))


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


def _extend_ends(points_m: np.ndarray, extension_m: float, step_m: float) -> np.ndarray:
    """Prolong a polyline straight along its end tangents by ``extension_m`` at both ends."""
    p = points_m
    n = max(math.ceil(extension_m / step_m), 1)
    k = np.linspace(extension_m, 0.0, n + 1)[:-1, None]
    t0 = (p[1] - p[0]) / np.linalg.norm(p[1] - p[0])
    t1 = (p[-1] - p[-2]) / np.linalg.norm(p[-1] - p[-2])
    head = p[0] - k * t0
    tail = p[-1] + k[::-1] * t1
    return np.vstack((head, p, tail))


def _left_normals(points_m: np.ndarray) -> np.ndarray:
    """Unit normals pointing to the LEFT of travel in ENU: the tangent rotated +90 deg."""
    tangent = np.gradient(points_m, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    return np.column_stack((-tangent[:, 1], tangent[:, 0]))


def lane_centerlines_enu(road: Road, extension_m: float = ROAD_EXTENSION_M) -> list[np.ndarray]:
    """Centre polylines of a road's lanes in ENU [m], lane 0 the leftmost in travel direction.

    Lanes are laid out symmetrically about the road centerline (the scenario gives a lane count
    and a width, not a per-direction split).
    """
    centre = _resample_polyline(road.centerline, LANE_SAMPLE_M)
    if extension_m > 0:
        centre = _extend_ends(centre, extension_m, LANE_SAMPLE_M)
    normal = _left_normals(centre)
    out = []
    for k in range(road.lanes):
        offset_left_m = ((road.lanes - 1) / 2.0 - k) * road.lane_width_m
        out.append(centre + offset_left_m * normal)
    return out


def _line_types(k: int, lanes: int) -> tuple[int, int]:
    # (left, right) in travel direction: highway-env draws line_types[0] at lateral -w/2, which
    # after the y flip is the ENU left side. Dashed lines are drawn once, on the right of a lane.
    # Solid edges are CONTINUOUS (drawn piecewise along the curve): CONTINUOUS_LINE is drawn
    # as one straight segment and cuts across curved roads.
    left = LineType.CONTINUOUS if k == 0 else LineType.NONE
    right = LineType.CONTINUOUS if k == lanes - 1 else LineType.STRIPED
    return left, right


def build_network(roads: list[Road]) -> RoadNetwork:
    """A highway-env road network with one edge per road and one lane per scenario lane."""
    net = RoadNetwork()
    for i, road in enumerate(roads):
        for k, lane_enu in enumerate(lane_centerlines_enu(road)):
            x_hw, y_hw = enu_to_hw(lane_enu[:, 0], lane_enu[:, 1])
            lane = ScenarioLane(list(zip(x_hw.tolist(), y_hw.tolist(), strict=True)),
                                width=road.lane_width_m, line_types=_line_types(k, road.lanes))
            net.add_lane(f"road{i}:start", f"road{i}:end", lane)
    return net


# --------------------------------------------------------------------------- vehicles


class _TrackHw:
    """A scenario trajectory converted to highway-env coordinates, interpolated in time."""

    def __init__(self, traj: Trajectory):
        self.t = traj.t
        self.x, self.y, heading = enu_to_hw(traj.x, traj.y, np.unwrap(traj.heading))
        self.heading = heading
        self.speed = traj.speed

    @property
    def t0(self) -> float:
        return float(self.t[0])

    @property
    def t1(self) -> float:
        return float(self.t[-1])

    def at(self, t_s: float) -> tuple[np.ndarray, float, float]:
        t = min(max(t_s, self.t0), self.t1)
        pos = np.array([np.interp(t, self.t, self.x), np.interp(t, self.t, self.y)])
        return pos, float(np.interp(t, self.t, self.heading)), float(np.interp(t, self.t, self.speed))


def _set_box(v: Vehicle, length_m: float, width_m: float) -> None:
    # highway-env reads the box from (class) attributes LENGTH/WIDTH; instance ones override.
    v.LENGTH, v.WIDTH = float(length_m), float(width_m)
    v.diagonal = math.hypot(v.LENGTH, v.WIDTH)


class ReplayVehicle(Vehicle):
    """A vehicle placed on its logged trajectory at every step (no dynamics, no IDM)."""

    def __init__(self, road: HwRoad, vehicle_id: str, track: _TrackHw, length_m: float,
                 width_m: float, height_m: float, t_s: float):
        pos, heading, speed = track.at(t_s)
        super().__init__(road, pos, heading, speed)
        self.vehicle_id = vehicle_id
        self.track = track
        self.height_m = float(height_m)
        _set_box(self, length_m, width_m)

    def place(self, t_s: float) -> None:
        """Move to the logged state at scenario time ``t_s`` [s]."""
        self.position, self.heading, self.speed = self.track.at(t_s)
        self.on_state_update()

    def act(self, action=None) -> None:
        pass  # a log does not take actions

    def on_state_update(self) -> None:
        # A replayed vehicle usually stays on its lane: one projection instead of a search
        # over every lane of the network (the dominant cost of a step with many actors).
        if self.lane is not None:
            s, lat = self.lane.local_coordinates(self.position)
            if abs(lat) <= self.lane.width_at(s) / 2.0 and 0.0 <= s <= self.lane.length:
                return
        super().on_state_update()

    def step(self, dt: float) -> None:
        # The env places replayed vehicles before the road steps; collision impulses must not
        # push a log around.
        self.impact = None


class LaneFollowingEgo(ControlledVehicle):
    """The policy-driven ego: acceleration from the action, steering from the lane follower.

    highway-env's ``ContinuousAction(lateral=False)`` sends steering 0, which drives straight
    off curved lanes; this vehicle replaces it with ``ControlledVehicle.steering_control`` on
    its lane (a pure-pursuit-like heading controller cascaded with lateral position control).
    """

    MIN_SPEED = 0.0  # braking stops the car, it does not reverse

    def act(self, action: dict | str | None = None) -> None:
        accel = float(action["acceleration"]) if isinstance(action, dict) else 0.0
        steer = self.steering_control(self.target_lane_index)
        Vehicle.act(self, {"acceleration": accel, "steering": steer})

    def step(self, dt: float) -> None:
        super().step(dt)
        self.speed = max(self.speed, 0.0)


# --------------------------------------------------------------------------- environment


def _as_scenario(scenario: Scenario | str | Path | None) -> Scenario:
    if isinstance(scenario, Scenario):
        return scenario
    if scenario is None:
        raise InputError(None, f"{ENV_ID} needs a scenario",
                         f'gymnasium.make("{ENV_ID}", scenario="scenario.json")')
    return scenario_io.load(scenario)


class ReplayEnv(AbstractEnv):
    """Replay a vid2sim scenario in highway-env (see the module docstring for all spaces).

    Parameters
    ----------
    scenario : Scenario, str or Path
        The scenario, or the path of a ``scenario.json``.
    ego_mode : {"policy", "log"}
        Who drives the ego; ``reset(options={"ego_mode": ...})`` switches it per episode.
    render_mode : {"rgb_array", "human"} or None
        ``rgb_array`` works headless (SDL's offscreen video driver; highway-env's "dummy"
        setting would skip drawing).
    config : dict, optional
        highway-env configuration overrides (e.g. ``policy_frequency`` [Hz],
        ``simulation_frequency`` [Hz], ``acceleration_range_mps2``, screen size).
    """

    metadata: ClassVar[dict] = {"render_modes": ["human", "rgb_array"], "render_fps": 10}

    def __init__(self, scenario: Scenario | str | Path | None = None, ego_mode: str = "policy",
                 render_mode: str | None = None, config: dict | None = None):
        self.scenario = _as_scenario(scenario)
        if ego_mode not in EGO_MODES:
            raise ValueError(f"ego_mode must be one of {EGO_MODES}, got {ego_mode!r}")
        self.ego_mode = ego_mode
        self._default_ego_mode = ego_mode
        if not self.scenario.roads:
            from vid2sim.export.assemble import straight_road_for

            self._roads = [straight_road_for(self.scenario.ego.trajectory)]
        else:
            self._roads = list(self.scenario.roads)
        self._network = build_network(self._roads)
        self._ego_track = _TrackHw(self.scenario.ego.trajectory)
        self._actor_tracks = [(a, _TrackHw(a.trajectory)) for a in self.scenario.actors]
        self.t_s = self._ego_track.t0
        self.actors: list[ReplayVehicle] = []
        if render_mode == "rgb_array":
            os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")
        super().__init__(config=config, render_mode=render_mode)

    @classmethod
    def default_config(cls) -> dict:
        config = super().default_config()
        config.update({
            "observation": {
                "type": "Kinematics", "vehicles_count": 8,
                "features": ["presence", "x", "y", "vx", "vy", "cos_h", "sin_h"],
                "absolute": False, "normalize": False, "clip": False, "see_behind": True,
                "order": "sorted",
            },
            "acceleration_range_mps2": [-8.0, 8.0],  # symmetric: action 0 = coast
            "simulation_frequency": 20,  # [Hz] two integration steps per decision
            "policy_frequency": 10,  # [Hz]
            "screen_width": 600,  # [px]
            "screen_height": 300,  # [px]
            "centering_position": [0.5, 0.5],
            "scaling": 5.0,  # [px/m]
            "headway_penalty_s": 1.0,
        })
        return config

    # ----------------------------------------------------------------- spaces

    def define_spaces(self) -> None:
        self.config["action"] = {
            "type": "ContinuousAction", "longitudinal": True, "lateral": False,
            "acceleration_range": tuple(self.config["acceleration_range_mps2"]),
        }
        super().define_spaces()

    # ----------------------------------------------------------------- scene

    @property
    def n_steps(self) -> int:
        """Policy steps in one episode: the scenario duration at the policy frequency."""
        duration_s = self._ego_track.t1 - self._ego_track.t0
        return max(math.floor(duration_s * self.config["policy_frequency"] + 1e-9), 1)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        mode = (options or {}).get("ego_mode", self._default_ego_mode)
        if mode not in EGO_MODES:
            raise ValueError(f"ego_mode must be one of {EGO_MODES}, got {mode!r}")
        self.ego_mode = mode
        return super().reset(seed=seed, options=options)

    def _reset(self) -> None:
        self.t_s = self._ego_track.t0
        self._policy_steps = 0
        self._info_key = None  # invalidate the per-step info cache
        self.road = HwRoad(network=self._network, np_random=self.np_random,
                           record_history=self.config["show_trajectories"])
        ego_rec = self.scenario.ego
        if self.ego_mode == "log":
            ego = ReplayVehicle(self.road, "ego", self._ego_track, ego_rec.length_m,
                                ego_rec.width_m, ego_rec.height_m, self.t_s)
        else:
            pos, heading, speed = self._ego_track.at(self.t_s)
            ego = LaneFollowingEgo(self.road, pos, heading, speed)
            ego.height_m = ego_rec.height_m
            ego.vehicle_id = "ego"
            _set_box(ego, ego_rec.length_m, ego_rec.width_m)
        ego.color = _EGO_COLOR
        self.vehicle = ego
        self.road.vehicles = [ego]
        self.actors = [
            ReplayVehicle(self.road, a.id, track, a.length_m, a.width_m, a.height_m, self.t_s)
            for a, track in self._actor_tracks
        ]
        for v in self.actors:
            v.color = _ACTOR_COLOR
        self._place_actors(self.t_s)
        self._v_ref = max(float(np.max(self.scenario.ego.trajectory.speed)), 5.0)

    def _place_actors(self, t_s: float) -> None:
        """Put every actor on its log at ``t_s``; only actors within their span are on the road."""
        present = []
        for v in self.actors:
            if v.track.t0 - 1e-9 <= t_s <= v.track.t1 + 1e-9:
                v.place(t_s)
                present.append(v)
        if self.ego_mode == "log":
            self.vehicle.place(t_s)
        self.road.vehicles = [self.vehicle, *present]

    def _simulate(self, action=None) -> None:
        frames = max(int(self.config["simulation_frequency"]
                         // self.config["policy_frequency"]), 1)
        # each policy step covers exactly 1 / policy_frequency of scenario time, so the
        # integration step is that split into whole substeps
        dt = 1.0 / (frames * self.config["policy_frequency"])
        if action is not None:
            self.action_type.act(action)
        for frame in range(frames):
            # Actors (and a logged ego) first go to the end of the substep, then the ego
            # integrates to it, then collisions are checked at one common time. The time comes
            # from the step count, not a running sum, so it does not drift.
            t_next = self._ego_track.t0 + (self.steps + 1) * dt
            self._place_actors(t_next)
            if self.ego_mode == "policy":
                self.vehicle.act(self.action_type.get_action(self.action_type.last_action))
            self.road.step(dt)
            self.t_s = t_next
            self.steps += 1
            if frame < frames - 1:
                self._automatic_rendering()
        self._policy_steps += 1
        self.enable_auto_render = False

    # ----------------------------------------------------------------- outcome

    def _ego_lane(self):
        ego = self.vehicle
        index = getattr(ego, "target_lane_index", None) or ego.lane_index
        return self.road.network.get_lane(index)

    def lead(self) -> tuple[Vehicle | None, float]:
        """The nearest vehicle ahead in the ego's lane and its bumper-to-bumper gap [m]."""
        ego = self.vehicle
        lane = self._ego_lane()
        s_ego, _ = lane.local_coordinates(ego.position)
        best, best_gap = None, math.inf
        for v in self.road.vehicles:
            if v is ego:
                continue
            s, lat = lane.local_coordinates(v.position)
            if s <= s_ego or abs(lat) > lane.width_at(s) / 2.0:
                continue
            gap = s - s_ego - (ego.LENGTH + v.LENGTH) / 2.0
            if gap < best_gap:
                best, best_gap = v, gap
        return best, best_gap

    def _info(self, obs, action=None) -> dict:
        # step() asks for the reward and then the info of the same state: compute once
        key = (self.steps, self._policy_steps)
        if getattr(self, "_info_key", None) != key:
            self._info_cache, self._info_key = self._compute_info(), key
        return dict(self._info_cache)

    def _compute_info(self) -> dict:
        ego = self.vehicle
        lead, gap_m = self.lead()
        info: dict[str, Any] = {
            "t_s": float(self.t_s),
            "ego_mode": self.ego_mode,
            "ego_speed_mps": float(ego.speed),
            "crashed": bool(ego.crashed),
            "offroad": not bool(ego.on_road),
            "lead_id": None, "gap_m": math.inf, "lead_speed_mps": math.nan,
            "closing_speed_mps": math.nan, "ttc_s": math.inf, "time_headway_s": math.inf,
        }
        if lead is not None:
            lane = self._ego_lane()
            s_ego, _ = lane.local_coordinates(ego.position)
            s_lead, _ = lane.local_coordinates(lead.position)
            lane_heading = lane.heading_at(s_lead)
            # speeds projected on the lane direction, so a crossing car does not count fully
            v_lead = float(lead.speed * math.cos(utils.wrap_to_pi(lead.heading - lane_heading)))
            v_ego = float(ego.speed * math.cos(
                utils.wrap_to_pi(ego.heading - lane.heading_at(s_ego))))
            closing = v_ego - v_lead
            info.update({
                "lead_id": lead.vehicle_id, "gap_m": float(gap_m), "lead_speed_mps": v_lead,
                "closing_speed_mps": closing,
                "ttc_s": float(max(gap_m, 0.0) / closing) if closing > 1e-6 else math.inf,
                "time_headway_s": float(max(gap_m, 0.0) / v_ego) if v_ego > 1e-6 else math.inf,
            })
        return info

    def _reward(self, action) -> float:
        info = self._info(None)
        r = float(np.clip(self.vehicle.speed / self._v_ref, 0.0, 1.0))
        if info["crashed"]:
            r -= 1.0
        if info["time_headway_s"] < self.config["headway_penalty_s"]:
            r -= 0.5
        return r

    def _is_terminated(self) -> bool:
        if self.ego_mode == "log":
            return False
        return bool(self.vehicle.crashed or not self.vehicle.on_road)

    def _is_truncated(self) -> bool:
        return self._policy_steps >= self.n_steps

    # ----------------------------------------------------------------- evaluator access

    def vehicle_states(self, t_s: float | None = None) -> list[VehicleState]:
        """Every vehicle on the road (ego first) in ENU at the current step.

        Parameters
        ----------
        t_s : float, optional
            Scenario time [s]. None (or the current time) gives the simulated states. Another
            time is allowed in log mode only: the replayed vehicles are then evaluated at
            ``t_s`` directly from their logs, without stepping.
        """
        if t_s is not None and abs(t_s - self.t_s) > 1e-9:
            if self.ego_mode != "log":
                raise ValueError("vehicle_states(t_s) at another time needs ego_mode='log'")
            vehicles = [self.vehicle, *self.actors]
            out = []
            for v in vehicles:
                if not v.track.t0 - 1e-9 <= t_s <= v.track.t1 + 1e-9 and v is not self.vehicle:
                    continue
                pos, heading, speed = v.track.at(t_s)
                out.append(self._state(v, pos, heading, speed))
            return out
        return [self._state(v, v.position, v.heading, v.speed) for v in self.road.vehicles]

    @staticmethod
    def _state(v, pos_hw, heading_hw, speed) -> VehicleState:
        x, y, h = hw_to_enu(pos_hw[0], pos_hw[1], heading_hw)
        return VehicleState(str(v.vehicle_id), float(x), float(y),
                            float(utils.wrap_to_pi(float(h))), float(v.LENGTH),
                            float(v.WIDTH), float(v.height_m), float(speed))

