"""The ego's lateral position: lane markings fused with GPS (vid2sim.geo.lateral).

A straight road along east; the true ego drives in a known lane at a known offset; its GPS
wanders metres across the road; the lane observations are made from the true motion
(tests/detect/lane_frames.py). The fused ego must sit where the true one was.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.detect.lanes.lane_frames import FPS, observations
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import EgoTrack, Origin, RoadResult
from vid2sim.core.scenario import Road
from vid2sim.detect.lanes.track import lane_track
from vid2sim.geo.lateral import LateralConfig, fuse_lateral

ORIGIN = Origin(60.17, 24.94, 0.0)
SPEED = 12.0

def fuse_lateral_with_speed(*args, **kwargs):
    """fuse_lateral as the build runs it: the lane track re-run with the ego's speed."""
    kwargs.setdefault("refilter", lambda track, speed: lane_track(track.observations,
                                                                   speed_mps=speed))
    return fuse_lateral(*args, **kwargs)



def ego_track(true_y: np.ndarray, gps_bias_m: float = 0.0, gps_sigma_m: float = 2.0,
              seed: int = 0) -> EgoTrack:
    """The smoothed-GPS ego: true x, the true lateral position plus a slowly wandering error."""
    rng = np.random.default_rng(seed)
    n = len(true_y)
    t = np.arange(n) / FPS
    err = np.zeros(n)
    for k in range(1, n):  # AR(1) at 10 Hz, ~2 s correlation
        err[k] = 0.95 * err[k - 1] + rng.normal(0.0, gps_sigma_m * np.sqrt(1 - 0.95 ** 2))
    x = SPEED * t
    y = true_y + gps_bias_m + err
    lat, lon, _ = EnuFrame(ORIGIN).to_geodetic(np.column_stack((x, y)))
    return EgoTrack(origin=ORIGIN, t_s=t, x_m=x, y_m=y, heading_rad=np.zeros(n),
                    speed_mps=np.full(n, SPEED), lat_deg=lat, lon_deg=lon)


def osm_road(lanes: int, forward: int, width: float = 3.0) -> RoadResult:
    line = np.column_stack((np.arange(-50.0, 500.0, 1.0), np.zeros(550)))
    road = Road(id="road0", name="", highway="residential", source="osm", osm_way_ids=[1],
                lanes=lanes, lane_width_m=width, centerline=line)
    return RoadResult(origin=ORIGIN, roads=[road], route_osm_way_ids=[1], matches=[],
                      ego_lane=np.zeros(0, int), ego_offset_m=np.zeros(0), source="osm",
                      lanes_forward=forward)


def tracked(obs):
    return lane_track(obs)


def test_two_way_road_ego_placed_from_the_centre_line_whatever_the_gps():
    # Lanes 3.3 m between the lines' centres (the map says 3.0); the ego 0.2 m left of its
    # lane's middle: 3.3 / 2 - 0.2 = 1.45 m right of the centre line.
    n = 300
    obs = observations(np.full(n, 0.2), width_m=3.3, noise_m=0.03, seed=1, lanes=(0, 1))
    true_y = np.full(n, -1.45)
    gps = ego_track(true_y, gps_bias_m=1.2, seed=2)
    result = fuse_lateral_with_speed(gps, tracked(obs), osm_road(2, 1))
    assert result.source == "lane markings + map"
    err = result.ego.y_m - true_y
    assert np.sqrt(np.mean(err ** 2)) < 0.05
    assert (result.lane == 0).all() and result.lane_changes == []
    np.testing.assert_allclose(result.offset_from_centerline_m, -1.45, atol=0.1)
    assert np.nanmedian(result.lane_width_m) == pytest.approx(3.3, abs=0.02)
    # The ego was moved across the road by what the GPS had wrong.
    np.testing.assert_allclose(result.correction_m, true_y - gps.y_m, atol=0.15)
    np.testing.assert_allclose(result.ego.heading_rad, 0.0, atol=0.02)
    assert any("lane markings" in n for n in result.notes)


def test_one_way_road_lane_from_the_gps_when_the_markings_do_not_say():
    n = 300
    obs = observations(np.full(n, 0.0), seed=3, lanes=(-1, 1))  # middle of three lanes
    gps = ego_track(np.zeros(n), gps_bias_m=1.0, gps_sigma_m=0.8, seed=4)
    result = fuse_lateral_with_speed(gps, tracked(obs), osm_road(3, 3, width=3.5))
    assert (result.lane == 1).all()
    assert np.sqrt(np.mean(result.ego.y_m ** 2)) < 0.05


