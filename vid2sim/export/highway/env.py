"""The ``vid2sim/Replay-v0`` environment: see :mod:`vid2sim.export.highway` for its spaces."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, ClassVar, NamedTuple

import numpy as np
from highway_env import utils
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.road.road import Road as HwRoad

from vid2sim.base.errors import MissingInputError
from vid2sim.core import scenario as scenario_io
from vid2sim.core.records import EGO_ID
from vid2sim.core.scenario import Scenario
from vid2sim.export.assemble import straight_road_for
from vid2sim.export.highway.info import StepInfo
from vid2sim.export.highway.network import hw_to_enu, network_for, path_lane
from vid2sim.export.highway.observation import FastKinematics
from vid2sim.export.highway.traffic import Traffic, measure
from vid2sim.export.highway.vehicles import (
    HandoverRule,
    LaneFollowingEgo,
    LogTrack,
    PathEgo,
    ReactiveVehicle,
    ReplayVehicle,
    SteeredEgo,
    conflict,
    set_box,
)

ENV_ID = "vid2sim/Replay-v0"
EGO_MODES = ("policy", "log")
EGO_PATHS = ("log", "lane")
MAX_SPEED_MPS = 40.0
"""highway-env's vehicle speed cap [m/s]; bounds how far past its log a policy ego can go."""
_EGO_COLOR = (50, 200, 0)  # RGB, highway-env's ego green
_ACTOR_COLOR = (100, 200, 255)  # RGB, highway-env's traffic blue
_REACTIVE_COLOR = (255, 150, 40)  # RGB, orange: an actor handed over to IDM


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


class Handover(NamedTuple):
    """A recorded actor leaving its log for IDM/MOBIL (reactive replay)."""

    actor_id: str
    t_s: float
    reason: str
    """``gap``, ``headway`` or ``ttc``: which of :class:`HandoverRule`'s limits the simulated
    ego broke (and the logged ego did not)."""


def _as_scenario(scenario: Scenario | str | Path | None) -> Scenario:
    if isinstance(scenario, Scenario):
        return scenario
    if scenario is None:
        raise MissingInputError(None, f"{ENV_ID} needs a scenario",
                                f'gymnasium.make("{ENV_ID}", scenario="scenario.json")')
    return scenario_io.load(scenario)


