"""Synthetic scenarios built in code for the export tests (straight road, curve, left turn)."""

from __future__ import annotations

import numpy as np

from vid2sim.records import Origin
from vid2sim.scenario import Actor, Ego, Road, Scenario, Source, Trajectory

ORIGIN = Origin(60.17, 24.94, 12.0)


def _traj_along(points_m: np.ndarray, s_of_t: np.ndarray, t_s: np.ndarray,
                left_offset_m: float = 0.0) -> Trajectory:
    """A trajectory moving along a polyline by arc length s(t), shifted to the left."""
    d = np.diff(points_m, axis=0)
    seg = np.linalg.norm(d, axis=1)
    s = np.r_[0.0, np.cumsum(seg)]
    x = np.interp(s_of_t, s, points_m[:, 0])
    y = np.interp(s_of_t, s, points_m[:, 1])
    seg_h = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    h = np.interp(s_of_t, 0.5 * (s[1:] + s[:-1]), seg_h)
    x, y = x - np.sin(h) * left_offset_m, y + np.cos(h) * left_offset_m
    speed = np.gradient(s_of_t, t_s)
    return Trajectory(t_s, x, y, h, np.maximum(speed, 0.0))


def left_turn_centerline(radius_m: float = 40.0, straight_m: float = 80.0) -> np.ndarray:
    """East for ``straight_m``, a quarter circle LEFT (counter-clockwise), then north."""
    a = np.column_stack((np.linspace(0.0, straight_m, 81), np.zeros(81)))
    th = np.linspace(0.0, np.pi / 2, 63)[1:]
    arc = np.column_stack((straight_m + radius_m * np.sin(th), radius_m - radius_m * np.cos(th)))
    b = np.column_stack((np.full(80, straight_m + radius_m),
                         radius_m + np.linspace(1.0, straight_m, 80)))
    return np.vstack((a, arc, b))


def make_scenario(centerline: np.ndarray, lanes: int = 2, lane_width_m: float = 3.5,
                  ego_speed_mps: float = 10.0, duration_s: float = 12.0, dt_s: float = 0.1,
                  ego_lane_from_left: int = 1, with_actors: bool = True) -> Scenario:
    """Ego in lane ``ego_lane_from_left``; a lead ahead in its lane that brakes, a car in the
    left lane that appears at 2 s and leaves at 9 s."""
    t = np.round(np.arange(0.0, duration_s + 1e-9, dt_s), 6)
    road = Road("r1", "Test road", "primary", "osm", [1], lanes, lane_width_m, centerline)
    ego_left_m = ((lanes - 1) / 2.0 - ego_lane_from_left) * lane_width_m
    ego = _traj_along(centerline, 5.0 + ego_speed_mps * t, t, ego_left_m)
    actors = []
    if with_actors:
        lead_v = np.where(t < 4.0, ego_speed_mps, np.maximum(ego_speed_mps - 2.0 * (t - 4.0), 3.0))
        lead_s = 30.0 + np.r_[0.0, np.cumsum(0.5 * (lead_v[1:] + lead_v[:-1]) * np.diff(t))]
        actors.append(Actor("7", "car", 4.4, 1.8, 1.5, _traj_along(centerline, lead_s, t,
                                                                     ego_left_m)))
        tb = t[(t >= 2.0) & (t <= 9.0)]
        actors.append(Actor("9", "truck", 8.0, 2.5, 3.2, _traj_along(
            centerline, 12.0 + (ego_speed_mps + 1.0) * tb, tb, ego_left_m + lane_width_m)))
    return Scenario(ORIGIN, [road], Ego(4.5, 1.8, 1.5, ego), actors, {"fx": 700.0},
                    Source(tool_version="test"))


def straight_scenario(**kw) -> Scenario:
    line = np.array([[0.0, 0.0], [400.0, 0.0]])
    return make_scenario(line, **kw)


def left_turn_scenario(**kw) -> Scenario:
    return make_scenario(left_turn_centerline(), **kw)
