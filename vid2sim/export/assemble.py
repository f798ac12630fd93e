"""Scenario assembly: ego trajectory + roads + ranged tracks -> one :class:`Scenario`.

Each tracked vehicle's world position at time ``t`` is the ego pose at ``t`` composed with its
position in the ego frame (x forward, y left):

    forward_m = range_m + length_m / 2 + camera_ahead_m     (range is to the vehicle's REAR)
    left_m    = lateral_m + camera_left_m
    x_enu = x_ego + cos(h) * forward_m - sin(h) * left_m
    y_enu = y_ego + sin(h) * forward_m + cos(h) * left_m

so actor positions are box centres. The ego trajectory is the EgoTrack's reference point (the
GPS/camera position), taken as the ego's box centre by the simulators; ``camera_ahead_m`` /
``camera_left_m`` of :class:`AssembleConfig` (default 0) say where the camera sits relative to
that reference point.

Track rows are split where the track is unseen for ``max_gap_s`` or more (separate actors ``ID``,
``ID-2``, ...), shorter gaps are bridged by the trajectory's linear interpolation, pieces seen
for less than ``min_seen_s`` are dropped. Positions are smoothed with a Gaussian-weighted local
linear fit in time (handles irregular sampling and gaps, no lag at the ends); speed is the
fit's slope, heading the direction of motion, held while slower than ``stationary_speed_mps``
and kept within ``max_yaw_from_road_deg`` of the road axis (or its reverse for oncoming
traffic): a monocular range rate error turns a parked car's motion tens of degrees sideways,
and a yawed box projects wider than the car it stands for.

Static vehicles: a monocular range that shrinks a little slower or faster than the ego closes
in (a range scale off by some per cent) makes a parked car drive along at that share of the
ego's speed. While the ego moves (its GPS/OXTS speed at least ``static_min_ego_speed_mps``) and its
trajectory is known to ``static_max_ego_noise_m``, a
track whose world speed stays below ``static_speed_fraction`` of the ego's speed is what a
static object looks like through such a range: it is held still at its best-seen position (the
mean of its world positions weighted by 1 / range_std^2, i.e. by its nearest, sharpest views),
heading along the road.
"""

from __future__ import annotations

import math
from collections import Counter, defaultdict
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np

from vid2sim.base.defaults import EGO_HEIGHT_M, EGO_LENGTH_M, EGO_WIDTH_M, LANE_WIDTH_M
from vid2sim.base.errors import InconsistentInputError
from vid2sim.core.records import EgoTrack, RangedBox, VehicleCategory
from vid2sim.core.scenario import Actor, Ego, Road, Scenario, Source, Trajectory

if TYPE_CHECKING:
    from vid2sim.core.camera import Camera

# Typical dimensions [m] (length, width, height): EU/US passenger-car fleet medians, a rigid
# delivery truck, a 12 m city bus, a motorcycle with rider, a low-floor tram (ranging's
# prior, vid2sim.detect.ranging.config: 2.30-2.65 m wide, 3.4-3.6 m high, 20-45 m long).
CLASS_PRIORS_M: dict[VehicleCategory, tuple[float, float, float]] = {
    VehicleCategory.CAR: (4.5, 1.8, 1.5),
    VehicleCategory.TRUCK: (8.0, 2.5, 3.2),
    VehicleCategory.BUS: (12.0, 2.55, 3.1),
    VehicleCategory.MOTORCYCLE: (2.2, 0.8, 1.5),
    VehicleCategory.TRAM: (30.0, 2.55, 3.5),
}


