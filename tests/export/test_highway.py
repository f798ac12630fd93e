"""The vid2sim/Replay-v0 environment: frames, lanes, replay fidelity, gym API, determinism."""

from __future__ import annotations

import dataclasses
import math

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import vid2sim  # noqa: F401  registers the environment
from vid2sim.adas.policies import AccPolicy, AebPolicy, FollowLogPolicy, run_episode
from vid2sim.base.errors import MissingInputError
from vid2sim.core.scenario import save
from vid2sim.export.highway import ReplayEnv, enu_to_hw, hw_to_enu
from vid2sim.export.highway.info import StepInfo
from vid2sim.samples.scenarios import braking_lead_scenario, left_turn_scenario, straight_scenario

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
    with pytest.raises(MissingInputError):
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


def test_show_logged_puts_the_road_where_stepping_does():
    # Jumping to a time (for pictures) gives the vehicles stepping there gives, and only the
    # actors whose logs span that time; a policy's ego has no log to be put on.
    sc = straight_scenario()
    stepped = ReplayEnv(sc, ego_mode="log")
    stepped.reset(seed=0)
    for _ in range(50):
        stepped.step(ZERO)
    jumped = ReplayEnv(sc, ego_mode="log")
    jumped.reset(seed=0)
    jumped.show_logged(stepped.t_s)
    a = {s.id: s for s in stepped.vehicle_states()}
    b = {s.id: s for s in jumped.vehicle_states()}
    assert a.keys() == b.keys() and "9" in a
    for vid, s in a.items():
        assert (b[vid].x_m, b[vid].y_m) == pytest.approx((s.x_m, s.y_m), abs=1e-6), vid
    jumped.show_logged(1.0)
    assert "9" not in {s.id for s in jumped.vehicle_states()}
    policy = ReplayEnv(sc, ego_mode="policy")
    policy.reset(seed=0)
    with pytest.raises(ValueError):
        policy.show_logged(2.0)


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


# --------------------------------------------------------------------------- issue 14 additions


def test_fast_kinematics_equals_highway_envs_observation():
    from highway_env.envs.common.observation import KinematicObservation

    env = ReplayEnv(straight_scenario(), ego_mode="log")
    env.reset(seed=0)
    cfg = dict(env.config["observation"])
    cfg.pop("type")
    reference = KinematicObservation(env, **cfg)
    for _ in range(60):
        obs, *_ = env.step(ZERO)
        np.testing.assert_array_equal(obs, reference.observe())


def test_lanes_are_numbered_from_the_right():
    from vid2sim.export.highway import hw_lane, lane_centerlines_enu, project_lane

    road = straight_scenario().roads[0]
    right, left = lane_centerlines_enu(road, extension_m=0.0)
    assert right[0, 1] == pytest.approx(-1.75) and left[0, 1] == pytest.approx(1.75)
    assert project_lane(1, 2) == 0 and hw_lane(0, 2) == 1 and project_lane(0, 3) == 2
    env = ReplayEnv(straight_scenario(), ego_mode="log")
    _, info = env.reset(seed=0)
    assert info["ego_lane"] == 0  # the ego drives in the right lane
    assert env.vehicle.lane_index[2] == 1  # highway-env's index of the same lane


def test_info_without_a_lead_is_finite_and_none_free():
    sc = straight_scenario(with_actors=False, duration_s=3.0)
    env = ReplayEnv(sc)
    _, info = env.reset(seed=0)
    assert not info["has_lead"] and info["lead_id"] == ""
    assert info["gap_m"] == math.inf and info["ttc_s"] == math.inf
    assert info["lead_speed_mps"] == 0.0 and info["closing_speed_mps"] == 0.0
    for value in info.values():
        assert value is not None and not (isinstance(value, float) and math.isnan(value))
    check_env(ReplayEnv(sc), skip_render_check=True)


