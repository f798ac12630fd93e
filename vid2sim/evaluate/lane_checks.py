"""Checks of the lane measurement against references that the measurement did not make.

- :func:`world_line_scatter`: a painted line does not move. Each frame's measured line,
  placed in the world with an independent record of the ego's motion (KITTI's OXTS
  RT3003 GPS/INS, :func:`kitti_camera_poses`), must fall on one smooth curve; the scatter
  about it is the measurement's noise (plus the reference's, centimetres for the RT3003).
- :func:`ego_cross_error`: a built scenario's ego against a known true ego path (the demo
  sample), signed, per instant, for figures by regime.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from shapely.geometry import LineString, Point

from vid2sim.base.errors import InconsistentInputError
from vid2sim.core.camera import parse_kitti_calib
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import Origin
from vid2sim.core.scenario import Scenario, Trajectory
from vid2sim.geo.oxts import read_kitti_oxts_table, read_kitti_stamps

# OXTS table columns (oxts/dataformat.txt of a KITTI raw drive).
_LAT, _LON, _ALT, _YAW, _VF = 0, 1, 2, 5, 8


def summary(error_m: np.ndarray) -> dict[str, float]:
    """RMS, 95th percentile of the magnitude, signed mean (bias) and maximum magnitude [m] of
    the finite values, and their count."""
    e = np.asarray(error_m, float)
    e = e[np.isfinite(e)]
    if e.size == 0:
        return {"n": 0, "rms_m": float("nan"), "p95_m": float("nan"),
                "bias_m": float("nan"), "max_m": float("nan")}
    return {"n": int(e.size), "rms_m": float(np.sqrt(np.mean(e * e))),
            "p95_m": float(np.percentile(np.abs(e), 95)), "bias_m": float(np.mean(e)),
            "max_m": float(np.max(np.abs(e)))}


# --------------------------------------------------------------------------- KITTI poses


def kitti_camera_poses(drive: Path, camera_stamps: str = "image_00_timestamps.txt"
                       ) -> dict[str, np.ndarray]:
    """The left grey camera's ground point over a KITTI raw drive, from the OXTS GPS/INS.

    The OXTS pose (position, yaw) is interpolated at each camera timestamp and moved by
    the camera's lever arm from the unit (``calib_imu_to_velo.txt`` then
    ``calib_velo_to_cam.txt``; about 1.08 m ahead and 0.32 m right on drive 2011_09_26).

    Returns
    -------
    dict
        ``t_s`` (camera time from the first frame [s]), ``x_m``, ``y_m`` (ENU about the first
        fix [m]), ``yaw_rad`` (counter-clockwise from east), ``speed_mps`` (forward speed).
    """
    drive = Path(drive)
    table = read_kitti_oxts_table(drive)
    t_oxts = np.array(read_kitti_stamps(drive / "oxts" / "timestamps.txt"))
    t_cam = np.array(read_kitti_stamps(drive / camera_stamps))
    if len(t_oxts) != len(table):
        raise InconsistentInputError(drive / "oxts", "timestamps and data files differ in number")
    enu = EnuFrame(Origin(table[0, _LAT], table[0, _LON], table[0, _ALT])).to_enu(
        table[:, _LAT], table[:, _LON], table[:, _ALT])
    yaw = np.unwrap(table[:, _YAW])
    x = np.interp(t_cam, t_oxts, enu[:, 0])
    y = np.interp(t_cam, t_oxts, enu[:, 1])
    h = np.interp(t_cam, t_oxts, yaw)
    lever = kitti_camera_lever_arm(drive)
    c, s = np.cos(h), np.sin(h)
    return {"t_s": t_cam - t_cam[0], "x_m": x + c * lever[0] - s * lever[1],
            "y_m": y + s * lever[0] + c * lever[1], "yaw_rad": h,
            "speed_mps": np.interp(t_cam, t_oxts, table[:, _VF])}


def kitti_camera_lever_arm(drive: Path) -> np.ndarray:
    """(x forward, y left) of the left grey camera in the OXTS unit's frame [m], from a
    KITTI raw drive's ``calib_imu_to_velo.txt`` and ``calib_velo_to_cam.txt``."""
    def rigid(name: str) -> tuple[np.ndarray, np.ndarray]:
        values = parse_kitti_calib((drive / name).read_text(encoding="utf-8"))
        return values["R"].reshape(3, 3), values["T"].reshape(3)

    r_vi, t_vi = rigid("calib_imu_to_velo.txt")  # p_velo = R p_imu + T
    r_cv, t_cv = rigid("calib_velo_to_cam.txt")  # p_cam = R p_velo + T
    cam_in_velo = -r_cv.T @ t_cv
    cam_in_imu = r_vi.T @ (cam_in_velo - t_vi)
    return cam_in_imu[:2]


