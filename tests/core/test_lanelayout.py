"""The road cross-section record: lane edges and centres, lanes at offsets, the JSON form
and its validation, and old scenario files without a cross-section."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.base.errors import ScenarioError
from vid2sim.core import scenario as scenario_io
from vid2sim.core.lanelayout import (
    BACKWARD,
    DIRECTIONS,
    DRIVING,
    FORWARD,
    LANE_TYPES,
    PARKING,
    RAIL,
    CrossSection,
    LaneSpec,
    uniform_cross_section,
    validate_cross_section,
)
from vid2sim.core.scenario import LANE_WIDTH_RANGE_M

#: two forward lanes right of the centerline, one oncoming, a parking strip on the left and
#: a track bed on the right (the KITTI raw 0001 street's kind of section)
STREET = CrossSection(-9.0, (
    LaneSpec(RAIL, FORWARD, 3.0), LaneSpec("border", FORWARD, 0.5),
    LaneSpec(DRIVING, FORWARD, 3.0), LaneSpec(DRIVING, FORWARD, 2.5),
    LaneSpec(DRIVING, BACKWARD, 3.0), LaneSpec(PARKING, BACKWARD, 2.0)))


def test_edges_and_centres_known_answer():
    np.testing.assert_allclose(STREET.edges_m, [-9.0, -6.0, -5.5, -2.5, 0.0, 3.0, 5.0])
    np.testing.assert_allclose(STREET.centres_m, [-7.5, -5.75, -4.0, -1.25, 1.5, 4.0])
    assert STREET.width_m == pytest.approx(14.0)
    assert STREET.n_driving == 3
    assert STREET.forward_driving() == [2, 3]
    assert STREET.indices(DRIVING, BACKWARD) == [4]


def test_lane_at_known_answer():
    got = STREET.lane_at(np.array([-10.0, -8.0, -5.6, -1.0, 0.5, 4.9, 5.1, np.nan]))
    np.testing.assert_array_equal(got, [-1, 0, 1, 3, 4, 5, -1, -1])


def test_uniform_section_is_centred():
    sec = uniform_cross_section(3, 3.5)
    np.testing.assert_allclose(sec.edges_m, [-5.25, -1.75, 1.75, 5.25])
    assert sec.forward_driving() == [0, 1, 2]


@st.composite
def sections(draw):
    n = draw(st.integers(1, 8))
    lanes = []
    for _ in range(n):
        kind = draw(st.sampled_from(LANE_TYPES))
        lo, hi = LANE_WIDTH_RANGE_M if kind == DRIVING else (0.1, 12.0)
        lanes.append(LaneSpec(kind, draw(st.sampled_from(DIRECTIONS)),
                              round(draw(st.floats(lo, min(hi, 6.0))), 4)))
    if not any(lane.type == DRIVING for lane in lanes):
        lanes[0] = LaneSpec(DRIVING, FORWARD, 3.0)
    edge = round(draw(st.floats(-30.0, 0.0)), 4)
    return CrossSection(edge, tuple(lanes))


@settings(max_examples=80, deadline=None)
@given(sections())
def test_json_round_trip_and_validation(sec):
    d = sec.to_json()
    validate_cross_section(d, "cross_section", None, sec.n_driving, LANE_WIDTH_RANGE_M)
    back = CrossSection.from_json(d)
    assert back == sec
    # lanes touch: each lane's centre lies inside it and lane_at finds it there
    np.testing.assert_array_equal(back.lane_at(back.centres_m), np.arange(len(back)))


@settings(max_examples=60, deadline=None)
@given(sections(), st.data())
def test_bad_values_raise_scenario_error(sec, data):
    d = copy.deepcopy(sec.to_json())
    k = data.draw(st.integers(0, len(sec) - 1))
    spoil = data.draw(st.sampled_from(["type", "direction", "width_nan", "width_neg",
                                       "width_huge", "edge", "edge_inf", "lanes", "count"]))
    if spoil == "type":
        d["lanes"][k]["type"] = data.draw(st.text(max_size=8).filter(
            lambda s: s not in LANE_TYPES))
    elif spoil == "direction":
        d["lanes"][k]["direction"] = "sideways"
    elif spoil == "width_nan":
        d["lanes"][k]["width_m"] = math.nan
    elif spoil == "width_neg":
        d["lanes"][k]["width_m"] = -1.0
    elif spoil == "width_huge":
        d["lanes"][k]["width_m"] = 50.0
    elif spoil == "edge":
        d["right_edge_m"] = "left"
    elif spoil == "edge_inf":
        d["right_edge_m"] = math.inf
    elif spoil == "lanes":
        d["lanes"] = []
    else:
        d["lanes"].append({"type": DRIVING, "direction": FORWARD, "width_m": 3.0})
    with pytest.raises(ScenarioError):
        validate_cross_section(d, "cross_section", None, sec.n_driving, LANE_WIDTH_RANGE_M)


def _scenario_dict():
    t = np.arange(0.0, 3.0, 0.5)
    traj = [{"t": float(x), "x": float(10 * x), "y": 0.0, "heading": 0.0, "speed": 10.0}
            for x in t]
    return {
        "schema": scenario_io.SCHEMA, "version": scenario_io.VERSION,
        "origin": {"lat": 49.0, "lon": 8.4, "alt": 110.0},
        "roads": [{"id": "road0", "name": "", "highway": "", "source": "trajectory",
                   "osm_way_ids": [], "lanes": 1, "lane_width_m": 3.5,
                   "centerline": [[-10.0, 0.0], [60.0, 0.0]]}],
        "ego": {"length_m": 4.5, "width_m": 1.8, "height_m": 1.5, "trajectory": traj},
        "actors": [{"id": "1", "category": "car", "length_m": 4.5, "width_m": 1.8,
                    "height_m": 1.5, "trajectory": traj}],
        "camera": {}, "source": {},
    }


def test_scenario_without_cross_section_loads_as_centred_lanes():
    sc = scenario_io.from_json(_scenario_dict())
    assert sc.roads[0].cross_section is None
    np.testing.assert_allclose(sc.roads[0].layout().edges_m, [-1.75, 1.75])
    assert not sc.actors[0].static


def test_scenario_with_cross_section_round_trips(tmp_path):
    d = _scenario_dict()
    d["roads"][0]["lanes"] = 3
    d["roads"][0]["cross_section"] = STREET.to_json()
    d["actors"][0]["static"] = True
    scenario_io.validate(d)
    sc = scenario_io.from_json(d)
    assert sc.roads[0].cross_section == STREET and sc.actors[0].static
    scenario_io.save(sc, tmp_path / "s.json")
    back = scenario_io.load(tmp_path / "s.json")
    assert back.roads[0].cross_section == STREET and back.actors[0].static


@pytest.mark.parametrize("spoil", ["driving_count", "static_type"])
def test_scenario_with_bad_cross_section_is_refused(spoil):
    d = _scenario_dict()
    d["roads"][0]["cross_section"] = STREET.to_json()  # 3 driving lanes, road says 1
    if spoil == "static_type":
        d["roads"][0]["lanes"] = 3
        d["actors"][0]["static"] = "yes"
    with pytest.raises(ScenarioError):
        scenario_io.validate(d)