@dataclass(frozen=True)
class AssembleConfig:
    """Parameters of :func:`assemble_scenario` (units in the names)."""

    max_gap_s: float = 1.0
    min_seen_s: float = 0.5
    smooth_sigma_s: float = 0.3
    stationary_speed_mps: float = 1.0
    """Below this speed the heading is held: monocular range noise on a parked car gives
    motion of a few tenths of a m/s in random directions."""
    camera_ahead_m: float = 0.0
    camera_left_m: float = 0.0
    ego_length_m: float = EGO_LENGTH_M
    ego_width_m: float = EGO_WIDTH_M
    ego_height_m: float = EGO_HEIGHT_M
    max_yaw_from_road_deg: float = 15.0
    """Largest angle between a vehicle's heading and the road axis (or its reverse, for
    oncoming traffic) [deg]. Monocular range rates are noisy, so the raw direction of motion of
    a slow or parked car is often tens of degrees off; 180 gives pure direction of motion."""
    oncoming_speed_mps: float = 1.0
    """A track whose median speed along the road axis is below minus this is oncoming."""
    width_ratio_bounds: tuple[float, float] = (0.6, 1.4)
    """Measured widths are clipped to these fractions of the class prior width."""
    class_priors_m: dict[VehicleCategory, tuple[float, float, float]] = field(
        default_factory=lambda: dict(CLASS_PRIORS_M))
    straight_road_lanes: int = 3
    straight_road_lane_width_m: float = LANE_WIDTH_M
    static_min_ego_speed_mps: float = 3.0
    """The ego must move at least this fast (median over the track) for its motion to tell a
    static vehicle: at walking pace a 20 % range scale error is a few tenths of a m/s either
    way, and a creeping lead in stop-and-go traffic must not be frozen."""
    static_max_ego_noise_m: float = 0.5
    """Static vehicles are held still only when the ego trajectory is known to this [m] (one
    sigma, the trace stage's estimate): a world-fixed car replays the ego's position error in
    the image, which a phone-grade GPS (2-5 m) makes larger than the monocular range error
    it removes (the demo sample, 3 m: keyframe F1 0.97 -> 0.79 with the hold), while an
    INS/RTK such as KITTI's OXTS (a few cm) does not."""
    static_speed_fraction: float = 0.3
    """A track moving slower than this share of the ego's speed (median over the track) is
    held still: monocular range scales of single tracks spread by up to about 30 % (the parked
    cars of KITTI raw 0001 shrank at 0.67-1.14 of the ego's closing speed,
    tests/detect/test_ranging_parked.py), which makes a parked car appear to move at up to that
    share of the ego's speed."""
    max_actor_speed_mps: float = 70.0
    """A track whose world speed exceeds this anywhere [m/s] is mis-ranged, not a vehicle:
    70 m/s (252 km/h) is above any road vehicle's top speed and the ``max_speed`` the
    OpenSCENARIO export declares (scenario.json's schema refuses 200). Such a track is dropped
    with a warning naming it rather than written into the scenario: an estimated camera whose
    scale the clip could not observe makes a range jump of a few metres between frames
    (the 60 s 720p clip without GPS: 219 m/s)."""


# --------------------------------------------------------------------------- maths


