"""Scenarios built in code (straight road, curve, left turn, braking lead, follower, parallel
traffic, KITTI labels as actors) for tests, benchmarks and examples."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.core.lanelayout import (
    BACKWARD,
    BORDER,
    DRIVING,
    FORWARD,
    PARKING,
    RAIL,
    CrossSection,
    LaneSpec,
)
from vid2sim.core.records import Origin
from vid2sim.core.scenario import Actor, Ego, Road, Scenario, Source, Trajectory

ORIGIN = Origin(60.17, 24.94, 12.0)


def trajectory_along(points_m: np.ndarray, s_of_t: np.ndarray, t_s: np.ndarray,
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
    ego = trajectory_along(centerline, 5.0 + ego_speed_mps * t, t, ego_left_m)
    actors = []
    if with_actors:
        lead_v = np.where(t < 4.0, ego_speed_mps, np.maximum(ego_speed_mps - 2.0 * (t - 4.0), 3.0))
        lead_s = 30.0 + np.r_[0.0, np.cumsum(0.5 * (lead_v[1:] + lead_v[:-1]) * np.diff(t))]
        actors.append(Actor("7", "car", 4.4, 1.8, 1.5, trajectory_along(centerline, lead_s, t,
                                                                     ego_left_m)))
        tb = t[(t >= 2.0) & (t <= 9.0)]
        actors.append(Actor("9", "truck", 8.0, 2.5, 3.2, trajectory_along(
            centerline, 12.0 + (ego_speed_mps + 1.0) * tb, tb, ego_left_m + lane_width_m)))
    return Scenario(ORIGIN, [road], Ego(4.5, 1.8, 1.5, ego), actors, {"fx": 700.0},
                    Source(tool_version="test"))


def straight_scenario(**kw) -> Scenario:
    line = np.array([[0.0, 0.0], [400.0, 0.0]])
    return make_scenario(line, **kw)


def left_turn_scenario(**kw) -> Scenario:
    return make_scenario(left_turn_centerline(), **kw)


def _s_profile(t_s: np.ndarray, v0_mps: float, brake_at_s: float, decel_mps2: float,
               v_end_mps: float) -> tuple[np.ndarray, np.ndarray]:
    """Speed and distance of a vehicle at ``v0`` that brakes at ``decel`` from ``brake_at``
    down to ``v_end`` and holds it (exact integrals)."""
    t_stop = brake_at_s + (v0_mps - v_end_mps) / decel_mps2
    v = np.where(t_s < brake_at_s, v0_mps,
                 np.where(t_s < t_stop, v0_mps - decel_mps2 * (t_s - brake_at_s), v_end_mps))
    s = np.where(t_s < brake_at_s, v0_mps * t_s,
                 np.where(t_s < t_stop,
                          v0_mps * t_s - 0.5 * decel_mps2 * (t_s - brake_at_s) ** 2,
                          v0_mps * t_stop - 0.5 * decel_mps2 * (t_stop - brake_at_s) ** 2
                          + v_end_mps * (t_s - t_stop)))
    return v, s


BRAKING_LEAD = {"speed_mps": 14.0, "lead_ahead_m": 30.0, "lead_brake_s": 3.0,
                "decel_mps2": 4.0, "end_speed_mps": 4.0, "reaction_s": 1.0}
"""The hand-made braking-lead scenario's numbers: both at 14 m/s, the lead 30 m ahead
(centre to centre) brakes at 4 m/s^2 from 3 s down to 4 m/s; the recorded driver does the
same 1 s later. Gap 25.55 m at first, 15.55 m at least (lost: 2 + 6 + 2 m)."""

RUN_INTO_LEAD = {"reaction_s": math.inf}
""":func:`braking_lead_scenario` overrides for a recorded driver who never brakes: the gap
closes at 10 m/s from 5.5 s and the ego drives into the lead at 6.8 s (13.05 m / 10 m/s)."""

LATE_REACTION = {"lead_ahead_m": 40.0, "lead_brake_s": 1.0, "end_speed_mps": 6.0,
                 "reaction_s": 3.0, "ego_decel_mps2": 6.0, "ego_end_speed_mps": 6.0,
                 "straight": True}
""":func:`braking_lead_scenario` overrides with a phase of constant closing speed: on a
straight road the lead, 35.55 m ahead (bumper to bumper), brakes from 1 s to 3 s (14 -> 6
m/s), the recorded driver keeps 14 m/s until 4 s (the gap closes at 8 m/s, from 27.55 m to
19.55 m: TTC 3.44 s -> 2.44 s) and then brakes at 6 m/s^2 to 6 m/s, 14.2 m behind the lead
at least. The braking lifts the TTC at once (d TTC / dt = gap * 6 / 8^2 - 1 > 0), so the
smallest TTC is the one where the braking begins."""


def braking_lead_scenario(duration_s: float = 12.0, dt_s: float = 0.1, **overrides) -> Scenario:
    """A 2-lane LEFT curve (radius 60 m); ego in the right lane, a lead ahead in the same lane
    that brakes (see :data:`BRAKING_LEAD`), a car in the left lane overtaking at 16 m/s.

    ``overrides`` replace :data:`BRAKING_LEAD`'s numbers (``reaction_s`` inf: the recorded
    driver never brakes) and may give ``ego_decel_mps2`` and ``ego_end_speed_mps`` (the
    recorded driver's braking; default the lead's) and ``straight`` (a straight road instead
    of the curve): :data:`RUN_INTO_LEAD`, :data:`LATE_REACTION`."""
    p = dict(BRAKING_LEAD, **overrides)
    line = (np.array([[0.0, 0.0], [400.0, 0.0]]) if p.get("straight")
            else left_turn_centerline(radius_m=60.0))
    t = np.round(np.arange(0.0, duration_s + 1e-9, dt_s), 6)
    road = Road("r1", "Curve", "primary", "osm", [1], 2, 3.5, line)
    right = -1.75  # the right lane's centre, left of the centerline negative
    v_ego, s_ego = _s_profile(t, p["speed_mps"], p["lead_brake_s"] + p["reaction_s"],
                              p.get("ego_decel_mps2", p["decel_mps2"]),
                              p.get("ego_end_speed_mps", p["end_speed_mps"]))
    v_lead, s_lead = _s_profile(t, p["speed_mps"], p["lead_brake_s"], p["decel_mps2"],
                                p["end_speed_mps"])
    ego = trajectory_along(line, 5.0 + s_ego, t, right)
    lead = Actor("lead", "car", 4.4, 1.8, 1.5,
                 trajectory_along(line, 5.0 + p["lead_ahead_m"] + s_lead, t, right))
    # the exact speeds of the profiles (a central difference of s would start the braking
    # one sample early)
    ego.speed[:], lead.trajectory.speed[:] = v_ego, v_lead
    passing = Actor("left", "car", 4.6, 1.85, 1.5,
                    trajectory_along(line, -10.0 + 16.0 * t, t, right + 3.5))
    return Scenario(ORIGIN, [road], Ego(4.5, 1.8, 1.5, ego), [lead, passing],
                    {"fx": 720.0, "height_m": 1.4, "image_width": 1280},
                    Source(tool_version="test"))


def follower_scenario(duration_s: float = 8.0, dt_s: float = 0.1,
                      follower_behind_m: float = 15.0, lanes: int = 2) -> Scenario:
    """Straight road of ``lanes`` lanes: the ego at 10 m/s in the right lane with a follower
    ``follower_behind_m`` behind (centre to centre) at the same speed, no lead."""
    line = np.array([[0.0, 0.0], [400.0, 0.0]])
    t = np.round(np.arange(0.0, duration_s + 1e-9, dt_s), 6)
    road = Road("r1", "Straight", "primary", "osm", [1], lanes, 3.5, line)
    right = -(lanes - 1) * 3.5 / 2
    ego = trajectory_along(line, 50.0 + 10.0 * t, t, right)
    follower = Actor("follower", "car", 4.5, 1.8, 1.5,
                     trajectory_along(line, 50.0 - follower_behind_m + 10.0 * t, t, right))
    return Scenario(ORIGIN, [road], Ego(4.5, 1.8, 1.5, ego), [follower], {},
                    Source(tool_version="test"))


# --------------------------------------------------------------------------- camera-relative

KITTI_LIKE_CAMERA = Camera(image_width=1242, image_height=375, fx=721.5, fy=721.5, cx=609.6, cy=172.9,
                height_m=1.65)


def straight_trajectory(t_s: np.ndarray, x0_m: float, y0_m: float, heading_rad: float,
                        speed_mps: float) -> Trajectory:
    """Constant speed along a fixed heading from (x0, y0) in ENU."""
    t = np.asarray(t_s, dtype=float)
    d = speed_mps * (t - t[0])
    return Trajectory(t=t, x=x0_m + d * math.cos(heading_rad), y=y0_m + d * math.sin(heading_rad),
                      heading=np.full(t.size, heading_rad), speed=np.full(t.size, speed_mps))


def parallel_traffic_scenario(heading_rad: float = 0.6, duration_s: float = 4.0, ego_speed_mps: float = 10.0,
                  actors: list[tuple[str, float, float, float, float, float]] | None = None,
                  camera: Camera = KITTI_LIKE_CAMERA) -> Scenario:
    """A straight two-lane road along ``heading_rad`` with the ego at 10 m/s and actors given as
    (id, start forward offset [m], lateral offset [m, left +], speed [m/s], t_start, t_end)
    relative to the ego's start pose; actors drive parallel to the ego."""
    if actors is None:
        actors = [("lead", 20.0, 0.0, 8.0, 0.0, duration_s),
                  ("left", 12.0, 3.5, 12.0, 0.0, duration_s),
                  ("right_far", 45.0, -3.5, 9.0, 1.0, duration_s),
                  ("hidden", 40.0, 0.0, 8.0, 0.0, duration_s)]
    t = np.linspace(0.0, duration_s, int(duration_s * 10) + 1)
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    ego = Ego(4.5, 1.8, 1.5, straight_trajectory(t, 0.0, 0.0, heading_rad, ego_speed_mps))
    acts = []
    for aid, fwd, lat, v, t0, t1 in actors:
        ta = t[(t >= t0 - 1e-9) & (t <= t1 + 1e-9)]
        # The actor's position at ta[0] follows its constant speed from time 0.
        x0 = fwd * c - lat * s + v * ta[0] * c
        y0 = fwd * s + lat * c + v * ta[0] * s
        acts.append(Actor(aid, "car", 4.3, 1.8, 1.5,
                          straight_trajectory(ta, x0, y0, heading_rad, v)))
    line = np.array([[-10 * c, -10 * s], [200 * c, 200 * s]])
    road = Road("r0", "test road", "primary", "trajectory", [], 2, 3.5, line)
    return Scenario(origin=Origin(60.17, 24.94, 0.0), roads=[road], ego=ego, actors=acts,
                    camera=camera.to_dict(),
                    source=Source(inputs=[{"name": "synthetic"}], tool_version="test",
                                  options={"fps": 10.0}, assumptions=["built in code"]))


