"""One score per episode in [0, 1], shaped like nuPlan's closed-loop scenario score.

nuPlan (``nuplan-devkit``: ``docs/metrics_description.md`` and the metric aggregator
``closed_loop_nonreactive_agents_weighted_average.yaml``) scores a scenario as the product of
multipliers times a weighted average::

    score = NC * DAC * DDC * MP * (5 TTC + 5 EP + 4 SL + 2 C) / (5 + 5 + 4 + 2)

with, as computed here from the episode's steps:

- **NC, no at-fault collision** (multiplier, 0 or 1): an at-fault collision zeroes the score
  (nuPlan allows none with a vehicle). At fault: the ego, moving, hits a vehicle ahead of it
  (nuPlan's active-front and stopped-track collisions), or one beside it while the ego is not
  inside its lane (a lane change: active-lateral). Not at fault: being hit from behind, or
  while standing (:func:`collision_at_fault`);
- **DAC, drivable area** (multiplier, 0 or 1): 0 when the environment reports the ego off
  the road at any step (``StepInfo.offroad``: beyond the road's ends, or outside the lanes
  when the ego steers itself);
- **DDC, driving direction** (multiplier, 1, 0.5 or 0): the ego's progress against the
  direction of the driving lane it is in, over any ``direction_horizon_s`` window: at most
  ``direction_compliance_m`` gives 1, more than ``direction_violation_m`` 0, between 0.5;
- **MP, making progress** (multiplier, 0 or 1): 1 when EP's ratio exceeds
  ``min_progress_ratio``;
- **TTC within bound** (weight 5, 0 or 1): 1 when the smallest time to collision with the
  lead (gap over closing speed, the environment's ``ttc_s``) stays at or above
  ``least_min_ttc_s``;
- **EP, ego progress** (weight 5, [0, 1]): the ego's progress along the recorded ego's path
  over the recorded ego's progress in the scenario, ``min(1, max(p, e) / max(P, e))`` with
  ``e = progress_floor_m``; 0 when the ego went backwards by more than ``e``;
- **SL, speed-limit compliance** (weight 4, [0, 1]): ``1 - sum(overspeed dt) / (max_overspeed
  * duration)``, floored at 0; only where the map gives a limit (scenario.json carries none
  yet: the term then drops out and the weights of the others are renormalised);
- **C, comfort** (weight 2, 0 or 1): 1 when the longitudinal acceleration, longitudinal jerk,
  lateral acceleration, yaw rate and yaw acceleration all stay within nuPlan's bounds
  (derivatives by a Savitzky-Golay filter of ``comfort_window_s`` and order 2, as nuPlan's).

Departures from nuPlan, for what vid2sim's environment can measure: nuPlan's TTC projects
both boxes along their headings up to 3 s; here it is the lead's gap over closing speed along
the ego's path (the same number for vehicles ahead in the ego's path, nothing for crossing
traffic). nuPlan's at-fault collision with a VRU gives 0 and with an object 0.5; vid2sim's
actors are vehicles. The jerk-vector magnitude bound is not checked (the longitudinal one is).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from vid2sim.core.lanelayout import BACKWARD, DRIVING
from vid2sim.core.polyline import signed_offsets
from vid2sim.core.scenario import Road, Trajectory

#: Columns of the score in results.csv, in order (``score`` first).
SCORE_COLUMNS = ("score", "score_no_at_fault", "score_drivable", "score_direction",
                 "score_making_progress", "score_ttc", "score_progress", "score_speed_limit",
                 "score_comfort")


@dataclass(frozen=True)
class ScoreWeights:
    """Weights of the weighted average (nuPlan's metric aggregator
    ``closed_loop_nonreactive_agents_weighted_average.yaml``)."""

    ttc: float = 5.0
    progress: float = 5.0
    speed_limit: float = 4.0
    comfort: float = 2.0


@dataclass(frozen=True)
class ComfortBounds:
    """nuPlan's comfort bounds (``ego_is_comfortable``: from expert driving logs)."""

    min_lon_accel_mps2: float = -4.05
    max_lon_accel_mps2: float = 2.40
    max_abs_lon_jerk_mps3: float = 4.13
    max_abs_lat_accel_mps2: float = 4.89
    max_abs_yaw_rate_radps: float = 0.95
    max_abs_yaw_accel_radps2: float = 1.93


