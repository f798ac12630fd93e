"""Standing vehicles ranged from the ego's own motion: motion parallax with a known baseline.

A vehicle that stands still (parked, queued at a light) moves in the ego's frame only by the
ego's motion, which the GPS/OXTS trajectory measures. Every box of its track is then the
projection of ONE rigid vehicle at one place in the world, seen from camera poses a known
distance apart: its bearing and image size change as the ego's displacement over its range
(structure from motion with a known baseline; Hartley & Zisserman, Multiple View Geometry,
2nd ed., ch. 10), and its bottom row as that displacement over the camera's height above the
ground UNDER IT. So the track's range no longer rests on the road plane through the ego's
wheels nor on the class's size prior: one fit of the whole track gives its position, size and
the height of the ground it stands on (:func:`fit_standing_track`), and the ego's speed is a
measurement of its range rate in the track filter.

Whether a track stands still is itself a question of the fit: a vehicle moving along the ego's
axis is indistinguishable from a standing one of another size on other ground (the monocular
scale ambiguity), so a track counts as standing only where the fit needs no implausible size
or ground height and its edges agree with one place in the world (:func:`is_standing`); a
vehicle moving across the ego's path, turning or braking leaves residuals no single place
explains.

Frames: the ego's vehicle frame at each box's time (x forward, y left, z up, origin on the road
below the camera); the world pose of the ego comes from :class:`EgoPath`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.core.outline import outline_boxes
from vid2sim.core.records import EgoTrack

# Numerical settings of the track fit (not properties of the world).
FD_STEP = 1e-4  # finite-difference step in the parameters' units [m]
MAX_ITERATIONS = 40
CONVERGED_M = 1e-3  # largest parameter step at convergence [m] (a millimetre)
LM_DAMPING = 1e-3  # Levenberg-Marquardt damping relative to the diagonal
MIN_SIZE_M = 0.2
N_PARAMS = 6  # rear range, lateral, width, height, length, ground height (at the reference)


@dataclass(frozen=True)
class EgoPath:
    """The ego's planar pose over time on the scenario clock: where each box was seen from.

    ``noise_m``: one-sigma position noise of the trajectory (the trace stage's estimate;
    None: unknown). ``travel_yaw_rad``: the direction the ego travels in, in the ranging's
    vehicle frame (counter-clockwise from its x axis): a car moves along its body's axis,
    and where the ranging turned the camera towards the lane markings' vanishing point
    (:func:`vid2sim.detect.pipeline.detect_and_range`) while the camera file measured the
    mounting, the body's axis lies that turn away from the ranging frame's (KITTI raw 0001:
    the calibration says 0.06 deg off the IMU axis, the lane markings 0.50 deg; a standing
    car 9 m to the side then fits 1-2 m off with the lanes' axis, within 0.3 m with the
    body's).
    """

    t_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    heading_rad: np.ndarray
    noise_m: float | None = None
    travel_yaw_rad: float = 0.0

    @classmethod
    def from_track(cls, ego: EgoTrack, noise_m: float | None = None) -> EgoPath:
        return cls(np.asarray(ego.t_s, float), np.asarray(ego.x_m, float),
                   np.asarray(ego.y_m, float), np.unwrap(np.asarray(ego.heading_rad, float)),
                   noise_m)

    def covers(self, t_s: np.ndarray) -> bool:
        return bool(len(self.t_s) > 1 and np.min(t_s) >= self.t_s[0] - 1e-6
                    and np.max(t_s) <= self.t_s[-1] + 1e-6)

    def relative_poses(self, t_s: np.ndarray, t_ref_s: float) -> np.ndarray:
        """(N, 3): the ego's position (forward, left) [m] and heading change [rad] at each
        ``t_s`` in the ranging's vehicle frame at ``t_ref_s`` (travelling along
        ``travel_yaw_rad``)."""
        x = np.interp(t_s, self.t_s, self.x_m) - np.interp(t_ref_s, self.t_s, self.x_m)
        y = np.interp(t_s, self.t_s, self.y_m) - np.interp(t_ref_s, self.t_s, self.y_m)
        heading_ref = float(np.interp(t_ref_s, self.t_s, self.heading_rad))
        # the ranging frame's x axis lies travel_yaw_rad clockwise of the travel direction
        h_axis = heading_ref - self.travel_yaw_rad
        c, s = math.cos(h_axis), math.sin(h_axis)
        return np.column_stack((c * x + s * y, -s * x + c * y,
                                np.interp(t_s, self.t_s, self.heading_rad) - heading_ref))

    def speed_yaw_rate(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Speed [m/s] and yaw rate [rad/s] at ``t_s`` (central differences of the path)."""
        vx, vy = np.gradient(self.x_m, self.t_s), np.gradient(self.y_m, self.t_s)
        w = np.gradient(self.heading_rad, self.t_s)
        return (np.interp(t_s, self.t_s, np.hypot(vx, vy)), np.interp(t_s, self.t_s, w))


