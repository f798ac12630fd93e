"""scenario.json: round trip, byte-identical canonical output, validation naming the field."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vid2sim.base.errors import FormatError, InputError, MissingInputError, ScenarioError
from vid2sim.core import _scenario_schema as schema
from vid2sim.core import scenario as sc
from vid2sim.core.records import EVENT_TYPES, Origin


def make_scenario() -> sc.Scenario:
    t = np.arange(0.0, 5.01, 0.5)
    ego = sc.Trajectory(t=t, x=10.0 * t, y=np.zeros_like(t), heading=np.zeros_like(t),
                        speed=np.full_like(t, 10.0))
    lead = sc.Trajectory(t=t, x=30.0 + 8.0 * t, y=np.full_like(t, 0.1),
                         heading=np.full_like(t, -1e-9), speed=np.full_like(t, 8.0))
    return sc.Scenario(
        origin=Origin(60.1699, 24.9384, 20.0),
        roads=[sc.Road(id="r0", name="Mannerheimintie", highway="primary", source="osm",
                       osm_way_ids=[123, 456], lanes=2, lane_width_m=3.5,
                       centerline=[[0.0, 0.0], [100.0, 0.0]])],
        ego=sc.Ego(4.5, 1.8, 1.5, ego),
        actors=[sc.Actor("1", "car", 4.4, 1.8, 1.5, lead)],
        camera={"fx": 721.5377, "fy": 721.5377, "image_width": 1242},
        source=sc.Source(inputs=[{"name": "drive.gpx", "sha256": "ab" * 32}], tool_version="0.1.0",
                         options={"rate_hz": 10.0}, assumptions=["flat road"]),
    )


def valid_dict() -> dict:
    return json.loads(sc.dumps_canonical(make_scenario().to_json()))


def test_save_load_round_trip_and_byte_identical(tmp_path):
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    sc.save(make_scenario(), a)
    sc.save(make_scenario(), b)
    assert a.read_bytes() == b.read_bytes()
    loaded = sc.load(a)
    assert loaded.origin == Origin(60.1699, 24.9384, 20.0)
    assert loaded.roads[0].osm_way_ids == [123, 456]
    assert loaded.ego.trajectory.x == pytest.approx(make_scenario().ego.trajectory.x)
    assert loaded.actors[0].id == "1" and loaded.duration_s == pytest.approx(5.0)
    # Saving what was loaded reproduces the file exactly.
    c = tmp_path / "c.json"
    sc.save(loaded, c)
    assert c.read_bytes() == a.read_bytes()


def test_canonical_text_contract():
    text = sc.dumps_canonical(make_scenario().to_json())
    data = json.loads(text)
    assert data["schema"] == "vid2sim.scenario" and data["version"] == 1
    assert list(data) == sorted(data)  # sorted keys
    assert text.endswith("\n")
    assert "-0.0" not in text  # the -1e-9 heading is written as 0.0
    assert set(data["ego"]["trajectory"][0]) == {"t", "x", "y", "heading", "speed"}
    assert sc.dumps_canonical({"lat": 60.123456789123, "x": 1.234567}) == \
        '{\n "lat": 60.123456789,\n "x": 1.2346\n}\n'


def test_valid_dict_passes():
    sc.validate(valid_dict())


def _mutations():
    def drop(*keys):
        def f(d):
            target = d
            for k in keys[:-1]:
                target = target[k]
            del target[keys[-1]]
        return f

    def put(value, *keys):
        def f(d):
            target = d
            for k in keys[:-1]:
                target = target[k]
            target[keys[-1]] = value
        return f

    return [
        (put("other", "schema"), "schema"),
        (put(2, "version"), "version"),
        (drop("origin", "lat"), "origin.lat"),
        (put(91.0, "origin", "lat"), "origin.lat"),
        (put("60", "origin", "lon"), "origin.lon"),
        (put(0, "roads", 0, "lanes"), "roads[0].lanes"),
        (put(-3.5, "roads", 0, "lane_width_m"), "roads[0].lane_width_m"),
        (put(["123"], "roads", 0, "osm_way_ids"), "roads[0].osm_way_ids"),
        (put([[0.0, 0.0]], "roads", 0, "centerline"), "roads[0].centerline"),
        (put(True, "ego", "length_m"), "ego.length_m"),
        (put(0.0, "ego", "width_m"), "ego.width_m"),
        (put([], "ego", "trajectory"), "ego.trajectory"),
        (put(0.0, "ego", "trajectory", 3, "t"), "ego.trajectory[3].t"),
        (put(-1.0, "ego", "trajectory", 2, "speed"), "ego.trajectory[2].speed"),
        (drop("ego", "trajectory", 1, "heading"), "ego.trajectory[1].heading"),
        (put("car", "actors", 0, "trajectory", 0, "x"), "actors[0].trajectory[0].x"),
        (drop("actors", 0, "category"), "actors[0].category"),
        (drop("camera"), "camera"),
        (drop("source"), "source"),
    ]


@pytest.mark.parametrize("mutate,field", _mutations())
def test_validation_names_the_offending_field(mutate, field):
    d = valid_dict()
    mutate(d)
    with pytest.raises(ScenarioError) as e:
        sc.validate(d, "s.json")
    assert e.value.field == field
    assert str(e.value).startswith("s.json: field '")


def test_duplicate_actor_ids_and_nan():
    d = valid_dict()
    d["actors"].append(copy.deepcopy(d["actors"][0]))
    with pytest.raises(ScenarioError) as e:  # the same id twice
        sc.validate(d)
    assert e.value.field == "actors[1].id"
    d = valid_dict()
    d["ego"]["trajectory"][0]["x"] = float("nan")
    with pytest.raises(ScenarioError) as e:
        sc.validate(d)
    assert e.value.field == "ego.trajectory[0].x"


def test_not_an_object():
    with pytest.raises(ScenarioError) as e:
        sc.validate([1, 2, 3])
    assert e.value.field == "<root>"


def test_load_errors(tmp_path):
    with pytest.raises(MissingInputError):
        sc.load(tmp_path / "missing.json")
    f = tmp_path / "broken.json"
    f.write_text("{not json")
    with pytest.raises(FormatError, match="line 1") as e:
        sc.load(f)
    assert "broken.json" in str(e.value)


def test_save_refuses_invalid_and_leaves_no_file(tmp_path):
    s = make_scenario()
    s.ego.trajectory.speed[2] = -5.0
    out = tmp_path / "s.json"
    with pytest.raises(ScenarioError):
        sc.save(s, out)
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_state_at_interpolates_heading_across_pi():
    tr = sc.Trajectory(t=[0.0, 1.0], x=[0.0, 1.0], y=[0.0, 0.0],
                       heading=[math.pi - 0.1, -math.pi + 0.1], speed=[1.0, 1.0])
    mid = tr.state_at(0.5)
    assert abs(math.remainder(float(mid["heading"]) - math.pi, 2 * math.pi)) < 1e-9
    assert float(mid["x"]) == pytest.approx(0.5)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-1e4, 1e4, allow_nan=False), min_size=2, max_size=30))
def test_trajectory_round_trip_property(xs):
    t = np.arange(len(xs), dtype=float)
    tr = sc.Trajectory(t=t, x=xs, y=xs[::-1], heading=np.zeros(len(xs)), speed=np.ones(len(xs)))
    back = sc.Trajectory.from_json(json.loads(sc.dumps_canonical({"p": tr.to_json()}))["p"])
    assert back.x == pytest.approx(np.round(xs, 4), abs=1e-9)
    assert np.array_equal(back.t, t)


# --------------------------------------------------------------------------- damage, limits

JUNK_VALUES = [None, True, "x", "", [], {}, [[]], -1, 0, 1e308, -1e308, 10**400, 1e9, -1e-9,
               [1e308, 0.0], [[0.0, 0.0], [0.0, 0.0]], {"t": 1}]


def _paths(obj, prefix=()):
    """Every (path, value) of a parsed JSON tree."""
    yield prefix, obj
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _paths(v, (*prefix, k))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _paths(v, (*prefix, i))


def _check_loaded(scenario: sc.Scenario) -> None:
    # A scenario that loads can be used: every number finite, roads usable by the exporters.
    from vid2sim.export.highway import lane_centerlines_enu

    for traj in [scenario.ego.trajectory, *(a.trajectory for a in scenario.actors)]:
        for arr in (traj.t, traj.x, traj.y, traj.heading, traj.speed):
            assert np.all(np.isfinite(arr))
    for road in scenario.roads:
        for lane in lane_centerlines_enu(road):
            assert np.all(np.isfinite(lane))


def test_scenario_field_damage_gives_scenario_error_only():
    from tests.damage import FUZZ

    @FUZZ
    @given(data=st.data())
    def check(data):
        d = valid_dict()
        paths = [p for p, _ in _paths(d) if p]
        for _ in range(data.draw(st.integers(1, 3))):
            path = data.draw(st.sampled_from(paths))
            parent = d
            for key in path[:-1]:
                parent = parent[key]
            parent[path[-1]] = copy.deepcopy(data.draw(st.sampled_from(JUNK_VALUES)))
            paths = [p for p, _ in _paths(d) if p]
        try:
            loaded = sc.from_json(d, "s.json")
        except ScenarioError:
            return
        _check_loaded(loaded)

    check()


def test_scenario_file_damage_gives_input_error_only(tmp_path):
    from tests.damage import FUZZ, damaged, input_error_or_result

    valid = sc.dumps_canonical(make_scenario().to_json()).encode()

    @FUZZ
    @given(data=damaged(valid))
    def check(data):
        f = tmp_path / "s.json"
        f.write_bytes(data)
        loaded = input_error_or_result(sc.load, f)
        if isinstance(loaded, sc.Scenario):
            _check_loaded(loaded)

    check()


@pytest.mark.parametrize("mutate,field", [
    (lambda d: d["roads"][0].update(lanes=10**9), "roads[0].lanes"),
    (lambda d: d["roads"][0].update(lane_width_m=1e-6), "roads[0].lane_width_m"),
    # all points coincide
    (lambda d: d["roads"][0].update(centerline=[[5.0, 5.0], [5.0, 5.0]]), "roads[0].centerline"),
    # turns back on itself
    (lambda d: d["roads"][0].update(centerline=[[0.0, 0.0], [50.0, 0.0], [0.0, 0.0]]),
     "roads[0].centerline"),
    # a point 1,000,000 km from the origin
    (lambda d: d["roads"][0].update(centerline=[[0.0, 0.0], [1e9, 0.0]]),
     "roads[0].centerline[1]"),
    (lambda d: d["ego"]["trajectory"][2].update(speed=1e6), "ego.trajectory[2].speed"),
    (lambda d: d["actors"][0].update(length_m=1e6), "actors[0].length_m"),
    (lambda d: d["ego"]["trajectory"][-1].update(t=2e5), "ego.trajectory"),  # lasts 2 days
    (lambda d: d["source"].update(inputs=5), "source.inputs"),
])
def test_physical_ranges_and_road_geometry(mutate, field):
    d = valid_dict()
    mutate(d)
    with pytest.raises(ScenarioError) as e:
        sc.validate(d, "s.json")
    assert e.value.field == field


def test_size_limits_fail_fast(tmp_path, monkeypatch):
    # Past the documented limits a scenario is refused before any exporter loops over it.
    big = tmp_path / "big.json"
    with open(big, "wb") as fh:
        fh.truncate(sc.MAX_SCENARIO_BYTES + 1)
    with pytest.raises(InputError, match="limit"):  # a size limit: no named class fits
        sc.load(big)
    monkeypatch.setattr(schema, "MAX_TRAJECTORY_POINTS", 15)
    with pytest.raises(ScenarioError):
        sc.validate(valid_dict())  # 11 ego + 11 actor points
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(FormatError, match="deep.json"):  # nested too deeply to parse
        sc.load(deep)


# --------------------------------------------------------------------------- events


def _with_events() -> dict:
    d = valid_dict()
    d["events"] = [{"type": "cut_in", "actor": "1", "t_s": 2.5, "from_lane": 1, "to_lane": 0},
                   {"type": "lane_change", "actor": "ego", "t_s": 4.0, "from_lane": 0,
                    "to_lane": -1}]
    return d


def test_events_round_trip_and_old_files_without_them(tmp_path):
    s = sc.from_json(_with_events())
    assert s.events == [sc.Event("cut_in", "1", 2.5, 1, 0),
                        sc.Event("lane_change", "ego", 4.0, 0, -1)]
    out = tmp_path / "s.json"
    sc.save(s, out)
    assert sc.load(out).events == s.events
    old = valid_dict()
    del old["events"]
    assert "events" not in old and sc.from_json(old).events == []
    # a scenario made without events writes an empty list
    assert json.loads(sc.dumps_canonical(make_scenario().to_json()))["events"] == []


@pytest.mark.parametrize("change,field", [
    ({"type": "overtake"}, "type"),  # not an event type
    ({"actor": "42"}, "actor"),  # no such actor
    ({"t_s": 9.0}, "t_s"),  # after the scenario's end
    ({"t_s": float("nan")}, "t_s"),
    ({"from_lane": 0}, "to_lane"),  # a lane change that does not change the lane
    ({"to_lane": 1, "from_lane": 2}, "type"),  # a cut_in that does not end in the ego lane
    ({"from_lane": 1.0}, "from_lane"),  # not an int
    ({"from_lane": True}, "from_lane"),
    ({"from_lane": 40}, "from_lane"),  # more than 16 lanes away
    ({"type": "cut_out"}, "type"),  # a cut_out that does not start in the ego lane
    ({"actor": "ego"}, "type"),  # the ego's own event is a lane_change
])
def test_event_validation_names_the_field(change, field):
    d = _with_events()
    d["events"][0].update(change)
    with pytest.raises(ScenarioError) as e:
        sc.validate(d, "s.json")
    assert e.value.field == f"events[0].{field}"
    for bad in ({"events": "x"}, {"events": [5]}):
        d = _with_events()
        d.update(bad)
        with pytest.raises(ScenarioError):
            sc.validate(d)


def test_event_damage_gives_scenario_error_only():
    from tests.damage import FUZZ

    @FUZZ
    @given(data=st.data())
    def check(data):
        d = _with_events()
        paths = [p for p, _ in _paths(d["events"]) if p]
        for _ in range(data.draw(st.integers(1, 3))):
            path = data.draw(st.sampled_from(paths))
            parent = d["events"]
            for key in path[:-1]:
                parent = parent[key]
            parent[path[-1]] = copy.deepcopy(data.draw(st.sampled_from(JUNK_VALUES)))
            paths = [p for p, _ in _paths(d["events"]) if p]
        try:
            loaded = sc.from_json(d, "s.json")
        except ScenarioError:
            return
        for ev in loaded.events:
            assert ev.type in EVENT_TYPES and math.isfinite(ev.t_s)
            assert ev.from_lane != ev.to_lane

    check()


_EVENT = st.one_of(
    st.builds(lambda a, t, k: {"type": "cut_in", "actor": a, "t_s": t, "from_lane": k,
                               "to_lane": 0},
              st.just("1"), st.floats(0.0, 5.0), st.sampled_from([-2, -1, 1, 2, 16])),
    st.builds(lambda a, t, k: {"type": "cut_out", "actor": a, "t_s": t, "from_lane": 0,
                               "to_lane": k},
              st.just("1"), st.floats(0.0, 5.0), st.sampled_from([-16, -1, 1, 3])),
    st.builds(lambda t, k: {"type": "lane_change", "actor": "ego", "t_s": t, "from_lane": 0,
                            "to_lane": k}, st.floats(0.0, 5.0), st.sampled_from([-1, 1])),
    st.builds(lambda t, a, b: {"type": "lane_change", "actor": "1", "t_s": t,
                               "from_lane": a, "to_lane": b},
              st.floats(0.0, 5.0), st.integers(1, 16), st.integers(-16, -1)))


@settings(max_examples=80)
@given(events=st.lists(_EVENT, max_size=6))
def test_valid_events_round_trip_through_json(events, tmp_path_factory):
    """Any valid list of events validates and survives save and load unchanged."""
    d = valid_dict()
    d["events"] = events
    s = sc.from_json(d, "s.json")
    assert [e.to_json() for e in s.events] == events
    out = tmp_path_factory.mktemp("ev") / "s.json"
    sc.save(s, out)
    back = sc.load(out)
    assert [(e.type, e.actor, e.from_lane, e.to_lane) for e in back.events] == [
        (e["type"], e["actor"], e["from_lane"], e["to_lane"]) for e in events]
    assert [e.t_s for e in back.events] == pytest.approx([e["t_s"] for e in events], abs=1e-4)