def test_policy_ego_follows_the_logged_path_at_its_own_speed():
    # a wavy ego path off the lane centres: whatever its speed, the ego stays on that path
    sc = left_turn_scenario(with_actors=False)
    traj = sc.ego.trajectory
    traj.y = traj.y + 0.8 * np.sin(traj.t / 2.0)
    fine = np.linspace(0.0, 1.0, 4000)
    px = np.interp(fine, np.linspace(0.0, 1.0, len(traj)), traj.x)
    py = np.interp(fine, np.linspace(0.0, 1.0, len(traj)), traj.y)
    for accel in (0.0, -0.25, 0.1):  # coast, brake gently, speed up (action units)
        env = ReplayEnv(sc)
        env.reset(seed=0)
        for _ in range(env.n_steps):
            _, _, terminated, _, info = env.step(np.array([accel], np.float32))
            assert not terminated
            ego = env.vehicle_states()[0]
            if ego.x_m > traj.x[-1]:
                break  # beyond the log: straight on
            off = np.min(np.hypot(px - ego.x_m, py - ego.y_m))
            assert off < 0.05, (accel, info["t_s"], off)


def test_ego_path_lane_option_steers_along_the_lane():
    sc = left_turn_scenario(with_actors=False, duration_s=17.0)
    sc.ego.trajectory.y = sc.ego.trajectory.y + 0.5  # logged 0.5 m off the lane centre
    env = ReplayEnv(sc, config={"ego_path": "lane"})
    _, info = env.reset(seed=0)
    for _ in range(env.n_steps):
        _, _, terminated, _, info = env.step(ZERO)
        assert not terminated
    assert abs(info["lane_offset_m"]) < 0.05  # the lane follower centred it
    with pytest.raises(ValueError):
        ReplayEnv(sc, config={"ego_path": "road"})


def test_lateral_control_action_and_steering_sign():
    sc = straight_scenario(with_actors=False, duration_s=4.0)
    env = ReplayEnv(sc, config={"lateral_control": True})
    _, info = env.reset(seed=0)
    assert env.action_space.shape == (2,)
    for _ in range(20):
        *_, info = env.step(np.array([0.0, 0.05], np.float32))
    # positive steering turns right (highway-env's mirrored frame): ENU heading decreases
    assert env.vehicle_states()[0].heading_rad < -0.05
    assert info["lane_offset_m"] < 0.0
    check_env(ReplayEnv(sc, config={"lateral_control": True}), skip_render_check=True)


def test_collision_names_the_vehicle_hit():
    env = ReplayEnv(straight_scenario())
    env.reset(seed=0)
    full = np.ones(1, dtype=np.float32)
    for _ in range(env.n_steps):
        *_, terminated, _, info = env.step(full)
        if terminated:
            break
    assert info["crashed"] and info["collision_with"] == "7"


@settings(max_examples=40, deadline=None)
@given(st.floats(-40.0, 240.0))
def test_path_pose_lies_on_the_path(s_m):
    env = ReplayEnv(left_turn_scenario(with_actors=False), ego_mode="log")
    path = env.path
    point, heading = path.pose_at(s_m + path.start_offset_m)
    s_back, lat = path.local_coordinates(point)
    assert s_back == pytest.approx(s_m + path.start_offset_m, abs=0.05)
    assert lat == pytest.approx(0.0, abs=0.05)
    assert abs(utils_wrap(heading - path.heading_at(s_back))) < 0.03


def utils_wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def test_exported_replay_script_runs(tmp_path):
    import os
    import subprocess
    import sys
    from pathlib import Path

    from vid2sim.cli import main

    path = tmp_path / "scenario.json"
    save(braking_lead_scenario(), path)
    out = tmp_path / "hw"
    assert main(["-q", "export", str(path), "--format", "highway-env", "--out", str(out)]) == 0
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    for args in ([], ["--log"]):
        proc = subprocess.run([sys.executable, str(out / "replay.py"), *args], env=env,
                              capture_output=True, text=True, timeout=300, check=False)
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert "collision=False" in proc.stdout


