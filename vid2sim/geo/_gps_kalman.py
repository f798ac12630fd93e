"""Constant-acceleration Kalman filter and RTS smoother of GPS fixes in the ENU plane."""

from __future__ import annotations

import math

import numpy as np

from vid2sim.geo.trace_params import TraceParams

# --------------------------------------------------------------------------- Kalman / RTS

# State: [x, y, vx, vy, ax, ay] in ENU [m, m/s, m/s^2]; constant acceleration driven by white
# jerk (Bar-Shalom, Estimation with Applications to Tracking and Navigation, sec. 6.3.3).


def transitions(dt: np.ndarray, q: float) -> tuple[np.ndarray, np.ndarray]:
    """(M, 6, 6) transition and process-noise matrices for steps of ``dt`` seconds."""
    m = len(dt)
    f1 = np.zeros((m, 3, 3))
    f1[:, 0, 0] = f1[:, 1, 1] = f1[:, 2, 2] = 1.0
    f1[:, 0, 1] = f1[:, 1, 2] = dt
    f1[:, 0, 2] = 0.5 * dt * dt
    q1 = np.empty((m, 3, 3))
    q1[:, 0, 0] = dt**5 / 20
    q1[:, 0, 1] = q1[:, 1, 0] = dt**4 / 8
    q1[:, 0, 2] = q1[:, 2, 0] = dt**3 / 6
    q1[:, 1, 1] = dt**3 / 3
    q1[:, 1, 2] = q1[:, 2, 1] = dt**2 / 2
    q1[:, 2, 2] = dt
    q1 *= q
    # The x and y axes are independent in the model: interleave the 3x3 blocks.
    f = np.zeros((m, 6, 6))
    qq = np.zeros((m, 6, 6))
    for axis in (0, 1):
        f[:, axis::2, axis::2] = f1
        qq[:, axis::2, axis::2] = q1
    return f, qq


def update_block(x: np.ndarray, P: np.ndarray, z: np.ndarray, lo: int,
                  R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update with a measurement of state elements ``lo`` and ``lo + 1`` (positions
    at 0, velocities at 2); a 2x2 innovation covariance inverted in closed form."""
    S = P[lo:lo + 2, lo:lo + 2] + R
    det = S[0, 0] * S[1, 1] - S[0, 1] * S[1, 0]
    s_inv = np.array([[S[1, 1], -S[0, 1]], [-S[1, 0], S[0, 0]]]) / det
    K = P[:, lo:lo + 2] @ s_inv
    x = x + K @ (z - x[lo:lo + 2])
    P = P - K @ P[lo:lo + 2, :]
    # Re-symmetrise: the tiny zero-velocity variances would otherwise let rounding build up.
    return x, 0.5 * (P + P.T)


def update_scalar(x: np.ndarray, P: np.ndarray, z: float, h: np.ndarray,
                   r: float) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update with one scalar measurement z = h . x + noise of variance r."""
    ph = P @ h
    k = ph / (h @ ph + r)
    x = x + k * (z - h @ x)
    P = P - np.outer(k, ph)
    return x, 0.5 * (P + P.T)


def smooth(t, xy, sig, spd, vel_meas, crs_ok, used, stopped, p: TraceParams):
    """Forward Kalman filter + RTS smoother over the used fixes; returns the smoothed state
    [x, y, vx, vy, ax, ay] at ALL fixes (unused ones get the Hermite interpolation of their
    used neighbours, acceleration 0)."""
    idx = np.flatnonzero(used)
    m = len(idx)
    xf = np.zeros((m, 6))
    pf = np.zeros((m, 6, 6))
    xp = np.zeros((m, 6))
    pp = np.zeros((m, 6, 6))
    fs, qs = transitions(np.diff(t[idx], prepend=t[idx[0]]), p.jerk_psd)
    x = np.zeros(6)
    x[:2] = xy[idx[0]]
    P = np.diag([sig[idx[0]] ** 2] * 2 + [30.0**2] * 2 + [3.0**2] * 2)
    cs = math.radians(p.course_sigma_deg)
    zupt_r = np.eye(2) * 1e-4
    for k, i in enumerate(idx):
        if k > 0:
            F = fs[k]
            x = F @ x
            P = F @ P @ F.T + qs[k]
        xp[k], pp[k] = x, P
        x, P = update_block(x, P, xy[i], 0, np.eye(2) * sig[i] ** 2)
        if stopped[i]:
            # Zero-velocity update: the vehicle is known to stand still.
            x, P = update_block(x, P, np.zeros(2), 2, zupt_r)
        elif crs_ok[i]:
            v = vel_meas[i]
            s = float(spd[i])
            u = v / s  # along-track unit vector
            n = np.array([-u[1], u[0]])
            R = (np.outer(u, u) * p.speed_sigma_mps**2
                 + np.outer(n, n) * max(s * cs, p.speed_sigma_mps) ** 2)
            x, P = update_block(x, P, v, 2, R)
        elif not np.isnan(spd[i]):
            # Speed without course: |v| = s, linearised about the current velocity.
            vn = float(np.hypot(x[2], x[3]))
            if vn > 0.5:
                h = np.zeros(6)
                h[2:4] = x[2:4] / vn
                x, P = update_scalar(x, P, float(spd[i]) - vn + float(h @ x), h,
                                      p.speed_sigma_mps**2)
        xf[k], pf[k] = x, P
    xs = xf.copy()
    if m > 1:
        # RTS gains for all steps at once: C_k = P_f,k F_k+1^T P_p,k+1^-1.
        gains = np.linalg.solve(pp[1:], fs[1:] @ pf[:-1]).transpose(0, 2, 1)
        for k in range(m - 2, -1, -1):
            xs[k] = xf[k] + gains[k] @ (xs[k + 1] - xp[k + 1])
    # Spread to all fixes: rejected ones get the Hermite interpolation of their neighbours.
    out = np.zeros((len(t), 6))
    pos, vel = hermite(t[idx], xs[:, :2], xs[:, 2:4], t)
    out[:, :2], out[:, 2:4] = pos, vel
    out[idx] = xs
    return out


def hermite(tk: np.ndarray, pk: np.ndarray, vk: np.ndarray,
             tq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Hermite interpolation of positions ``pk`` with derivatives ``vk`` at ``tq``;
    returns positions and their time derivative (clamped to the ends outside ``tk``)."""
    tq = np.clip(tq, tk[0], tk[-1])
    j = np.clip(np.searchsorted(tk, tq, side="right") - 1, 0, len(tk) - 2)
    h = (tk[j + 1] - tk[j])[:, None]
    s = ((tq - tk[j])[:, None]) / h
    p0, p1, v0, v1 = pk[j], pk[j + 1], vk[j], vk[j + 1]
    s2, s3 = s * s, s * s * s
    pos = ((2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * h * v0
           + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * h * v1)
    vel = ((6 * s2 - 6 * s) * p0 / h + (3 * s2 - 4 * s + 1) * v0
           + (-6 * s2 + 6 * s) * p1 / h + (3 * s2 - 2 * s) * v1)
    return pos, vel
