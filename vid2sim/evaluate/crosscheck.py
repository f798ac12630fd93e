"""vid2sim's own criticality figures against commonroad-crime's on the same scenario.

``test-policy --policy log`` reports, per policy step, the lead's bumper-to-bumper gap along
the ego's path, the time to collision ``gap / closing speed`` and the time headway
``gap / ego speed``. commonroad-crime (run by ``.ci/commonroad_crime.sh`` on the CommonRoad
export) reports, per time step, HW (the headway distance along the ego lanelet's
curvilinear frame), TTC (constant accelerations, "Collision Avoidance Theory" eq. 5.24) and
THW (the time the ego, on its logged future path, needs to reach the lead's present rear).

:func:`pair_steps` lines the two up step by step and labels each step with its *regime*:

- ``constant closing``: the relative acceleration is below crime's own threshold
  (:data:`CONSTANT_CLOSING_MPS2`), where its TTC is the constant-velocity one and the two
  definitions coincide;
- ``lead braking`` / ``ego braking`` / ``other``: the lead (or else the ego) decelerates by
  more than that; crime's TTC extrapolates the accelerations, vid2sim's does not.

Accelerations are central differences of the logged speeds on the export's time grid, as
crime computes them. Pure functions on plain records.
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from vid2sim.core.scenario import Scenario

#: Relative acceleration below which crime's TTC is gap / closing speed [m/s^2] (the
#: ``abs(delta_a) <= 0.1`` branch of commonroad-crime 0.4.5's TTC).
CONSTANT_CLOSING_MPS2 = 0.1
#: TTCs are compared up to this [s]: beyond it nothing is urgent, and at the near-zero closing
#: speeds that give such values both tools divide by noise (summary.html cuts its plots at the
#: same 10 s)
COMPARE_TTC_MAX_S = 10.0


@dataclass(frozen=True)
class StepPair:
    """One time step with both tools' figures (``inf`` undefined, ``nan`` missing)."""

    t_s: float
    regime: str
    ttc_s: float
    crime_ttc_s: float
    gap_m: float
    crime_hw_m: float
    thw_s: float
    crime_thw_s: float


def _value(v) -> float:
    if v is None:
        return math.nan
    if isinstance(v, str):
        return math.inf if v == "inf" else -math.inf
    return float(v)


def regime(ego_accel_mps2: float, lead_accel_mps2: float) -> str:
    """The step's regime (see the module docstring)."""
    if abs(lead_accel_mps2 - ego_accel_mps2) <= CONSTANT_CLOSING_MPS2:
        return "constant closing"
    if lead_accel_mps2 < -CONSTANT_CLOSING_MPS2:
        return "lead braking"
    if ego_accel_mps2 < -CONSTANT_CLOSING_MPS2:
        return "ego braking"
    return "other"


def pair_steps(crime: dict, series: dict[str, np.ndarray], scenario: Scenario,
               lead_id: str) -> list[StepPair]:
    """Both tools' figures for the lead ``lead_id`` at every step both have.

    ``crime``: the JSON of ``.ci/crime_measures.py`` (rows of actor, time_step, ttc_s, thw_s,
    hw_m; ``dt_s``); ``series``: :attr:`vid2sim.adas.episode.EpisodeResult.series` of the
    ``log`` policy (``t_s``, ``gap_m``, ``ttc_s``, ``ego_speed_mps``; NaN without a lead).
    """
    dt = float(crime["dt_s"])
    t0 = float(scenario.ego.trajectory.t[0])
    lead = next(a for a in scenario.actors if a.id == lead_id)
    rows = {int(r["time_step"]): r for r in crime["rows"] if r["actor"] == lead_id}
    steps = np.array(sorted(rows))
    times = t0 + steps * dt
    accel = {}
    for name, traj in (("ego", scenario.ego.trajectory), ("lead", lead.trajectory)):
        speed = np.interp(times, traj.t, traj.speed)
        accel[name] = np.gradient(speed, times) if len(times) > 1 else np.zeros(len(times))
    index = {round(float(t) / dt): i for i, t in enumerate(series["t_s"] - t0)}
    out = []
    for j, k in enumerate(steps):
        i = index.get(int(k))
        if i is None:
            continue
        r = rows[int(k)]
        gap, v = float(series["gap_m"][i]), float(series["ego_speed_mps"][i])
        ours_ttc = float(series["ttc_s"][i])
        thw = gap / v if math.isfinite(gap) and v > 1e-6 else math.inf
        out.append(StepPair(float(times[j]), regime(accel["ego"][j], accel["lead"][j]),
                            ours_ttc if math.isfinite(gap) else math.nan,
                            _value(r.get("ttc_s")), gap, _value(r.get("hw_m")), thw,
                            _value(r.get("thw_s"))))
    return out


def by_regime(pairs: list[StepPair], horizon_s: float = COMPARE_TTC_MAX_S
              ) -> dict[str, dict[str, float]]:
    """Per regime: steps, steps where both TTCs are finite (and vid2sim's at most
    ``horizon_s``), and the signed relative difference of crime's TTC from vid2sim's there
    (median and largest magnitude), the steps where crime's is inf and vid2sim's within the
    horizon, and the largest |HW - gap| [m] where both are finite."""
    groups: dict[str, list[StepPair]] = defaultdict(list)
    for p in pairs:
        groups[p.regime].append(p)
    out = {}
    for name, ps in sorted(groups.items()):
        near = [p for p in ps if 0 < p.ttc_s <= horizon_s]
        both = [p for p in near if math.isfinite(p.crime_ttc_s)]
        rel = np.array([(p.crime_ttc_s - p.ttc_s) / p.ttc_s for p in both])
        hw = [abs(p.crime_hw_m - p.gap_m) for p in ps
              if math.isfinite(p.crime_hw_m) and math.isfinite(p.gap_m)]
        out[name] = {
            "steps": len(ps), "both_finite": len(both),
            "crime_inf_ours_finite": sum(p.crime_ttc_s == math.inf for p in near),
            "median_rel_diff": float(np.median(rel)) if rel.size else math.nan,
            "max_abs_rel_diff": float(np.max(np.abs(rel))) if rel.size else math.nan,
            "max_hw_diff_m": float(max(hw)) if hw else math.nan,
        }
    return out


def minima(pairs: list[StepPair]) -> tuple[float, float]:
    """The smallest finite TTC of vid2sim and of crime over the paired steps [s] (inf for
    none)."""
    ours = [p.ttc_s for p in pairs if math.isfinite(p.ttc_s)]
    theirs = [p.crime_ttc_s for p in pairs if math.isfinite(p.crime_ttc_s)]
    return min(ours, default=math.inf), min(theirs, default=math.inf)