class ReplayEnv(AbstractEnv):
    """Replay a vid2sim scenario in highway-env (see :mod:`vid2sim.export.highway` for the
    spaces, the info keys and the options).

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
        Configuration overrides: ``lateral_control`` (bool), ``ego_path`` ("log" or "lane"),
        ``reactive`` (bool), ``handover`` (dict of :class:`HandoverRule` fields),
        ``acceleration_range_mps2``, ``steering_range_rad``, ``policy_frequency`` [Hz],
        ``simulation_frequency`` [Hz], screen size, and highway-env's own keys.
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
            self._roads = [straight_road_for(self.scenario.ego.trajectory)]
        else:
            self._roads = list(self.scenario.roads)
        self._network = network_for(self._roads)
        self._ego_track = LogTrack(self.scenario.ego.trajectory)
        self._actor_tracks = [(a, LogTrack(a.trajectory)) for a in self.scenario.actors]
        self._path = None  # the ego's logged path as a lane, built on first reset
        self.t_s = self._ego_track.t0
        self.actors: list[ReplayVehicle | ReactiveVehicle] = []
        self.handovers: list[Handover] = []
        self.observe_kinematics = True
        """False: the Kinematics observation is all zeros (a wrapper that replaces the
        observation sets it, to skip its cost)."""
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
            # highway-env's ContinuousAction default: +-45 deg front-wheel angle
            "steering_range_rad": [-math.pi / 4, math.pi / 4],
            "lateral_control": False,
            "ego_path": "log",
            "reactive": False,
            "handover": {},
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
        if self.config["ego_path"] not in EGO_PATHS:
            raise ValueError(f"ego_path must be one of {EGO_PATHS}, "
                             f"got {self.config['ego_path']!r}")
        self.config["action"] = {
            "type": "ContinuousAction", "longitudinal": True,
            "lateral": bool(self.config["lateral_control"]),
            "acceleration_range": tuple(self.config["acceleration_range_mps2"]),
            "steering_range": tuple(self.config["steering_range_rad"]),
        }
        super().define_spaces()
        obs_config = dict(self.config["observation"])
        if obs_config.pop("type") == "Kinematics":
            self.observation_type = FastKinematics(self, **obs_config)
            self.observation_space = self.observation_type.space()

    # ----------------------------------------------------------------- scene

    @property
    def n_steps(self) -> int:
        """Policy steps in one episode: the scenario duration at the policy frequency."""
        duration_s = self._ego_track.t1 - self._ego_track.t0
        return max(math.floor(duration_s * self.config["policy_frequency"] + 1e-9), 1)

    @property
    def path(self):
        """The ego's logged path as a lane (highway-env frame; see
        :func:`~vid2sim.export.highway.network.path_lane`)."""
        if self._path is None:
            tr = self._ego_track
            lane = self._network.get_lane(self._network.get_closest_lane_index(
                np.array([tr.x[0], tr.y[0]]), float(tr.heading[0])))
            duration_s = tr.t1 - tr.t0
            self._path = path_lane(tr.x, tr.y, float(tr.heading[0]), lane.width_at(0.0),
                                   ahead_m=MAX_SPEED_MPS * duration_s + 50.0)
        return self._path

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        mode = (options or {}).get("ego_mode", self._default_ego_mode)
        if mode not in EGO_MODES:
            raise ValueError(f"ego_mode must be one of {EGO_MODES}, got {mode!r}")
        self.ego_mode = mode
        return super().reset(seed=seed, options=options)

    def _reset(self) -> None:
        self.t_s = self._ego_track.t0
        self._policy_steps = 0
        # the logged ego's lane changes, to repeat in lane mode (see _follow_logged_lanes)
        self._ego_lane_events = sorted((e for e in self.scenario.events if e.actor == EGO_ID),
                                       key=lambda e: e.t_s)
        self._info_key = None  # invalidate the per-step caches
        self._traffic_key = None
        self.handovers = []
        self.collision_with = ""
        self._rule = HandoverRule(**self.config["handover"])
        self.road = HwRoad(network=self._network, np_random=self.np_random,
                           record_history=self.config["show_trajectories"])
        ego = self._make_ego()
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
        self._prev_speed, self._prev_heading = float(ego.speed), float(ego.heading)
        self._odometer_m = 0.0
        self.ego_accel_mps2 = 0.0
        self.ego_yaw_rate_radps = 0.0

    def _make_ego(self):
        rec = self.scenario.ego
        if self.ego_mode == "log":
            ego = ReplayVehicle(self.road, "ego", self._ego_track, rec.length_m, rec.width_m,
                                rec.height_m, self.t_s)
            ego.track = self._ego_track
        else:
            pos, heading, speed = self._ego_track.at(self.t_s)
            if self.config["lateral_control"]:
                ego = SteeredEgo(self.road, pos, heading, speed)
            elif self.config["ego_path"] == "lane":
                ego = LaneFollowingEgo(self.road, pos, heading, speed)
            else:
                path = self.path
                ego = PathEgo(self.road, path, path.start_offset_m, speed)
            ego.vehicle_id = "ego"
            ego.height_m = rec.height_m
            set_box(ego, rec.length_m, rec.width_m)
        return ego

    def _follows_path(self) -> bool:
        """The ego is on its logged path (log replay or longitudinal-only path mode)."""
        return self.ego_mode == "log" or isinstance(self.vehicle, PathEgo)

    def _place_actors(self, t_s: float) -> None:
        """Put every replayed actor on its log at ``t_s``; only actors within their span are on
        the road. Actors handed over to IDM stay until the episode ends."""
        present = []
        for v in self.actors:
            if isinstance(v, ReactiveVehicle):
                present.append(v)
            elif v.track.present(t_s):
                v.place(t_s)
                present.append(v)
        if self.ego_mode == "log":
            self.vehicle.place(t_s)
        self.road.vehicles = [self.vehicle, *present]

    def _hand_over(self, t_s: float) -> None:
        """Reactive replay: each replayed actor whose path the simulated ego occupies too
        closely, where the logged ego did not, leaves its log for IDM/MOBIL."""
        ego, rule = self.vehicle, self._rule
        logged_pos, logged_heading, logged_speed = self._ego_track.at(t_s)
        for i, v in enumerate(self.actors):
            if not isinstance(v, ReplayVehicle) or v not in self.road.vehicles:
                continue
            reason = self._conflict(v, ego.position, ego.heading, ego.speed, rule)
            if reason is None or self._conflict(v, logged_pos, logged_heading, logged_speed,
                                                rule) is not None:
                continue
            reactive = ReactiveVehicle.from_replay(v)
            reactive.color = _REACTIVE_COLOR
            self.actors[i] = reactive
            self.road.vehicles[self.road.vehicles.index(v)] = reactive
            self.handovers.append(Handover(v.vehicle_id, float(t_s), reason))

    def _conflict(self, actor, ego_pos, ego_heading, ego_speed, rule) -> str | None:
        lane = actor.lane
        s_a, lat_a = lane.local_coordinates(actor.position)
        s_e, lat_e = lane.local_coordinates(ego_pos)
        ego = self.vehicle
        if s_e <= s_a or abs(lat_e - lat_a) > (actor.WIDTH + ego.WIDTH) / 2 + rule.lateral_margin_m:
            return None  # the ego is not ahead in its path
        gap = s_e - s_a - (actor.LENGTH + ego.LENGTH) / 2.0
        v_a = actor.speed * math.cos(utils.wrap_to_pi(actor.heading - lane.heading_at(s_a)))
        v_e = ego_speed * math.cos(utils.wrap_to_pi(ego_heading - lane.heading_at(s_e)))
        return conflict(gap, v_a - v_e, v_a, rule)

    def _simulate(self, action=None) -> None:
        frames = max(int(self.config["simulation_frequency"]
                         // self.config["policy_frequency"]), 1)
        # each policy step covers exactly 1 / policy_frequency of scenario time, so the
        # integration step is that split into whole substeps
        dt = 1.0 / (frames * self.config["policy_frequency"])
        if action is not None:
            self.action_type.act(action)
        for frame in range(frames):
            if self.config["reactive"] and self.ego_mode == "policy":
                self._hand_over(self.t_s)
            # Actors (and a logged ego) first go to the end of the substep, then the ego and
            # the reactive actors integrate to it, then collisions are checked at one common
            # time. The time comes from the step count, not a running sum, so it does not drift.
            t_next = self._ego_track.t0 + (self.steps + 1) * dt
            self._place_actors(t_next)
            self._follow_logged_lanes(t_next)
            if self.ego_mode == "policy":
                self.vehicle.act(self.action_type.get_action(self.action_type.last_action))
            for v in self.road.vehicles:
                if isinstance(v, ReactiveVehicle):
                    v.act()
            v_before = float(self.vehicle.speed)
            self.road.step(dt)
            if self.vehicle.crashed and not self.collision_with:
                self.collision_with = self._collided_with()
            self._odometer_m += 0.5 * (v_before + float(self.vehicle.speed)) * dt
            self.t_s = t_next
            self.steps += 1
            if frame < frames - 1:
                self._automatic_rendering()
        step_s = 1.0 / self.config["policy_frequency"]
        self.ego_accel_mps2 = (float(self.vehicle.speed) - self._prev_speed) / step_s
        # ENU yaw rate: highway-env's headings are mirrored
        self.ego_yaw_rate_radps = -utils.wrap_to_pi(float(self.vehicle.heading)
                                                    - self._prev_heading) / step_s
        self._prev_speed, self._prev_heading = float(self.vehicle.speed), float(self.vehicle.heading)
        self._policy_steps += 1
        self.enable_auto_render = False

    def _follow_logged_lanes(self, t_s: float) -> None:
        """A policy's ego that follows its map lane (``ego_path="lane"``) changes lanes when
        the logged ego did: at each of the scenario's ego ``lane_change`` events its target
        lane moves one lane to the event's side; the policy keeps the longitudinal control.
        (On the logged path, ``ego_path="log"``, the lane changes are in the path itself.)"""
        while self._ego_lane_events and self._ego_lane_events[0].t_s <= t_s:
            ev = self._ego_lane_events.pop(0)
            ego = self.vehicle
            if self.ego_mode != "policy" or not isinstance(ego, LaneFollowingEgo):
                continue
            start, end, index = ego.target_lane_index
            n_lanes = len(self.road.network.graph[start][end])
            # highway-env counts lanes from the left, events count +1 to the left
            new = min(max(index - (ev.to_lane - ev.from_lane), 0), n_lanes - 1)
            ego.target_lane_index = (start, end, new)

    def _collided_with(self) -> str:
        """Id of the vehicle the ego hit: the nearest one highway-env marked as crashed."""
        ego = self.vehicle
        hit = [v for v in self.road.vehicles if v is not ego and v.crashed]
        if not hit:
            return "?"
        v = min(hit, key=lambda o: float(np.linalg.norm(o.position - ego.position)))
        return str(getattr(v, "vehicle_id", "?"))

    # ----------------------------------------------------------------- outcome

    def reference_line(self):
        """The lane object along which gaps and the lead are measured: the logged path when
        the ego follows it, else the lane the ego steers along or is in."""
        if self._follows_path():
            return self.path
        ego = self.vehicle
        index = getattr(ego, "target_lane_index", None) or ego.lane_index
        return self.road.network.get_lane(index)

    def traffic(self) -> Traffic:
        """Every vehicle relative to the ego at the current step (cached per step)."""
        key = (self.steps, self._policy_steps, id(self.road))
        if self._traffic_key != key:
            others = [v for v in self.road.vehicles if v is not self.vehicle]
            self._traffic = measure(self.vehicle, others, self.reference_line(), self._network)
            self._traffic_key = key
        return self._traffic

    def odometer_m(self) -> float:
        """Distance the ego has travelled since the reset [m]: the arc length along its logged
        path when it follows it, else the integral of its speed."""
        if self._follows_path():
            s, _ = self.path.local_coordinates(self.vehicle.position)
            return float(s - self.path.start_offset_m)
        return float(self._odometer_m)

    def lead(self):
        """The nearest vehicle ahead in the ego's path and its bumper-to-bumper gap [m]
        (``(None, inf)`` without one)."""
        lead = self.traffic().lead
        if lead is None:
            return None, math.inf
        vehicle = next(v for v in self.road.vehicles if getattr(v, "vehicle_id", None) == lead.id)
        return vehicle, lead.gap_m

    def offroad(self) -> bool:
        """The ego is off the road: beyond the ends of the map's lanes, or (when it steers
        itself) outside its lane. On its logged path only the ends count: the recorded car
        drove there, so a lateral offset from the map's lanes is the map's error."""
        ego = self.vehicle
        lane = ego.lane
        s, lat = lane.local_coordinates(ego.position)
        if self._follows_path():
            return not (-lane.VEHICLE_LENGTH <= s < lane.length + lane.VEHICLE_LENGTH)
        return not lane.on_lane(ego.position, s, lat)

    def _info(self, obs, action=None) -> dict:
        # step() asks for the reward and then the info of the same state: compute once
        key = (self.steps, self._policy_steps)
        if getattr(self, "_info_key", None) != key:
            self._info_cache, self._info_key = self._compute_info(), key
        return dict(self._info_cache)

    def _compute_info(self) -> dict[str, Any]:
        traffic = self.traffic()
        ego = traffic.ego
        lead_state = {}
        lead = traffic.lead
        if lead is not None:
            # speeds projected on the path direction, so a crossing car does not count fully
            v_ego = ego.speed_along_mps
            closing = v_ego - lead.speed_along_mps
            gap = lead.gap_m
            lead_state = {
                "has_lead": True, "lead_id": lead.id, "gap_m": float(gap),
                "lead_speed_mps": float(lead.speed_along_mps),
                "closing_speed_mps": float(closing),
                "ttc_s": float(max(gap, 0.0) / closing) if closing > 1e-6 else math.inf,
                "time_headway_s": float(max(gap, 0.0) / v_ego) if v_ego > 1e-6 else math.inf}
        return StepInfo(
            t_s=float(self.t_s), ego_mode=self.ego_mode, ego_speed_mps=float(self.vehicle.speed),
            ego_accel_mps2=float(self.ego_accel_mps2), ego_lane=int(ego.lane),
            lane_offset_m=float(ego.lane_offset_m), lane_width_m=float(ego.lane_width_m),
            crashed=bool(self.vehicle.crashed), collision_with=self.collision_with,
            offroad=bool(self.offroad()), handovers=len(self.handovers), **lead_state).to_dict()

    def _reward(self, action) -> float:
        info = StepInfo.of(self._info(None))
        r = float(np.clip(self.vehicle.speed / self._v_ref, 0.0, 1.0))
        if info.crashed:
            r -= 1.0
        if info.time_headway_s < self.config["headway_penalty_s"]:
            r -= 0.5
        return r

    def _is_terminated(self) -> bool:
        if self.ego_mode == "log":
            return False
        return bool(self.vehicle.crashed or self.offroad())

    def _is_truncated(self) -> bool:
        return self._policy_steps >= self.n_steps

    # ----------------------------------------------------------------- evaluator access

    def show_logged(self, t_s: float) -> None:
        """Log mode only: put the ego and every actor on its log at ``t_s`` [s] without
        simulating the time in between, for a picture of the replay at that moment (stepping
        there costs a step per frame of video: 18 s to reach the end of a 60 s clip at 30 fps).
        """
        if self.ego_mode != "log":
            raise ValueError("show_logged needs ego_mode='log'")
        self._place_actors(float(t_s))
        self.t_s = float(t_s)

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
                if not v.track.present(t_s) and v is not self.vehicle:
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