def scenario_from_kitti_labels(label_file: Path, numbers: tuple[int, ...], fps: float,
                               camera) -> Scenario:
    """A camera-relative scenario (static ego) whose actors sit where KITTI's 3D labels put
    the vehicles: vehicle x = camera Z, y = -camera X; yaw from rotation_y."""
    tracks: dict[str, list[tuple[float, float, float, float, tuple[float, float, float]]]] = {}
    for line in label_file.read_text().splitlines():
        f = line.split()
        if int(f[0]) not in numbers or f[2] not in ("Car", "Van", "Truck"):
            continue
        h, w, length, x, _y, z, ry = map(float, f[10:17])
        t = numbers.index(int(f[0])) / fps
        yaw = math.atan2(-math.cos(ry), -math.sin(ry))
        tracks.setdefault(f[1], []).append((t, z, -x, yaw, (length, w, h)))
    actors = []
    for tid, pts in tracks.items():
        pts.sort()
        if len(pts) == 1:  # a single sighting: hold it for a moment so it has a trajectory
            pts.append((pts[0][0] + 1e-3, *pts[0][1:]))
        t, xs, ys, yaws, sizes = zip(*pts, strict=True)
        length, w, h = sizes[0]
        actors.append(Actor(tid, "car", length, w, h,
                            Trajectory(t=t, x=xs, y=ys, heading=yaws, speed=np.zeros(len(t)))))
    t_ego = np.array([0.0, (len(numbers) - 1) / fps])
    ego = Ego(4.5, 1.8, 1.5, Trajectory(t=t_ego, x=[0, 0], y=[0, 0], heading=[0, 0],
                                        speed=[0, 0]))
    return Scenario(origin=Origin(49.0, 8.4, 0.0), roads=[], ego=ego, actors=actors,
                    camera=camera.to_dict(), source=Source(assumptions=["from KITTI 3D labels"]))


