"""Reference policies: action mapping, IDM known answers, AEB latch, ego-mode switching."""

from __future__ import annotations

import numpy as np
import pytest

from vid2sim.adas.policies import AccPolicy, AebPolicy, accel_to_action, run_episode
from vid2sim.export.highway import ReplayEnv
from vid2sim.export.highway.info import StepInfo
from vid2sim.samples.scenarios import straight_scenario


def test_accel_to_action_is_the_inverse_linear_map():
    assert accel_to_action(0.0)[0] == pytest.approx(0.0)
    assert accel_to_action(-8.0)[0] == pytest.approx(-1.0)
    assert accel_to_action(4.0, (-8.0, 4.0))[0] == pytest.approx(1.0)
    assert accel_to_action(-20.0)[0] == -1.0  # clipped


def _state(**fields) -> StepInfo:
    base = {"t_s": 0.0, "ego_mode": "policy", "ego_speed_mps": 10.0, "ego_accel_mps2": 0.0,
            "ego_lane": 0, "lane_offset_m": 0.0, "lane_width_m": 3.5, "crashed": False,
            "collision_with": "", "offroad": False}
    return StepInfo(**{**base, **fields})


def test_idm_free_road_and_equilibrium():
    acc = AccPolicy(desired_speed_mps=20.0, max_accel_mps2=1.5)
    free = _state(ego_speed_mps=10.0)
    assert acc.acceleration(free) == pytest.approx(1.5 * (1 - 0.5**4))
    # at the desired gap s* with no closing speed the interaction term is -a_max
    v = 10.0
    s_star = acc.min_gap_m + v * acc.time_headway_s
    follow = _state(ego_speed_mps=v, has_lead=True, lead_id="1", gap_m=s_star,
                    closing_speed_mps=0.0).to_dict()  # the dict gymnasium hands over
    assert acc.acceleration(follow) == pytest.approx(1.5 * (1 - 0.5**4) - 1.5)


def test_aeb_latches_until_released():
    aeb = AebPolicy(trigger_ttc_s=1.5, release_ttc_s=3.0)
    obs = np.zeros((8, 7), np.float32)
    assert aeb(obs, _state(ttc_s=5.0, ego_speed_mps=10.0))[0] == pytest.approx(0.0)
    assert aeb(obs, _state(ttc_s=1.0, ego_speed_mps=10.0))[0] == pytest.approx(-1.0)
    assert aeb(obs, _state(ttc_s=2.0, ego_speed_mps=8.0))[0] == pytest.approx(-1.0)  # latched
    assert aeb(obs, _state(ttc_s=4.0, ego_speed_mps=6.0))[0] == pytest.approx(0.0)


def test_reset_option_switches_ego_mode():
    env = ReplayEnv(straight_scenario(duration_s=3.0))
    infos = run_episode(env, AccPolicy(), seed=0, options={"ego_mode": "log"})
    assert {i["ego_mode"] for i in infos} == {"log"}
    infos = run_episode(env, AccPolicy(), seed=0)
    assert {i["ego_mode"] for i in infos} == {"policy"}
    with pytest.raises(ValueError):
        env.reset(options={"ego_mode": "idm"})
