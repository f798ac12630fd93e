"""Benchmark ``vid2sim test-policy``: a 5 x 5 variation grid on the demo scenario, end to end.

    python benchmarks/bench_policy.py [--scenario build/scenario.json] [--repeat 2]

Without ``--scenario`` it builds the demo first (``vid2sim demo --use-detections``, ~10 s, not
timed). Reports, best of ``--repeat`` runs in this process:

- one episode of the bare environment (reference ACC + AEB on ``info``) with highway-env's
  pandas Kinematics observation and with the environment's numpy one (the same numbers);
- one ``test-policy`` episode of ``acc+aeb`` (camera observation);
- the whole campaign ``--vary lead_decel=0.5:1.5:5,gap=0.6:1.2:5`` (25 episodes, plus the
  log replays for the roles and the plots, results.csv and summary.html) with 1 and 2 worker
  processes; the bar is one minute on the 2-core development machine.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from highway_env.envs.common.observation import KinematicObservation

from vid2sim.adas.campaign import CampaignOptions, run_campaign
from vid2sim.adas.episode import run_episode
from vid2sim.adas.policies import AccPolicy, AebPolicy
from vid2sim.adas.policies import run_episode as raw_run_episode
from vid2sim.adas.registry import parse_policy
from vid2sim.core import scenario as scenario_io
from vid2sim.export.highway import ReplayEnv

GRID = "lead_decel=0.5:1.5:5,gap=0.6:1.2:5"


class PandasObservationEnv(ReplayEnv):
    """The environment with highway-env's own (pandas) Kinematics observation, for the ratio."""

    def define_spaces(self) -> None:
        super().define_spaces()
        cfg = dict(self.config["observation"])
        cfg.pop("type")
        self.observation_type = KinematicObservation(self, **cfg)


def _raw_episode_seconds(scenario, env_cls, repeat: int) -> float:
    """One episode of the bare environment (its own observation) with ``AccPolicy``."""
    v_ref = max(float(scenario.ego.trajectory.speed.max()), 5.0)
    best = float("inf")
    for _ in range(repeat):
        env = env_cls(scenario)
        t0 = time.perf_counter()
        raw_run_episode(env, AebPolicy(base=AccPolicy(desired_speed_mps=v_ref)), seed=0)
        best = min(best, time.perf_counter() - t0)
    return best


def _policy_episode_seconds(scenario, repeat: int) -> float:
    """One ``test-policy`` episode (camera observation, ISO ACC + staged AEB), setup included."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        run_episode(scenario, parse_policy("acc+aeb"))
        best = min(best, time.perf_counter() - t0)
    return best


def _cpu_s() -> float:
    """CPU seconds of this process and its finished children (the pool's workers)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenario", type=Path, default=None)
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        path = args.scenario
        if path is None:
            from vid2sim.app.demo import run_demo
            from vid2sim.app.settings import Settings

            run_demo(Path(tmp) / "demo", force_detections=True, settings=Settings(progress=False))
            path = Path(tmp) / "demo" / "build" / "scenario.json"
        sc = scenario_io.load(path)
        print(f"scenario {path}: {sc.duration_s:.1f} s, {len(sc.actors)} actors, "
              f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
        steps = round(sc.duration_s * 10)
        slow = _raw_episode_seconds(sc, PandasObservationEnv, args.repeat + 1)
        fast = _raw_episode_seconds(sc, ReplayEnv, args.repeat + 1)
        camera = _policy_episode_seconds(sc, args.repeat + 1)
        print(f"episode ({steps} steps), bare env + AccPolicy/AebPolicy: {slow:.3f} s with "
              f"highway-env's pandas Kinematics observation, {fast:.3f} s with the numpy one "
              f"({slow / fast:.1f}x)")
        print(f"episode ({steps} steps), test-policy acc+aeb through the camera model: "
              f"{camera:.3f} s ({1e3 * camera / steps:.2f} ms/step, setup included)")
        for jobs in (1, 2):
            best, best_cpu = float("inf"), float("inf")
            for k in range(args.repeat):
                opts = CampaignOptions(inputs=(path,), policy="acc+aeb", vary=GRID, jobs=jobs,
                                       out_dir=Path(tmp) / f"out{jobs}_{k}")
                c0, t0 = _cpu_s(), time.perf_counter()
                summary = run_campaign(opts)
                best = min(best, time.perf_counter() - t0)
                best_cpu = min(best_cpu, _cpu_s() - c0)
            # CPU seconds do not depend on other sessions' load: with one process they are
            # what the wall time would be on an idle machine
            print(f"5 x 5 grid, {jobs} process(es): {best:.1f} s wall, {best_cpu:.1f} s CPU "
                  f"(all processes; bar 60 s wall) -- {summary.splitlines()[0]}")


if __name__ == "__main__":
    main()
