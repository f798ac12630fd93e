"""Vehicles of the replay: logged actors (replayed, or handed over to IDM/MOBIL) and the egos.

- :class:`ReplayVehicle` is placed on its logged trajectory at every step (no dynamics).
- :class:`ReactiveVehicle` is highway-env's ``IDMVehicle`` (IDM car following, MOBIL lane
  changes) started from a replayed actor's logged state when the ego's deviation makes its log
  implausible (reactive replay, as nuPlan's and Waymax's "reactive agents"); :func:`conflict`
  is the rule.
- :class:`PathEgo` drives along the ego's logged path with the policy's acceleration
  (longitudinal-only control, the default); :class:`LaneFollowingEgo` instead steers itself
  along its lane with highway-env's lane-following controller; :class:`SteeredEgo` takes
  acceleration and steering from the policy (lateral control).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from highway_env.road.road import Road as HwRoad
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.controller import ControlledVehicle
from highway_env.vehicle.kinematics import Vehicle

from vid2sim.core.scenario import Trajectory
from vid2sim.export.highway.network import ScenarioLane, enu_to_hw, nearby_lane_index


class LogTrack:
    """A scenario trajectory converted to highway-env coordinates, interpolated in time."""

    def __init__(self, traj: Trajectory):
        self.t = traj.t
        self.x, self.y, self.heading = enu_to_hw(traj.x, traj.y, np.unwrap(traj.heading))
        self.speed = traj.speed
        self.t0, self.t1 = float(self.t[0]), float(self.t[-1])

    def at(self, t_s: float) -> tuple[np.ndarray, float, float]:
        """Position [m] (highway-env frame), heading [rad] and speed [m/s] at ``t_s`` [s]
        (held at the log's first/last sample outside its span)."""
        t = min(max(t_s, self.t0), self.t1)
        pos = np.array([np.interp(t, self.t, self.x), np.interp(t, self.t, self.y)])
        return (pos, float(np.interp(t, self.t, self.heading)),
                float(np.interp(t, self.t, self.speed)))

    def present(self, t_s: float) -> bool:
        return self.t0 - 1e-9 <= t_s <= self.t1 + 1e-9


def set_box(v: Vehicle, length_m: float, width_m: float) -> None:
    """Give a highway-env vehicle its own footprint [m]."""
    # highway-env reads the box from (class) attributes LENGTH/WIDTH; instance ones override.
    v.LENGTH, v.WIDTH = float(length_m), float(width_m)
    v.diagonal = math.hypot(v.LENGTH, v.WIDTH)


class _NearbyLane:
    """Lane bookkeeping by :func:`nearby_lane_index` instead of a search of every lane."""

    def on_state_update(self) -> None:
        if self.road:
            self.lane_index, self.lane = nearby_lane_index(
                self.road.network, getattr(self, "lane_index", None), self.position,
                self.heading)
            if self.road.record_history:
                self.history.appendleft(self.create_from(self))


class ReplayVehicle(Vehicle):
    """A vehicle placed on its logged trajectory at every step (no dynamics, no IDM).

    Its lane is looked up only when something asks for it (``lane_index``/``lane``): a log
    does not need one to move, and most substeps nobody asks.
    """

    @property
    def lane_index(self):
        if self._lane_stale:
            self._lane_index, self._lane = nearby_lane_index(
                self.road.network, self._lane_index, self.position, self.heading)
            self._lane_stale = False
        return self._lane_index

    @lane_index.setter
    def lane_index(self, value) -> None:
        self._lane_index, self._lane_stale = value, False

    @property
    def lane(self):
        self.lane_index  # noqa: B018 - refreshes a stale lane
        return self._lane

    @lane.setter
    def lane(self, value) -> None:
        self._lane = value

    def __init__(self, road: HwRoad, vehicle_id: str, track: LogTrack, length_m: float,
                 width_m: float, height_m: float, t_s: float):
        pos, heading, speed = track.at(t_s)
        super().__init__(road, pos, heading, speed)
        self.vehicle_id = vehicle_id
        self.track = track
        self.height_m = float(height_m)
        set_box(self, length_m, width_m)

    def place(self, t_s: float) -> None:
        """Move to the logged state at scenario time ``t_s`` [s]."""
        self.position, self.heading, self.speed = self.track.at(t_s)
        self.on_state_update()

    def act(self, action=None) -> None:
        pass  # a log does not take actions

    def on_state_update(self) -> None:
        self._lane_stale = True
        if self.road is not None and self.road.record_history:
            self.history.appendleft(self.create_from(self))

    def step(self, dt: float) -> None:
        # The env places replayed vehicles before the road steps; collision impulses must not
        # push a log around.
        self.impact = None


class ReactiveVehicle(_NearbyLane, IDMVehicle):
    """A recorded actor handed over to highway-env's IDM (longitudinal) and MOBIL (lane
    changes), started from its logged state; it keeps its id, box and log for reference."""

    MIN_SPEED = 0.0  # IDM brakes to a stop; it does not reverse

    @classmethod
    def from_replay(cls, v: ReplayVehicle) -> ReactiveVehicle:
        """The IDM vehicle at ``v``'s current (logged) state, aiming at its logged speed."""
        new = cls(v.road, v.position.copy(), heading=float(v.heading), speed=float(v.speed),
                  target_lane_index=v.lane_index, target_speed=max(float(v.speed), 0.1),
                  enable_lane_change=True)
        new.vehicle_id, new.track, new.height_m = v.vehicle_id, v.track, v.height_m
        set_box(new, v.LENGTH, v.WIDTH)
        new.crashed = v.crashed
        return new

    def step(self, dt: float) -> None:
        super().step(dt)
        self.speed = max(self.speed, 0.0)


@dataclass(frozen=True)
class HandoverRule:
    """When a replayed actor leaves its log (reactive replay).

    A follower whose path the ego occupies (the two bodies overlap laterally, with
    ``lateral_margin_m`` to spare) takes over from its log when the simulated ego is closer
    than a careful driver would accept, and the logged ego was not (the log is plausible as
    long as the ego does what it did when it was recorded).
    """

    ttc_s: float = 3.0
    """Time to collision below which a driver reacts [s]: the upper end of the critical TTCs
    used in traffic-conflict studies (1.5-3 s; Hayward 1972, van der Horst 1990)."""
    gap_m: float = 2.0
    """Bumper-to-bumper gap below which a driver reacts whatever the speeds [m]: the IDM's
    standstill distance s0 (Treiber, Hennecke and Helbing 2000)."""
    headway_s: float = 0.5
    """Time headway (gap / own speed) below which a driver reacts [s]: half the 1 s below
    which following is considered dangerous tailgating in most European traffic codes."""
    lateral_margin_m: float = 0.2
    """Added to the half widths when testing whether the ego occupies the actor's path [m]."""


def conflict(gap_m: float, closing_mps: float, follower_speed_mps: float,
             rule: HandoverRule) -> str | None:
    """Why a follower could not keep driving as logged behind a vehicle ahead: ``"gap"``,
    ``"headway"``, ``"ttc"`` or None.

    Parameters
    ----------
    gap_m : float
        Bumper-to-bumper gap from the follower to the vehicle ahead [m].
    closing_mps : float
        Follower speed minus the speed of the vehicle ahead, along the lane [m/s].
    follower_speed_mps : float
        The follower's speed [m/s].
    """
    if gap_m < rule.gap_m:
        return "gap"
    if follower_speed_mps > 0.1 and gap_m / follower_speed_mps < rule.headway_s:
        return "headway"
    if closing_mps > 1e-6 and gap_m / closing_mps < rule.ttc_s:
        return "ttc"
    return None


class LaneFollowingEgo(_NearbyLane, ControlledVehicle):
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


class PathEgo(_NearbyLane, Vehicle):
    """The policy-driven ego on its logged path: the action sets the acceleration, the path
    (the log's positions, prolonged straight at both ends) sets where it goes.

    This is the lateral behaviour of the recorded driver, so the vehicles in the ego's path are
    the ones the driver had in front of the car, whatever the map's lane geometry; a policy
    that brakes or speeds up moves along the same path earlier or later.
    """

    MIN_SPEED = 0.0

    def __init__(self, road: HwRoad, path: ScenarioLane, s_m: float, speed_mps: float):
        position, heading = path.pose_at(s_m)
        super().__init__(road, position, heading, speed_mps)
        self.path = path
        self.s_m = float(s_m)

    def act(self, action: dict | str | None = None) -> None:
        accel = float(action["acceleration"]) if isinstance(action, dict) else 0.0
        Vehicle.act(self, {"acceleration": accel, "steering": 0.0})

    def step(self, dt: float) -> None:
        self.clip_actions()  # a crashed ego brakes to a stop (highway-env's behaviour)
        a = float(self.action["acceleration"])
        v0 = float(self.speed)
        v1 = v0 + a * dt
        if v1 < 0.0:  # stops within the step: travel to the stopping point only
            ds = v0 * v0 / (2.0 * -a) if a < 0 else 0.0
            v1 = 0.0
        else:
            ds = 0.5 * (v0 + v1) * dt  # exact for a constant acceleration
        self.s_m += ds
        self.speed = v1
        self.position, self.heading = self.path.pose_at(self.s_m)
        self.impact = None  # a collision is recorded (crashed), the path is kept
        self.on_state_update()


class SteeredEgo(_NearbyLane, Vehicle):
    """The policy-driven ego with lateral control: acceleration and front-wheel steering angle
    from the action, integrated by highway-env's kinematic bicycle model."""

    MIN_SPEED = 0.0

    def step(self, dt: float) -> None:
        super().step(dt)
        self.speed = max(self.speed, 0.0)
