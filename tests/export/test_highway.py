"""The vid2sim/Replay-v0 environment: frames, lanes, replay fidelity, gym API, determinism."""

from __future__ import annotations

import math

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import given, settings
from hypothesis import strategies as st

import vid2sim  # noqa: F401  registers the environment
from vid2sim.errors import InputError
from vid2sim.export.highway import ReplayEnv, enu_to_hw, hw_to_enu
from vid2sim.export.policies import AccPolicy, AebPolicy, FollowLogPolicy, run_episode
from vid2sim.scenario import save

from .scenarios import left_turn_scenario, straight_scenario

ZERO = np.zeros(1, dtype=np.float32)


def test_frame_flip_round_trip_and_sign():
    x, y, h = enu_to_hw(3.0, 2.0, 0.5)
    assert (x, y, h) == (3.0, -2.0, -0.5)
    assert hw_to_enu(x, y, h) == (3.0, 2.0, 0.5)


def test_make_by_id_with_path_and_render_headless(tmp_path):
    path = tmp_path / "scenario.json"
    save(straight_scenario(), path)
    env = gymnasium.make("vid2sim/Replay-v0", scenario=str(path), render_mode="rgb_array")
    obs, _info = env.reset(seed=1)
    assert obs.shape == (8, 7) and obs.dtype == np.float32
    img = env.render()
    assert img.shape == (300, 600, 3)
    # the road is drawn: not one flat colour
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 3
    env.close()


def test_bad_scenario_path_is_an_input_error(tmp_path):
    with pytest.raises(InputError):
        gymnasium.make("vid2sim/Replay-v0", scenario=str(tmp_path / "missing.json"))


def test_right_hand_traffic_stays_right():
    # heading east, ego in the right lane of two: it must sit south of the centerline (ENU y < 0),
    # in highway-env's lane 1 (the right one) and at positive highway-env y (screen down).
    env = ReplayEnv(straight_scenario(), ego_mode="log")
    env.reset(seed=0)
    ego = env.vehicle
    assert ego.lane_index[2] == 1
    assert ego.position[1] > 0
    state = env.vehicle_states()[0]
    assert state.id == "ego" and state.y_m == pytest.approx(-1.75)
    # the truck in the left lane (ENU y > 0) is in lane 0
    env.step(ZERO)
    for _ in range(25):
        env.step(ZERO)
    truck = next(v for v in env.road.vehicles if getattr(v, "vehicle_id", "") == "9")
    assert truck.lane_index[2] == 0


def test_left_turn_stays_left_with_lane_following():
    sc = left_turn_scenario(with_actors=False, duration_s=17.0)
    env = ReplayEnv(sc, ego_mode="policy")
    env.reset(seed=0)
    headings = []
    while True:
        _, _, terminated, truncated, info = env.step(ZERO)  # coast, steering by lane following
        headings.append(env.vehicle_states()[0].heading_rad)
        assert not terminated, f"left the road at t={info['t_s']:.1f} s"
        if truncated:
            break
    # ENU heading rises from east (0) to north (+pi/2): a left turn
    assert headings[0] == pytest.approx(0.0, abs=0.05)
    assert headings[-1] == pytest.approx(math.pi / 2, abs=0.05)
    end = env.vehicle_states()[0]
    assert end.y_m > 40.0  # went north, not off to the south


def test_replay_fidelity_every_step():
    for sc in (straight_scenario(), left_turn_scenario()):
        env = ReplayEnv(sc, ego_mode="log")
        env.reset(seed=0)
        trajs = {a.id: a.trajectory for a in sc.actors}
        trajs["ego"] = sc.ego.trajectory
        seen = set()
        truncated = False
        while not truncated:
            _, _, terminated, truncated, info = env.step(ZERO)
            assert not terminated
            for vs in env.vehicle_states():
                ref = trajs[vs.id].state_at(info["t_s"])
                err = math.hypot(vs.x_m - float(ref["x"]), vs.y_m - float(ref["y"]))
                assert err < (0.5 if vs.id == "ego" else 0.2), (vs.id, info["t_s"], err)
                seen.add(vs.id)
        assert seen == set(trajs)
        assert info["t_s"] == pytest.approx(sc.duration_s)


def test_actor_presence_follows_its_time_span():
    env = ReplayEnv(straight_scenario(), ego_mode="log")
    env.reset(seed=0)
    ids_at = {}
    for _ in range(env.n_steps):
        _, _, _, _, info = env.step(ZERO)
        ids_at[round(info["t_s"], 1)] = {s.id for s in env.vehicle_states()}
    assert "9" not in ids_at[1.0] and "9" in ids_at[5.0] and "9" not in ids_at[10.0]


