"""Minimal reference policies on the simulator's exact values: follow the log, ACC (IDM), AEB.

A policy is a callable ``policy(obs, info) -> action``; these read the environment's ``info``
as a typed record (:class:`vid2sim.export.highway.info.StepInfo`: ``t_s``,
``ego_speed_mps``, ``has_lead``, ``gap_m``, ``closing_speed_mps``, ``ttc_s``, ...) and return the action array: one value in [-1, 1] mapped
linearly to the acceleration range ``acceleration_range_mps2`` of the environment's config.
They are short examples for the raw environment; the driving functions that
``vid2sim test-policy`` runs (ISO-limited ACC, staged AEB, LKA, through a camera model) are in
:mod:`vid2sim.adas.functions`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from vid2sim.adas.functions import DEFAULT_ACCEL_RANGE_MPS2, accel_to_action, idm_acceleration
from vid2sim.core.scenario import Trajectory
from vid2sim.export.highway.info import StepInfo

Policy = Callable[[np.ndarray, dict], np.ndarray]
__all__ = ["DEFAULT_ACCEL_RANGE_MPS2", "AccPolicy", "AebPolicy", "FollowLogPolicy", "Policy",
           "accel_to_action", "run_episode"]


@dataclass
class FollowLogPolicy:
    """Track the logged ego speed profile: feed-forward logged acceleration plus proportional
    feedback on speed and on the along-track position error.

    The position is recovered from the observation's ego row (absolute highway-env x, y, whose
    y points south: ``y_enu = -y_hw``).
    """

    log: Trajectory
    kp_speed_per_s: float = 1.0
    kp_position_per_s2: float = 0.5
    accel_range_mps2: tuple[float, float] = DEFAULT_ACCEL_RANGE_MPS2

    def __post_init__(self) -> None:
        self._accel = np.gradient(self.log.speed, self.log.t) if len(self.log) > 1 else np.zeros(1)

    def __call__(self, obs: np.ndarray, info: StepInfo | dict) -> np.ndarray:
        state = StepInfo.of(info)
        t = state.t_s
        ref = self.log.state_at(t)
        x_enu, y_enu = float(obs[0][1]), -float(obs[0][2])
        heading = float(ref["heading"])
        along_err_m = ((float(ref["x"]) - x_enu) * math.cos(heading)
                       + (float(ref["y"]) - y_enu) * math.sin(heading))
        a = (float(np.interp(t, self.log.t, self._accel))
             + self.kp_speed_per_s * (float(ref["speed"]) - state.ego_speed_mps)
             + self.kp_position_per_s2 * along_err_m)
        return accel_to_action(a, self.accel_range_mps2)


@dataclass
class AccPolicy:
    """Adaptive cruise control with the Intelligent Driver Model (Treiber et al., 2000):

    ``a = a_max [1 - (v / v0)^4 - (s* / s)^2]``,
    ``s* = s0 + v T + v dv / (2 sqrt(a_max b))`` with ``dv`` the closing speed and ``s`` the gap.
    """

    desired_speed_mps: float = 15.0
    time_headway_s: float = 1.5
    min_gap_m: float = 2.0
    max_accel_mps2: float = 1.5
    comfort_decel_mps2: float = 2.0
    max_decel_mps2: float = 8.0
    accel_range_mps2: tuple[float, float] = DEFAULT_ACCEL_RANGE_MPS2

    def acceleration(self, info: StepInfo | dict) -> float:
        """IDM acceleration [m/s^2] for the state in ``info``."""
        state = StepInfo.of(info)
        a = idm_acceleration(
            state.ego_speed_mps, self.desired_speed_mps,
            state.gap_m if state.has_lead else None,
            state.closing_speed_mps, time_gap_s=self.time_headway_s,
            min_gap_m=self.min_gap_m, max_accel_mps2=self.max_accel_mps2,
            comfort_decel_mps2=self.comfort_decel_mps2)
        return max(a, -self.max_decel_mps2)

    def __call__(self, obs: np.ndarray, info: dict) -> np.ndarray:
        return accel_to_action(self.acceleration(info), self.accel_range_mps2)


@dataclass
class AebPolicy:
    """Autonomous emergency braking on top of another policy.

    Brakes with ``brake_decel_mps2`` once the time to collision drops below ``trigger_ttc_s``
    and keeps braking (latched) until the ego stops or the TTC exceeds ``release_ttc_s``;
    otherwise passes the base policy's action through (or coasts without one).
    """

    base: Policy | None = None
    trigger_ttc_s: float = 1.5
    release_ttc_s: float = 3.0
    brake_decel_mps2: float = 8.0
    accel_range_mps2: tuple[float, float] = DEFAULT_ACCEL_RANGE_MPS2
    braking: bool = False

    def __call__(self, obs: np.ndarray, info: dict) -> np.ndarray:
        state = StepInfo.of(info)
        ttc = state.ttc_s
        if ttc < self.trigger_ttc_s:
            self.braking = True
        elif self.braking and (ttc > self.release_ttc_s or state.ego_speed_mps < 0.1):
            self.braking = False
        if self.braking:
            return accel_to_action(-self.brake_decel_mps2, self.accel_range_mps2)
        if self.base is not None:
            return self.base(obs, info)
        return accel_to_action(0.0, self.accel_range_mps2)


def run_episode(env, policy: Policy, *, seed: int | None = None,
                options: dict | None = None) -> list[dict]:
    """Roll out one episode; returns the ``info`` of the reset and of every step, each with the
    step's ``reward``, ``terminated`` and ``truncated`` added."""
    obs, info = env.reset(seed=seed, options=options)
    infos = [dict(info, reward=0.0, terminated=False, truncated=False)]
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs, info))
        infos.append(dict(info, reward=float(reward), terminated=terminated, truncated=truncated))
        if terminated or truncated:
            return infos
