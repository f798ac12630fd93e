"""Scenarios built in code for the evaluation tests (no files, no real data)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from vid2sim.camera import Camera
from vid2sim.records import Origin
from vid2sim.scenario import Actor, Ego, Road, Scenario, Source, Trajectory

CAMERA = Camera(image_width=1242, image_height=375, fx=721.5, fy=721.5, cx=609.6, cy=172.9,
                height_m=1.65)


def straight_trajectory(t_s: np.ndarray, x0_m: float, y0_m: float, heading_rad: float,
                        speed_mps: float) -> Trajectory:
    """Constant speed along a fixed heading from (x0, y0) in ENU."""
    t = np.asarray(t_s, dtype=float)
    d = speed_mps * (t - t[0])
    return Trajectory(t=t, x=x0_m + d * math.cos(heading_rad), y=y0_m + d * math.sin(heading_rad),
                      heading=np.full(t.size, heading_rad), speed=np.full(t.size, speed_mps))


def make_scenario(heading_rad: float = 0.6, duration_s: float = 4.0, ego_speed_mps: float = 10.0,
                  actors: list[tuple[str, float, float, float, float, float]] | None = None,
                  camera: Camera = CAMERA) -> Scenario:
    """A straight two-lane road along ``heading_rad`` with the ego at 10 m/s and actors given as
    (id, start forward offset [m], lateral offset [m, left +], speed [m/s], t_start, t_end)
    relative to the ego's start pose; actors drive parallel to the ego."""
    if actors is None:
        actors = [("lead", 20.0, 0.0, 8.0, 0.0, duration_s),
                  ("left", 12.0, 3.5, 12.0, 0.0, duration_s),
                  ("right_far", 45.0, -3.5, 9.0, 1.0, duration_s),
                  ("hidden", 40.0, 0.0, 8.0, 0.0, duration_s)]
    t = np.linspace(0.0, duration_s, int(duration_s * 10) + 1)
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    ego = Ego(4.5, 1.8, 1.5, straight_trajectory(t, 0.0, 0.0, heading_rad, ego_speed_mps))
    acts = []
    for aid, fwd, lat, v, t0, t1 in actors:
        ta = t[(t >= t0 - 1e-9) & (t <= t1 + 1e-9)]
        # The actor's position at ta[0] follows its constant speed from time 0.
        x0 = fwd * c - lat * s + v * ta[0] * c
        y0 = fwd * s + lat * c + v * ta[0] * s
        acts.append(Actor(aid, "car", 4.3, 1.8, 1.5,
                          straight_trajectory(ta, x0, y0, heading_rad, v)))
    line = np.array([[-10 * c, -10 * s], [200 * c, 200 * s]])
    road = Road("r0", "test road", "primary", "trajectory", [], 2, 3.5, line)
    return Scenario(origin=Origin(60.17, 24.94, 0.0), roads=[road], ego=ego, actors=acts,
                    camera=camera.to_dict(),
                    source=Source(inputs=[{"name": "synthetic"}], tool_version="test",
                                  options={"fps": 10.0}, assumptions=["built in code"]))


@pytest.fixture
def scenario() -> Scenario:
    return make_scenario()
