"""The camera model of :mod:`vid2sim.core.camera`, vectorised over parameters for the fits.

The least-squares fits of this package evaluate the projection of thousands of points for
many trial cameras; :class:`~vid2sim.core.camera.Camera` projects for one camera at a time
through OpenCV. These functions are the same model written in numpy so that the camera's
angles may differ per point (a per-frame body pitch), and they are checked against
``Camera.project`` / ``Camera.pixel_rays_veh`` in the tests.

Conventions (as in :mod:`vid2sim.core.camera`): vehicle frame x forward, y left, z up;
camera frame x right, y down, z along the optical axis; ``R_veh_from_cam = Rz(yaw) Ry(pitch)
Rx(roll) B``; OpenCV's radial distortion ``x_d = x (1 + k1 r^2 + k2 r^4)`` on normalised
coordinates (tangential terms are not estimated: consumer lenses are centred to well under
their radial error).
"""

from __future__ import annotations

import numpy as np

#: Camera axes in the vehicle frame at zero mounting angles (columns: cam x, y, z).
B_VEH_FROM_CAM = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])

#: Newton steps that invert the radial model along the radius (quadratic convergence:
#: 1e-12 from the distorted radius in 5 for |k1| <= 0.6 at r <= 1).
UNDISTORT_STEPS = 6


def rotations(pitch_rad: np.ndarray, yaw_rad: np.ndarray, roll_rad: np.ndarray) -> np.ndarray:
    """(N, 3, 3) ``R_veh_from_cam`` for arrays of mounting angles [rad] (broadcast)."""
    p, y, r = np.broadcast_arrays(np.asarray(pitch_rad, float), np.asarray(yaw_rad, float),
                                  np.asarray(roll_rad, float))
    p, y, r = p.ravel(), y.ravel(), r.ravel()
    n = p.size
    cp, sp, cy, sy, cr, sr = np.cos(p), np.sin(p), np.cos(y), np.sin(y), np.cos(r), np.sin(r)
    rz = np.zeros((n, 3, 3))
    rz[:, 0, 0], rz[:, 0, 1], rz[:, 1, 0], rz[:, 1, 1], rz[:, 2, 2] = cy, -sy, sy, cy, 1.0
    ry = np.zeros((n, 3, 3))
    ry[:, 0, 0], ry[:, 0, 2], ry[:, 2, 0], ry[:, 2, 2], ry[:, 1, 1] = cp, sp, -sp, cp, 1.0
    rx = np.zeros((n, 3, 3))
    rx[:, 1, 1], rx[:, 1, 2], rx[:, 2, 1], rx[:, 2, 2], rx[:, 0, 0] = cr, -sr, sr, cr, 1.0
    return rz @ ry @ rx @ B_VEH_FROM_CAM


def distort(xn: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """Normalised undistorted (N, 2) -> normalised distorted (radial model)."""
    r2 = np.sum(xn * xn, axis=-1, keepdims=True)
    return xn * (1.0 + k1 * r2 + k2 * r2 * r2)


def undistort(xd: np.ndarray, k1: float, k2: float) -> np.ndarray:
    """Normalised distorted (N, 2) -> normalised undistorted: Newton's method on the radius,
    ``r (1 + k1 r^2 + k2 r^4) = r_d``, from ``r = r_d`` (the direction is unchanged)."""
    xd = np.asarray(xd, dtype=float)
    if k1 == 0.0 and k2 == 0.0:
        return xd.copy()
    rd = np.sqrt(np.sum(xd * xd, axis=-1, keepdims=True))
    r = rd.copy()
    for _ in range(UNDISTORT_STEPS):
        r2 = r * r
        fr = r * (1.0 + k1 * r2 + k2 * r2 * r2) - rd
        dfr = 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 * r2
        r = r - fr / np.where(np.abs(dfr) > 1e-6, dfr, 1e-6)
    scale = np.where(rd > 1e-12, r / np.where(rd > 1e-12, rd, 1.0), 1.0)
    return xd * scale


def pixels_to_normalised(px: np.ndarray, f: float, c: np.ndarray, k1: float, k2: float
                         ) -> np.ndarray:
    """Raw (distorted) pixels -> undistorted normalised coordinates."""
    return undistort((np.asarray(px, float) - c) / f, k1, k2)


def normalised_to_pixels(xn: np.ndarray, f: float, c: np.ndarray, k1: float, k2: float
                         ) -> np.ndarray:
    """Undistorted normalised coordinates -> raw (distorted) pixels."""
    return distort(xn, k1, k2) * f + c


def rays_vehicle(xn: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """(N, 3) viewing rays in the vehicle frame of normalised points, one rotation per point
    (``rot`` (N, 3, 3)) or one for all ((3, 3))."""
    cam = np.concatenate((xn, np.ones((len(xn), 1))), axis=1)
    if rot.ndim == 2:
        return cam @ rot.T
    return np.einsum("nij,nj->ni", rot, cam)


def camera_points(p_veh: np.ndarray, height_m: float, rot: np.ndarray) -> np.ndarray:
    """(N, 3) vehicle-frame points -> camera frame (camera ``height_m`` above the origin)."""
    d = p_veh - np.array([0.0, 0.0, height_m])
    if rot.ndim == 2:
        return d @ rot
    return np.einsum("nji,nj->ni", rot, d)


def ground_points(xn: np.ndarray, rot: np.ndarray, height_m: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Back-project normalised points onto the road plane z = 0.

    :return: (N, 3) vehicle-frame points (NaN above the horizon) and the (N,) mask of rays
        that meet the road ahead
    """
    rays = rays_vehicle(xn, rot)
    down = rays[:, 2] < -1e-9
    s = np.where(down, -height_m / np.where(down, rays[:, 2], -1.0), np.nan)
    pts = np.array([0.0, 0.0, height_m]) + s[:, None] * rays
    return pts, down


def project_normalised(p_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame points -> normalised image coordinates and the in-front mask."""
    z = p_cam[:, 2]
    ok = z > 1e-6
    zz = np.where(ok, z, 1.0)
    return p_cam[:, :2] / zz[:, None], ok


def horizon_row(f: float, c: np.ndarray, pitch_rad: float, yaw_rad: float, roll_rad: float,
                u_px: float | None = None) -> float:
    """Row of the road plane's vanishing line at column ``u_px`` (default the principal
    point's), pinhole: the image of directions with zero vehicle z."""
    n = rotations(pitch_rad, yaw_rad, roll_rad)[0].T @ np.array([0.0, 0.0, 1.0])
    xn = ((c[0] if u_px is None else u_px) - c[0]) / f
    return float(c[1] + f * (-(n[0] * xn + n[2]) / n[1]))


def forward_vanishing_point(f: float, c: np.ndarray, pitch_rad: float, yaw_rad: float,
                            roll_rad: float) -> np.ndarray:
    """Pinhole pixel where the vehicle's forward direction vanishes."""
    d = rotations(pitch_rad, yaw_rad, roll_rad)[0].T @ np.array([1.0, 0.0, 0.0])
    return c + f * d[:2] / d[2]
