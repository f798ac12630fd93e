"""Benchmark the export stage: env construction, reset, steps (log and policy mode), rendering,
OpenSCENARIO/OpenDRIVE writing, on a synthetic scenario (curved 1.2 km road, 3 lanes, N actors).

    python benchmarks/bench_env.py [--actors 20] [--duration 60]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from vid2sim.adas.policies import AccPolicy, AebPolicy, run_episode
from vid2sim.core.scenario import Actor, Ego, Road, Scenario, Source
from vid2sim.export.highway import ReplayEnv
from vid2sim.export.openscenario import write_openscenario
from vid2sim.samples.scenarios import ORIGIN, trajectory_along


def synthetic(n_actors: int, duration_s: float) -> Scenario:
    s = np.linspace(0.0, 1200.0, 1201)
    # a gentle S-curve: heading swings +-0.6 rad over the road
    h = 0.6 * np.sin(2 * np.pi * s / 800.0)
    pts = np.column_stack((np.r_[0, np.cumsum(np.cos(h[:-1]))], np.r_[0, np.cumsum(np.sin(h[:-1]))]))
    t = np.round(np.arange(0.0, duration_s + 1e-9, 0.1), 6)
    road = Road("r", "bench", "primary", "osm", [1], 3, 3.5, pts)
    ego = trajectory_along(pts, 10.0 + 12.0 * t, t, 0.0)
    rng = np.random.default_rng(0)
    actors = []
    for i in range(n_actors):
        lane = rng.integers(-1, 2)
        v = rng.uniform(9.0, 15.0)
        actors.append(Actor(str(i), "car", 4.5, 1.8, 1.5, trajectory_along(
            pts, 30.0 + 15.0 * i + v * t, t, 3.5 * lane)))
    return Scenario(ORIGIN, [road], Ego(4.5, 1.8, 1.5, ego), actors, {}, Source())


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--actors", type=int, default=20)
    ap.add_argument("--duration", type=float, default=60.0)
    args = ap.parse_args()
    sc = synthetic(args.actors, args.duration)

    t0 = time.perf_counter()
    env = ReplayEnv(sc, ego_mode="log")
    t_make = time.perf_counter() - t0
    zero = np.zeros(1, np.float32)
    for mode in ("log", "policy"):
        t0 = time.perf_counter()
        if mode == "log":
            env.reset(seed=0, options={"ego_mode": "log"})
            for _ in range(env.n_steps):
                env.step(zero)
        else:
            run_episode(env, AebPolicy(base=AccPolicy(desired_speed_mps=12.0)), seed=0)
        dt = time.perf_counter() - t0
        print(f"{mode:6s} episode: {env.n_steps} steps in {dt:.2f} s "
              f"({1e3 * dt / env.n_steps:.2f} ms/step, {args.duration / dt:.0f}x real time)")
    renv = ReplayEnv(sc, ego_mode="log", render_mode="rgb_array")
    renv.reset(seed=0)
    t0 = time.perf_counter()
    for _ in range(50):
        renv.step(zero)
        renv.render()
    print(f"render: {1e3 * (time.perf_counter() - t0) / 50:.1f} ms per step+frame")
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        write_openscenario(sc, Path(tmp))
        print(f"openscenario+opendrive export: {time.perf_counter() - t0:.2f} s "
              f"(1.2 km road, {1 + args.actors} vehicles x {len(sc.ego.trajectory)} vertices)")
    print(f"env construction: {t_make:.2f} s")


if __name__ == "__main__":
    main()
