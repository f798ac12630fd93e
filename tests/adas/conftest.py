"""Fixtures of the policy tests: the demo build (made in code) and the KITTI raw 0001 build."""

from __future__ import annotations

import numpy as np
import pytest

from vid2sim.app.build import build
from vid2sim.app.demo import run_demo
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.core import scenario as scenario_io
from vid2sim.core.scenario import Scenario


@pytest.fixture(scope="session")
def demo_scenario_path(tmp_path_factory):
    """``vid2sim demo --use-detections``: the build's scenario.json (about 10 s to make)."""
    out = tmp_path_factory.mktemp("demo")
    run_demo(out, force_detections=True, settings=Settings(progress=False))
    return out / "build" / "scenario.json"


@pytest.fixture(scope="session")
def demo_scenario(demo_scenario_path) -> Scenario:
    return scenario_io.load(demo_scenario_path)


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


@pytest.fixture(scope="session")
def kitti_scenario(tmp_path_factory, kitti_raw_dir, model_dir) -> Scenario:
    """``vid2sim build`` of KITTI raw 0001 with its GPS and camera (real YOLOX-nano, every
    second frame as tests/test_pipeline.py; about a minute)."""
    out = tmp_path_factory.mktemp("kitti")
    settings = Settings(detector=DetectorSettings(model_dir=model_dir, detect_every=2),
                        allow_download=False, progress=False)
    result = build(Inputs(video=kitti_raw_dir / "video.mp4", gps=kitti_raw_dir,
                          camera=kitti_raw_dir / "camera.yaml"), out / "k", settings)
    return scenario_io.load(result.files["scenario"])
