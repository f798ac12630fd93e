"""Assembly -> environment -> OpenSCENARIO on a camera-relative scenario (no GPS: ego at 0 m/s on
an assumed straight road), the default of `vid2sim build` without --gps."""

from __future__ import annotations

import math

import numpy as np

from tests.export.test_assemble import CAMERA, box, ego_track
from vid2sim.adas.policies import AccPolicy, AebPolicy, run_episode
from vid2sim.core.scenario import Source
from vid2sim.export.highway import ReplayEnv
from vid2sim.export.openscenario import write_openscenario


def _camera_relative():
    from vid2sim.export.assemble import assemble_scenario

    ego = ego_track(speed_mps=0.0, duration_s=8.0)
    rows = ([box(t, 1, 15.0, 0.0) for t in np.arange(0.0, 8.05, 0.1)]
            + [box(t, 2, 25.0 - 2.0 * t, 3.5, "truck") for t in np.arange(1.0, 6.0, 0.1)])
    return assemble_scenario(ego, [], rows, CAMERA, source=Source())[0]


def test_camera_relative_scenario_replays_and_exports(tmp_path):
    sc = _camera_relative()
    env = ReplayEnv(sc, ego_mode="log")
    infos = run_episode(env, lambda obs, info: np.zeros(1, np.float32), seed=0)
    assert infos[-1]["truncated"] and not any(i["terminated"] for i in infos)
    # the stopped lead, rear 15 m ahead of the camera (= ego centre): its centre is at
    # 15 + 2.25 m, so the bumper gap is 17.25 - 2.25 - 2.25 = 12.75 m
    assert infos[10]["lead_id"] == "1"
    assert abs(infos[10]["gap_m"] - 12.75) < 1e-6
    # the truck in the left lane approaches the stopped ego, i.e. it drives west (towards us)
    truck = next(a for a in sc.actors if a.id == "2")
    assert abs(abs(float(truck.trajectory.state_at(3.0)["heading"])) - math.pi) < 1e-6

    # the policy ego (ACC + AEB) starts, closes in on the stopped lead and stops short of it
    env = ReplayEnv(sc)
    infos = run_episode(env, AebPolicy(base=AccPolicy(desired_speed_mps=10.0)), seed=0)
    assert not any(i["crashed"] for i in infos)
    assert max(i["ego_speed_mps"] for i in infos) > 1.0
    assert 0.5 < infos[-1]["gap_m"] < 12.75

    xosc, xodr = write_openscenario(sc, tmp_path)
    assert xosc.exists() and xodr.exists()


def test_scenario_without_roads_gets_a_straight_road_everywhere(tmp_path):
    from vid2sim.samples.scenarios import straight_scenario

    sc = straight_scenario(duration_s=3.0)
    sc.roads = []
    env = ReplayEnv(sc, ego_mode="log")
    infos = run_episode(env, lambda obs, info: np.zeros(1, np.float32), seed=0)
    assert not any(i["offroad"] for i in infos)
    _, xodr = write_openscenario(sc, tmp_path)
    assert "<road " in xodr.read_text()
