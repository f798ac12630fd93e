"""Range-rate and range truth for STATIC vehicles from the ego motion of a KITTI raw drive.

Used by ``tests/detect/test_ranging_parked.py`` and ``benchmarks/bench_ranging.py --parked``
(one definition of the truth for both).

Derivation. Take a body frame x forward, y left, z up, moving in the road plane with
velocity (vf, vl) and yaw rate wz (positive turning left, counter-clockwise seen from above:
the OXTS ``wz`` has the sign of d(yaw)/dt, checked on drive 0001, correlation 0.995). A point
P fixed in the world has, in a body frame whose origin is O, coordinates p with

    dp/dt = -v_O - w x p,   w x p = (-wz * p_y, wz * p_x, 0)

so dp_x/dt = -v_O,x + wz * p_y. For O the IMU, v_O,x = vf. The camera frame is the body frame
shifted by the lever arm r (camera position relative to the IMU); shifting the origin does
not change x-differences, so d(range)/dt = -vf + wz * (lateral + r_y), with ``lateral`` the
point's y relative to the camera and r_y the camera's y relative to the IMU. In KITTI the
left grey camera sits 1.08 m ahead of and 0.32 m to the RIGHT of the OXTS (r_y = -0.32 m, from
calib_imu_to_velo.txt and calib_velo_to_cam.txt); with |wz| <= 0.042 rad/s on drive 0001 the
lever arm changes the rate by at most 0.013 m/s.

Time bases: the pipeline's ``t_s`` is frame / video fps (10 fps in the MPEG-4 file) while the
camera really captured every 0.1032 s on average (9.7 Hz, image_00_timestamps.txt), so a rate
in "per video second" is 3.2 % larger in magnitude than the same rate per real second. The
truth here is given in the pipeline's time base (the change of range per frame times the
video fps) so the comparison measures ranging, not the file's frame rate; ``real_rate_mps``
keeps the physical value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vid2sim.core.camera import Camera, parse_kitti_calib
from vid2sim.core.records import RangedBox, RangingResult
from vid2sim.geo.readers import (
    OXTS_VF,
    OXTS_VL,
    OXTS_WZ,
    read_kitti_oxts_table,
    read_kitti_stamps,
)

RANGE_BINS_M = ((0.0, 20.0), (20.0, 40.0), (40.0, math.inf))


def static_range_rate(vf_mps, wz_radps, lateral_m, camera_left_of_imu_m: float = 0.0):
    """d(range)/dt [m/s] of a static point at ``lateral_m`` (left positive, from the camera)
    for an ego with forward speed ``vf_mps`` and yaw rate ``wz_radps`` (left positive), both
    measured at an IMU that the camera sits ``camera_left_of_imu_m`` to the left of (negative:
    to the right). Works on scalars and arrays."""
    return -np.asarray(vf_mps) + np.asarray(wz_radps) * (np.asarray(lateral_m)
                                                          + camera_left_of_imu_m)


def _calib(path: Path) -> tuple[np.ndarray, np.ndarray]:
    vals = parse_kitti_calib(path.read_text())
    return vals["R"].reshape(3, 3), vals["T"]


def camera_from_imu_m(drive: Path) -> np.ndarray:
    """Position (x forward, y left, z up) of the camera relative to the OXTS unit [m], from
    the drive's KITTI calibration (IMU -> velodyne -> camera 0)."""
    r_vi, t_vi = _calib(drive / "calib_imu_to_velo.txt")  # p_velo = R p_imu + T
    r_cv, t_cv = _calib(drive / "calib_velo_to_cam.txt")  # p_cam = R p_velo + T
    cam_in_velo = -r_cv.T @ t_cv
    return r_vi.T @ (cam_in_velo - t_vi)  # velodyne and IMU axes are both x fwd, y left


@dataclass
class EgoMotion:
    """The ego motion at each video frame (from OXTS interpolated to the frame stamps)."""

    t_real_s: np.ndarray  # capture time of each frame, from its first [s]
    vf_mps: np.ndarray
    wz_radps: np.ndarray
    frame_dt_s: np.ndarray  # real time per frame about each frame [s]
    xy_m: np.ndarray  # (N, 2) camera position in a world frame fixed at frame 0's IMU
    yaw_rad: np.ndarray
    camera_m: np.ndarray  # camera position relative to the IMU (x, y, z) [m]

    @property
    def camera_left_of_imu_m(self) -> float:
        return float(self.camera_m[1])


