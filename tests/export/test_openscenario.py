"""OpenSCENARIO 1.2 / OpenDRIVE 1.8 export: reference-line fit, schema validity, content."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import scenariogeneration
import xmlschema
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.cli import main
from vid2sim.core.enu import EnuFrame
from vid2sim.core.scenario import save
from vid2sim.export.openscenario import fit_reference_line, write_openscenario
from vid2sim.samples.scenarios import (
    ORIGIN,
    left_turn_centerline,
    left_turn_scenario,
    straight_scenario,
)

# scenariogeneration installs its XSDs in site-packages/schemas/
SCHEMAS = Path(scenariogeneration.__file__).resolve().parents[1] / "schemas"


def _schema(name: str) -> xmlschema.XMLSchema:
    path = SCHEMAS / name
    if not path.exists():
        pytest.skip(f"scenariogeneration's schema {name} not installed at {SCHEMAS}")
    return xmlschema.XMLSchema(str(path))


def test_fit_straight_line_is_one_line():
    line, err = fit_reference_line(np.array([[0.0, 0.0], [100.0, 100.0]]))
    assert err < 1e-6
    assert [p[0] for p in line.pieces()] == ["line"]
    assert line.heading0_rad == pytest.approx(math.pi / 4)
    assert line.length_m == pytest.approx(100.0 * math.sqrt(2))


def test_fit_circle_is_one_arc_of_the_right_sign():
    r = 60.0
    th = np.linspace(0.0, math.pi / 2, 200)
    pts = np.column_stack((r * np.sin(th), r - r * np.cos(th)))  # counter-clockwise = left
    line, err = fit_reference_line(pts)
    assert err < 0.05
    assert all(k == pytest.approx(1.0 / r, rel=0.02) for _, k, _, _ in line.pieces())


def test_fit_left_turn_within_tolerance():
    line, err = fit_reference_line(left_turn_centerline())
    assert err <= 0.2
    kinds = {p[0] for p in line.pieces()}
    assert "spiral" in kinds or "arc" in kinds


@settings(max_examples=15, deadline=None)
@given(st.floats(25.0, 400.0), st.floats(-math.pi, math.pi), st.floats(20.0, 200.0))
def test_fit_arcs_of_any_radius_and_heading(radius_m, heading_rad, length_m):
    s = np.linspace(0.0, length_m, int(length_m) + 1)
    h = heading_rad + s / radius_m
    pts = np.column_stack((radius_m * (np.sin(h) - math.sin(heading_rad)),
                           -radius_m * (np.cos(h) - math.cos(heading_rad))))
    line, err = fit_reference_line(pts)
    assert err <= 0.2
    end = line.sample(np.array([line.length_m]))[0]
    assert np.linalg.norm(end - pts[-1]) <= 0.2


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> tuple[Path, Path]:
    return write_openscenario(left_turn_scenario(), tmp_path_factory.mktemp("osc"))


def test_xosc_validates_against_openscenario_1_2(exported):
    xosc, _ = exported
    _schema("OpenSCENARIO_1_2.xsd").validate(str(xosc))
    header = ET.parse(xosc).getroot().find("FileHeader")
    assert (header.get("revMajor"), header.get("revMinor")) == ("1", "2")


def test_xodr_validates_against_shipped_opendrive_schema(exported):
    _, xodr = exported
    _schema("opendrive_17_core.xsd").validate(str(xodr))
    root = ET.parse(xodr).getroot()
    header = root.find("header")
    assert (header.get("revMajor"), header.get("revMinor")) == ("1", "8")
    assert header.find("geoReference").text == EnuFrame(ORIGIN).proj_string()


def test_xodr_road_geometry_follows_the_centerline(exported):
    _, xodr = exported
    road = ET.parse(xodr).getroot().find("road")
    geoms = road.find("planView").findall("geometry")
    first, last = geoms[0], geoms[-1]
    assert float(first.get("x")) == pytest.approx(0.0, abs=1e-6)
    assert float(first.get("hdg")) == pytest.approx(0.0, abs=0.01)
    # the final geometry heads north (a left turn), ending near the centerline's end
    assert float(last.get("hdg")) == pytest.approx(math.pi / 2, abs=0.02)
    assert float(road.get("length")) == pytest.approx(80 + 20 * math.pi + 80, abs=0.5)
    lanes = road.find("lanes")
    right = lanes.find("laneSection").find("right").findall("lane")
    assert sorted(int(lane.get("id")) for lane in right) == [-2, -1]
    assert float(lanes.find("laneOffset").get("a")) == pytest.approx(3.5)
    assert road.find("elevationProfile").find("elevation") is not None


def test_xosc_vehicles_and_timed_trajectories(exported):
    xosc, _ = exported
    root = ET.parse(xosc).getroot()
    names = [o.get("name") for o in root.iter("ScenarioObject")]
    assert names == ["Ego", "actor_7", "actor_9"]
    truck = next(v for v in root.iter("Vehicle") if v.get("name") == "actor_9")
    dims = truck.find("BoundingBox").find("Dimensions")
    assert (float(dims.get("length")), float(dims.get("width"))) == (8.0, 2.5)
    sc = left_turn_scenario()
    polylines = {mg.find("Actors").find("EntityRef").get("entityRef"): mg.find(".//Polyline")
                 for mg in root.iter("ManeuverGroup")}
    truck_traj = sc.actors[1].trajectory
    vertices = polylines["actor_9"].findall("Vertex")
    assert len(vertices) == len(truck_traj)
    assert float(vertices[0].get("time")) == pytest.approx(truck_traj.t[0])
    pos = vertices[10].find("Position").find("WorldPosition")
    assert float(pos.get("x")) == pytest.approx(truck_traj.x[10], abs=1e-6)
    assert float(pos.get("y")) == pytest.approx(truck_traj.y[10], abs=1e-6)
    # the truck appears at 2 s: hidden in Init, shown by an event
    assert any(e.get("name") == "actor_9_appear" for e in root.iter("Event"))
    stop = root.find("Storyboard").find("StopTrigger").find(".//SimulationTimeCondition")
    assert float(stop.get("value")) == pytest.approx(sc.duration_s)


def test_cli_export_openscenario_and_bad_input(tmp_path, capsys):
    path = tmp_path / "scenario.json"
    save(straight_scenario(), path)
    assert main(["export", str(path), "--format", "openscenario", "--out",
                 str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "scenario.xosc").exists()
    assert (tmp_path / "out" / "road.xodr").exists()
    assert not [p for p in (tmp_path / "out").iterdir() if p.name.startswith(".")]
    bad = tmp_path / "bad.json"
    bad.write_text('{"schema": "vid2sim.scenario", "version": 1, "origin": {"lat": 0}}')
    assert main(["export", str(bad), "--format", "openscenario", "--out",
                 str(tmp_path / "o2")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "origin.lon" in err[0]


def test_cli_export_highway_env(tmp_path):
    path = tmp_path / "scenario.json"
    save(straight_scenario(duration_s=4.0), path)
    out = tmp_path / "hw"
    assert main(["export", str(path), "--format", "highway-env", "--out", str(out)]) == 0
    assert (out / "scenario.json").read_text() == path.read_text()
    assert (out / "replay.py").exists()
    assert (out / "preview.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_vehicle_seen_once_still_exports_valid_xosc(tmp_path):
    from vid2sim.core.scenario import Trajectory

    sc = straight_scenario(duration_s=3.0)
    sc.actors[0].trajectory = Trajectory([1.0], [40.0], [-1.75], [0.0], [0.0])
    xosc, _ = write_openscenario(sc, tmp_path)
    _schema("OpenSCENARIO_1_2.xsd").validate(str(xosc))


def test_fit_refines_only_where_needed_and_jacobian_is_exact():
    from vid2sim.export.openscenario import _ClothoidModel

    knots = np.linspace(0.0, 100.0, 6)
    model = _ClothoidModel(1.0, 2.0, knots, np.linspace(0.0, 100.0, 51))
    p = np.r_[0.3, np.random.default_rng(0).normal(0.0, 0.01, 6)]
    eps = 1e-7
    numeric = np.column_stack([
        ((model.positions(p + eps * e) - model.positions(p - eps * e)) / (2 * eps)).ravel()
        for e in np.eye(7)])
    np.testing.assert_allclose(model.jacobian(p), numeric, atol=1e-5)
    # 1 km straight then a 30 m-radius quarter turn: only the turn gets short pieces
    th = np.linspace(0.0, math.pi / 2, 48)[1:]
    pts = np.vstack((np.column_stack((np.linspace(0, 1000, 1001), np.zeros(1001))),
                     np.column_stack((1000 + 30 * np.sin(th), 30 - 30 * np.cos(th)))))
    line, err = fit_reference_line(pts)
    assert err <= 0.2
    lengths = np.diff(line.knots_s_m)
    assert lengths.max() >= 19.0 and len(lengths) < 70


def test_asam_quality_checker_passes(tmp_path):
    """Runs .ci/asam_qc.sh when a checker venv exists (it pins old numpy/lxml, so it is never
    installed into the project's environment by the tests)."""
    import os
    import subprocess

    venv = Path(os.environ.get("VID2SIM_QC_VENV", "/tmp/vid2sim-qcvenv"))
    if not (venv / "bin" / "qc_opendrive").exists():
        pytest.skip(f"no ASAM checker venv at {venv} (create one with .ci/asam_qc.sh DIR {venv})")
    write_openscenario(left_turn_scenario(), tmp_path)
    script = Path(__file__).resolve().parents[2] / ".ci" / "asam_qc.sh"
    run = subprocess.run(["bash", str(script), str(tmp_path), str(venv)], capture_output=True,
                         text=True, timeout=600, check=False)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "xodrBundle" in run.stdout and "xoscBundle" in run.stdout


def test_same_scenario_gives_byte_identical_files(tmp_path):
    sc = left_turn_scenario()
    a = write_openscenario(sc, tmp_path / "a")
    b = write_openscenario(sc, tmp_path / "b")
    for pa, pb in zip(a, b, strict=True):
        assert pa.read_bytes() == pb.read_bytes()
    _schema("OpenSCENARIO_1_2.xsd").validate(str(a[0]))  # the fixed date is a valid dateTime


def test_declares_the_variation_parameters(tmp_path):
    """Every scenario.xosc declares test-policy's --vary parameters (neutral values: the
    recorded scenario), a variant's file its own values; the schema accepts both."""
    from vid2sim.adas.variations import PARAMETERS
    from vid2sim.export.openscenario import VARIATION_PARAMETERS

    def declared(path):
        root = ET.parse(path).getroot()
        return {p.get("name"): (p.get("parameterType"), float(p.get("value")),
                                [(c.get("rule"), float(c.get("value")))
                                 for c in p.iter("ValueConstraint")])
                for p in root.find("ParameterDeclarations")}

    xosc, _ = write_openscenario(left_turn_scenario(), tmp_path / "base")
    base = declared(xosc)
    assert set(base) == {"lead_decel", "gap", "ego_speed", "cut_in"} == set(VARIATION_PARAMETERS)
    for name, (kind, value, _) in base.items():
        assert kind == "double" and value == PARAMETERS[name][1]
    assert base["gap"][2] == [("greaterThan", 0.0)]
    assert base["lead_decel"][2] == [("greaterOrEqual", 0.0)]
    variant, _ = write_openscenario(left_turn_scenario(), tmp_path / "variant",
                                    parameters={"gap": 0.8, "noise": 1.0})
    values = {k: v[1] for k, v in declared(variant).items()}
    assert values == {"lead_decel": 1.0, "gap": 0.8, "ego_speed": 0.0, "cut_in": 0.0,
                      "noise": 1.0}
    _schema("OpenSCENARIO_1_2.xsd").validate(str(variant))
