"""The bird's-eye view and the strip of the replay videos: geometry with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from tests.evaluate.conftest import make_scenario
from vid2sim.core.lanelayout import CrossSection, LaneSpec
from vid2sim.core.scenario import Road
from vid2sim.evaluate.birdseye import (
    ACTOR_BGR,
    EGO_BGR,
    LANE_BGR,
    LEAD_BGR,
    BirdsEye,
    Mark,
    lane_edges_at,
    nice_length_m,
)
from vid2sim.evaluate.replayconfig import BirdsEyeConfig
from vid2sim.evaluate.report import lead_series
from vid2sim.evaluate.scenetime import SceneClock
from vid2sim.evaluate.timeline import Plot, Strip, Trace, ttc_s


def _road(heading: float = 0.0, section: CrossSection | None = None) -> Road:
    c, s = math.cos(heading), math.sin(heading)
    line = np.array([[-100 * c, -100 * s], [300 * c, 300 * s]])
    return Road("r", "", "primary", "trajectory", [], 2, 3.5, line, section)


@given(heading=st.floats(-math.pi, math.pi), fwd=st.floats(-10, 50), left=st.floats(-20, 20),
       ego_x=st.floats(-50, 50), ego_y=st.floats(-50, 50))
def test_a_point_ahead_and_left_lands_above_and_left_of_the_ego(heading, fwd, left, ego_x, ego_y):
    view = BirdsEye([], 600, 500)
    c, s = math.cos(heading), math.sin(heading)
    p = np.array([[ego_x + fwd * c - left * s, ego_y + fwd * s + left * c]])
    u, v = view.to_px((ego_x, ego_y, heading), p)[0]
    u0, v0 = view.origin_px
    assert u == pytest.approx(u0 - view.scale * left, abs=1e-6)
    assert v == pytest.approx(v0 - view.scale * fwd, abs=1e-6)


def test_scale_fits_the_configured_span():
    cfg = BirdsEyeConfig(ahead_m=60.0, behind_m=15.0)
    view = BirdsEye([], 600, 500, cfg)
    # 4 % margins top and bottom, 75 m in between
    assert view.scale == pytest.approx(500 * 0.92 / 75.0)
    assert view.origin_px[1] == pytest.approx(500 * 0.96 - 15.0 * view.scale)


def test_vehicles_and_lanes_are_drawn_where_they_are():
    section = CrossSection(-5.0, (LaneSpec("parking", "forward", 2.0),
                                  LaneSpec("driving", "forward", 3.5),
                                  LaneSpec("driving", "forward", 3.5)))
    view = BirdsEye([_road(0.7, section)], 600, 500)
    h = 0.7
    ego = (10.0 * math.cos(h), 10.0 * math.sin(h), h)
    c, s = math.cos(h), math.sin(h)
    # an actor 20 m ahead, one lane (3.5 m) left; the lead 30 m ahead in the ego's lane
    actor = (ego[0] + 20 * c - 3.5 * s, ego[1] + 20 * s + 3.5 * c)
    lead = (ego[0] + 30 * c, ego[1] + 30 * s)
    img = view.draw(ego, [Mark("ego", *ego, 4.5, 1.8, "ego"),
                          Mark("7", *actor, h, 4.5, 1.8, "actor"),
                          Mark("9", *lead, h, 4.5, 1.8, "lead")])
    u0, v0 = view.origin_px
    at = {name: img[round(v0 - view.scale * f), round(u0 - view.scale * l)].tolist()
          for name, f, l in (("ego", 0, 0), ("actor", 20, 3.5), ("lead", 30, 0),
                             # the parking strip: the ego sits 0.5 m left of the right edge
                             # of the middle lane (offsets -5 .. -3 m: 4 m right of the ego)
                             ("parking", 5, -4.0), ("driving", 5, -2.0))}
    assert at["ego"] == list(EGO_BGR)
    assert at["actor"] == list(ACTOR_BGR)
    assert at["lead"] == list(LEAD_BGR)
    assert at["parking"] == list(LANE_BGR["parking"])
    assert at["driving"] == list(LANE_BGR["driving"])


@given(offset=st.floats(-4.99, 5.99), heading=st.floats(-3.0, 3.0), along=st.floats(0, 150))
def test_lane_edges_hold_the_point(offset, heading, along):
    section = CrossSection(-5.0, (LaneSpec("parking", "forward", 2.0),
                                  LaneSpec("driving", "forward", 4.0),
                                  LaneSpec("driving", "backward", 4.0),
                                  LaneSpec("border", "backward", 1.0)))
    assume(min(abs(offset - e) for e in (-5.0, -3.0, 1.0, 5.0, 6.0)) > 1e-6)  # not on an edge
    view = BirdsEye([_road(heading, section)], 400, 300)
    c, s = math.cos(heading), math.sin(heading)
    x, y = along * c - offset * s, along * s + offset * c
    edges = lane_edges_at(view.roads, x, y)
    assert edges is not None
    right, left = edges
    k = int(np.argmin(np.hypot(right[:, 0] - x, right[:, 1] - y)))
    normal = np.array([-s, c])
    lo = float(np.dot(right[k], normal))
    hi = float(np.dot(left[k], normal))
    assert lo - 1e-6 <= offset <= hi + 1e-6
    # edges at -5, -3, 1, 5, 6 m: parking 2 m, two driving lanes of 4 m, a border of 1 m
    expected = 2.0 if offset < -3.0 else 4.0 if offset < 5.0 else 1.0
    assert hi - lo == pytest.approx(expected, abs=1e-6)


def test_no_lane_beyond_the_road():
    view = BirdsEye([_road()], 400, 300)
    assert lane_edges_at(view.roads, 50.0, 3.6) is None  # 2 x 3.5 m about the centerline
    assert lane_edges_at(view.roads, 50.0, 3.4) is not None


@given(st.floats(1e-3, 1e6))
def test_scale_bar_is_a_round_length_within_the_limit(max_m):
    m = nice_length_m(max_m)
    assert m <= max_m * (1 + 1e-12)
    assert m > max_m / 2.5 - 1e-12  # 1 -> 2 -> 5 -> 10: never more than 2.5x below
    mantissa = m / 10 ** math.floor(math.log10(m) + 1e-12)
    assert round(mantissa, 9) in (1.0, 2.0, 5.0)


def test_the_scene_clock_finds_the_report_s_lead():
    sc = make_scenario()  # "lead" 20 m ahead, "hidden" behind it, "left" a lane aside
    ref = lead_series(sc)
    clock = SceneClock(sc)
    for t, rng, lead_id in zip(ref["t_s"], ref["range_m"], ref["lead_id"], strict=True):
        ego, actors = clock.at(float(t))
        lead = clock.lead(ego, actors)
        assert lead is not None and lead.id == lead_id
        assert lead.range_m == pytest.approx(rng, abs=1e-6)
        # ego 10 m/s, lead 8 m/s, parallel
        assert lead.closing_mps == pytest.approx(2.0, abs=1e-9)


def test_the_scene_clock_sweeps_actors_in_and_out():
    sc = make_scenario()  # "right_far" starts at 1 s
    clock = SceneClock(sc)
    _, actors = clock.at(0.5)
    assert "right_far" not in actors and {"lead", "left", "hidden"} <= set(actors)
    _, actors = clock.at(1.5)
    assert "right_far" in actors
    with pytest.raises(ValueError):
        clock.at(1.0)  # forward only


def test_ttc_is_range_over_closing_speed():
    ttc = ttc_s(np.array([20.0, 20.0, np.nan, -1.0]), np.array([4.0, -1.0, 3.0, 2.0]))
    assert ttc[0] == pytest.approx(5.0)
    assert ttc[1] == math.inf  # opening
    assert math.isnan(ttc[2])  # no lead
    assert ttc[3] == 0.0  # overlapping


def test_strip_cursor_spans_the_clip():
    t = np.linspace(0.0, 10.0, 101)
    strip = Strip(800, 120, 0.0, 10.0, [Plot("v", [Trace("v", t, t, (0, 255, 0))])],
                  (t, np.full(101, 2.0)))
    assert strip.x_px(0.0) == pytest.approx(strip.left)
    assert strip.x_px(10.0) == pytest.approx(800 - strip.right)
    a, b = strip.draw(2.0, "t 2"), strip.draw(8.0, "t 8")
    assert a.shape == (120, 800, 3)
    # the white cursor moved from 2 s to 8 s
    col = [int(strip.x_px(x)) for x in (2.0, 8.0)]
    assert (a[60, col[0]] == 255).all() and not (a[60, col[1]] == 255).all()
    assert (b[60, col[1]] == 255).all()


def test_the_lead_is_followed_along_the_ego_s_path_through_a_bend():
    # both in the right lane of a 60 m bend; the lead 30 m ahead (centres), braking from 3 s,
    # the recorded ego from 4 s: the range along the lane is known from their s(t) profiles
    from vid2sim.samples.scenarios import BRAKING_LEAD, _s_profile, braking_lead_scenario

    sc = braking_lead_scenario()
    p = BRAKING_LEAD
    t = np.round(np.arange(0.0, 12.0 + 1e-9, 0.1), 6)
    _, s_ego = _s_profile(t, p["speed_mps"], p["lead_brake_s"] + p["reaction_s"],
                          p["decel_mps2"], p["end_speed_mps"])
    _, s_lead = _s_profile(t, p["speed_mps"], p["lead_brake_s"], p["decel_mps2"],
                           p["end_speed_mps"])
    def lane_s(s_c):
        # arc length along the right lane (1.75 m right of the centerline: radius 61.75 m in
        # the 60 m quarter bend that follows 80 m of straight) at centerline arc length s_c
        bend = math.pi / 2 * 60.0
        in_bend = np.clip(np.asarray(s_c) - 80.0, 0.0, bend)
        return np.asarray(s_c) + in_bend * (1.75 / 60.0)

    expected = lane_s(5.0 + p["lead_ahead_m"] + s_lead) - lane_s(5.0 + s_ego) - 4.4 / 2.0
    clock = SceneClock(sc)
    # while the lead is on the path the ego drove (beyond its last pose the path goes on
    # straight, as the environment's, and leaves the bend)
    on_path = 5.0 + p["lead_ahead_m"] + s_lead <= 5.0 + s_ego[-1]
    assert on_path.sum() > 60  # 7 s, the bend and the braking included
    for k, tk in enumerate(t):
        ego, actors = clock.at(float(tk))
        lead = clock.lead(ego, actors)
        if not on_path[k]:
            continue
        assert lead is not None and lead.id == "lead", tk
        # (0.15 m: the generator places the cars on a 1 m polyline of the circle)
        assert lead.range_m == pytest.approx(expected[k], abs=0.15), tk
    # the report's lead plot measures along the same path: it keeps the lead in the bend
    # (along the ego's straight axis it lost it there)
    report = lead_series(sc)
    on_report = np.interp(report["t_s"], t, on_path.astype(float)) > 0.99
    assert on_report.sum() > 50 and set(report["lead_id"][on_report]) == {"lead"}
