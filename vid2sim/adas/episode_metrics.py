"""Safety and comfort figures of one episode, from the environment's per-step ``info``.

All figures are finite numbers or ``inf`` (where no lead ever came), never NaN:

- ``collision``: the ego touched another vehicle (highway-env's box intersection test);
- ``min_ttc_s``: smallest time to collision with the lead, gap over closing speed [s];
- ``min_headway_s``: smallest time headway to the lead, gap over own speed [s];
- ``min_gap_m``: smallest bumper-to-bumper gap to the lead along the ego's path [m]
  (negative: the boxes overlapped);
- ``max_decel_mps2``: largest deceleration, from the speed change over each step [m/s^2];
- ``max_jerk_mps3``: largest change of that acceleration per second [m/s^3];
- ``lane_departures``: times the ego's body crossed a marking of the map lane it was in
  (its centre farther than (lane width - ego width) / 2 from the lane centre, re-armed
  :data:`DEPARTURE_HYSTERESIS_M` inside); a lane change counts as one;
- ``duration_s``: simulated time (shorter than the scenario when the episode ended early).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from vid2sim.export.highway.info import StepInfo

COLUMNS = ("collision", "min_ttc_s", "min_headway_s", "min_gap_m", "max_decel_mps2",
           "max_jerk_mps3", "lane_departures", "duration_s")
DEPARTURE_HYSTERESIS_M = 0.1
"""How far back inside its lane the ego must come before another departure counts [m]."""


@dataclass(frozen=True)
class EpisodeMetrics:
    collision: bool
    min_ttc_s: float
    min_headway_s: float
    min_gap_m: float
    max_decel_mps2: float
    max_jerk_mps3: float
    lane_departures: int
    duration_s: float

    def as_dict(self) -> dict:
        return asdict(self)


def lane_departures(offsets_m: np.ndarray, lane_widths_m: np.ndarray, ego_width_m: float) -> int:
    """Rising edges of ``|offset| > (lane width - ego width) / 2`` with hysteresis."""
    limit = (np.asarray(lane_widths_m, float) - ego_width_m) / 2.0
    out, count = False, 0
    for off, lim in zip(np.abs(np.asarray(offsets_m, float)), limit, strict=True):
        if not out and off > lim:
            out, count = True, count + 1
        elif out and off < lim - DEPARTURE_HYSTERESIS_M:
            out = False
    return count


def episode_metrics(infos: list[StepInfo | dict], step_s: float, ego_width_m: float
                    ) -> EpisodeMetrics:
    """The figures of an episode from its ``info`` list (reset first, then every step).

    Parameters
    ----------
    infos : list of StepInfo or dict
        ``info`` of ``vid2sim/Replay-v0`` at the reset and after each step.
    step_s : float
        Policy period [s].
    ego_width_m : float
        For lane departures.
    """
    infos = [StepInfo.of(i) for i in infos]
    speed = np.array([i.ego_speed_mps for i in infos], float)
    accel = np.diff(speed) / step_s if len(speed) > 1 else np.zeros(0)
    jerk = np.diff(accel) / step_s if len(accel) > 1 else np.zeros(0)
    lead = [i for i in infos if i.has_lead]
    return EpisodeMetrics(
        collision=any(i.crashed for i in infos),
        min_ttc_s=min((float(i.ttc_s) for i in lead), default=math.inf),
        min_headway_s=min((float(i.time_headway_s) for i in lead), default=math.inf),
        min_gap_m=min((float(i.gap_m) for i in lead), default=math.inf),
        max_decel_mps2=float(max(0.0, -accel.min())) if accel.size else 0.0,
        max_jerk_mps3=float(np.abs(jerk).max()) if jerk.size else 0.0,
        lane_departures=lane_departures([i.lane_offset_m for i in infos],
                                        [i.lane_width_m for i in infos], ego_width_m),
        duration_s=float(infos[-1].t_s - infos[0].t_s))