@dataclass(frozen=True)
class ScoreConfig:
    """Thresholds of :func:`episode_score` (nuPlan's defaults, ``metrics_description.md``)."""

    weights: ScoreWeights = field(default_factory=ScoreWeights)
    comfort: ComfortBounds = field(default_factory=ComfortBounds)
    #: smallest acceptable minimum TTC [s] (nuPlan ``least_min_ttc``)
    least_min_ttc_s: float = 0.95
    #: the ego's progress over the expert's below which it "makes no progress" (nuPlan
    #: ``min_progress_threshold``)
    min_progress_ratio: float = 0.2
    #: progress below this is noise [m] (nuPlan ``score_progress_threshold``)
    progress_floor_m: float = 0.1
    #: driving against the lane's direction by at most this is compliant [m], beyond
    #: ``direction_violation_m`` a violation, within ``direction_horizon_s`` [s] (nuPlan
    #: ``driving_direction_compliance_threshold``, ``..._violation_threshold``, ``time_horizon``)
    direction_compliance_m: float = 2.0
    direction_violation_m: float = 6.0
    direction_horizon_s: float = 1.0
    #: overspeed at which a whole episode's speed-limit term reaches 0 [m/s] (nuPlan
    #: ``max_overspeed_value_threshold``, 5 mph)
    max_overspeed_mps: float = 2.23
    #: below this speed the ego stands, and a collision is not its fault [m/s] (nuPlan's
    #: ``stopped_speed_threshold``)
    stopped_speed_mps: float = 0.05
    #: Savitzky-Golay window of the comfort derivatives [s] (nuPlan: 5 samples at 10 Hz)
    comfort_window_s: float = 0.5


@dataclass(frozen=True)
class EpisodeScore:
    """The score and its terms (multipliers 0/0.5/1, weighted terms in [0, 1]; the speed-limit
    term NaN where the map has no limit)."""

    score: float
    no_at_fault: float
    drivable: float
    direction: float
    making_progress: float
    ttc: float
    progress: float
    speed_limit: float
    comfort: float

    def as_row(self) -> dict[str, float]:
        d = asdict(self)
        return {"score": d.pop("score"), **{f"score_{k}": v for k, v in d.items()}}


@dataclass(frozen=True)
class EpisodeTrace:
    """What the score reads from an episode, one value per policy step (the reset first)."""

    t_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray
    speed_mps: np.ndarray
    ttc_s: np.ndarray
    offroad: np.ndarray
    at_fault_collision: bool


def collision_at_fault(along_m: float, ego_speed_mps: float, ego_in_lane: bool,
                       ego_length_m: float, other_length_m: float,
                       config: ScoreConfig | None = None) -> bool:
    """Whether a collision is the ego's fault (nuPlan's classes), from the other vehicle's
    centre ``along_m`` ahead of the ego's along its path at the first contact: ahead by more
    than half the centre distance of boxes touching end to end, a front collision (at fault);
    behind by as much, a rear one (not); between, beside it (at fault only while the ego is
    not inside its lane, changing lanes). A standing ego is never at fault."""
    cfg = config or ScoreConfig()
    if ego_speed_mps < cfg.stopped_speed_mps:
        return False
    half = (ego_length_m + other_length_m) / 4.0
    if along_m > half:
        return True
    if along_m < -half:
        return False
    return not ego_in_lane


def progress_ratio(trace: EpisodeTrace, recorded: Trajectory, floor_m: float) -> float:
    """EP: the ego's progress along the recorded path over the recorded ego's."""
    path = np.column_stack((recorded.x, recorded.y))
    expert = float(np.sum(np.hypot(*np.diff(path, axis=0).T))) if len(path) > 1 else 0.0
    if expert < floor_m:
        return 1.0  # the recorded ego stood: any episode keeps up
    s, _ = signed_offsets(path, np.column_stack((trace.x_m, trace.y_m)))
    ego = float(s[-1] - s[0])
    if ego < -floor_m:
        return 0.0
    return float(min(1.0, max(ego, floor_m) / max(expert, floor_m)))


def against_flow_m(trace: EpisodeTrace, roads: list[Road], horizon_s: float) -> float:
    """Largest distance the ego moved against its driving lane's direction within any
    ``horizon_s`` window [m] (0 on roads without backward lanes or without roads)."""
    if not roads or len(trace.t_s) < 2:
        return 0.0
    xy = np.column_stack((trace.x_m, trace.y_m))
    best_d = np.full(len(xy), np.inf)
    sign = np.zeros(len(xy))
    s_best = np.zeros(len(xy))
    for road in roads:
        s, d = signed_offsets(road.centerline, xy)
        section = road.layout()
        k = section.lane_at(d)
        closer = np.abs(d) < best_d
        lane_sign = np.array([0.0 if kk < 0 or section.lanes[kk].type != DRIVING else (
            -1.0 if section.lanes[kk].direction == BACKWARD else 1.0) for kk in k])
        best_d = np.where(closer, np.abs(d), best_d)
        sign = np.where(closer, lane_sign, sign)
        s_best = np.where(closer, s, s_best)
    with_flow = np.r_[0.0, np.diff(s_best) * sign[1:]]
    dt = float(np.median(np.diff(trace.t_s)))
    n = max(1, round(horizon_s / dt))
    windows = np.convolve(with_flow, np.ones(n), mode="valid") if len(with_flow) >= n \
        else np.array([with_flow.sum()])
    return float(max(0.0, -windows.min()))