def ego_motion(drive: Path) -> EgoMotion:
    """Read a KITTI raw drive's OXTS and image_00 stamps; integrate the planar pose."""
    oxts = read_kitti_oxts_table(drive)
    t_ox = np.array(read_kitti_stamps(drive / "oxts" / "timestamps.txt"))
    t_im = np.array(read_kitti_stamps(drive / "image_00_timestamps.txt"))
    t0 = t_im[0]
    t_ox, t_im = t_ox - t0, t_im - t0
    vf, vl, wz = oxts[:, OXTS_VF], oxts[:, OXTS_VL], oxts[:, OXTS_WZ]
    # Planar dead reckoning of the IMU (trapezoid rule) at the OXTS stamps.
    dt = np.diff(t_ox)
    yaw = np.concatenate(([0.0], np.cumsum(0.5 * (wz[1:] + wz[:-1]) * dt)))
    vx = vf * np.cos(yaw) - vl * np.sin(yaw)
    vy = vf * np.sin(yaw) + vl * np.cos(yaw)
    x = np.concatenate(([0.0], np.cumsum(0.5 * (vx[1:] + vx[:-1]) * dt)))
    y = np.concatenate(([0.0], np.cumsum(0.5 * (vy[1:] + vy[:-1]) * dt)))

    def at(a: np.ndarray) -> np.ndarray:  # OXTS stamps lead/lag the frames' by < 5 ms
        return np.interp(t_im, t_ox, a)

    yaw_f = at(yaw)
    cam = camera_from_imu_m(drive)
    c, s = np.cos(yaw_f), np.sin(yaw_f)
    xy = np.column_stack((at(x) + c * cam[0] - s * cam[1], at(y) + s * cam[0] + c * cam[1]))
    return EgoMotion(t_im, at(vf), at(wz), np.gradient(t_im), xy, yaw_f, cam)


@dataclass
class ParkedRow:
    """One box of a static vehicle with its truth."""

    track_id: int
    frame: int
    t_s: float
    range_m: float
    lateral_m: float
    rate_mps: float  # the pipeline's range rate
    true_rate_mps: float  # truth in the pipeline's time base (frame / video fps)
    real_rate_mps: float  # truth per real second
    odo_range_m: float  # range of the track's median world point seen from this frame


def select_static(boxes: list[RangedBox], min_boxes: int = 5, min_abs_lateral_m: float = 4.5
                  ) -> tuple[list[int], dict[int, str]]:
    """Track ids taken as parked cars, and every other track with the reason it is left out.

    Parked: category car, at least ``min_boxes`` boxes, and the median lateral offset beyond
    the neighbouring lane's centre by half a car (|lateral| > 3.6 + 0.9 m): a car in the ego
    lane or the next one may be driving (the weak-detection tracks also find one 45 m ahead
    in the lane to the right, driving away at the ego's speed). Parked cars stand at the kerb
    or in a car park, 6-22 m to the left in this drive. Nothing is dropped for disagreeing
    with the truth."""
    by_track: dict[int, list[RangedBox]] = {}
    for b in boxes:
        by_track.setdefault(b.track_id, []).append(b)
    keep, excluded = [], {}
    for tid, bs in sorted(by_track.items()):
        lat = float(np.median([b.lateral_m for b in bs]))
        if bs[0].category != "car":
            excluded[tid] = f"category {bs[0].category}"
        elif len(bs) < min_boxes:
            excluded[tid] = f"only {len(bs)} boxes"
        elif abs(lat) <= min_abs_lateral_m:
            excluded[tid] = (f"median lateral {lat:+.1f} m: in the ego lane or the next one, "
                             "may be driving")
        else:
            keep.append(tid)
    return keep, excluded