#: The street of :func:`street_scenario`, right to left: a tram's track bed beyond a kerb
#: strip, two lanes in the ego's direction, one oncoming lane, a parking strip on the left
#: (the kind of street KITTI raw 0001 drives along).
STREET_SECTION = CrossSection(-8.0, (
    LaneSpec(RAIL, FORWARD, 3.0), LaneSpec(BORDER, FORWARD, 1.5),
    LaneSpec(DRIVING, FORWARD, 3.25), LaneSpec(DRIVING, FORWARD, 3.25),
    LaneSpec(DRIVING, BACKWARD, 3.25), LaneSpec(PARKING, BACKWARD, 2.3)))


def street_scenario(duration_s: float = 12.0, dt_s: float = 0.1) -> Scenario:
    """A LEFT curve with :data:`STREET_SECTION`: the ego in the right lane at 10 m/s, a car
    overtaking in the lane left of it, an oncoming car, three cars parked on the left strip
    (static, facing the oncoming lane's way) and a tram on its bed, all where a street puts
    them (lane middles, the strip's middle, the bed's middle)."""
    line = left_turn_centerline(radius_m=60.0)
    t = np.round(np.arange(0.0, duration_s + 1e-9, dt_s), 6)
    centres = STREET_SECTION.centres_m
    road = Road("r1", "Street", "secondary", "osm", [1], STREET_SECTION.n_driving, 3.25, line,
                cross_section=STREET_SECTION)
    ego = trajectory_along(line, 10.0 + 10.0 * t, t, centres[2])
    length = float(np.sum(np.linalg.norm(np.diff(line, axis=0), axis=1)))
    oncoming = _reversed(trajectory_along(line, length - 20.0 - 11.0 * t, t, centres[4]))
    oncoming.speed[:] = 11.0
    actors = [Actor("overtaker", "car", 4.5, 1.8, 1.5,
                    trajectory_along(line, 5.0 + 12.0 * t, t, centres[3])),
              Actor("oncoming", "car", 4.5, 1.8, 1.5, oncoming),
              Actor("tram", "tram", 30.0, 2.55, 3.5,
                    trajectory_along(line, 60.0 + 8.0 * t, t, centres[0]))]
    for k, s in enumerate((50.0, 70.0, 95.0)):
        parked = trajectory_along(line, np.full_like(t, s), t, centres[5])
        parked.speed[:] = 0.0
        actors.append(Actor(f"parked{k}", "car", 4.5, 1.8, 1.5, _reversed(parked),
                            static=True))
    return Scenario(ORIGIN, [road], Ego(4.5, 1.8, 1.5, ego), actors, {"fx": 700.0},
                    Source(tool_version="test"))


def _reversed(traj: Trajectory) -> Trajectory:
    """The trajectory facing the other way (its heading turned by pi)."""
    h = np.arctan2(np.sin(traj.heading + np.pi), np.cos(traj.heading + np.pi))
    return Trajectory(traj.t, traj.x, traj.y, h, traj.speed)
