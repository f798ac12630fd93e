"""The camera sensor model: exactness at level 0, the range-error law, latency, dropouts and
tracking, field of view, lane model, seeding and the gym contract."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given
from hypothesis import strategies as st

from vid2sim.adas.sensor import (
    CameraGeometry,
    CameraSensor,
    SensorConfig,
    lane_model_sigmas,
    lateral_sigma_m,
    range_rate_sigma_mps,
    range_sigma_m,
    read_frame,
)
from vid2sim.core.scenario import Actor, Ego, Road, Scenario, Source
from vid2sim.export.highway import ReplayEnv
from vid2sim.samples.scenarios import ORIGIN, straight_scenario, trajectory_along

KITTI = CameraGeometry(focal_px=721.5377, height_m=1.65, hfov_rad=2 * math.atan(621 / 721.5377))
ZERO = np.zeros(1, np.float32)


def parked_lead_scenario(range_m: float, lateral_m: float = 0.0, duration_s: float = 20.0,
                         camera: dict | None = None) -> Scenario:
    """The ego stands still; a car's rear stands ``range_m`` ahead of the ego's centre (where
    the camera is), offset ``lateral_m`` to the left; the bumper gap is ``range_m`` - 2.25."""
    line = np.array([[-50.0, 0.0], [400.0, 0.0]])
    t = np.round(np.arange(0.0, duration_s + 1e-9, 0.1), 6)
    ego = trajectory_along(line, 50.0 + 0 * t, t, 0.0)
    car = Actor("car", "car", 4.4, 1.8, 1.5,
                trajectory_along(line, 50.0 + range_m + 2.2 + 0 * t, t, lateral_m))
    road = Road("r", "", "primary", "osm", [1], 3, 3.5, line)
    cam = camera or {"fx": 721.5377, "height_m": 1.65, "image_width": 1242}
    return Scenario(ORIGIN, [road], Ego(4.5, 1.8, 1.5, ego), [car], cam, Source())


def test_range_error_law_known_answers():
    cfg = SensorConfig(level=1.0)
    # Z^2 sigma_px / (f H): 20^2 * 2 / (721.5 * 1.65) = 0.672 m, 3.4 % at 20 m
    assert range_sigma_m(20.0, cfg, KITTI) == pytest.approx(0.6720, abs=1e-3)
    assert range_sigma_m(40.0, cfg, KITTI) == pytest.approx(4 * 0.6720, abs=4e-3)
    assert range_sigma_m(20.0, SensorConfig(level=2.0), KITTI) == pytest.approx(2 * 0.6720,
                                                                                 abs=2e-3)
    assert range_sigma_m(20.0, SensorConfig(level=0.0), KITTI) == 0.0
    assert range_rate_sigma_mps(25.0, cfg) == pytest.approx(0.5)
    # lateral: column error Z sigma / f at Y = 0
    assert lateral_sigma_m(20.0, 0.0, cfg, KITTI) == pytest.approx(20 * 2 / 721.5377)
    off, head, curv = lane_model_sigmas(cfg, KITTI)
    s1, s2 = 5 * 3 / 721.5377, 20 * 3 / 721.5377
    assert off == pytest.approx(math.sqrt((20 * s1) ** 2 + (5 * s2) ** 2) / 15 / math.sqrt(2))
    assert head == pytest.approx(math.hypot(s1, s2) / 15 / math.sqrt(2))
    assert curv == pytest.approx(2 * s2 / 400 / math.sqrt(2))


@given(st.floats(1.0, 120.0), st.floats(0.0, 4.0))
def test_range_error_grows_with_the_square_of_range(z, level):
    cfg = SensorConfig(level=level)
    assert range_sigma_m(2 * z, cfg, KITTI) == pytest.approx(4 * range_sigma_m(z, cfg, KITTI))


def test_camera_geometry_from_records():
    cam = CameraGeometry.from_record({"fx": 560.0, "height_m": 1.35, "image_width": 960})
    assert cam.focal_px == 560.0 and cam.height_m == 1.35
    assert cam.hfov_rad == pytest.approx(2 * math.atan(480 / 560))
    default = CameraGeometry.from_record({})  # the project's default dash-cam
    assert default.hfov_rad == pytest.approx(math.pi / 2) and default.height_m == 1.3
    with pytest.raises(ValueError):
        CameraGeometry.from_record({"fx": -1.0})


def test_level_zero_is_the_exact_traffic():
    env = CameraSensor(ReplayEnv(straight_scenario()))
    obs, info = env.reset(seed=0)
    for _ in range(60):
        obs, _, _, _, info = env.step(ZERO)
        frame = read_frame(obs)
        assert frame.t_s == pytest.approx(info["t_s"], abs=1e-5)
        assert frame.speed_mps == pytest.approx(info["ego_speed_mps"], abs=1e-5)
        assert frame.lead is not None and info["has_lead"]
        assert frame.lead.range_m == pytest.approx(info["gap_m"], abs=1e-4)
        assert -frame.lead.range_rate_mps == pytest.approx(info["closing_speed_mps"], abs=1e-4)
        assert frame.lane is not None and frame.lane.lane_width_m == pytest.approx(3.5)
        assert frame.lane.lateral_offset_m == pytest.approx(info["lane_offset_m"], abs=1e-5)
    # the truck in the left lane ahead is reported one lane to the left
    assert any(o.lane_offset == 1 for o in frame.objects)


@pytest.mark.parametrize("range_m", [15.0, 30.0])
def test_measured_range_spread_follows_the_law(range_m):
    sc = parked_lead_scenario(range_m)
    cfg = SensorConfig(level=1.0, dropout=0.0)
    ranges = []
    for seed in range(4):
        env = CameraSensor(ReplayEnv(sc, ego_mode="log"), cfg)
        obs, _ = env.reset(seed=seed)
        for _ in range(env.unwrapped.n_steps):
            obs, *_ = env.step(ZERO)
            ranges.append(read_frame(obs).lead.range_m)
    ranges = np.array(ranges)
    sigma = range_sigma_m(range_m, cfg, KITTI)  # the camera sits at the ego's centre
    gap = range_m - 2.25  # reported: bumper to bumper
    assert ranges.mean() == pytest.approx(gap, abs=4 * sigma / math.sqrt(len(ranges)))
    assert ranges.std() == pytest.approx(sigma, rel=0.08)  # 800 samples: 2.5 % standard error


def test_latency_reports_the_previous_step():
    env = CameraSensor(ReplayEnv(straight_scenario()), SensorConfig(level=1e-9, dropout=0.0,
                                                                     lane_dropout=0.0))
    obs, info = env.reset(seed=0)
    gaps = [info["gap_m"]]
    reported = [read_frame(obs).lead.range_m]
    for _ in range(80):
        obs, _, _, _, info = env.step(ZERO)
        gaps.append(info["gap_m"])
        reported.append(read_frame(obs).lead.range_m)
    # one 0.1 s frame of latency: the report at step k is the truth at step k - 1
    np.testing.assert_allclose(reported[1:], gaps[:-1], atol=1e-3)


def test_dropouts_are_coasted_for_the_hold_time():
    cfg = SensorConfig(level=10.0, sigma_px=0.0, range_rate_sigma_mps=0.0,
                       range_rate_sigma_per_m=0.0, dropout=0.05, hold_s=0.3)  # p = 0.5
    env = CameraSensor(ReplayEnv(parked_lead_scenario(20.0), ego_mode="log"), cfg)
    obs, _ = env.reset(seed=7)
    present = []
    for _ in range(env.unwrapped.n_steps):
        obs, *_ = env.step(ZERO)
        lead = read_frame(obs).lead
        present.append(lead is not None)
        if lead is not None:
            assert lead.range_m == pytest.approx(20.0 - 2.25, abs=1e-4)  # no noise, parked
    # missed on half the frames; coasting fills gaps of up to 3 frames: missing only after 4
    # misses in a row, p^4 = 1/16 of the frames (200 frames: +-0.017 standard error)
    assert np.mean(present) == pytest.approx(1 - 0.5**4, abs=0.05)


def test_field_of_view_and_range_limit():
    wide = parked_lead_scenario(10.0, lateral_m=30.0)  # 72 deg off the axis
    far = parked_lead_scenario(120.0)
    for sc, visible_exact in ((wide, True), (far, True)):
        exact = CameraSensor(ReplayEnv(sc, ego_mode="log"))
        obs, _ = exact.reset(seed=0)
        assert (len(read_frame(obs).objects) + (read_frame(obs).lead is not None) > 0
                ) == visible_exact
        cam = CameraSensor(ReplayEnv(sc, ego_mode="log"), SensorConfig(level=1.0))
        obs, _ = cam.reset(seed=0)
        frame = read_frame(obs)
        assert frame.lead is None and frame.objects == ()


def test_noise_is_seeded():
    def run(seed):
        env = CameraSensor(ReplayEnv(straight_scenario(duration_s=3.0)),
                           SensorConfig(level=1.0))
        obs, _ = env.reset(seed=seed)
        out = [obs]
        for _ in range(20):
            obs, *_ = env.step(ZERO)
            out.append(obs)
        return np.array(out)

    np.testing.assert_array_equal(run(5), run(5))
    assert not np.array_equal(run(5), run(6))


def test_wrapped_environment_passes_check_env():
    check_env(CameraSensor(ReplayEnv(straight_scenario(duration_s=3.0)),
                           SensorConfig(level=1.0)), skip_render_check=True)
