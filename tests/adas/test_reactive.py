"""Reactive replay: a follower behind an ego that brakes hard at t = 2 s.

Without it the follower replays its log and drives into the ego; with it the follower leaves
its log for IDM as soon as the simulated ego is too close ahead of it (it was not in the log)
and stops behind the ego.
"""

from __future__ import annotations

import csv

import numpy as np
import pytest

from vid2sim.adas.episode import run_episode
from vid2sim.adas.registry import parse_policy
from vid2sim.cli import main
from vid2sim.core.scenario import save
from vid2sim.export.highway import HandoverRule, ReactiveVehicle, ReplayEnv
from vid2sim.export.highway.vehicles import conflict
from vid2sim.samples.scenarios import follower_scenario

BRAKE = np.array([-1.0], np.float32)  # -8 m/s^2
COAST = np.zeros(1, np.float32)

POLICY_FILE = '''
"""Brake as hard as possible from t = 2 s on (the observation's ego row starts with t_s)."""


def policy(observation, info):
    return [-1.0] if observation[0][0] >= 2.0 - 1e-6 else [0.0]
'''


def _drive(env) -> list[dict]:
    _, info = env.reset(seed=0)
    infos = [info]
    while True:
        action = BRAKE if info["t_s"] >= 2.0 - 1e-6 else COAST
        _, _, terminated, truncated, info = env.step(action)
        infos.append(info)
        if terminated or truncated:
            return infos


def test_without_reactive_replay_the_follower_drives_into_the_ego():
    env = ReplayEnv(follower_scenario())
    infos = _drive(env)
    assert infos[-1]["crashed"] and infos[-1]["collision_with"] == "follower"
    # 10.5 m gap, ego stops from 10 m/s at 8 m/s^2 (6.25 m), log at 10 m/s: contact at 3.68 s
    assert infos[-1]["t_s"] == pytest.approx(3.7, abs=0.15)
    assert env.handovers == []


@pytest.mark.parametrize("lanes", [1, 2])
def test_with_reactive_replay_the_follower_hands_over(lanes):
    env = ReplayEnv(follower_scenario(lanes=lanes), config={"reactive": True})
    infos = _drive(env)
    assert not any(i["crashed"] for i in infos)
    assert infos[-1]["t_s"] == pytest.approx(8.0)  # ran to the end
    assert len(env.handovers) == 1 and infos[-1]["handovers"] == 1
    hand = env.handovers[0]
    assert hand.actor_id == "follower" and hand.reason == "ttc"
    # TTC = (10.5 - 4 tau^2) / (8 tau) falls below 3 s at tau = 0.41 s after the braking
    assert hand.t_s == pytest.approx(2.41, abs=0.1)
    follower = next(v for v in env.road.vehicles if getattr(v, "vehicle_id", "") == "follower")
    assert isinstance(follower, ReactiveVehicle)
    states = {s.id: s for s in env.vehicle_states()}
    ego, fol = states["ego"], states["follower"]
    if lanes == 1:  # nowhere to go: IDM stops it behind the stopped ego
        assert follower.speed < 0.5
        assert 0.5 < ego.x_m - fol.x_m - (ego.length_m + fol.length_m) / 2 < 10.5
    else:  # MOBIL: the left lane is free, so it changes lane and drives past
        assert fol.y_m == pytest.approx(1.75, abs=0.3) and fol.x_m > ego.x_m


def test_log_replay_never_hands_over():
    env = ReplayEnv(follower_scenario(), ego_mode="log", config={"reactive": True})
    env.reset(seed=0)
    for _ in range(env.n_steps):
        env.step(COAST)
    assert env.handovers == []
    r = run_episode(follower_scenario(), parse_policy("log"), reactive=True)
    assert r.handovers == [] and not r.metrics.collision


def test_conflict_rule_known_answers():
    rule = HandoverRule()
    assert conflict(1.5, 0.0, 10.0, rule) == "gap"
    assert conflict(4.0, 0.0, 10.0, rule) == "headway"  # 0.4 s < 0.5 s
    assert conflict(20.0, 8.0, 10.0, rule) == "ttc"  # 2.5 s < 3 s
    assert conflict(20.0, 5.0, 10.0, rule) is None  # 4 s
    assert conflict(20.0, -3.0, 10.0, rule) is None  # opening


@pytest.mark.parametrize("reactive", [False, True])
def test_cli_reactive_flag(tmp_path, reactive, monkeypatch):
    (tmp_path / "brake_at_two.py").write_text(POLICY_FILE)
    monkeypatch.chdir(tmp_path)
    path = tmp_path / "follower.json"
    save(follower_scenario(), path)
    out = tmp_path / "out"
    args = ["-q", "test-policy", str(path), "--policy", "brake_at_two:policy", "--out", str(out)]
    assert main([*args, "--reactive"] if reactive else args) == 0
    with open(out / "results.csv", newline="") as fh:
        row = next(csv.DictReader(fh))
    assert row["collision"] == ("0" if reactive else "1")
    assert row["handovers"] == ("1" if reactive else "0")
    if reactive:
        assert row["handover_times_s"].startswith("follower@2.")
    else:
        assert row["terminated_by"] == "collision with follower"
