"""The road's cross-section from lines and vehicles (known answers and properties), the
OSM tags' cross-section, parked cars on their strip and vehicles held standing off the
driving lanes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.core.lanelayout import (
    BACKWARD,
    BORDER,
    DRIVING,
    FORWARD,
    PARKING,
    SHOULDER,
    CrossSection,
    LaneSpec,
)
from vid2sim.core.records import LaneBoundary, LaneObservation, LaneTrack, MarkingKind
from vid2sim.core.scenario import Actor, Trajectory
from vid2sim.export.crosssection import (
    SeenLine,
    StandingVehicle,
    infer_cross_section,
    seen_lines,
)
from vid2sim.export.scenelayout import (
    LayoutConfig,
    extend_line,
    line_frame,
    off_road_standing,
    place_static,
)
from vid2sim.geo.roads import cross_section_from_tags

SOLID, DASHED, EDGE = (MarkingKind.SOLID.value, MarkingKind.DASHED.value,
                       MarkingKind.ROAD_EDGE.value)


def _types(section: CrossSection) -> list[str]:
    return [f"{lane.type}:{lane.direction}" for lane in section.lanes]


# --------------------------------------------------------------------------- lines


def _track(lines_by_frame: list[list[tuple[float, str]]], lateral_m: list[float]) -> LaneTrack:
    """A lane track whose frames saw lines at the given offsets from the camera [m]."""
    obs = []
    for k, lines in enumerate(lines_by_frame):
        right = [LaneBoundary(y, 0.0, 0.0, kind) for y, kind in lines if y < 0]
        left = [LaneBoundary(y, 0.0, 0.0, kind) for y, kind in lines if y >= 0]
        right.sort(key=lambda b: -b.offset_m)
        left.sort(key=lambda b: b.offset_m)
        obs.append(LaneObservation(k, 0.1 * k, left=left[0] if left else None,
                                   right=right[0] if right else None,
                                   lines_left=tuple(left[1:]), lines_right=tuple(right[1:])))
    n = len(obs)
    z = np.zeros(n)
    return LaneTrack(np.arange(n), 0.1 * np.arange(n), np.ones(n, bool), z, z, z,
                     np.asarray(lateral_m, float), z.astype(int), np.full(n, 3.0), z, z,
                     observations=obs)


def test_seen_lines_place_and_filter_known_answer():
    # the ego drifts 0.2 m left; lines at -1.5 (edge), +1.5 (dashed), +4.5 (solid) from the
    # lane middle, seen in every frame; a shadow line at +7 in 1 frame of 10 is dropped
    frames, lateral = [], []
    for k in range(10):
        drift = 0.02 * k
        seen = [(-1.5 - drift, EDGE), (1.5 - drift, DASHED), (4.5 - drift, SOLID)]
        if k == 3:
            seen.append((7.0 - drift, SOLID))
        frames.append(seen)
        lateral.append(drift)
    got = seen_lines(_track(frames, lateral), anchor_m=-1.0)
    assert [ln.kind for ln in got] == [EDGE, DASHED, SOLID]
    np.testing.assert_allclose([ln.offset_m for ln in got], [-2.5, 0.5, 3.5], atol=1e-9)
    assert all(ln.support == 1.0 for ln in got)


# --------------------------------------------------------------------------- inference


def test_lanes_from_line_offsets_known_answer():
    # ego lane 3.0 m centred at 0; a dashed line 3.0 m further left, then a solid centre
    # line and one more lane beyond it; the kerb on the right
    lines = [SeenLine(-1.5, EDGE, 1.0), SeenLine(1.5, DASHED, 1.0),
             SeenLine(4.4, SOLID, 0.9), SeenLine(7.6, SOLID, 0.5)]
    inf = infer_cross_section(lines, [], lane_width_m=3.0)
    assert _types(inf.section) == ["driving:forward", "driving:forward", "driving:backward"]
    np.testing.assert_allclose(inf.section.edges_m, [-1.5, 1.5, 4.4, 7.6])
    assert inf.ego_lane == 0


def test_wide_gap_splits_into_lanes_of_the_ego_width():
    lines = [SeenLine(-1.75, EDGE, 1.0), SeenLine(1.75, DASHED, 1.0),
             SeenLine(8.75, EDGE, 0.8)]  # 7 m between: two lanes of 3.5 m
    inf = infer_cross_section(lines, [], lane_width_m=3.5)
    np.testing.assert_allclose(inf.section.edges_m, [-1.75, 1.75, 5.25, 8.75])


def test_ego_lane_number_adds_lanes_on_the_right():
    inf = infer_cross_section([SeenLine(1.5, SOLID, 1.0)], [], lane_width_m=3.0, ego_lane=1)
    assert inf.ego_lane == 1
    assert _types(inf.section) == ["driving:forward", "driving:forward"]
    np.testing.assert_allclose(inf.section.edges_m, [-4.5, -1.5, 1.5])


def _parked(offsets, **kw):
    return [StandingVehicle(str(i), y, True, 0, **kw) for i, y in enumerate(offsets)]


def test_parking_strip_from_static_actor_offsets_known_answer():
    # two lanes (edge right, solid left at 4.5); cars parked 5.6-6.0 m left of the road's
    # reference line, i.e. 1.1-1.5 m beyond the solid line: a strip from 4.5 m to the
    # 90th percentile reach + 1.2 m margin
    lines = [SeenLine(-1.5, EDGE, 1.0), SeenLine(1.5, DASHED, 1.0), SeenLine(4.5, SOLID, 1.0)]
    offsets = [5.6, 5.8, 6.0, 5.7]
    inf = infer_cross_section(lines, _parked(offsets), lane_width_m=3.0)
    assert _types(inf.section) == ["driving:forward", "driving:forward", "parking:forward"]
    reach = float(np.quantile(np.array(offsets) - 4.5, 0.9))
    assert inf.section.edges_m[-1] == pytest.approx(4.5 + reach + 1.2)
    assert inf.parked_sides == ["left"]


def test_one_parked_car_makes_no_strip():
    inf = infer_cross_section([SeenLine(-1.5, EDGE, 1.0), SeenLine(1.5, SOLID, 1.0)],
                              _parked([2.8]), lane_width_m=3.0)
    assert PARKING not in [lane.type for lane in inf.section.lanes]


def test_shoulder_instead_of_parking_on_a_motorway():
    inf = infer_cross_section([SeenLine(1.75, SOLID, 1.0)], _parked([-3.0, -3.2, -2.9]),
                              lane_width_m=3.5, highway="motorway")
    assert inf.section.lanes[0].type == SHOULDER


def test_car_park_beyond_the_strip_gets_a_border_and_a_parking_area():
    lines = [SeenLine(-1.5, EDGE, 1.0), SeenLine(1.5, SOLID, 1.0)]
    vehicles = _parked([2.6, 2.8, 2.7]) + _parked([9.0, 12.0, 14.0])
    inf = infer_cross_section(lines, vehicles, lane_width_m=3.0)
    kinds = [lane.type for lane in inf.section.lanes]
    assert kinds == [DRIVING, PARKING, BORDER, PARKING]
    e = inf.section.edges_m
    assert e[3] == pytest.approx(9.0 - 1.2) and e[4] == pytest.approx(14.0 + 1.2)
    assert inf.car_parks == ["left"]


def test_rail_vehicle_beyond_the_kerb_gets_a_track_bed():
    lines = [SeenLine(-1.5, EDGE, 1.0), SeenLine(1.5, SOLID, 1.0)]
    tram = [StandingVehicle("t", -6.0, False, -1, rail=True, width_m=2.55, samples=40)]
    inf = infer_cross_section(lines, tram, lane_width_m=3.0)
    assert _types(inf.section)[:2] == ["rail:backward", "border:forward"]
    lo, hi = inf.section.edges_m[0], inf.section.edges_m[1]
    assert lo == pytest.approx(-7.5) and hi == pytest.approx(-4.5)
    assert inf.rail_beds == 1


def test_moving_vehicles_beyond_the_lines_add_lanes_in_their_direction():
    movers = [StandingVehicle(str(i), 3.2, False, -1) for i in range(3)]
    inf = infer_cross_section([SeenLine(-1.5, DASHED, 1.0), SeenLine(1.5, DASHED, 1.0)],
                              movers, lane_width_m=3.0)
    assert inf.added_lanes == 1
    assert _types(inf.section)[-1] == "driving:backward"


def test_map_prior_keeps_its_lanes_at_the_video_width():
    prior = cross_section_from_tags({"highway": "secondary", "lanes": "3", "lanes:forward": "2",
                                     "lanes:backward": "1", "parking:lane:left": "parallel"})
    inf = infer_cross_section([SeenLine(1.5, DASHED, 1.0)], [], lane_width_m=3.0, prior=prior)
    assert _types(inf.section) == ["driving:forward", "driving:forward", "driving:backward",
                                   "parking:backward"]
    np.testing.assert_allclose(inf.section.edges_m, [-6.0, -3.0, 0.0, 3.0, 5.3])


@settings(max_examples=60, deadline=None)
@given(width=st.floats(2.5, 4.0), n_left=st.integers(0, 3), ego_lane=st.integers(0, 2),
       anchor=st.floats(-5.0, 5.0), parked=st.lists(st.floats(-12.0, 12.0), max_size=6))
def test_inferred_section_is_consistent(width, n_left, ego_lane, anchor, parked):
    lines = [SeenLine(anchor + width * (k + 0.5), DASHED, 1.0) for k in range(n_left)]
    inf = infer_cross_section(lines, _parked(parked), lane_width_m=width, ego_lane=ego_lane,
                              anchor_m=anchor)
    sec = inf.section
    e = sec.edges_m
    assert np.all(np.diff(e) > 0)  # lanes touch and none is empty
    forward = sec.forward_driving()
    assert len(forward) >= ego_lane + 1
    # the ego's lane holds the anchor and is lane ego_lane of the forward lanes
    assert int(sec.lane_at(anchor)) == forward[inf.ego_lane]
    assert inf.ego_lane == ego_lane
    CrossSection.from_json(sec.to_json())  # writable


# --------------------------------------------------------------------------- OSM tags


def test_cross_section_from_tags_known_answers():
    two_way = cross_section_from_tags({"lanes": "4", "lanes:forward": "2", "width": "14",
                                       "parking:right": "lane", "parking:right:width": "2.0"})
    assert _types(two_way) == ["parking:forward", "driving:forward", "driving:forward",
                               "driving:backward", "driving:backward"]
    np.testing.assert_allclose(two_way.edges_m, [-9.0, -7.0, -3.5, 0.0, 3.5, 7.0])
    # drawn against the travel direction: the way's left (parking) is on our right
    against = cross_section_from_tags({"lanes": "2", "oneway": "yes",
                                       "parking:lane:left": "parallel"}, along_way=False)
    assert _types(against)[0] == "parking:forward"
    shoulder = cross_section_from_tags({"highway": "motorway", "lanes": "2", "oneway": "yes",
                                        "shoulder": "right"})
    assert shoulder.lanes[0] == LaneSpec(SHOULDER, FORWARD, 2.5)


@settings(max_examples=80, deadline=None)
@given(st.dictionaries(
    st.sampled_from(["lanes", "lanes:forward", "lanes:backward", "width", "oneway", "highway",
                     "parking:lane:left", "parking:lane:right", "parking:both",
                     "parking:left:width", "shoulder", "shoulder:width"]),
    st.one_of(st.sampled_from(["1", "2", "3", "yes", "no", "-1", "both", "parallel",
                               "diagonal", "motorway", "2.5", "nan", "-3", "x"]),
              st.text(max_size=5)), max_size=8), st.booleans())
def test_cross_section_from_any_tags_is_valid(tags, along):
    sec = cross_section_from_tags(tags, along)
    assert sec.n_driving >= 1
    assert np.all(np.diff(sec.edges_m) > 0) and np.all(np.isfinite(sec.edges_m))


# --------------------------------------------------------------------------- placing


def _actor(aid, x, y, speed=0.0, static=False, t=None):
    t = np.arange(len(x)) * 0.1 if t is None else t
    n = len(t)
    return Actor(aid, "car", 4.5, 1.8, 1.5,
                 Trajectory(t, np.asarray(x, float), np.asarray(y, float), np.zeros(n),
                            np.full(n, speed)), static=static)


LINE = np.column_stack((np.linspace(0.0, 200.0, 201), np.zeros(201)))
SECTION = CrossSection(-1.5, (LaneSpec(DRIVING, FORWARD, 3.0), LaneSpec(DRIVING, BACKWARD, 3.0),
                              LaneSpec(PARKING, BACKWARD, 2.4), LaneSpec(BORDER, BACKWARD, 1.0),
                              LaneSpec(PARKING, BACKWARD, 8.0)))


def test_place_static_moves_into_the_strip_and_faces_its_lane():
    a, moved = place_static(_actor("p", [50.0], [5.6], static=True), LINE, SECTION, 50.0, 5.6,
                            1.0)
    assert not moved
    assert a.trajectory.y[0] == pytest.approx(5.6)  # inside the strip 4.5-6.9 m: kept
    assert abs(abs(a.trajectory.heading[0]) - np.pi) < 1e-9  # faces the oncoming lane's way
    assert np.all(a.trajectory.speed == 0.0)
    a, moved = place_static(_actor("p", [50.0], [3.9], static=True), LINE, SECTION, 50.0, 3.9,
                            1.0)  # 0.6 m short of the strip: moved in, its side on the line
    assert moved and a.trajectory.y[0] == pytest.approx(4.5 + 0.9)


def test_place_static_keeps_a_car_park_position():
    a, _ = place_static(_actor("p", [50.0], [12.0], static=True), LINE, SECTION, 50.0, 12.0,
                        1.0)
    assert a.trajectory.y[0] == pytest.approx(12.0)
    a, _ = place_static(_actor("p", [50.0], [16.3], static=True), LINE, SECTION, 50.0, 16.3,
                        1.0)
    assert a.trajectory.y[0] == pytest.approx(15.9 - 0.9)  # clamped inside the area


def test_off_road_standing_known_answer():
    t = np.arange(0.0, 3.0, 0.1)
    offsets = []
    actors = [
        _actor("lot", 80 + 4.0 * t, np.full_like(t, 17.0), 4.0, t=t),  # 0.4 u, off the road
        _actor("back", 80 - 9.0 * t, np.full_like(t, 7.4), 9.0, t=t),  # -0.9 u, on the kerb
        _actor("lane", 80 + 4.0 * t, np.full_like(t, 0.0), 4.0, t=t),  # in a driving lane
        _actor("fast", 80 + 15.0 * t, np.full_like(t, 17.0), 15.0, t=t),  # faster than ego
        _actor("strip", 80 + 4.0 * t, np.full_like(t, 5.6), 4.0, t=t),  # in a parking strip
    ]
    for a in actors:
        offsets.append((a.trajectory.x.copy(), a.trajectory.y.copy()))
    held = off_road_standing(actors, offsets, SECTION, lambda tt: np.full_like(tt, 10.0),
                             LayoutConfig())
    assert held == {"lot", "back"}


@settings(max_examples=60, deadline=None)
@given(heading=st.floats(-3.1, 3.1), bend=st.floats(-0.02, 0.02),
       before=st.floats(0.0, 80.0), after=st.floats(0.0, 80.0))
def test_extend_line_keeps_the_line_and_runs_on_straight(heading, bend, before, after):
    s = np.linspace(0.0, 50.0, 51)
    h = heading + bend * s
    line = np.column_stack((np.cumsum(np.cos(h)), np.cumsum(np.sin(h))))
    ext = extend_line(line, before, after)
    n0 = len(ext) - len(line) - (int(np.ceil(after)) if after > 1e-3 else 0)
    np.testing.assert_allclose(ext[n0:n0 + len(line)], line)
    assert np.linalg.norm(ext[0] - line[0]) == pytest.approx(before, abs=1e-3)
    assert np.linalg.norm(ext[-1] - line[-1]) == pytest.approx(after, abs=1e-3)
    # points, normals: unit left normals perpendicular to the line's direction
    pts, normal = line_frame(ext, np.linspace(0.0, 40.0, 9))
    np.testing.assert_allclose(np.hypot(normal[:, 0], normal[:, 1]), 1.0)
    assert np.all(np.isfinite(pts))
