"""commonroad-crime's TTC / HW against test-policy's ``log`` figures, by regime and scenario.

    python benchmarks/bench_crime.py [--scenario NAME=path/scenario.json ...]
        [--venv /tmp/vid2sim-crimevenv]

Scenarios: the hand-made braking leads (``late-reaction``: straight road, a phase of constant
closing; ``braking-lead``: the 60 m curve) and any ``--scenario`` given (the demo build, the
KITTI raw 0001 build). For each: the CommonRoad export with the ego as obstacle, crime's
measures in its own venv (``.ci/commonroad_crime.sh``), the ``log`` replay in vid2sim's
environment, and per regime (:mod:`vid2sim.evaluate.crosscheck`) the steps where the ego has
a lead, those where both TTCs are finite, crime's TTC minus vid2sim's relative to vid2sim's
(median = signed bias, largest magnitude), the steps where crime says inf and vid2sim a
finite TTC, and the largest |HW - gap|. Steps are those where vid2sim's lead is an actor
crime evaluated (every actor is); the figures are one table per scenario. CPU seconds of
crime's run are printed (it is a separate process).
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from vid2sim.adas.policies import run_episode as raw_run_episode
from vid2sim.core import scenario as scenario_io
from vid2sim.evaluate.crosscheck import by_regime, minima, pair_steps
from vid2sim.export.commonroad import write_commonroad
from vid2sim.export.highway import ReplayEnv
from vid2sim.samples.scenarios import LATE_REACTION, braking_lead_scenario

SCRIPT = Path(__file__).resolve().parents[1] / ".ci" / "commonroad_crime.sh"


def log_infos(scenario) -> list[dict]:
    env = ReplayEnv(scenario, ego_mode="log")
    try:
        return raw_run_episode(env, lambda obs, info: np.zeros(1, np.float32), seed=0)
    finally:
        env.close()


def series_for(infos: list[dict], lead_id: str) -> dict[str, np.ndarray]:
    """test-policy's per-step figures where ``lead_id`` is the ego's lead (NaN elsewhere)."""
    mine = np.array([i["has_lead"] and i["lead_id"] == lead_id for i in infos])
    col = {k: np.array([float(i[k]) for i in infos]) for k in ("t_s", "gap_m", "ttc_s",
                                                                "ego_speed_mps")}
    for k in ("gap_m", "ttc_s"):
        col[k] = np.where(mine, col[k], np.nan)
    return col


def crime_rows(scenario, work: Path, venv: Path) -> tuple[dict, float]:
    write_commonroad(scenario, work, ego_as_obstacle=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run(["bash", str(SCRIPT), str(work), str(work / "crime.json"), str(venv)],
                   check=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return json.loads((work / "crime.json").read_text()), cpu


def report(name: str, scenario, venv: Path) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        crime, cpu = crime_rows(scenario, Path(tmp), venv)
    infos = log_infos(scenario)
    leads = sorted({i["lead_id"] for i in infos if i["has_lead"]})
    pairs = []
    for lead in leads:
        if lead in {a.id for a in scenario.actors}:
            pairs += [p for p in pair_steps(crime, series_for(infos, lead), scenario, lead)
                      if math.isfinite(p.gap_m)]
    ours, theirs = minima(pairs)
    print(f"\n## {name}: {len(scenario.actors)} actors, {len(pairs)} steps with a lead "
          f"({len(leads)} lead(s)); crime {cpu:.1f} s CPU")
    print(f"smallest finite TTC: vid2sim {ours:.3f} s, crime {theirs:.3f} s"
          + (f" ({(theirs - ours) / ours:+.1%})" if math.isfinite(ours * theirs) else ""))
    print("| regime | steps | both finite | median rel. diff | max abs rel. diff | "
          "crime inf, vid2sim finite | max abs(HW - gap) [m] |")
    print("|---|---|---|---|---|---|---|")
    for regime, row in by_regime(pairs).items():
        print(f"| {regime} | {row['steps']} | {row['both_finite']} | "
              f"{row['median_rel_diff']:+.2%} | {row['max_abs_rel_diff']:.2%} | "
              f"{row['crime_inf_ours_finite']} | {row['max_hw_diff_m']:.3f} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", action="append", default=[], metavar="NAME=PATH")
    ap.add_argument("--venv", type=Path, default=Path("/tmp/vid2sim-crimevenv"))
    args = ap.parse_args()
    cases = [("late-reaction", braking_lead_scenario(**LATE_REACTION)),
             ("braking-lead (curve)", braking_lead_scenario())]
    for item in args.scenario:
        name, _, path = item.partition("=")
        cases.append((name, scenario_io.load(path)))
    for name, sc in cases:
        report(name, sc, args.venv)


if __name__ == "__main__":
    main()