def local_linear_smooth(t_s: np.ndarray, values: np.ndarray, sigma_s: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Gaussian-weighted local linear regression of ``values`` at each ``t_s``.

    Returns
    -------
    smoothed : ndarray
        Fitted value at each time (same unit as ``values``).
    slope : ndarray
        Fitted derivative [unit/s].
    """
    t = np.asarray(t_s, float)
    v = np.asarray(values, float)
    if t.size == 1:
        return v.copy(), np.zeros(1)
    level, slope = np.empty_like(v), np.empty_like(v)
    block = 256  # rows per block; samples beyond 5 sigma carry no weight (< 4e-6)
    for i0 in range(0, t.size, block):
        i1 = min(i0 + block, t.size)
        j0 = int(np.searchsorted(t, t[i0] - 5 * sigma_s))
        j1 = int(np.searchsorted(t, t[i1 - 1] + 5 * sigma_s, side="right"))
        dt = t[None, j0:j1] - t[i0:i1, None]  # row i: offsets of the samples from t_i
        vv = v[None, j0:j1]
        w = np.exp(-0.5 * (dt / sigma_s) ** 2)
        sw, swt, swtt = w.sum(1), (w * dt).sum(1), (w * dt * dt).sum(1)
        swv, swtv = (w * vv).sum(1), (w * dt * vv).sum(1)
        det = sw * swtt - swt**2
        ok = det > 1e-9 * sw * np.maximum(swtt, 1e-300)
        b = np.where(ok, (sw * swtv - swt * swv) / np.where(ok, det, 1.0), 0.0)
        slope[i0:i1] = b
        level[i0:i1] = (swv - b * swt) / sw
    return level, slope


def heading_from_motion(vx_mps: np.ndarray, vy_mps: np.ndarray, fallback_rad: np.ndarray,
                        stationary_speed_mps: float) -> np.ndarray:
    """Direction of motion [rad, CCW from east], held through slow stretches.

    Samples slower than ``stationary_speed_mps`` keep the previous moving heading; slow samples
    before the first moving one take the first moving heading; a never-moving vehicle takes
    ``fallback_rad`` (e.g. the ego heading: a parked car usually faces along the road).
    """
    speed = np.hypot(vx_mps, vy_mps)
    moving = speed >= stationary_speed_mps
    if not moving.any():
        return np.asarray(fallback_rad, float).copy()
    heading = np.arctan2(vy_mps, vx_mps)
    idx = np.where(moving, np.arange(speed.size), -1)
    idx = np.maximum.accumulate(idx)
    idx[idx < 0] = int(np.argmax(moving))
    return heading[idx]


class RoadAxis:
    """Nearest-tangent lookup over roads' centerlines: built once per scenario, queried per
    actor (rebuilding it per actor made assembly quadratic in the video's length: 3.7 s at
    1,500 frames, 53.5 s at 6,000)."""

    #: spacing of the lookup points along each centerline [m]
    STEP_M = 2.0

    def __init__(self, roads: list[Road]):
        from scipy.spatial import cKDTree  # scipy.spatial: imported where it is needed

        pts, heads = [], []
        for road in roads:
            c = np.asarray(road.centerline, float)
            seg = np.diff(c, axis=0)
            length = np.linalg.norm(seg, axis=1)
            keep = length > 1e-9
            if not keep.any():
                continue
            # points every <= STEP_M along each segment, each with its segment's heading
            p0, d = c[:-1][keep], seg[keep]
            n = np.ceil(length[keep] / self.STEP_M).astype(int)
            owner = np.repeat(np.arange(len(n)), n)
            first = np.repeat(np.cumsum(n) - n, n)
            frac = ((np.arange(owner.size) - first) / n[owner])[:, None]
            pts.append(p0[owner] + frac * d[owner])
            heads.append(np.arctan2(d[:, 1], d[:, 0])[owner])
        if not pts:
            raise ValueError("roads without centerlines")
        self._tree = cKDTree(np.vstack(pts))
        self._heading = np.concatenate(heads)

    def heading_at(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Heading of the nearest centerline's tangent (travel order) at ENU points [rad]."""
        _, idx = self._tree.query(np.column_stack((x_m, y_m)))
        return self._heading[idx]


def road_axis_heading(roads: list[Road], x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    """Heading of the nearest road centerline's tangent (travel order) at ENU points [rad].

    For many queries on the same roads build one :class:`RoadAxis` and query it.
    """
    return RoadAxis(roads).heading_at(x_m, y_m)


def heading_along_road(vx_mps: np.ndarray, vy_mps: np.ndarray, axis_rad: np.ndarray,
                       cfg: AssembleConfig) -> np.ndarray:
    """Heading from motion, regularised by the road axis [rad, CCW from east].

    The track is oncoming when its median velocity along the axis is below
    ``-oncoming_speed_mps`` (then its base heading is the reversed axis). While it moves forward
    along its base direction faster than ``stationary_speed_mps`` the heading is the direction
    of motion, clipped to ``max_yaw_from_road_deg`` either side of the base; slower samples hold
    the last moving offset (zero before any).
    """
    ca, sa = np.cos(axis_rad), np.sin(axis_rad)
    v_along = vx_mps * ca + vy_mps * sa
    v_left = -vx_mps * sa + vy_mps * ca
    sign = -1.0 if np.median(v_along) < -cfg.oncoming_speed_mps else 1.0
    u, w = sign * v_along, sign * v_left  # forward and leftward in the vehicle's own direction
    moving = u >= cfg.stationary_speed_mps
    max_yaw = math.radians(cfg.max_yaw_from_road_deg)
    offset = np.where(moving, np.clip(np.arctan2(w, np.maximum(u, 1e-9)), -max_yaw, max_yaw), 0.0)
    idx = np.maximum.accumulate(np.where(moving, np.arange(u.size), -1))
    held = np.where(idx >= 0, offset[np.maximum(idx, 0)], 0.0)
    return axis_rad + (math.pi if sign < 0 else 0.0) + held


def is_static(speed_mps: np.ndarray, ego_speed_mps: np.ndarray, cfg: AssembleConfig) -> bool:
    """Whether a track with these world speeds is a static object seen through a monocular
    range (see the module docstring): the ego moves (median speed at least
    ``cfg.static_min_ego_speed_mps``) and the track's median speed is below
    ``cfg.static_speed_fraction`` of the ego's."""
    ego = float(np.median(np.abs(ego_speed_mps))) if len(ego_speed_mps) else 0.0
    if not (ego >= cfg.static_min_ego_speed_mps) or len(speed_mps) < 2:
        return False
    return float(np.median(speed_mps)) < cfg.static_speed_fraction * ego


def _ego_pose_at(ego: EgoTrack, t_s: np.ndarray, heading_unwrapped: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    h = (np.unwrap(np.asarray(ego.heading_rad, float)) if heading_unwrapped is None
         else heading_unwrapped)
    return (np.interp(t_s, ego.t_s, ego.x_m), np.interp(t_s, ego.t_s, ego.y_m),
            np.interp(t_s, ego.t_s, h))


# --------------------------------------------------------------------------- roads


def _ego_xyh(ego) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    if isinstance(ego, EgoTrack):
        return np.asarray(ego.x_m, float), np.asarray(ego.y_m, float), np.asarray(ego.heading_rad, float)
    traj = ego.trajectory if isinstance(ego, Ego) else ego
    return traj.x, traj.y, traj.heading


def straight_road_for(ego: EgoTrack | Ego | Trajectory, lanes: int = 3,
                      lane_width_m: float = LANE_WIDTH_M, ahead_m: float = 150.0,
                      behind_m: float = 50.0) -> Road:
    """A straight road under the ego for scenarios without a map.

    The road runs along the ego's overall direction of travel (first to last position, or the
    initial heading when the ego barely moves), from ``behind_m`` before its first position to
    ``ahead_m`` beyond its last one (vehicles seen ahead of a stopped ego need road), with the
    ego in the middle lane (for an even count, the lane right of the centre: right-hand
    traffic).
    """
    x, y, h = _ego_xyh(ego)
    start, end = np.array([x[0], y[0]]), np.array([x[-1], y[-1]])
    if np.linalg.norm(end - start) > 1.0:
        d = (end - start) / np.linalg.norm(end - start)
    else:
        d = np.array([math.cos(h[0]), math.sin(h[0])])
    left = np.array([-d[1], d[0]])
    along = (np.column_stack((x, y)) - start) @ d
    ego_lane = lanes // 2  # 0 = leftmost
    ego_left_of_centre_m = ((lanes - 1) / 2.0 - ego_lane) * lane_width_m
    base = start - ego_left_of_centre_m * left
    centerline = np.array([base + (along.min() - behind_m) * d, base + (along.max() + ahead_m) * d])
    return Road(id="straight", name="", highway="unknown", source="assumed", osm_way_ids=[],
                lanes=int(lanes), lane_width_m=float(lane_width_m), centerline=centerline)


# --------------------------------------------------------------------------- tracks


def _split_rows(rows: list[RangedBox], max_gap_s: float) -> list[list[RangedBox]]:
    rows = sorted(rows, key=lambda r: r.t_s)
    pieces: list[list[RangedBox]] = [[]]
    for r in rows:
        if pieces[-1] and r.t_s - pieces[-1][-1].t_s >= max_gap_s:
            pieces.append([])
        if pieces[-1] and r.t_s <= pieces[-1][-1].t_s:
            continue  # one row per time; a duplicate frame adds nothing
        pieces[-1].append(r)
    return [p for p in pieces if p]


def _dimensions(rows: list[RangedBox], cfg: AssembleConfig, warnings: list[str], label: str
                ) -> tuple[str, float, float, float]:
    category = Counter(r.category for r in rows).most_common(1)[0][0]
    prior = cfg.class_priors_m.get(category)
    if prior is None:
        warnings.append(f"track {label}: unknown category {category!r}, car dimensions used")
        prior = cfg.class_priors_m[VehicleCategory.CAR]
    length, width, height = prior
    widths = np.array([r.width_m for r in rows], float)
    widths = widths[np.isfinite(widths) & (widths > 0)]
    if widths.size:
        lo, hi = cfg.width_ratio_bounds
        width = float(np.clip(np.median(widths), lo * prior[1], hi * prior[1]))
    return category, float(length), float(width), float(height)


def _actor_from_rows(rows: list[RangedBox], actor_id: str, ego: EgoTrack, cfg: AssembleConfig,
                     warnings: list[str], roads: list[Road] | RoadAxis | None = None,
                     ego_heading_unwrapped: np.ndarray | None = None,
                     hold_static: bool = False, standing: bool = False,
                     ground_m: float = 0.0) -> Actor:
    category, length, width, height = _dimensions(rows, cfg, warnings, actor_id)
    t = np.array([r.t_s for r in rows], float)
    xe, ye, he = _ego_pose_at(ego, t, ego_heading_unwrapped)
    fwd = np.array([r.range_m for r in rows], float) + length / 2.0 + cfg.camera_ahead_m
    lft = np.array([r.lateral_m for r in rows], float) + cfg.camera_left_m
    # rotate the ego-frame offset (x forward, y left) by the ego heading (CCW from east)
    x = xe + np.cos(he) * fwd - np.sin(he) * lft
    y = ye + np.sin(he) * fwd + np.cos(he) * lft
    xs, vx = local_linear_smooth(t, x, cfg.smooth_sigma_s)
    ys, vy = local_linear_smooth(t, y, cfg.smooth_sigma_s)
    held = (hold_static and not standing
            and is_static(np.hypot(vx, vy), np.interp(t, ego.t_s, ego.speed_mps), cfg))
    if standing or held:
        # Held still where it was seen best (see the module docstring).
        wts = 1.0 / np.maximum(np.array([r.range_std_m for r in rows], float), 0.1) ** 2
        wts = np.where(np.isfinite(wts), wts, 0.0) + 1e-12
        xs = np.full_like(xs, float(np.sum(wts * x) / np.sum(wts)))
        ys = np.full_like(ys, float(np.sum(wts * y) / np.sum(wts)))
        vx, vy = np.zeros_like(vx), np.zeros_like(vy)
        axis = (roads if isinstance(roads, RoadAxis) else RoadAxis(roads)) if roads else None
        he = (axis.heading_at(xs[:1], ys[:1]) if axis is not None
              else np.array([float(np.median(he))]))
        heading = np.full_like(xs, float(he[0]))
        return Actor(id=actor_id, category=category, length_m=length, width_m=width,
                     height_m=height, trajectory=Trajectory(t, xs, ys, heading, np.zeros_like(t)),
                     static=True, static_by="ranging" if standing else "assembly",
                     ground_m=ground_m)
    if roads and cfg.max_yaw_from_road_deg < 180.0:
        axis = roads if isinstance(roads, RoadAxis) else RoadAxis(roads)
        heading = heading_along_road(vx, vy, axis.heading_at(xs, ys), cfg)
    else:
        heading = heading_from_motion(vx, vy, he, cfg.stationary_speed_mps)
    speed = np.hypot(vx, vy)
    return Actor(id=actor_id, category=category, length_m=length, width_m=width,
                 height_m=height, trajectory=Trajectory(t, xs, ys, heading, speed),
                 ground_m=ground_m)


def actors_from_tracks(tracks: list[RangedBox], ego: EgoTrack,
                       config: AssembleConfig | None = None, roads: list[Road] | None = None,
                       ego_noise_m: float | None = None,
                       standing_tracks: frozenset[int] = frozenset(),
                       ground_m_by_track: dict[int, float] | None = None
                       ) -> tuple[list[Actor], list[str]]:
    """World trajectories of tracked vehicles (see the module docstring); also warnings.

    With ``roads``, headings are regularised by the road axis (:func:`heading_along_road`);
    without, they are the plain direction of motion (:func:`heading_from_motion`). Tracks the
    ranging fitted as standing vehicles from the ego's motion (``standing_tracks``) stand
    still (``static_by`` "ranging"); the others are held still by the speed rule only when
    the ego trajectory's position noise ``ego_noise_m`` is known and at most
    ``static_max_ego_noise_m`` (``static_by`` "assembly"). ``ground_m_by_track``: the height
    of the ground under each track above the ego's road (the ranging's), kept per actor."""
    cfg = config or AssembleConfig()
    hold = ego_noise_m is not None and ego_noise_m <= cfg.static_max_ego_noise_m
    warnings: list[str] = []
    by_id: dict[int, list[RangedBox]] = defaultdict(list)
    n_bad = 0
    for r in tracks:
        if math.isfinite(r.range_m) and math.isfinite(r.lateral_m) and math.isfinite(r.t_s):
            by_id[int(r.track_id)].append(r)
        else:
            n_bad += 1
    if n_bad:
        warnings.append(f"{n_bad} track rows without a finite range/lateral/time were skipped")
    t_lo, t_hi = float(ego.t_s[0]), float(ego.t_s[-1])
    # Shared by every actor: built once, so the cost stays linear in the number of actors.
    axis = RoadAxis(roads) if roads and cfg.max_yaw_from_road_deg < 180.0 else None
    ego_heading = np.unwrap(np.asarray(ego.heading_rad, float))
    actors: list[Actor] = []
    n_short = 0
    for track_id in sorted(by_id):
        pieces = _split_rows(by_id[track_id], cfg.max_gap_s)
        kept = [p for p in pieces if p[-1].t_s - p[0].t_s >= cfg.min_seen_s - 1e-9]
        n_short += len(pieces) - len(kept)
        for k, rows in enumerate(kept):
            actor_id = str(track_id) if k == 0 else f"{track_id}-{k + 1}"
            if rows[0].t_s < t_lo - 0.5 or rows[-1].t_s > t_hi + 0.5:
                warnings.append(f"track {actor_id}: seen outside the ego trajectory's time span "
                                f"[{t_lo:.1f}, {t_hi:.1f}] s; ego pose held at the ends")
            actor = _actor_from_rows(
                rows, actor_id, ego, cfg, warnings, axis, ego_heading, hold,
                track_id in standing_tracks, round(float((ground_m_by_track or {}).get(
                    track_id, 0.0)), 3))
            fastest = float(np.max(actor.trajectory.speed, initial=0.0))
            if not fastest <= cfg.max_actor_speed_mps:
                warnings.append(f"track {actor_id}: world speed {fastest:.0f} m/s is no "
                                f"vehicle's (over {cfg.max_actor_speed_mps:g}): mis-ranged, "
                                "dropped (check the camera: pass --camera or --gps)")
                continue
            actors.append(actor)
    if n_short:
        warnings.append(f"{n_short} track pieces seen for less than {cfg.min_seen_s:g} s dropped")
    return actors, warnings


# --------------------------------------------------------------------------- scenario


def ego_from_track(ego: EgoTrack, config: AssembleConfig | None = None) -> Ego:
    """The scenario's ego record: the EgoTrack's poses and speeds with configured dimensions."""
    cfg = config or AssembleConfig()
    traj = Trajectory(ego.t_s, ego.x_m, ego.y_m, ego.heading_rad,
                      np.maximum(np.asarray(ego.speed_mps, float), 0.0))
    return Ego(cfg.ego_length_m, cfg.ego_width_m, cfg.ego_height_m, traj)


def assemble_scenario(ego: EgoTrack, roads: list[Road], tracks: list[RangedBox] | None,
                      camera: Camera, *, source: Source,
                      config: AssembleConfig | None = None,
                      ego_noise_m: float | None = None,
                      standing_tracks: frozenset[int] = frozenset(),
                      ground_m_by_track: dict[int, float] | None = None
                      ) -> tuple[Scenario, list[str]]:
    """Build the scenario from the pipeline's records.

    Parameters
    ----------
    ego : EgoTrack
        Smoothed ego trajectory (scenario clock, ENU).
    roads : list of Road
        Matched roads; empty means no map: a straight road is assumed (and recorded).
    tracks : list of RangedBox or None
        Ranged tracked boxes (``tracks.csv`` rows); None or empty gives a scenario without
        actors.
    camera : Camera
        The camera; stored in the scenario (with its assumptions added to ``source``).
    source : Source
        Provenance; copied, this function appends its own assumptions.
    ego_noise_m : float, optional
        One-sigma position noise of the ego trajectory [m] (None: unknown, e.g. no GPS);
        static vehicles are held still only below ``config.static_max_ego_noise_m``.
    standing_tracks : frozenset of int
        Tracks the ranging fitted as standing vehicles from the ego's own motion
        (:attr:`vid2sim.core.records.RangingResult.standing_tracks`): replayed standing.
    ground_m_by_track : dict, optional
        Track id -> height of the ground it stands on above the ego's road [m].

    Returns
    -------
    scenario : Scenario
    warnings : list of str
        Human-readable notes (dropped pieces, skipped rows, assumptions).
    """
    cfg = config or AssembleConfig()
    if len(ego.t_s) < 2:

        raise InconsistentInputError(None, "the ego trajectory has fewer than two samples",
                                     "check the GPS input and --gps-offset")
    warnings: list[str] = []
    assumptions = list(source.assumptions)
    assumptions.extend(a for a in camera.assumptions if a not in assumptions)
    roads = list(roads)
    if not roads:
        roads = [straight_road_for(ego, cfg.straight_road_lanes, cfg.straight_road_lane_width_m)]
        note = (f"no road map: straight {cfg.straight_road_lanes}-lane road of "
                f"{cfg.straight_road_lane_width_m:g} m lanes along the ego's direction of travel")
        assumptions.append(note)
        warnings.append(note)
    actors: list[Actor] = []
    if tracks:
        actors, track_warnings = actors_from_tracks(tracks, ego, cfg, roads, ego_noise_m,
                                                    standing_tracks, ground_m_by_track)
        warnings.extend(track_warnings)
        assumptions.append(
            f"actor dimensions from class priors {sorted(str(c) for c in cfg.class_priors_m)} (length, height) "
            f"and the measured width; camera {cfg.camera_ahead_m:g} m ahead and "
            f"{cfg.camera_left_m:g} m left of the ego reference point")
    scenario = Scenario(origin=ego.origin, roads=roads, ego=ego_from_track(ego, cfg),
                        actors=actors, camera=camera.to_dict(),
                        source=replace(source, assumptions=assumptions))
    return scenario, warnings