def static_truth(boxes: list[RangedBox], motion: EgoMotion, track_ids: list[int]
                 ) -> list[ParkedRow]:
    """Truth for each box of the given (static) tracks.

    The range rate from :func:`static_range_rate` with the box's estimated lateral offset
    (an error of 1 m there moves the truth by at most 0.04 m/s here). ``odo_range_m``: each box's
    (range, lateral) placed in the world with the odometry pose, the track's median world
    point, and that point's range from each frame: what the range should be if the track's
    median position were right and only the ego moved."""
    fps = _video_fps(boxes)
    rows = []
    for tid in track_ids:
        bs = sorted((b for b in boxes if b.track_id == tid), key=lambda b: b.frame)
        k = np.array([b.frame for b in bs])
        rng = np.array([b.range_m for b in bs])
        lat = np.array([b.lateral_m for b in bs])
        c, s = np.cos(motion.yaw_rad[k]), np.sin(motion.yaw_rad[k])
        world = motion.xy_m[k] + np.column_stack((c * rng - s * lat, s * rng + c * lat))
        p = np.median(world, axis=0)
        d = p - motion.xy_m[k]
        odo = c * d[:, 0] + s * d[:, 1]
        real = static_range_rate(motion.vf_mps[k], motion.wz_radps[k], lat,
                                 motion.camera_left_of_imu_m)
        video = real * motion.frame_dt_s[k] * fps
        rows += [ParkedRow(tid, int(k[i]), bs[i].t_s, float(rng[i]), float(lat[i]),
                           bs[i].range_rate_mps, float(video[i]), float(real[i]), float(odo[i]))
                 for i in range(len(bs))]
    return rows


def triangulate_outer_corner(boxes: list[RangedBox], motion: EgoMotion, camera: Camera,
                             track_ids: list[int], margin_px: float = 3.0
                             ) -> dict[int, dict[str, np.ndarray]]:
    """Range of each static track from bearings alone: a second, cue-free truth.

    The outer box edge of a vehicle beside the road (x1 for one on the left, x2 on the right)
    is the bearing of its outer rear corner, whose x is the rear range. Rays through that
    edge from the camera poses of the odometry are intersected by least squares; the point's
    x seen from each frame is the range. Only as good as the bearing span (a car far ahead
    and straight on gives none) and as the edge (a nearer parked car hiding the corner moves
    it). Returns per track: frames, range [m], lateral of the corner [m], bearing span [deg],
    RMS ray miss [m]."""
    out = {}
    for tid in track_ids:
        bs = sorted((b for b in boxes if b.track_id == tid), key=lambda b: b.frame)
        left = np.median([b.lateral_m for b in bs]) > 0
        u = np.array([b.x1 if left else b.x2 for b in bs])
        ok = (u > margin_px) & (u < camera.image_width - 1 - margin_px)
        if ok.sum() < 4:
            continue
        k = np.array([b.frame for b in bs])[ok]
        rays = camera.pixel_rays_veh(np.column_stack((u[ok], [bs[i].y2 for i in
                                                               np.flatnonzero(ok)])))
        bearing = np.arctan2(rays[:, 1], rays[:, 0])
        th = motion.yaw_rad[k] + bearing
        d = np.column_stack((np.cos(th), np.sin(th)))
        proj = np.eye(2)[None] - d[:, :, None] * d[:, None, :]
        p = np.linalg.solve(proj.sum(0), np.einsum("nij,nj->i", proj, motion.xy_m[k]))
        rel = p - motion.xy_m[k]
        c, s = np.cos(motion.yaw_rad[k]), np.sin(motion.yaw_rad[k])
        miss = np.einsum("nij,nj->ni", proj, rel)
        out[tid] = {"frame": k, "range_m": c * rel[:, 0] + s * rel[:, 1],
                    "lateral_m": -s * rel[:, 0] + c * rel[:, 1],
                    "span_deg": float(np.degrees(np.ptp(bearing))),
                    "miss_m": float(np.sqrt(np.mean(np.sum(miss ** 2, axis=1))))}
    return out


def _video_fps(boxes: list[RangedBox]) -> float:
    ratios = [b.frame / b.t_s for b in boxes if b.t_s > 0]
    return float(np.median(ratios)) if ratios else 10.0


def rate_errors(rows: list[ParkedRow], real_time: bool = False) -> dict[str, dict[str, float]]:
    """Range-rate error (estimate - truth) per range bin of the ESTIMATED range, per track and
    overall: n, RMSE, median |error|, median signed error [m/s]. Boxes without a rate (a
    one-box track) are left out."""
    rows = [r for r in rows if np.isfinite(r.rate_mps)]
    err = np.array([r.rate_mps - (r.real_rate_mps if real_time else r.true_rate_mps)
                    for r in rows])
    rng = np.array([r.range_m for r in rows])
    tid = np.array([r.track_id for r in rows])
    groups = {f"{lo:g}-{hi:g} m": (rng >= lo) & (rng < hi) for lo, hi in RANGE_BINS_M}
    groups.update({f"track {t}": tid == t for t in sorted(set(tid.tolist()))})
    groups["all"] = np.ones(len(rows), dtype=bool)
    out = {}
    for name, m in groups.items():
        e = err[m]
        out[name] = {"n": int(m.sum()),
                     "rmse": float(np.sqrt(np.mean(e ** 2))) if m.any() else math.nan,
                     "mae": float(np.median(np.abs(e))) if m.any() else math.nan,
                     "bias": float(np.median(e)) if m.any() else math.nan}
    return out


