"""Constant-velocity Kalman filter and Rauch-Tung-Striebel smoother for the tracks' range
and lateral offset, with a maximum-likelihood choice of the acceleration noise."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vid2sim.detect.ranging.config import RangingConfig

# Normalised innovation squared beyond which a measurement is down-weighted to sit at the
# gate (16 = 4 sigma: one bad box in a thousand good ones trips it, a wrong one always does).
INNOVATION_GATE_NIS = 16.0
# The inverse-range variance correction (x/z)^4 is clamped to [1/16, 16]: a factor two in
# range either way; beyond that the reading is an outlier for the gate, not a rescaling.
INVERSE_RATIO_CLAMP = 16.0
# Prior spread of the lateral rate as a share of the range rate's: vehicles drift sideways
# at a lane change's 1-2 m/s, not at the 8 m/s a range can close at.
LATERAL_RATE_PRIOR_FRACTION = 0.25
# Initial position variance of a track in units of its first measurement's [m^2, plus a
# constant]: diffuse, so the first frame alone sets the start.
DIFFUSE_PRIOR = 1e4


@dataclass
class SmoothedTrack:
    """Smoothed states of one track at its measurement times."""

    range_m: np.ndarray
    range_rate_mps: np.ndarray
    lateral_m: np.ndarray
    lateral_rate_mps: np.ndarray
    range_std_m: np.ndarray
    accel_noise_mps2: float
    log_likelihood: float


def _kf_rts_cv(t_s: list[float], z: list[float], r: list[float], valid: list[bool], q: float,
               v0_std: float, inverse: bool = False
               ) -> tuple[list[float], list[float], list[float], float]:
    """Constant-velocity Kalman filter + RTS smoother on one axis, in plain floats.

    The 2x2 algebra is written out: numpy's per-call overhead on 2x2 matrices would cost ten
    times more than the arithmetic on a long video. Process noise is the discretised
    continuous white-noise acceleration (Bar-Shalom, Li & Kirubarajan, Estimation with
    Applications to Tracking and Navigation, 2001, sec. 6.2.2): Q = q [[dt^3/3, dt^2/2],
    [dt^2/2, dt]]. The smoother is Rauch, Tung & Striebel (AIAA J. 3(8), 1965).

    With ``inverse`` the measurement variance r (given at the reading z) is moved to the
    predicted range x as r (x/z)^4. A monocular range comes from pixel sizes and offsets,
    so its error is additive in 1/z: its variance grows as z^4, and a variance evaluated at
    the noisy reading itself gives the short readings of a far track more weight than the
    long ones, which pulled far tracks 10-15 % short and their range rates towards zero.
    (An extended Kalman update on 1/z does the same but breaks down for a vehicle passing
    alongside, whose rear range crosses zero.)

    Returns smoothed position, rate, position std and the innovation log-likelihood.
    """
    n = len(t_s)
    first = valid.index(True) if True in valid else 0
    x, v = z[first], 0.0
    pxx, pxv, pvv = r[first] * DIFFUSE_PRIOR + DIFFUSE_PRIOR, 0.0, v0_std ** 2
    # Filtered and predicted states/covariances, needed by the backward pass.
    fx, fv, fpxx, fpxv, fpvv = [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n
    ppxx, ppxv, ppvv, dts = [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n
    px_, pv_ = [0.0] * n, [0.0] * n
    loglik = 0.0
    for k in range(n):
        dt = t_s[k] - t_s[k - 1] if k else 0.0
        dts[k] = dt
        # predict: F = [[1, dt], [0, 1]]
        x = x + dt * v
        pxx, pxv = (pxx + 2 * dt * pxv + dt * dt * pvv + q * dt ** 3 / 3,
                    pxv + dt * pvv + q * dt * dt / 2)
        pvv = pvv + q * dt
        px_[k], pv_[k], ppxx[k], ppxv[k], ppvv[k] = x, v, pxx, pxv, pvv
        if valid[k]:
            rk = r[k]
            if inverse and k > first and z[k] > 0 and x > 0:
                # The variance at the predicted range, not at the noisy reading.
                rk *= min(max((x / z[k]) ** 4, 1 / INVERSE_RATIO_CLAMP), INVERSE_RATIO_CLAMP)
            innov = z[k] - x
            s = pxx + rk
            nis = innov * innov / s
            if nis > INNOVATION_GATE_NIS and k > first:
                # Robust: an innovation beyond 4 sigma inflates that frame's noise until it
                # sits at 4 sigma, so one bad box does not throw the track.
                s = pxx + rk * nis / INNOVATION_GATE_NIS
            elif k > first:
                loglik -= 0.5 * (nis + math.log(s))
            kx, kv = pxx / s, pxv / s
            x, v = x + kx * innov, v + kv * innov
            pxx, pxv, pvv = pxx - kx * pxx, pxv - kx * pxv, pvv - kv * pxv
        fx[k], fv[k], fpxx[k], fpxv[k], fpvv[k] = x, v, pxx, pxv, pvv
    sx, sv, sxx = fx[:], fv[:], fpxx[:]
    sxv, svv = fpxv[:], fpvv[:]
    for k in range(n - 2, -1, -1):
        dt = dts[k + 1]
        # C = P_f F^T P_p^-1 with the 2x2 inverse written out.
        a, b, d = ppxx[k + 1], ppxv[k + 1], ppvv[k + 1]
        det = a * d - b * b
        if det <= 0:
            continue
        m11, m12 = fpxx[k] + dt * fpxv[k], fpxv[k]  # P_f F^T, rows (x, v)
        m21, m22 = fpxv[k] + dt * fpvv[k], fpvv[k]
        c11, c12 = (m11 * d - m12 * b) / det, (m12 * a - m11 * b) / det
        c21, c22 = (m21 * d - m22 * b) / det, (m22 * a - m21 * b) / det
        ex, ev = sx[k + 1] - px_[k + 1], sv[k + 1] - pv_[k + 1]
        sx[k] = fx[k] + c11 * ex + c12 * ev
        sv[k] = fv[k] + c21 * ex + c22 * ev
        # P_s = P_f + C (P_s,k+1 - P_p,k+1) C^T
        dxx, dxv, dvv = sxx[k + 1] - a, sxv[k + 1] - b, svv[k + 1] - d
        t11, t12 = c11 * dxx + c12 * dxv, c11 * dxv + c12 * dvv
        t21, t22 = c21 * dxx + c22 * dxv, c21 * dxv + c22 * dvv
        sxx[k] = fpxx[k] + t11 * c11 + t12 * c12
        sxv[k] = fpxv[k] + t11 * c21 + t12 * c22
        svv[k] = fpvv[k] + t21 * c21 + t22 * c22
    return sx, sv, [math.sqrt(max(p, 0.0)) for p in sxx], loglik


def smooth_track(t_s: np.ndarray, z: np.ndarray, r: np.ndarray, valid: np.ndarray,
                 q_long: float, q_lat: float, v0_std: float, inverse: bool = False
                 ) -> SmoothedTrack:
    """Constant-velocity Kalman filter and RTS smoother for one track.

    State (range, range rate) and (lateral, lateral rate), filtered as two independent axes
    (the range-lateral correlation of one box's fit is small next to the motion); irregular
    time steps and frames without a valid measurement (only predicted) are handled;
    innovations beyond 4 sigma are down-weighted.

    Parameters
    ----------
    t_s : (N,) times [s], non-decreasing
    z : (N, 2) measured range and lateral [m]
    r : (N, 2, 2) measurement covariances [m^2] (the diagonal is used)
    valid : (N,) whether each measurement exists
    q_long, q_lat : white-noise acceleration spectral densities [m^2/s^3]
    v0_std : prior spread of the range rate [m/s] (a quarter of it for the lateral rate)
    inverse : update the range in inverse range (see :func:`_kf_rts_cv`)
    """
    t = [float(v) for v in t_s]
    ok = [bool(v) for v in valid]
    zx = [float(v) if np.isfinite(v) else 0.0 for v in z[:, 0]]
    zy = [float(v) if np.isfinite(v) else 0.0 for v in z[:, 1]]
    rx = [max(float(v), 1e-6) if np.isfinite(v) else 1e6 for v in r[:, 0, 0]]
    ry = [max(float(v), 1e-6) if np.isfinite(v) else 1e6 for v in r[:, 1, 1]]
    x, vx, sdx, ll = _kf_rts_cv(t, zx, rx, ok, q_long, v0_std, inverse=inverse)
    y, vy, _, _ = _kf_rts_cv(t, zy, ry, ok, q_lat, v0_std * LATERAL_RATE_PRIOR_FRACTION)
    return SmoothedTrack(np.array(x), np.array(vx), np.array(y), np.array(vy), np.array(sdx),
                         q_long, ll)


def smooth_track_adaptive(t_s: np.ndarray, z: np.ndarray, r: np.ndarray, valid: np.ndarray,
                          config: RangingConfig) -> SmoothedTrack:
    """Run :func:`smooth_track` for each candidate acceleration noise and keep the one whose
    range innovations are the most likely (a calm follower and a hard braker need different
    ones: maximum-likelihood choice of the process noise, as in adaptive Kalman filtering),
    preferring the calmer one unless the likelihood clearly says otherwise."""
    fits = [smooth_track(t_s, z, r, valid, q, config.lateral_accel_noise_mps2,
                         config.initial_range_rate_std_mps, inverse=config.inverse_range_update)
            for q in sorted(config.accel_noise_grid_mps2)]
    top = max(f.log_likelihood for f in fits)
    return next(f for f in fits if f.log_likelihood >= top - config.accel_noise_margin_loglik)