@settings(max_examples=60, deadline=None)
@given(st.floats(0.0, 230.0), st.floats(-5.0, 5.0), st.integers(0, 1))
def test_nearby_lane_matches_highway_envs_closest_lane(s_m, lat_m, start):
    from vid2sim.export.highway import build_network
    from vid2sim.export.highway.network import nearby_lane_index

    # On the line between the two lanes both are equally near: either answer is right.
    assume(abs(lat_m - 3.5) > 1e-6)
    net = build_network(left_turn_scenario().roads)
    lane0 = net.get_lane(("road0:start", "road0:end", 0))
    point = lane0.position(s_m, lat_m - 1.75)  # across both lanes and a little beyond
    index, lane = nearby_lane_index(net, ("road0:start", "road0:end", start), point)
    assert lane is net.get_lane(index)
    assert index == net.get_closest_lane_index(point)


def _lane_change_scenario(t_change_s: float = 4.5):
    """A straight two-lane road; the logged ego moves from the right lane to the left one
    between 3 and 6 s (minimum-jerk across 3.5 m), crossing the line at ``t_change_s``, with
    its ``lane_change`` event."""
    from vid2sim.core.scenario import Event

    sc = straight_scenario(with_actors=False, duration_s=10.0)
    traj = sc.ego.trajectory
    u = np.clip((traj.t - (t_change_s - 1.5)) / 3.0, 0.0, 1.0)
    traj.y = traj.y + 3.5 * u ** 3 * (10 - 15 * u + 6 * u ** 2)
    sc.events = [Event("lane_change", "ego", t_change_s, 0, 1)]
    return sc


@pytest.mark.parametrize("ego_path", ["lane", "log"])
def test_policy_ego_changes_lane_when_the_logged_ego_did(ego_path):
    sc = _lane_change_scenario()
    env = ReplayEnv(sc, config={"ego_path": ego_path})
    _, info = env.reset(seed=0)
    assert info["ego_lane"] == 0
    lanes, speeds = {}, []
    for _ in range(env.n_steps):
        # the policy brakes gently: the longitudinal control stays the policy's
        _, _, terminated, _, info = env.step(np.array([-0.05], np.float32))
        assert not terminated
        lanes[round(info["t_s"], 1)] = info["ego_lane"]
        speeds.append(info["ego_speed_mps"])
    assert all(v == 0 for t, v in lanes.items() if t <= 4.0)  # right lane before the event
    assert all(v == 1 for t, v in lanes.items() if t >= 7.0)  # left lane after it
    assert abs(info["lane_offset_m"]) < 0.3  # settled in the left lane
    log_speed = float(sc.ego.trajectory.speed[-1])
    assert speeds[-1] < log_speed - 2.0  # slower than the log: the policy braked
    # without the event, the lane follower keeps its lane
    if ego_path == "lane":
        sc.events = []
        env = ReplayEnv(sc, config={"ego_path": "lane"})
        env.reset(seed=0)
        for _ in range(env.n_steps):
            *_, info = env.step(np.array([-0.05], np.float32))
        assert info["ego_lane"] == 0


def test_info_is_exactly_the_typed_record_and_a_missing_key_is_an_error():
    env = gymnasium.make("vid2sim/Replay-v0", scenario=braking_lead_scenario())
    _, info = env.reset(seed=0)
    assert set(info) == {f.name for f in dataclasses.fields(StepInfo)}
    assert StepInfo.of(info).to_dict() == info
    renamed = {("gap" if k == "gap_m" else k): v for k, v in info.items()}
    with pytest.raises(KeyError, match="gap_m"):
        StepInfo.of(renamed)
    # a policy reading a renamed key fails at once instead of never braking
    ttc_gone = {k: v for k, v in info.items() if k != "ttc_s"}
    with pytest.raises(KeyError, match="ttc_s"):
        AebPolicy()(np.zeros((1, 1)), ttc_gone)
    env.close()