def comfortable(trace: EpisodeTrace, bounds: ComfortBounds, window_s: float) -> bool:
    """C: longitudinal acceleration and jerk, lateral acceleration, yaw rate and yaw
    acceleration within the bounds (Savitzky-Golay derivatives, nuPlan's filter)."""
    t = trace.t_s
    if len(t) < 3:
        return True
    dt = float(np.median(np.diff(t)))
    win = min(len(t), max(3, round(window_s / dt)))
    if win % 2 == 0:
        win -= 1 if win > 3 else -1
    win = min(win, len(t) if len(t) % 2 else len(t) - 1)
    if win < 3:
        return True

    # scipy.signal takes 1-3 s to import; the settings tree imports this module in every
    # command, the video commands included, so it is loaded where it is used.
    from scipy.signal import savgol_filter

    def deriv(y, order=1):
        return savgol_filter(np.asarray(y, float), win, 2, deriv=order, delta=dt)

    accel = deriv(trace.speed_mps)
    jerk = deriv(trace.speed_mps, 2)
    yaw_rate = deriv(np.unwrap(trace.heading_rad))
    yaw_accel = deriv(np.unwrap(trace.heading_rad), 2)
    lat = trace.speed_mps * yaw_rate
    b = bounds
    return bool(accel.min() >= b.min_lon_accel_mps2 and accel.max() <= b.max_lon_accel_mps2
                and np.abs(jerk).max() <= b.max_abs_lon_jerk_mps3
                and np.abs(lat).max() <= b.max_abs_lat_accel_mps2
                and np.abs(yaw_rate).max() <= b.max_abs_yaw_rate_radps
                and np.abs(yaw_accel).max() <= b.max_abs_yaw_accel_radps2)


def speed_limit_term(trace: EpisodeTrace, limit_mps: float | None,
                     max_overspeed_mps: float) -> float:
    """SL: 1 minus the time-integrated overspeed over ``max_overspeed * duration`` (NaN
    without a limit)."""
    if limit_mps is None or not math.isfinite(limit_mps) or len(trace.t_s) < 2:
        return math.nan
    dt = float(np.median(np.diff(trace.t_s)))
    duration = float(trace.t_s[-1] - trace.t_s[0])
    over = np.maximum(trace.speed_mps - limit_mps, 0.0)
    return float(max(0.0, 1.0 - over.sum() * dt / (max(max_overspeed_mps, 1e-3) * duration)))


def episode_score(trace: EpisodeTrace, recorded: Trajectory, roads: list[Road],
                  speed_limit_mps: float | None = None,
                  config: ScoreConfig | None = None) -> EpisodeScore:
    """The nuPlan-shaped score of one episode (see the module docstring)."""
    cfg = config or ScoreConfig()
    no_fault = 0.0 if trace.at_fault_collision else 1.0
    drivable = 0.0 if bool(np.any(trace.offroad)) else 1.0
    against = against_flow_m(trace, roads, cfg.direction_horizon_s)
    direction = 1.0 if against <= cfg.direction_compliance_m else (
        0.0 if against > cfg.direction_violation_m else 0.5)
    progress = progress_ratio(trace, recorded, cfg.progress_floor_m)
    making = 1.0 if progress > cfg.min_progress_ratio else 0.0
    ttc = 1.0 if float(np.min(trace.ttc_s, initial=math.inf)) >= cfg.least_min_ttc_s else 0.0
    limit = speed_limit_term(trace, speed_limit_mps, cfg.max_overspeed_mps)
    comfort = 1.0 if comfortable(trace, cfg.comfort, cfg.comfort_window_s) else 0.0
    w = cfg.weights
    terms = [(w.ttc, ttc), (w.progress, progress), (w.comfort, comfort)]
    if math.isfinite(limit):
        terms.append((w.speed_limit, limit))
    average = sum(a * b for a, b in terms) / sum(a for a, _ in terms)
    score = no_fault * drivable * direction * making * average
    return EpisodeScore(float(score), no_fault, drivable, direction, making, ttc, progress,
                        limit, comfort)