def test_vehicle_states_at_other_time_in_log_mode():
    sc = straight_scenario()
    env = ReplayEnv(sc, ego_mode="log")
    env.reset(seed=0)
    states = {s.id: s for s in env.vehicle_states(t_s=3.05)}
    ref = sc.actors[0].trajectory.state_at(3.05)
    assert states["7"].x_m == pytest.approx(float(ref["x"]))
    assert states["9"].length_m == 8.0 and states["9"].height_m == 3.2


def test_info_lead_gap_ttc_headway():
    env = ReplayEnv(straight_scenario(), ego_mode="log")
    _, info = env.reset(seed=0)
    # lead 25 m ahead (centre to centre), lengths 4.5 and 4.4 -> gap 20.55 m
    assert info["lead_id"] == "7"
    assert info["gap_m"] == pytest.approx(25.0 - 4.45, abs=1e-6)
    assert info["time_headway_s"] == pytest.approx(info["gap_m"] / 10.0)
    assert info["ttc_s"] == math.inf
    for _ in range(60):  # t = 6 s: the lead brakes at 2 m/s^2 since 4 s -> 4 m/s slower
        _, _, _, _, info = env.step(ZERO)
    assert info["closing_speed_mps"] == pytest.approx(4.0, abs=0.05)
    assert info["ttc_s"] == pytest.approx(info["gap_m"] / info["closing_speed_mps"], rel=1e-6)


def test_check_env_passes():
    check_env(ReplayEnv(straight_scenario(duration_s=3.0)), skip_render_check=True)


def test_seeding_is_deterministic():
    def rollout(seed):
        env = ReplayEnv(straight_scenario(duration_s=4.0))
        obs, _ = env.reset(seed=seed)
        out = [obs]
        rng = np.random.default_rng(0)
        for _ in range(env.n_steps):
            obs, *_ = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
            out.append(obs)
        return np.array(out)

    np.testing.assert_array_equal(rollout(3), rollout(3))


def test_collision_terminates_in_policy_mode_only():
    sc = straight_scenario()
    env = ReplayEnv(sc)
    env.reset(seed=0)
    full = np.ones(1, dtype=np.float32)  # +8 m/s^2 into the braking lead
    terminated = False
    for _ in range(env.n_steps):
        _, _, terminated, truncated, info = env.step(full)
        if terminated or truncated:
            break
    assert terminated and info["crashed"]


def test_acc_with_aeb_keeps_distance_to_braking_lead():
    env = ReplayEnv(straight_scenario())
    infos = run_episode(env, AebPolicy(base=AccPolicy(desired_speed_mps=12.0)), seed=0)
    assert infos[-1]["truncated"] and not any(i["crashed"] for i in infos)
    assert min(i["gap_m"] for i in infos) > 2.0


def test_follow_log_policy_tracks_the_logged_ego():
    sc = left_turn_scenario(with_actors=False)
    env = ReplayEnv(sc)
    infos = run_episode(env, FollowLogPolicy(sc.ego.trajectory), seed=0)
    assert infos[-1]["truncated"]
    # lane following + speed tracking: the ego ends where its log ends
    end = env.vehicle_states()[0]
    ref = sc.ego.trajectory.state_at(infos[-1]["t_s"])
    assert math.hypot(end.x_m - float(ref["x"]), end.y_m - float(ref["y"])) < 1.0


@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, 200.0), st.floats(-6.0, 6.0))
def test_scenario_lane_projection_inverts_position(s_m, lat_m):
    from vid2sim.export.highway import build_network

    road = left_turn_scenario().roads[0]
    lane = build_network([road]).get_lane(("road0:start", "road0:end", 0))
    s_back, lat_back = lane.local_coordinates(lane.position(s_m, lat_m))
    # exact on straights; on the arc highway-env's piecewise-constant heading (1 m samples)
    # shifts s by up to |lat| * curvature * 1 m (6 m / 40 m = 0.15 m)
    assert s_back == pytest.approx(s_m, abs=0.2)
    assert lat_back == pytest.approx(lat_m, abs=0.05)


def test_leaving_the_road_terminates_in_policy_mode():
    # the map road ends 60 m into a 200 m drive; the simulation extends it by 50 m
    sc = straight_scenario(duration_s=15.0, with_actors=False)
    sc.roads[0].centerline = np.array([[0.0, 0.0], [60.0, 0.0]])
    env = ReplayEnv(sc)
    infos = run_episode(env, lambda obs, info: ZERO, seed=0)
    assert infos[-1]["terminated"] and infos[-1]["offroad"] and not infos[-1]["crashed"]
    end_x = env.vehicle_states()[0].x_m
    assert 110.0 < end_x < 125.0  # past the extended end (110 m) plus at most a car length
