"""A street's cross-section in the exports: the gym network's lanes per type and direction,
and OpenDRIVE lane types (schema and, where installed, the ASAM quality checkers)."""

from __future__ import annotations

import os
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import scenariogeneration
import xmlschema

from vid2sim.core.lanelayout import BACKWARD, DRIVING, FORWARD
from vid2sim.export.highway.network import build_network, lane_centerlines_enu
from vid2sim.export.opendrive import centre_split
from vid2sim.export.openscenario import write_openscenario
from vid2sim.samples.scenarios import STREET_SECTION, street_scenario

SCHEMAS = Path(scenariogeneration.__file__).resolve().parents[1] / "schemas"


def test_network_has_an_edge_per_lane_kind():
    road = street_scenario().roads[0]
    net = build_network([road])
    forward = net.graph["road0:start"]["road0:end"]
    assert len(forward) == 2 and all(ln.lane_type == DRIVING for ln in forward)
    back = net.graph["road0:back:start"]["road0:back:end"]
    assert len(back) == 1 and back[0].direction == BACKWARD
    others = {ln.lane_type for a in net.graph for b in net.graph[a] for ln in net.graph[a][b]
              if not a.startswith(("road0:start", "road0:back"))}
    assert others == {"rail", "border", "parking"}
    # the forward lanes' centres: 3.25 m and 6.5 m... right of the centre line
    lines = lane_centerlines_enu(road, extension_m=0.0)
    np.testing.assert_allclose(lines[0][0], [0.0, -8.0 + 4.5 + 1.625], atol=1e-6)
    np.testing.assert_allclose(lines[1][0], [0.0, -8.0 + 4.5 + 3.25 + 1.625], atol=1e-6)


def test_opendrive_centre_lane_splits_the_directions():
    assert centre_split(STREET_SECTION) == 4  # rail, border, two forward lanes on the right


@pytest.fixture(scope="module")
def street_export(tmp_path_factory):
    out = tmp_path_factory.mktemp("street")
    write_openscenario(street_scenario(), out)
    return out


def test_opendrive_lane_types_and_schema(street_export):
    xodr = street_export / "road.xodr"
    schema = SCHEMAS / "opendrive_17_core.xsd"
    if not schema.exists():
        pytest.skip(f"scenariogeneration's schema not installed at {SCHEMAS}")
    xmlschema.XMLSchema(str(schema)).validate(str(xodr))
    road = ET.parse(xodr).getroot().find("road")
    section = road.find("lanes/laneSection")
    right = sorted(((int(ln.get("id")), ln.get("type")) for ln in section.find("right")),
                   reverse=True)
    left = sorted((int(ln.get("id")), ln.get("type")) for ln in section.find("left"))
    assert right == [(-1, "driving"), (-2, "driving"), (-3, "border"), (-4, "rail")]
    assert left == [(1, "driving"), (2, "parking")]
    widths = {int(ln.get("id")): float(ln.find("width").get("a"))
              for side in ("right", "left") for ln in section.find(side)}
    assert widths[-4] == pytest.approx(3.0) and widths[2] == pytest.approx(2.3)
    # the centre lane sits on the boundary left of the forward lanes
    offset = road.find("lanes/laneOffset")
    assert float(offset.get("a")) == pytest.approx(-8.0 + 3.0 + 1.5 + 6.5)
    # the tram is a tram in OpenSCENARIO
    xosc = ET.parse(street_export / "scenario.xosc").getroot()
    cats = {v.get("name"): v.get("vehicleCategory") for v in xosc.iter("Vehicle")}
    assert "tram" in cats.values()


def test_asam_quality_checker_passes_with_lane_types(street_export):
    venv = Path(os.environ.get("VID2SIM_QC_VENV", "/tmp/vid2sim-qcvenv"))
    if not (venv / "bin" / "qc_opendrive").exists():
        pytest.skip(f"no ASAM checker venv at {venv} (create one with .ci/asam_qc.sh DIR {venv})")
    script = Path(__file__).resolve().parents[2] / ".ci" / "asam_qc.sh"
    run = subprocess.run(["bash", str(script), str(street_export), str(venv)],
                         capture_output=True, text=True, timeout=600, check=False)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "0 issues" in run.stdout


def test_forward_lane_numbers_count_forward_driving_lanes():
    assert STREET_SECTION.forward_driving() == [2, 3]
    assert [STREET_SECTION.lanes[k].direction for k in STREET_SECTION.forward_driving()] == \
        [FORWARD, FORWARD]