# --------------------------------------------------------------------------- line scatter


def world_line_scatter(offset_m: np.ndarray, poses: dict[str, np.ndarray],
                       x_eval_m: float | np.ndarray = 0.0, degree: int = 3
                       ) -> dict[str, float | np.ndarray]:
    """Scatter of one painted line's measured positions about a smooth curve in the world.

    Parameters
    ----------
    offset_m : (N,) the line's lateral offset in the vehicle frame at ``x_eval_m`` ahead of
        the camera's ground point, per frame (NaN where not measured) [m]
    poses : the camera's ground point per frame (:func:`kitti_camera_poses`)
    x_eval_m : where along the vehicle's x axis the offset was taken [m]
    degree : the curve is a polynomial of this degree across the drive's chord (a street's
        lines over ~100 m; a cubic follows a gentle S)

    Returns
    -------
    dict
        :func:`summary` of the residuals across the curve, ``lag1`` (their correlation from
        one frame to the next: near 1 means slow drifts, near 0 white noise) and
        ``residual_m`` (N,), NaN where not measured.
    """
    off = np.asarray(offset_m, float)
    x, y, h = poses["x_m"][: len(off)], poses["y_m"][: len(off)], poses["yaw_rad"][: len(off)]
    c, s = np.cos(h), np.sin(h)
    wx = x + c * x_eval_m - s * off
    wy = y + s * x_eval_m + c * off
    chord = np.array([x[-1] - x[0], y[-1] - y[0]])
    chord /= max(np.linalg.norm(chord), 1e-9)
    normal = np.array([-chord[1], chord[0]])
    along = (wx - x[0]) * chord[0] + (wy - y[0]) * chord[1]
    across = (wx - x[0]) * normal[0] + (wy - y[0]) * normal[1]
    ok = np.isfinite(across)
    resid = np.full(len(off), np.nan)
    if ok.sum() <= degree + 2:
        return {**summary(resid), "lag1": float("nan"), "residual_m": resid}
    coef = np.polyfit(along[ok], across[ok], degree)
    resid[ok] = across[ok] - np.polyval(coef, along[ok])
    pairs = ok[:-1] & ok[1:]
    lag1 = (float(np.corrcoef(resid[:-1][pairs], resid[1:][pairs])[0, 1])
            if pairs.sum() > 3 else float("nan"))
    return {**summary(resid), "lag1": lag1, "residual_m": resid}


# --------------------------------------------------------------------------- demo truth