def test_markings_that_show_the_road_edge_put_the_ego_in_the_rightmost_lane():
    # The GPS, 1.9 m off to the left, is nearer the middle lane than the right one; the
    # markings (a road edge right of the ego, nothing beyond) say the rightmost.
    n = 300
    obs = observations(np.full(n, 0.0), seed=5, lanes=(0, 2))
    result = fuse_lateral_with_speed(ego_track(np.full(n, -3.5), gps_bias_m=1.9, gps_sigma_m=0.5,
                                    seed=6), tracked(obs), osm_road(3, 3, width=3.5))
    assert (result.lane == 0).all()
    assert np.sqrt(np.mean((result.ego.y_m + 3.5) ** 2)) < 0.05


def test_a_lane_change_moves_the_ego_and_is_reported_in_road_lanes():
    t = np.arange(0.0, 30.0, 1.0 / FPS)
    u = np.clip((t - 14.0) / 3.0, 0.0, 1.0)
    lateral = 3.5 * u ** 3 * (10 - 15 * u + 6 * u * u)
    obs = observations(lateral, noise_m=0.03, seed=7, lanes=(0, 1))
    true_y = -1.75 + lateral
    result = fuse_lateral_with_speed(ego_track(true_y, seed=8), tracked(obs), osm_road(2, 2, width=3.5))
    assert [(c.from_lane, c.to_lane) for c in result.lane_changes] == [(0, 1)]
    assert result.lane_changes[0].t_s == pytest.approx(15.5, abs=0.3)
    assert result.lane[0] == 0 and result.lane[-1] == 1
    assert np.sqrt(np.mean((result.ego.y_m - true_y) ** 2)) < 0.1
    # The heading follows the lateral motion of the change.
    mid = np.argmin(np.abs(t - 15.5))
    assert result.ego.heading_rad[mid] == pytest.approx(np.arctan2(3.5 * 1.875 / 3.0, SPEED),
                                                        abs=0.03)


def test_without_markings_the_gps_stays_and_says_so():
    n = 50
    ego = ego_track(np.zeros(n))
    result = fuse_lateral_with_speed(ego, None, osm_road(2, 1))
    assert result.ego is ego and result.source == "gps"
    assert result.notes and "GPS" in result.notes[0]
    empty = lane_track(observations(np.zeros(n), missing=np.ones(n, bool)))
    result = fuse_lateral_with_speed(ego, empty, osm_road(2, 1))
    assert result.ego is ego and result.source == "gps" and result.lanes is not None


def test_trajectory_road_keeps_the_gps_path_and_gives_the_lane_middle():
    n = 200
    obs = observations(np.full(n, 0.4), seed=9, lanes=(0, 1))
    ego = ego_track(np.zeros(n), gps_sigma_m=0.0)
    road = RoadResult(origin=ORIGIN, roads=[], route_osm_way_ids=[], matches=[],
                      ego_lane=np.zeros(n, int), ego_offset_m=np.zeros(n),
                      source="trajectory")
    result = fuse_lateral_with_speed(ego, tracked(obs), road)
    assert result.source == "lane markings (no map)"
    np.testing.assert_array_equal(result.ego.y_m, ego.y_m)
    assert (result.lane == 0).all()  # the road edge right of the ego: rightmost lane
    # The lane's middle is 0.4 m right of the ego (heading east: -y).
    np.testing.assert_allclose(result.lane_center_xy_m[:, 1], -0.4, atol=0.03)
    np.testing.assert_allclose(result.offset_in_lane_m, 0.4, atol=0.03)


@settings(max_examples=15, deadline=None)
@given(offset=st.floats(-1.0, 1.0), bias=st.floats(-2.0, 2.0), seed=st.integers(0, 100))
def test_fused_ego_keeps_time_speed_and_its_geodetic_twin(offset, bias, seed):
    n = 120
    obs = observations(np.full(n, offset), seed=seed, lanes=(0, 1))
    ego = ego_track(np.full(n, -1.75 + offset), gps_bias_m=bias, seed=seed)
    result = fuse_lateral_with_speed(ego, tracked(obs), osm_road(2, 1, width=3.5),
                          LateralConfig(centerline_smoothing_m=0.0))
    new = result.ego
    np.testing.assert_array_equal(new.t_s, ego.t_s)
    np.testing.assert_array_equal(new.speed_mps, ego.speed_mps)
    enu = EnuFrame(ORIGIN).to_enu(new.lat_deg, new.lon_deg)
    np.testing.assert_allclose(enu[:, 0], new.x_m, atol=1e-3)
    np.testing.assert_allclose(enu[:, 1], new.y_m, atol=1e-3)
    np.testing.assert_allclose(new.y_m, -1.75 + offset, atol=0.05)
    # Along the road nothing moved.
    np.testing.assert_allclose(new.x_m, ego.x_m, atol=1e-6)
