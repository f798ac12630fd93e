"""One episode of a policy on a scenario: environment, sensor, policy, metrics, time series."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from vid2sim.adas.episode_metrics import EpisodeMetrics, episode_metrics
from vid2sim.adas.registry import PolicySpec
from vid2sim.adas.sensor import CameraSensor, SensorConfig
from vid2sim.base.errors import InputError
from vid2sim.core.scenario import Scenario
from vid2sim.export.highway import Handover, ReplayEnv
from vid2sim.export.highway.info import StepInfo

SERIES = ("t_s", "gap_m", "ttc_s", "ego_speed_mps", "lead_speed_mps")
"""The per-step values kept for the report's plots (gap, TTC and lead speed NaN without a
lead: they are for drawing only, never written to results.csv)."""


@dataclass
class EpisodeResult:
    """What one episode produced (or why it was not run)."""

    metrics: EpisodeMetrics | None
    handovers: list[Handover] = field(default_factory=list)
    events: list[tuple[float, str]] = field(default_factory=list)
    series: dict[str, np.ndarray] = field(default_factory=dict)
    skip_reason: str = ""
    terminated_by: str = ""
    """``collision with <id>``, ``offroad`` or "" (no collision, ran to the scenario's end)."""


def make_env(scenario: Scenario, spec: PolicySpec, *, reactive: bool = False,
             sensor: SensorConfig | None = None):
    """The environment a policy runs in: ``vid2sim/Replay-v0`` with the policy's control mode,
    wrapped in the camera sensor unless the policy reads the environment's own observation."""
    env = ReplayEnv(scenario, ego_mode=spec.ego_mode,
                    config={"lateral_control": spec.lateral, "reactive": bool(reactive)})
    if spec.observation == "camera":
        return CameraSensor(env, sensor or SensorConfig())
    return env


def run_episode(scenario: Scenario, spec: PolicySpec, *, reactive: bool = False,
                sensor: SensorConfig | None = None, seed: int | None = 0) -> EpisodeResult:
    """Run ``spec`` on ``scenario`` once and score it.

    Raises :class:`InputError` when a user policy fails (raises, or returns an action of the
    wrong shape or a non-finite one): it would fail the same way on every episode.
    """
    env = make_env(scenario, spec, reactive=reactive, sensor=sensor)
    sim = env.unwrapped
    policy = spec.make(scenario, sim.config)
    shape = env.action_space.shape
    obs, info = env.reset(seed=seed)
    infos = [StepInfo.of(info)]
    terminated = truncated = False
    while not (terminated or truncated):
        try:
            action = np.asarray(policy(obs, info), dtype=np.float32).reshape(-1)
        except Exception as exc:
            raise InputError(None, f"policy {spec.name!r} raised {type(exc).__name__}: {exc} "
                             f"at t={infos[-1].t_s:.1f} s") from exc
        if action.shape != shape or not np.all(np.isfinite(action)):
            raise InputError(None, f"policy {spec.name!r} returned {action.tolist()} at "
                             f"t={infos[-1].t_s:.1f} s", f"expected {shape[0]} finite value(s) "
                             "in [-1, 1]")
        obs, _, terminated, truncated, info = env.step(action)
        infos.append(StepInfo.of(info))
    env.close()
    step_s = 1.0 / sim.config["policy_frequency"]
    metrics = episode_metrics(infos, step_s, scenario.ego.width_m)
    ended = ""
    if metrics.collision:
        ended = f"collision with {infos[-1].collision_with}"
    elif terminated:
        ended = "offroad"
    return EpisodeResult(metrics, list(sim.handovers), list(getattr(policy, "events", [])),
                         series_of(infos), terminated_by=ended)


def series_of(infos: list[StepInfo]) -> dict[str, np.ndarray]:
    """Per-step arrays for plotting (float32; NaN where there was no lead)."""
    def col(key, lead_only):
        return np.array([float(getattr(i, key)) if (i.has_lead or not lead_only) else math.nan
                         for i in infos], dtype=np.float32)

    return {"t_s": col("t_s", False), "gap_m": col("gap_m", True), "ttc_s": col("ttc_s", True),
            "ego_speed_mps": col("ego_speed_mps", False),
            "lead_speed_mps": col("lead_speed_mps", True)}