def ego_cross_error(origin: Origin, trajectory: Trajectory, truth: Scenario
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Signed lateral error of an ego trajectory against the true ego path.

    Both are compared at the truth's sample times inside the trajectory's span; the frames
    are reconciled through WGS-84 (a build picks its own ENU origin).

    Parameters
    ----------
    origin, trajectory : the ego to check (e.g. ``built.origin, built.ego.trajectory``)
    truth : the true scenario (:func:`vid2sim.samples.demo_truth.truth_scenario`)

    Returns
    -------
    t_s : (N,) times [s]
    cross_m : (N,) position minus true position across the true heading, positive left [m]
    """
    true_ego = truth.ego.trajectory
    t = true_ego.t[(true_ego.t >= trajectory.t[0]) & (true_ego.t <= trajectory.t[-1])]
    now = true_ego.state_at(t)
    est = trajectory.state_at(t)
    lat, lon, _ = EnuFrame(origin).to_geodetic(np.column_stack((est["x"], est["y"])))
    p = EnuFrame(truth.origin).to_enu(lat, lon)
    h = now["heading"]
    dx, dy = p[:, 0] - now["x"], p[:, 1] - now["y"]
    return t, -dx * np.sin(h) + dy * np.cos(h)


def true_curvature(truth: Scenario, t_s: np.ndarray) -> np.ndarray:
    """Curvature of the true ego path at ``t_s`` [1/m, positive left]: heading rate over
    speed."""
    traj = truth.ego.trajectory
    heading = np.unwrap(traj.heading)
    kappa = np.gradient(heading, traj.t) / np.maximum(traj.speed, 0.5)
    return np.interp(t_s, traj.t, kappa)


def actor_enters_lane_s(truth: Scenario, actor_id: str, half_lane_m: float) -> float | None:
    """First time [s] the actor's centre comes within ``half_lane_m`` of the true ego's line
    of travel (laterally, ahead of the ego): the moment it enters the ego's lane."""
    ego = truth.ego.trajectory
    actor = next((a for a in truth.actors if a.id == actor_id), None)
    if actor is None:
        return None
    t = actor.trajectory.t
    e = ego.state_at(t)
    a = actor.trajectory.state_at(t)
    dx, dy = a["x"] - e["x"], a["y"] - e["y"]
    ahead = dx * np.cos(e["heading"]) + dy * np.sin(e["heading"])
    lateral = -dx * np.sin(e["heading"]) + dy * np.cos(e["heading"])
    inside = (np.abs(lateral) <= half_lane_m) & (ahead > 0)
    return float(t[np.argmax(inside)]) if inside.any() else None


def offset_from_centerline_m(centerline: np.ndarray, x_m: np.ndarray, y_m: np.ndarray
                             ) -> np.ndarray:
    """Signed distance [m, positive left of the direction of travel] of ENU points from a
    road's centerline polyline (N, 2), measured across the road at each point's nearest
    point on it (shapely's projection)."""
    line = LineString(np.asarray(centerline, dtype=float))
    out = np.empty(len(x_m))
    for k, (x, y) in enumerate(zip(np.asarray(x_m, float), np.asarray(y_m, float),
                                   strict=True)):
        s = line.project(Point(x, y))
        a = line.interpolate(max(s - 0.25, 0.0))
        b = line.interpolate(min(s + 0.25, line.length))
        q = line.interpolate(s)
        tx, ty = b.x - a.x, b.y - a.y
        out[k] = ((x - q.x) * -ty + (y - q.y) * tx) / max(np.hypot(tx, ty), 1e-9)
    return out


def actor_enters_lane_on_road_s(truth: Scenario, actor_id: str, lane_left_m: float,
                                lane_right_m: float, step_s: float = 0.001) -> float | None:
    """First time [s] the actor's centre lies between two offsets from the true road's
    centerline (the ego lane's boundaries, :func:`offset_from_centerline_m`), measured along
    the road, so a bend ahead does not move it (:func:`actor_enters_lane_s` measures across
    the ego's heading, which a bend 15 m ahead shifts by curvature x 15^2 / 2)."""
    actor = next((a for a in truth.actors if a.id == actor_id), None)
    if actor is None or not truth.roads:
        return None
    t = np.arange(actor.trajectory.t[0], actor.trajectory.t[-1], step_s)
    s = actor.trajectory.state_at(t)
    off = offset_from_centerline_m(truth.roads[0].centerline, s["x"], s["y"])
    inside = (off <= lane_left_m) & (off >= lane_right_m)
    return float(t[np.argmax(inside)]) if inside.any() else None
