"""The demo's traffic: the lead's braking, the cut-in, oncoming and parked cars (IDM-driven)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from vid2sim.samples.demo_drive import (
    ACTORS,
    CAMERA_BEHIND_FRONT_M,
    EGO_LANE_OFFSET_M,
    EGO_START_S_M,
    EGO_WIDTH_M,
    LEFT_LANE_OFFSET_M,
    PARKED_OFFSET_M,
    PARKED_S_M,
    SIM_DT_S,
)
from vid2sim.samples.render import RoadGeometry

# --------------------------------------------------------------------------- traffic


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _quintic(x: np.ndarray | float) -> np.ndarray:
    """Minimum-jerk blend 0 -> 1 (zero slope and curvature at both ends): a lane change."""
    x = np.clip(x, 0.0, 1.0)
    return x ** 3 * (10.0 - 15.0 * x + 6.0 * x * x)


def _idm_accel(v: float, gap_m: float, dv_mps: float, v0: float, t_headway_s: float = 1.4,
               s0_m: float = 2.5, a_max: float = 1.5, b_comf: float = 2.5) -> float:
    """Intelligent Driver Model acceleration (Treiber, Hennecke, Helbing 2000) [m/s^2].

    ``dv_mps`` = own speed - leader speed (positive when closing); ``gap_m`` bumper to bumper.
    """
    free = 1.0 - (v / v0) ** 4
    if not math.isfinite(gap_m):
        return a_max * free
    s_star = s0_m + max(0.0, v * t_headway_s + v * dv_mps / (2.0 * math.sqrt(a_max * b_comf)))
    return a_max * (free - (s_star / max(gap_m, 0.1)) ** 2)


@dataclass(slots=True)
class TrafficTruth:
    """Every vehicle's road coordinates at the simulation step.

    :param t_s: (K,) times from the first video frame [s]
    :param s_m: name -> (K,) arc length along the route [m] (of the footprint centre; for the
        ego, of the camera's ground point)
    :param d_m: name -> (K,) lateral offset from the centerline, positive left [m]
    """

    t_s: np.ndarray
    s_m: dict[str, np.ndarray] = field(default_factory=dict)
    d_m: dict[str, np.ndarray] = field(default_factory=dict)


def simulate_traffic(duration_s: float, route_length_m: float) -> TrafficTruth:
    """The scripted drive in road coordinates (deterministic; no randomness at all).

    - lead: 13 m/s, brakes smoothly to 6 m/s (peak 3 m/s^2) from t = 11 s, then holds;
    - ego: Intelligent Driver Model behind whatever is ahead in its lane;
    - cut-in: starts 15 m behind the ego in the left lane at 16.5 m/s, passes, and changes
      lane (3 s minimum-jerk) once it is 8 m clear of the ego's front; IDM on the lead;
    - oncoming car and van in the left lane, timed to pass the ego after the cut-in;
    - three cars parked in the parking strip along the right kerb.
    """
    n = math.ceil((duration_s + 1.0) / SIM_DT_S) + 1
    t = np.arange(n) * SIM_DT_S
    spec = {a.id: a for a in ACTORS}
    lead, cut = spec["lead"], spec["cutin"]

    # Lead: a smoothstep speed change over 3.5 s has peak deceleration 1.5 * 7 / 3.5 = 3 m/s^2.
    brake_start_s, brake_len_s, v_hi, v_lo = 11.0, 3.5, 13.0, 6.0
    v_lead = v_hi + (v_lo - v_hi) * _smoothstep((t - brake_start_s) / brake_len_s)
    s_lead0 = EGO_START_S_M + CAMERA_BEHIND_FRONT_M + 25.0 + lead.length_m / 2.0
    s_lead = s_lead0 + np.concatenate(([0.0], np.cumsum((v_lead[1:] + v_lead[:-1]) / 2.0)
                                       * SIM_DT_S))

    s_ego = np.empty(n)
    v_ego = np.empty(n)
    s_cut = np.empty(n)
    v_cut = np.empty(n)
    d_cut = np.full(n, LEFT_LANE_OFFSET_M)
    s_ego[0], v_ego[0] = EGO_START_S_M, 13.0
    s_cut[0], v_cut[0] = EGO_START_S_M - 15.0, 16.5
    lc_start = None
    lc_duration_s = 3.0
    ego_front = CAMERA_BEHIND_FRONT_M
    for k in range(n - 1):
        # Cut-in lane change: trigger once its rear clears the ego's front by 8 m.
        if lc_start is None and s_cut[k] - cut.length_m / 2.0 > s_ego[k] + ego_front + 8.0:
            lc_start = t[k]
        if lc_start is not None:
            d_cut[k] = LEFT_LANE_OFFSET_M + (EGO_LANE_OFFSET_M - LEFT_LANE_OFFSET_M) * \
                _quintic((t[k] - lc_start) / lc_duration_s)
        # Cut-in: free road while overtaking in the left lane, then follows the lead.
        if lc_start is None:
            a_cut = _idm_accel(v_cut[k], math.inf, 0.0, v0=16.5)
        else:
            gap_cut = (s_lead[k] - lead.length_m / 2.0) - (s_cut[k] + cut.length_m / 2.0)
            a_cut = _idm_accel(v_cut[k], gap_cut, v_cut[k] - v_lead[k], v0=16.5)
        # Ego: leader = nearest vehicle ahead overlapping its lane laterally.
        leaders = [(s_lead[k] - lead.length_m / 2.0, v_lead[k])]
        if abs(d_cut[k] - EGO_LANE_OFFSET_M) < (EGO_WIDTH_M + cut.width_m) / 2.0 + 0.3 and \
                s_cut[k] > s_ego[k]:
            leaders.append((s_cut[k] - cut.length_m / 2.0, v_cut[k]))
        rear, v_lead_k = min(leaders)
        a_ego = _idm_accel(v_ego[k], rear - (s_ego[k] + ego_front), v_ego[k] - v_lead_k, v0=14.0)
        # Braking limits: an ACC-like -4 m/s^2 for the ego (IDM alone brakes implausibly
        # hard when a car cuts in), a car's -6 m/s^2 for the cut-in.
        for arr_v, arr_s, a in ((v_ego, s_ego, max(a_ego, -4.0)),
                                (v_cut, s_cut, max(a_cut, -6.0))):
            arr_v[k + 1] = max(0.0, arr_v[k] + a * SIM_DT_S)
            arr_s[k + 1] = arr_s[k] + (arr_v[k] + arr_v[k + 1]) / 2.0 * SIM_DT_S
    if lc_start is not None:
        d_cut[-1] = LEFT_LANE_OFFSET_M + (EGO_LANE_OFFSET_M - LEFT_LANE_OFFSET_M) * \
            _quintic((t[-1] - lc_start) / lc_duration_s)

    truth = TrafficTruth(t_s=t)
    truth.s_m.update(ego=s_ego, lead=s_lead, cutin=s_cut)
    truth.d_m.update(ego=np.full(n, EGO_LANE_OFFSET_M), lead=np.full(n, EGO_LANE_OFFSET_M),
                     cutin=d_cut)
    # Oncoming traffic, timed by when it meets the ego (constant speed, left lane).
    for name, meet_s, speed in (("oncoming1", 15.5, 12.5), ("oncoming2", 21.0, 11.0)):
        s_meet = float(np.interp(meet_s, t, s_ego))
        truth.s_m[name] = s_meet + speed * (meet_s - t)
        truth.d_m[name] = np.full(n, LEFT_LANE_OFFSET_M)
    for name, s_parked in PARKED_S_M.items():
        truth.s_m[name] = np.full(n, s_parked)
        truth.d_m[name] = np.full(n, PARKED_OFFSET_M)
    for name, s in truth.s_m.items():
        if s.min() < 0.0 or s.max() > route_length_m:
            raise RuntimeError(f"demo drive: {name} leaves the {route_length_m:.0f} m route")
    return truth


@dataclass(slots=True)
class EnuTrack:
    """A vehicle's ENU trajectory at the simulation step."""

    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray
    speed_mps: np.ndarray


def traffic_to_enu(traffic: TrafficTruth, road: RoadGeometry) -> dict[str, EnuTrack]:
    """Road coordinates -> ENU; heading and speed from the ENU motion itself, so they are
    consistent with the positions (the lateral motion of a lane change included)."""
    out = {}
    for name, s in traffic.s_m.items():
        xy = road.points_at(s, traffic.d_m[name])
        vel = np.gradient(xy, SIM_DT_S, axis=0)
        speed = np.hypot(vel[:, 0], vel[:, 1])
        heading = np.unwrap(np.arctan2(vel[:, 1], vel[:, 0]))
        if speed.max() < 1e-6:
            # Parked: the direction of the road (a stationary car has no velocity heading).
            n = road.points_at(s, 1.0) - road.points_at(s, 0.0)
            heading = np.unwrap(np.arctan2(-n[:, 0], n[:, 1]))
        # Smooth the heading over 0.2 s: the piecewise-linear centerline makes its derivative
        # step at every 0.5 m sample, which is not how a car yaws.
        kernel = np.ones(21) / 21.0
        heading = np.convolve(np.pad(heading, 10, mode="edge"), kernel, mode="valid")
        out[name] = EnuTrack(xy[:, 0], xy[:, 1], heading, speed)
    return out