def range_consistency(rows: list[ParkedRow]) -> dict[int, dict[str, float]]:
    """Per track: spread of estimated minus odometry-predicted range (median absolute
    residual, and the 90th percentile of |residual|) [m], and the scale, the slope of the
    estimated range against the odometry-predicted one (1: ranges shrink at the right speed;
    0.5: they shrink at half the speed the ego closes in)."""
    out = {}
    for tid in sorted({r.track_id for r in rows}):
        est = np.array([r.range_m for r in rows if r.track_id == tid])
        odo = np.array([r.odo_range_m for r in rows if r.track_id == tid])
        res = est - odo
        slope = float(np.polyfit(odo, est, 1)[0]) if np.ptp(odo) > 1.0 else math.nan
        out[tid] = {"n": len(est), "odo_span_m": float(np.ptp(odo)),
                    "mad_m": float(np.median(np.abs(res))),
                    "p90_m": float(np.percentile(np.abs(res), 90)), "scale": slope,
                    "median_range_m": float(np.median(est)),
                    "median_lateral_m": float(np.median(
                        [r.lateral_m for r in rows if r.track_id == tid]))}
    return out


def triangulation_ratios(rows: list[ParkedRow], tri: dict[int, dict[str, np.ndarray]],
                         min_span_deg: float = 10.0, max_miss_m: float = 1.0
                         ) -> dict[int, float]:
    """Median estimated / triangulated range per track whose bearings span at least
    ``min_span_deg`` and whose rays meet within ``max_miss_m`` (else the triangulation is
    no truth: too little parallax, or the edge was not one point, e.g. an id switch)."""
    out = {}
    for tid, t in tri.items():
        if t["span_deg"] < min_span_deg or t["miss_m"] > max_miss_m:
            continue
        est = {r.frame: r.range_m for r in rows if r.track_id == tid}
        ratio = [est[f] / r for f, r in zip(t["frame"], t["range_m"], strict=True)
                 if f in est and r > 1.0]
        if ratio:
            out[tid] = float(np.median(ratio))
    return out


def format_report(rows: list[ParkedRow], excluded: dict[int, str], label: str,
                  tri: dict[int, dict[str, np.ndarray]] | None = None) -> str:
    """The figures as text: rate errors per bin, per track (with the range consistency of
    each track and, given ``tri``, its estimated / triangulated range), overall, and what was
    left out."""
    ratios = triangulation_ratios(rows, tri) if tri else {}
    errs = rate_errors(rows)
    real = rate_errors(rows, real_time=True)["all"]
    cons = range_consistency(rows)
    lines = [(f"range rate of parked cars vs OXTS truth, {label} "
              "(estimate - truth [m/s]; bins of estimated range):")]
    for name, e in errs.items():
        if name.startswith("track"):
            continue
        lines.append(f"  {name:10s} n={e['n']:4d}  RMSE {e['rmse']:5.2f}  median|err| "
                     f"{e['mae']:5.2f}  median err {e['bias']:+5.2f}")
    lines.append(f"  (all, truth per real second instead of per video second: RMSE "
                 f"{real['rmse']:.2f}, median|err| {real['mae']:.2f}, median err "
                 f"{real['bias']:+.2f})")
    lines.append("  track  boxes  med.range  med.lat  rate RMSE  med|err|  med err   "
                 "range vs odometry: med|res|  p90|res|  scale   est/triangulated")
    for tid, c in cons.items():
        e = errs[f"track {tid}"]
        lines.append(f"  {tid:5d}  {c['n']:5d}  {c['median_range_m']:8.1f}  "
                     f"{c['median_lateral_m']:+7.1f}  {e['rmse']:9.2f}  {e['mae']:8.2f}  "
                     f"{e['bias']:+7.2f}   {c['mad_m']:24.2f}  {c['p90_m']:8.2f}  "
                     f"{c['scale']:5.2f}   "
                     + (f"{ratios[tid]:.2f}" if tid in ratios else "-"))
    scales = np.array([c["scale"] for c in cons.values()])
    lines.append(f"  median scale over tracks {np.nanmedian(scales):.2f}; median |residual| "
                 f"over boxes {np.median(np.abs([r.range_m - r.odo_range_m for r in rows])):.2f} m")
    if ratios:
        lines.append(f"  median est/triangulated range over {len(ratios)} tracks with >= 10 deg "
                     f"of parallax: {np.median(list(ratios.values())):.2f}")
    for tid, why in excluded.items():
        lines.append(f"  left out: track {tid}: {why}")
    return "\n".join(lines)


