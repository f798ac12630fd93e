"""The references the lane measurement is checked against (vid2sim.evaluate.lane_checks)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.core.records import Origin
from vid2sim.core.scenario import Ego, Scenario, Source, Trajectory
from vid2sim.evaluate.lane_checks import (
    ego_cross_error,
    kitti_camera_lever_arm,
    kitti_camera_poses,
    summary,
    world_line_scatter,
)


def weaving_poses(n: int = 120, seed: int = 0) -> dict[str, np.ndarray]:
    """A car driving east at 10 m/s, weaving across its lane."""
    t = np.arange(n) / 10.0
    y = 0.4 * np.sin(0.7 * t) + np.random.default_rng(seed).normal(0, 0.01, n).cumsum()
    x = 10.0 * t
    yaw = np.arctan2(np.gradient(y, t), np.gradient(x, t))
    return {"t_s": t, "x_m": x, "y_m": y, "yaw_rad": yaw, "speed_mps": np.full(n, 10.0)}


@settings(max_examples=20)
@given(line_y=st.floats(-5, 5), x_eval=st.floats(0, 10))
def test_a_line_measured_exactly_stays_on_one_curve(line_y, x_eval):
    poses = weaving_poses()
    y, h = poses["y_m"], poses["yaw_rad"]
    # The straight line y = line_y, seen at x_eval ahead along the car's axis: the point on
    # the car's y axis shifted x_eval forward meets it after (line_y - y - x_eval sin h) /
    # cos h metres.
    offset = (line_y - y - x_eval * np.sin(h)) / np.cos(h)
    s = world_line_scatter(offset, poses, x_eval)
    assert s["rms_m"] < 1e-6 and s["n"] == len(offset)


def test_white_noise_is_its_own_scatter():
    poses = weaving_poses(2000)
    rng = np.random.default_rng(1)
    offset = 1.5 - poses["y_m"] + rng.normal(0.0, 0.05, 2000)
    offset[::7] = np.nan  # frames without a measurement are left out
    s = world_line_scatter(offset, poses)
    assert s["rms_m"] == pytest.approx(0.05, rel=0.1)
    assert abs(s["lag1"]) < 0.1
    assert np.isnan(s["residual_m"][::7]).all()


def test_summary_of_signed_errors():
    s = summary(np.array([0.1, -0.1, 0.3, np.nan]))
    assert s["n"] == 3 and s["bias_m"] == pytest.approx(0.1)
    assert s["max_m"] == pytest.approx(0.3)
    assert s["rms_m"] == pytest.approx(np.sqrt(0.11 / 3))
    assert np.isnan(summary(np.array([]))["rms_m"])


def _scenario(y_shift: float) -> tuple[Origin, Trajectory, Scenario]:
    t = np.arange(0.0, 10.0, 0.1)
    heading = np.full(len(t), np.pi / 2)  # north
    traj = Trajectory(t, np.zeros(len(t)), 10.0 * t, heading, np.full(len(t), 10.0))
    origin = Origin(60.0, 25.0, 0.0)
    truth = Scenario(origin=origin, roads=[], ego=Ego(4.5, 1.8, 1.5, traj), actors=[],
                     camera={}, source=Source())
    moved = Trajectory(t, np.full(len(t), -y_shift), 10.0 * t, heading, traj.speed)
    return origin, moved, truth


@given(shift=st.floats(-3, 3))
def test_cross_error_is_signed_positive_left(shift):
    origin, moved, truth = _scenario(shift)
    t, cross = ego_cross_error(origin, moved, truth)
    # Heading north, left is west (-x): a trajectory moved west by `shift` is `shift` left.
    np.testing.assert_allclose(cross, shift, atol=1e-6)
    assert len(t) == len(truth.ego.trajectory.t)


def test_kitti_camera_lever_arm(kitti_raw_dir):
    poses = kitti_camera_poses(kitti_raw_dir)
    assert len(poses["t_s"]) == 108 and poses["t_s"][0] == 0.0
    # The camera is ~1.08 m ahead of and ~0.31 m right of the OXTS unit.
    lever = kitti_camera_lever_arm(kitti_raw_dir)
    assert lever[0] == pytest.approx(1.08, abs=0.02) and lever[1] == pytest.approx(-0.31,
                                                                                  abs=0.02)
    assert np.median(poses["speed_mps"]) == pytest.approx(10.0, abs=3.5)
