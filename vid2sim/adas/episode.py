"""One episode of a policy on a scenario: environment, sensor, policy, metrics, time series."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from vid2sim.adas.episode_metrics import EpisodeMetrics, episode_metrics
from vid2sim.adas.registry import PolicySpec
from vid2sim.adas.score import (
    EpisodeScore,
    EpisodeTrace,
    ScoreConfig,
    collision_at_fault,
    episode_score,
)
from vid2sim.adas.sensor import CameraSensor, SensorConfig
from vid2sim.base.errors import ImpossibleValueError, InputError
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
    collision_t_s: float | None = None
    """Scenario time of the first step with the ego crashed [s] (None: no collision)."""
    score: EpisodeScore | None = None
    """The nuPlan-shaped episode score (:mod:`vid2sim.adas.score`)."""


class TraceRecorder:
    """Collects what the score reads at each step: the ego's pose (ENU), speed, TTC, off-road
    flag, and at the first contact whether the collision is the ego's fault."""

    def __init__(self, sim, config: ScoreConfig):
        self.sim, self.config = sim, config
        self.rows: list[tuple[float, ...]] = []
        self.at_fault: bool | None = None

    def add(self, info: StepInfo) -> None:
        ego = self.sim.vehicle_states()[0]
        self.rows.append((info.t_s, ego.x_m, ego.y_m, ego.heading_rad, info.ego_speed_mps,
                          info.ttc_s, float(info.offroad)))
        if self.at_fault is None and info.crashed:
            self.at_fault = self._fault(info, ego)

    def _fault(self, info: StepInfo, ego) -> bool:
        other = next((o for o in self.sim.traffic().objects if o.id == info.collision_with),
                     None)
        if other is None:
            return True  # hit something the ego's path does not see: assume the worst
        in_lane = abs(info.lane_offset_m) <= (info.lane_width_m - ego.width_m) / 2.0
        return collision_at_fault(other.along_m, info.ego_speed_mps, in_lane, ego.length_m,
                                  other.length_m, self.config)

    def trace(self) -> EpisodeTrace:
        t, x, y, h, v, ttc, off = (np.array(c, float) for c in zip(*self.rows, strict=True))
        return EpisodeTrace(t, x, y, h, v, ttc, off > 0, bool(self.at_fault))


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
                sensor: SensorConfig | None = None, seed: int | None = 0,
                observer: Callable[[ReplayEnv, StepInfo], None] | None = None,
                score_config: ScoreConfig | None = None) -> EpisodeResult:
    """Run ``spec`` on ``scenario`` once and score it (metrics, and the nuPlan-shaped score
    against the scenario's recorded ego). ``observer(env, info)`` is called after the reset
    and after every step (the episode videos draw each step with it).

    Raises :class:`InputError` when a user policy fails (raises, or returns an action of the
    wrong shape or a non-finite one): it would fail the same way on every episode.
    """
    env = make_env(scenario, spec, reactive=reactive, sensor=sensor)
    sim = env.unwrapped
    policy = spec.make(scenario, sim.config)
    shape = env.action_space.shape
    obs, info = env.reset(seed=seed)
    infos = [StepInfo.of(info)]
    if observer is not None:
        observer(sim, infos[-1])
    recorder = TraceRecorder(sim, score_config or ScoreConfig())
    recorder.add(infos[-1])
    terminated = truncated = False
    while not (terminated or truncated):
        try:
            action = np.asarray(policy(obs, info), dtype=np.float32).reshape(-1)
        except Exception as exc:
            raise InputError(None, f"policy {spec.name!r} raised {type(exc).__name__}: {exc} "
                             f"at t={infos[-1].t_s:.1f} s") from exc
        if action.shape != shape or not np.all(np.isfinite(action)):
            raise ImpossibleValueError(
                None, f"policy {spec.name!r} returned {action.tolist()} at "
                f"t={infos[-1].t_s:.1f} s", f"expected {shape[0]} finite value(s) "
                "in [-1, 1]")
        obs, _, terminated, truncated, info = env.step(action)
        infos.append(StepInfo.of(info))
        if observer is not None:
            observer(sim, infos[-1])
        recorder.add(infos[-1])
    env.close()
    step_s = 1.0 / sim.config["policy_frequency"]
    metrics = episode_metrics(infos, step_s, scenario.ego.width_m)
    ended = ""
    if metrics.collision:
        ended = f"collision with {infos[-1].collision_with}"
    elif terminated:
        ended = "offroad"
    crash = next((float(i.t_s) for i in infos if i.crashed), None)
    score = episode_score(recorder.trace(), scenario.ego.trajectory, scenario.roads,
                          config=score_config)
    return EpisodeResult(metrics, list(sim.handovers), list(getattr(policy, "events", [])),
                         series_of(infos), terminated_by=ended, collision_t_s=crash,
                         score=score)


def series_of(infos: list[StepInfo]) -> dict[str, np.ndarray]:
    """Per-step arrays for plotting (float32; NaN where there was no lead)."""
    def col(key, lead_only):
        return np.array([float(getattr(i, key)) if (i.has_lead or not lead_only) else math.nan
                         for i in infos], dtype=np.float32)

    return {"t_s": col("t_s", False), "gap_m": col("gap_m", True), "ttc_s": col("ttc_s", True),
            "ego_speed_mps": col("ego_speed_mps", False),
            "lead_speed_mps": col("lead_speed_mps", True)}