@dataclass
class ParkedEvaluation:
    """The parked cars of a ranging result with their truths (see :func:`evaluate_parked`)."""

    keep: list[int]
    excluded: dict[int, str]
    rows: list[ParkedRow]
    tri: dict[int, dict[str, np.ndarray]]

    def report(self, label: str) -> str:
        return format_report(self.rows, self.excluded, label, self.tri)


def evaluate_parked(result: RangingResult, camera: Camera, motion: EgoMotion
                    ) -> ParkedEvaluation:
    """Select the parked cars of a ranging result and attach all three truths."""
    keep, excluded = select_static(result.boxes)
    return ParkedEvaluation(keep, excluded, static_truth(result.boxes, motion, keep),
                            triangulate_outer_corner(result.boxes, motion, camera, keep))


# --------------------------------------------------------------------------- replayed scenario

#: The parked cars of KITTI raw 0001 scored in a built scenario: their centres 5-11 m to the
#: left of the ego (the row at the kerb, not the car park behind the hedge) and at most 45 m
#: ahead (issue 13's acceptance).
PARKED_LEFT_M = (5.0, 11.0)
PARKED_MAX_AHEAD_M = 45.0


@dataclass(frozen=True)
class ReplayedStatic:
    """World speeds of a scenario's actors while they stand where parked cars stand.

    ``speed_mps``: every sample's speed [m/s]; ``along_mps``: its velocity along the ego's
    heading (positive: moving with the ego) [m/s], whose median is the bias (a monocular range
    that shrinks slower than the ego closes in makes parked cars drive along with it);
    ``per_actor``: actor id -> (samples, median speed, median along-ego velocity).
    """

    speed_mps: np.ndarray
    along_mps: np.ndarray
    per_actor: dict[str, tuple[int, float, float]]

    @property
    def median_speed_mps(self) -> float:
        return float(np.median(self.speed_mps)) if self.speed_mps.size else math.nan

    @property
    def bias_mps(self) -> float:
        return float(np.median(self.along_mps)) if self.along_mps.size else math.nan


def replayed_static_speeds(scenario, left_m: tuple[float, float] = PARKED_LEFT_M,
                           max_ahead_m: float = PARKED_MAX_AHEAD_M) -> ReplayedStatic:
    """Speeds of ``scenario``'s car actors at the samples where their centre lies ``left_m``
    to the left of the ego's position and 0 to ``max_ahead_m`` ahead of it, in the ego's
    heading at that time (the zone where a drive's parked cars stand).

    ``scenario`` is a :class:`vid2sim.core.scenario.Scenario` (scenario.json as loaded).
    """
    ego = scenario.ego.trajectory
    speeds, along, per_actor = [], [], {}
    for actor in scenario.actors:
        if actor.category != "car":
            continue
        tr = actor.trajectory
        pose = ego.state_at(tr.t)
        h = np.asarray(pose["heading"], dtype=float)
        dx, dy = tr.x - pose["x"], tr.y - pose["y"]
        ahead = np.cos(h) * dx + np.sin(h) * dy
        left = -np.sin(h) * dx + np.cos(h) * dy
        zone = (left >= left_m[0]) & (left <= left_m[1]) & (ahead >= 0) & (ahead <= max_ahead_m)
        if not zone.any():
            continue
        v_along = tr.speed * np.cos(tr.heading - h)
        speeds.append(tr.speed[zone])
        along.append(v_along[zone])
        per_actor[actor.id] = (int(zone.sum()), float(np.median(tr.speed[zone])),
                               float(np.median(v_along[zone])))
    cat = np.concatenate(speeds) if speeds else np.zeros(0)
    return ReplayedStatic(cat, np.concatenate(along) if along else np.zeros(0), per_actor)