def place_standing(theta: np.ndarray, poses: np.ndarray, yaw_ref_rad: float = 0.0
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rear range, lateral offset and yaw of a standing vehicle in the ego's frame at each
    pose (:meth:`EgoPath.relative_poses`), from its rear range ``theta[0]``, lateral
    ``theta[1]`` and length ``theta[4]`` in the reference frame, where it stands at
    ``yaw_ref_rad`` (parallel to the ego's travel)."""
    half = theta[4] / 2
    # its footprint centre (where outline_boxes turns it about: half a length ahead of the
    # rear range) in the reference frame, then in each pose's frame
    dx, dy = theta[0] + half - poses[:, 0], theta[1] - poses[:, 1]
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    return c * dx + s * dy - half, -s * dx + c * dy, yaw_ref_rad - poses[:, 2]


def standing_range_rate(range_m: np.ndarray, lateral_m: np.ndarray, speed_mps: np.ndarray,
                        yaw_rate_radps: np.ndarray) -> np.ndarray:
    """d(range)/dt of a standing point at (``range_m``, ``lateral_m``) for an ego moving
    forward at ``speed_mps`` and turning at ``yaw_rate_radps`` (left positive): the point's
    velocity in the rotating ego frame is -v - w x p, whose forward part is -v + w y."""
    del range_m  # the forward component does not depend on it
    return -np.asarray(speed_mps) + np.asarray(yaw_rate_radps) * np.asarray(lateral_m)


@dataclass(frozen=True)
class StandingFit:
    """One track fitted as a standing vehicle.

    ``theta``: rear range and lateral offset at the reference time, width, height, length and
    the height of the ground under it relative to the ego's road plane [m]; ``cov`` their
    covariance; ``chi2_per_dof``: the robust fit's normalised residual; ``range_m`` /
    ``lateral_m``: its place at every box.
    """

    theta: np.ndarray
    cov: np.ndarray
    chi2_per_dof: float
    range_m: np.ndarray
    lateral_m: np.ndarray
    converged: bool
    #: the vehicle's heading relative to the ego's travel [rad]: 0 parallel (a kerbside row),
    #: pi / 2 crosswise (a car park's bays)
    body_yaw_rad: float = 0.0

    @property
    def ground_m(self) -> float:
        return float(self.theta[5])

    @property
    def ground_std_m(self) -> float:
        return float(math.sqrt(max(self.cov[5, 5], 0.0)))


def _edges(camera: Camera, theta: np.ndarray, poses: np.ndarray, outline: np.ndarray,
           yaw_ref_rad: float) -> np.ndarray:
    """Predicted (u1, v1, u2, v2) of every box for the parameters ``theta`` (one row each)
    or (K, 6) rows evaluated at once (K blocks of len(poses) boxes)."""
    th = np.atleast_2d(theta)
    k, n = th.shape[0], len(poses)
    rng, lat, yaw = [], [], []
    for row in th:
        r, y, w = place_standing(row, poses, yaw_ref_rad)
        rng.append(r), lat.append(y), yaw.append(w)
    rep = np.repeat(th, n, axis=0)
    return outline_boxes(camera, np.concatenate(rng), np.concatenate(lat), rep[:, 2],
                         rep[:, 3], rep[:, 4], np.tile(outline, (k, 1)), np.concatenate(yaw),
                         z_m=rep[:, 5]).reshape(k, n, 4)


def _weights(r: np.ndarray, c: float) -> np.ndarray:
    """Cauchy IRLS weights of normalised residuals (c: the scale, in sigmas): a box edge on
    another car (occlusion, a merged box) pulls no more than a few sigmas' worth."""
    return 1.0 / (1.0 + (r / c) ** 2)


def fit_standing_track(camera: Camera, obs: np.ndarray, sig: np.ndarray, use: np.ndarray,
                       outline: np.ndarray, poses: np.ndarray, start: np.ndarray,
                       prior_mean: np.ndarray, prior_std: np.ndarray,
                       robust_sigmas: float = 3.0, yaw_ref_rad: float = 0.0,
                       max_iterations: int | None = None, body_yaw_rad: float = 0.0
                       ) -> StandingFit:
    """Fit one track's boxes as ONE standing vehicle seen from the ego's poses.

    Parameters
    ----------
    obs, sig, use : (N, 4) ndarray
        Box edges (u1, v1, u2, v2) [px], their one-sigma noise [px] and which are usable
        (not cut by the image border).
    outline : (N, K) ndarray
        The vehicle's outline rows (:func:`vid2sim.core.outline.shape_matrix`).
    poses : (N, 3) ndarray
        The ego's pose at each box relative to the reference (:meth:`EgoPath.relative_poses`).
    start : (6,) ndarray
        Starting parameters (rear range, lateral, width, height, length, ground height).
    prior_mean, prior_std : (4,) ndarray
        Priors of width, height, length and ground height [m].
    robust_sigmas : float
        Scale of the Cauchy weights of the edge residuals.
    yaw_ref_rad : float
        The vehicle's heading in the reference frame: parallel to the ego's travel
        (:attr:`EgoPath.travel_yaw_rad`), as a parked or queued vehicle stands.
    max_iterations : int, optional
        Levenberg-Marquardt steps at most (default :data:`MAX_ITERATIONS`).
    body_yaw_rad : float
        The vehicle's heading relative to ``yaw_ref_rad`` (pi / 2: parked crosswise, as in a
        car park's bays); its reported range is then its nearest face's.

    Returns
    -------
    StandingFit
    """
    args = (camera, obs, sig, use, outline, poses, prior_mean, prior_std,
            yaw_ref_rad + body_yaw_rad)
    theta = np.asarray(start, float).copy()
    n_edge = obs.size
    r0, jac = _residuals_and_jacobian(*args, theta=theta)
    cost = _robust_cost(r0, n_edge, robust_sigmas)
    damping = LM_DAMPING
    converged = False
    for _ in range(max_iterations or MAX_ITERATIONS):
        w_all = np.concatenate([_weights(r0[:n_edge], robust_sigmas), np.ones(len(r0) - n_edge)])
        jw = jac * w_all[:, None]
        a = jac.T @ jw
        g = jw.T @ r0
        for _ in range(MAX_DAMPING_TRIES):
            delta = np.linalg.solve(a + damping * np.diag(np.diag(a)) + 1e-12 * np.eye(N_PARAMS), g)
            trial = _bounded(theta + delta)
            r_t = _residuals(*args, theta=trial)
            c_t = _robust_cost(r_t, n_edge, robust_sigmas)
            if c_t <= cost:
                break
            damping *= 10.0
        else:
            converged = True  # no step lowers the cost: at a minimum to numerical precision
            break
        step = np.max(np.abs(trial - theta))
        theta, damping = trial, max(damping / 3.0, 1e-9)
        done = step < CONVERGED_M or cost - c_t < 1e-9 * max(cost, 1.0)
        cost = c_t
        r0, jac = _residuals_and_jacobian(*args, theta=theta)
        if done:
            converged = True
            break
    return _standing_fit(theta, r0, jac, use, poses, robust_sigmas, yaw_ref_rad, converged,
                         body_yaw_rad)


#: Levenberg-Marquardt: tries of a larger damping before a step is given up.
MAX_DAMPING_TRIES = 8


def _bounded(theta: np.ndarray) -> np.ndarray:
    """Parameters kept physical: a rear range ahead of the camera, sizes above a floor."""
    out = theta.copy()
    out[0] = max(out[0], 0.5)
    out[2:5] = np.maximum(out[2:5], MIN_SIZE_M)
    return out


def _robust_cost(r: np.ndarray, n_edge: int, c: float) -> float:
    """Cauchy loss of the edge residuals (in sigmas^2) plus the priors' squares."""
    edge = r[:n_edge]
    return float(np.sum(c ** 2 * np.log1p((edge / c) ** 2)) + np.sum(r[n_edge:] ** 2))


def _standing_fit(theta: np.ndarray, r0: np.ndarray, jac: np.ndarray, use: np.ndarray,
                  poses: np.ndarray, robust_sigmas: float, yaw_ref_rad: float,
                  converged: bool, body_yaw_rad: float = 0.0) -> StandingFit:
    """The fit's covariance (robust weights at the solution), normalised residual and the
    vehicle's place at every box."""
    n_edge = use.size
    w_all = np.concatenate([_weights(r0[:n_edge], robust_sigmas), np.ones(len(r0) - n_edge)])
    cov = np.linalg.inv(jac.T @ (jac * w_all[:, None]) + 1e-12 * np.eye(N_PARAMS))
    # Robust normalised residual: the Cauchy loss's per-edge value in sigmas^2 (log form), so
    # a few occluded edges do not decide but a track that fits no single place does.
    edge = r0[:n_edge][use.ravel()]
    chi2 = float(np.sum(robust_sigmas ** 2 * np.log1p((edge / robust_sigmas) ** 2)))
    chi2_per_dof = chi2 / max(int(use.sum()) - N_PARAMS, 1)
    rng, lat, _ = place_standing(theta, poses, yaw_ref_rad)
    # the range is that of the face nearest the ego: a crosswise vehicle's footprint reaches
    # half its width, not half its length, short of its centre
    half_l, half_w = theta[4] / 2, theta[2] / 2
    rng = rng + half_l - (half_l * abs(math.cos(body_yaw_rad))
                          + half_w * abs(math.sin(body_yaw_rad)))
    return StandingFit(theta, cov, chi2_per_dof, rng, lat, converged, body_yaw_rad)


def _residuals(camera: Camera, obs: np.ndarray, sig: np.ndarray, use: np.ndarray,
               outline: np.ndarray, poses: np.ndarray, prior_mean: np.ndarray,
               prior_std: np.ndarray, yaw_ref_rad: float, *, theta: np.ndarray
               ) -> np.ndarray:
    """Normalised residuals at one parameter vector (edges, then the four priors)."""
    pred = _edges(camera, theta, poses, outline, yaw_ref_rad)[0]
    r_edge = np.nan_to_num(np.where(use, (obs - pred) / sig, 0.0), nan=0.0).ravel()
    return np.concatenate([r_edge, (prior_mean - theta[2:6]) / prior_std])


def _residuals_and_jacobian(camera: Camera, obs: np.ndarray, sig: np.ndarray,
                            use: np.ndarray, outline: np.ndarray, poses: np.ndarray,
                            prior_mean: np.ndarray, prior_std: np.ndarray, yaw_ref_rad: float,
                            *, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normalised residuals (edges, then the four priors) and their Jacobian with respect to
    ``theta`` (forward differences, all parameter steps in one projection)."""
    th = np.tile(theta, (N_PARAMS + 1, 1))
    th[1:] += np.diag(np.full(N_PARAMS, FD_STEP))
    pred = _edges(camera, th, poses, outline, yaw_ref_rad)
    r_edge = np.where(use, (obs - pred) / sig, 0.0)
    r_edge = np.nan_to_num(r_edge, nan=0.0).reshape(N_PARAMS + 1, -1)
    r_prior = (prior_mean - th[:, 2:6]) / prior_std
    r = np.concatenate([r_edge, r_prior], axis=1)
    jac = -(r[1:] - r[0]) / FD_STEP
    return r[0], jac.T
