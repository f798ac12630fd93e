"""Helpers of the policy tests (the demo and KITTI raw 0001 builds are session fixtures of
tests/conftest.py)."""

from __future__ import annotations

import numpy as np

from vid2sim.core.scenario import Scenario


def recorded_gaps(scenario: Scenario, half_width_m: float) -> np.ndarray:
    """Gap to the lead at every ego sample, measured straight from the trajectories (not with
    the environment): each actor's nearest point on the ego's densified path gives its arc
    length and lateral offset; the lead is the nearest one ahead within ``half_width_m``.
    ``inf`` where there is none."""
    ego = scenario.ego.trajectory
    s_ego = np.r_[0.0, np.cumsum(np.hypot(np.diff(ego.x), np.diff(ego.y)))]
    # densify the path to 0.1 m so the nearest point is as good as a projection
    s_fine = np.arange(0.0, s_ego[-1] + 60.0, 0.1)
    heading = np.unwrap(ego.heading)
    x = np.interp(s_fine, s_ego, ego.x)
    y = np.interp(s_fine, s_ego, ego.y)
    beyond = s_fine > s_ego[-1]
    x[beyond] = ego.x[-1] + (s_fine[beyond] - s_ego[-1]) * np.cos(heading[-1])
    y[beyond] = ego.y[-1] + (s_fine[beyond] - s_ego[-1]) * np.sin(heading[-1])
    gaps = np.full(len(ego), np.inf)
    for a in scenario.actors:
        tr = a.trajectory
        for k, t in enumerate(ego.t):
            if not tr.t[0] - 1e-9 <= t <= tr.t[-1] + 1e-9:
                continue
            st = tr.state_at(t)
            d2 = (x - float(st["x"])) ** 2 + (y - float(st["y"])) ** 2
            i = int(np.argmin(d2))
            if np.sqrt(d2[i]) > half_width_m:
                continue
            along = s_fine[i] - s_ego[k]
            if along <= 0:
                continue
            gaps[k] = min(gaps[k], along - (scenario.ego.length_m + a.length_m) / 2)
    return gaps
