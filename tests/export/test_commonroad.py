"""CommonRoad export: geometry with known answers, the file read back with commonroad-io,
the demo and KITTI raw 0001 builds, bad input."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import shapely
from hypothesis import given
from hypothesis import strategies as st

from vid2sim.base.errors import ImpossibleValueError, InconsistentInputError
from vid2sim.cli import main
from vid2sim.core.lanelayout import CrossSection, LaneSpec
from vid2sim.core.polyline import signed_offsets
from vid2sim.core.scenario import Road, save
from vid2sim.export.commonroad import (
    OBSTACLE_TYPES,
    TimeGrid,
    build_commonroad,
    offset_polyline,
    time_grid,
    write_commonroad,
)
from vid2sim.samples.scenarios import braking_lead_scenario, street_scenario

cr_reader = pytest.importorskip(
    "commonroad.common.reader.file_reader_xml",
    reason="commonroad-io is not installed (docs/commonroad.md: pip install --no-deps ...)")


def _read(path: Path):
    """The file as commonroad-io reads it: ``CommonRoadFileReader.open`` of an XML file is
    this XML reader (the facade itself imports commonroad-io's protobuf modules, see
    :func:`test_common_road_file_reader_reads_it`)."""
    return cr_reader.XMLFileReader(str(path)).open()


# --------------------------------------------------------------------------- geometry


def test_offset_of_a_straight_line_is_parallel():
    line = np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]])
    np.testing.assert_allclose(offset_polyline(line, 1.5), line + [0.0, 1.5])
    np.testing.assert_allclose(offset_polyline(line, -2.0), line - [0.0, 2.0])


@given(st.floats(20.0, 300.0), st.floats(-6.0, 6.0), st.floats(-math.pi, math.pi))
def test_offset_of_an_arc_is_the_concentric_arc(radius_m, offset_m, heading_rad):
    """A left arc of radius R offset d to the left is the arc of radius R - d (every vertex)."""
    th = heading_rad + np.linspace(0.0, 1.0, 60)
    centre = np.array([-radius_m * math.sin(heading_rad), radius_m * math.cos(heading_rad)])
    pts = centre + radius_m * np.column_stack((np.sin(th), -np.cos(th)))
    out = offset_polyline(pts, offset_m)
    assert out.shape == pts.shape
    # mitred vertices lie on the chords' offset lines: within the sagitta of the chord
    sagitta = radius_m * (1 - math.cos(0.5 / 59))
    np.testing.assert_allclose(np.hypot(*(out - centre).T), radius_m - offset_m,
                               atol=sagitta + 1e-9)


def test_time_grid_is_the_ego_rate_and_spans_are_whole_steps():
    sc = braking_lead_scenario(duration_s=12.0, dt_s=0.1)
    grid = time_grid(sc)
    assert grid == TimeGrid(0.0, 0.1, 121)
    late = replace(sc.ego.trajectory, t=sc.ego.trajectory.t + 0.03)
    steps = grid.steps_within(late)
    assert steps[0] == 1 and steps[-1] == 120  # 0.1 is the first step inside 0.03..12.03
    once = replace(late, t=late.t[:1] + 5.0, x=late.x[:1], y=late.y[:1],
                   heading=late.heading[:1], speed=late.speed[:1])
    assert list(grid.steps_within(once)) == [50]  # seen once: the nearest step


# --------------------------------------------------------------------------- the file


@pytest.fixture(scope="module")
def street(tmp_path_factory):
    sc = street_scenario()
    out = tmp_path_factory.mktemp("cr")
    write_commonroad(sc, out, ego_as_obstacle=True)
    return sc, out, *_read(out / "scenario.xml")


def test_lanelets_are_the_cross_section_with_types_neighbours_and_directions(street):
    sc, _, cr, _ = street
    section = sc.roads[0].layout()
    lanelets = sorted(cr.lanelet_network.lanelets, key=lambda ln: ln.lanelet_id)
    assert len(lanelets) == len(section.lanes) == 6
    types = [{t.value for t in ln.lanelet_type} for ln in lanelets]
    assert types == [{"restricted"}, {"border"}, {"unknown"}, {"unknown"}, {"unknown"},
                     {"parking"}]
    assert {u.value for u in lanelets[0].user_one_way} == {"train"}
    ids = [ln.lanelet_id for ln in lanelets]
    # forward driving lanes 2 and 3: neighbours right and left, same direction between them
    assert (lanelets[2].adj_right, lanelets[2].adj_left) == (ids[1], ids[3])
    assert lanelets[2].adj_left_same_direction and lanelets[3].adj_left == ids[4]
    assert lanelets[3].adj_left_same_direction is False
    # the oncoming lane runs the other way: its left neighbour is the road's right one
    assert (lanelets[4].adj_left, lanelets[4].adj_right) == (ids[3], ids[5])
    assert lanelets[2].line_marking_left_vertices.value == "dashed"
    assert lanelets[3].line_marking_left_vertices.value == "solid"
    # each lanelet's width and place: its centre line at the lane's offset, in its direction
    line = sc.roads[0].centerline
    for k, ln in enumerate(lanelets):
        s, d = signed_offsets(line, ln.center_vertices[5:-5])
        np.testing.assert_allclose(d, section.centres_m[k], atol=0.02)
        forward = section.lanes[k].direction == "forward"
        assert (np.diff(s) > 0).all() == forward and (np.diff(s) < 0).all() != forward
        width = np.hypot(*(ln.left_vertices - ln.right_vertices).T)
        np.testing.assert_allclose(width[5:-5], section.lanes[k].width_m, rtol=0.02)


def test_every_actor_is_an_obstacle_where_the_scenario_has_it(street):
    sc, out, cr, _ = street
    ids = json.loads((out / "ids.json").read_text())
    assert len(cr.dynamic_obstacles) == len(sc.actors) + 1 and not cr.static_obstacles
    for actor in sc.actors:
        ob = cr.obstacle_by_id(ids["actors"][actor.id])
        assert ob.obstacle_type.value == OBSTACLE_TYPES[actor.category]
        assert (ob.obstacle_shape.length, ob.obstacle_shape.width) == (actor.length_m,
                                                                        actor.width_m)
        _assert_follows(ob, actor.trajectory, 0.1)
    assert cr.obstacle_by_id(ids["actors"]["tram"]).obstacle_type.value == "train"
    _assert_follows(cr.obstacle_by_id(ids["ego"]), sc.ego.trajectory, 0.1)


def _assert_follows(obstacle, traj, dt_s: float) -> None:
    """Every state of the obstacle within 0.1 m of the log at its time (all steps)."""
    states = [obstacle.initial_state, *(obstacle.prediction.trajectory.state_list
                                        if obstacle.prediction else [])]
    steps = [s.time_step for s in states]
    assert steps == list(range(steps[0], steps[0] + len(steps)))
    t = np.array(steps) * dt_s
    assert t[0] >= traj.t[0] - 1e-6 and t[-1] <= traj.t[-1] + 1e-6
    want = traj.state_at(t)
    got = np.array([s.position for s in states])
    err = np.hypot(got[:, 0] - want["x"], got[:, 1] - want["y"])
    assert err.max() <= 0.1
    np.testing.assert_allclose([s.velocity for s in states], want["speed"], atol=1e-3)


def test_planning_problem_starts_at_the_log_and_aims_at_its_end(street):
    sc, _, cr, problems = street
    (pp,) = problems.planning_problem_dict.values()
    log = sc.ego.trajectory
    assert pp.initial_state.time_step == 0
    np.testing.assert_allclose(pp.initial_state.position, [log.x[0], log.y[0]], atol=1e-4)
    assert pp.initial_state.velocity == pytest.approx(log.speed[0])
    (goal,) = pp.goal.state_list
    end_x, end_y = float(log.x[-1]), float(log.y[-1])
    assert goal.position.contains_point(shapely.Point(end_x, end_y))
    assert not goal.position.contains_point(shapely.Point(end_x, end_y + 4.0))  # a lane over
    assert goal.time_step.start <= round(log.t[-1] / 0.1) <= goal.time_step.end
    assert str(cr.scenario_id) == "ZAM_Vid2simScenario-1_1_T-1"
    assert {t.value for t in cr.tags} >= {"two_lane", "oncoming_traffic"}


def test_ego_is_no_obstacle_without_the_flag(tmp_path):
    sc = braking_lead_scenario()
    export = build_commonroad(sc)
    assert export.ids["ego"] is None and len(export.scenario.dynamic_obstacles) == 2


def test_same_scenario_gives_byte_identical_files(tmp_path):
    sc = street_scenario()
    write_commonroad(sc, tmp_path / "a")
    write_commonroad(sc, tmp_path / "b")
    assert (tmp_path / "a" / "scenario.xml").read_bytes() == \
        (tmp_path / "b" / "scenario.xml").read_bytes()


def test_common_road_file_reader_reads_it(street):
    """CommonRoadFileReader itself: commonroad-io's facade imports its protobuf modules,
    generated for protobuf 3.20, which the installed protobuf reads with its pure-Python
    implementation only (a separate process: the test process has protobuf loaded)."""
    sc, out, _, _ = street
    code = ("import sys; from commonroad.common.file_reader import CommonRoadFileReader; "
            "s, p = CommonRoadFileReader(sys.argv[1]).open(); "
            "print(len(s.dynamic_obstacles), len(s.lanelet_network.lanelets), "
            "len(p.planning_problem_dict))")
    env = dict(os.environ, PROTOCOL_BUFFERS_PYTHON_IMPLEMENTATION="python")
    run = subprocess.run([sys.executable, "-c", code, str(out / "scenario.xml")], env=env,
                         capture_output=True, text=True, timeout=120, check=False)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.split() == [str(len(sc.actors) + 1), "6", "1"]


# --------------------------------------------------------------------------- real builds


@pytest.mark.parametrize("build", ["demo_scenario_path", "kitti_scenario"])
def test_export_of_a_build(build, request, tmp_path):
    """The demo build and the KITTI raw 0001 build through the CLI: as many obstacles as
    actors, each within 0.1 m of scenario.json at every step, one lanelet per lane."""
    value = request.getfixturevalue(build)
    if isinstance(value, Path):
        path = value
    else:
        path = tmp_path / "scenario.json"
        save(value, path)
    from vid2sim.core import scenario as scenario_io

    sc = scenario_io.load(path)
    assert main(["export", str(path), "--format", "commonroad", "--out",
                 str(tmp_path / "cr")]) == 0
    cr, problems = _read(tmp_path / "cr" / "scenario.xml")
    ids = json.loads((tmp_path / "cr" / "ids.json").read_text())
    assert len(cr.dynamic_obstacles) == len(sc.actors) > 0
    dt = cr.dt
    assert dt == pytest.approx(float(np.median(np.diff(sc.ego.trajectory.t))))
    for actor in sc.actors:
        _assert_follows(cr.obstacle_by_id(ids["actors"][actor.id]), actor.trajectory, dt)
    assert len(cr.lanelet_network.lanelets) == sum(len(r.layout()) for r in sc.roads)
    assert len(problems.planning_problem_dict) == 1


# --------------------------------------------------------------------------- bad input


def _no_road(tmp_path) -> Path:
    sc = replace(braking_lead_scenario(), roads=[])
    save(sc, tmp_path / "scenario.json")
    return tmp_path / "scenario.json"


def _folded_lane(tmp_path) -> Path:
    """A road curving at 5 m radius with a lane 8-11 m left of its centerline: the lane's
    inner bound folds over itself."""
    th = np.linspace(0.0, 1.5, 40)
    line = np.column_stack((5.0 * np.sin(th), 5.0 - 5.0 * np.cos(th)))
    section = CrossSection(-3.0, (LaneSpec("driving", "forward", 3.0),
                                  LaneSpec("border", "forward", 8.0),
                                  LaneSpec("parking", "forward", 3.0)))
    sc = braking_lead_scenario()
    road = Road("r1", "Tight", "service", "osm", [1], 1, 3.0, line, cross_section=section)
    save(replace(sc, roads=[road]), tmp_path / "scenario.json")
    return tmp_path / "scenario.json"


@pytest.mark.parametrize(("make", "error"), [(_no_road, InconsistentInputError),
                                             (_folded_lane, ImpossibleValueError)])
def test_a_scenario_commonroad_cannot_hold_is_one_error_line(make, error, tmp_path, capsys):
    path = make(tmp_path)
    out = tmp_path / "out"
    from vid2sim.core import scenario as scenario_io

    with pytest.raises(error):
        write_commonroad(scenario_io.load(path), tmp_path / "direct")
    assert main(["export", str(path), "--format", "commonroad", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ")
    assert not out.exists() or not any(out.iterdir())


def test_without_commonroad_io_the_format_is_one_error_line(tmp_path, monkeypatch, capsys):
    path = tmp_path / "scenario.json"
    save(braking_lead_scenario(), path)
    monkeypatch.setitem(sys.modules, "commonroad.common.writer.file_writer_xml", None)
    assert main(["export", str(path), "--format", "commonroad", "--out",
                 str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "commonroad-io" in err[0]
    assert not (tmp_path / "out").exists()
