"""The GPS clock against the video's: match the visual ego-motion's profile to the GPS's.

The road's flow gives, per frame pair, the ego's forward motion in camera heights and its
heading change in units of the provisional focal length: the speed and the heading rate up
to one unknown scale each. The GPS gives both in metres and radians on its own clock. For a
trial offset ``tau`` (video time of the GPS's t = 0) the GPS profiles are read at the pairs'
times minus ``tau``, each visual profile gets its best scale (least squares), and the
misfit, in units of its own noise, is summed; the offset is the minimum over a coarse then a
fine grid. Its one-sigma comes from the misfit's curvature there, inflated for the residuals'
correlation from pair to pair (they are smooth profiles, not independent samples).

When the ego drives at a steady speed along a straight road, or speeds up at a steady rate
(a ramp shifted in time is a ramp scaled), every offset fits alike: the offset is then
reported as not observable, with the numbers that say why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vid2sim.core.calibration import TimeOffset


@dataclass(frozen=True, slots=True)
class SyncConfig:
    """Settings of the time sync.

    :param coarse_step_s, fine_step_s: grid steps of the two passes [s]
    :param min_overlap: least share of the video's pairs that a trial offset must put
        inside the GPS's span
    :param speed_noise_mps: one-sigma of a pair's visual speed beyond its scale [m/s]
        (road flow on KITTI raw 0001: 0.3-0.5 m/s per pair)
    :param speed_noise_frac: and relative to the speed
    :param yaw_rate_noise: one-sigma of a pair's visual heading rate [rad/s]
    :param max_std_s: an offset less certain than this is not observable [s]
    :param rival_chi2: another minimum farther than ``rival_gap_s`` within this much of
        the best misfit (in sigmas squared) makes the offset ambiguous
    :param rival_gap_s: see ``rival_chi2``
    """

    coarse_step_s: float = 0.25
    fine_step_s: float = 0.02
    min_overlap: float = 0.6
    speed_noise_mps: float = 0.3
    speed_noise_frac: float = 0.03
    yaw_rate_noise: float = 0.01
    max_std_s: float = 0.5
    rival_chi2: float = 4.0
    rival_gap_s: float = 1.0


def _misfit(tau: float, t: np.ndarray, v_vis: np.ndarray, w_vis: np.ndarray,
            gps_t: np.ndarray, gps_v: np.ndarray, gps_w: np.ndarray, cfg: SyncConfig
            ) -> tuple[float, np.ndarray, int]:
    """Chi-square of the best-scaled visual profiles against the GPS's at offset ``tau``
    (averaged over the overlapping pairs and scaled to all of them, so that offsets with
    less overlap compare fairly), the normalised residuals, and the pairs used."""
    u = t - tau
    inside = (u >= gps_t[0]) & (u <= gps_t[-1])
    n = int(inside.sum())
    if n < 3:
        return math.inf, np.zeros(0), 0
    vg = np.interp(u[inside], gps_t, gps_v)
    wg = np.interp(u[inside], gps_t, gps_w)
    vv, wv = v_vis[inside], w_vis[inside]
    a = float(np.dot(vv, vg) / max(np.dot(vv, vv), 1e-12))
    b = float(np.dot(wv, wg) / max(np.dot(wv, wv), 1e-12))
    a = min(max(a, 0.5), 2.0) if a > 0 else 1.0
    sv = cfg.speed_noise_mps + cfg.speed_noise_frac * np.abs(vg)
    r = np.concatenate(((a * vv - vg) / sv, (b * wv - wg) / cfg.yaw_rate_noise))
    return float(np.mean(r ** 2)) * 2 * len(t), r, n


def estimate_time_offset(t_s: np.ndarray, speed: np.ndarray, yaw_rate: np.ndarray,
                         gps_t_s: np.ndarray, gps_speed: np.ndarray, gps_yaw_rate: np.ndarray,
                         config: SyncConfig | None = None) -> TimeOffset:
    """Offset of the GPS clock (``gps_t_s``: seconds from its first fix) against the video's
    (``t_s``: pairs' video times), i.e. the video time of the first fix.

    ``speed`` and ``yaw_rate`` are the visual profiles in any scale; the GPS's in m/s and
    rad/s."""
    cfg = config or SyncConfig()
    t, v, w = (np.asarray(x, float) for x in (t_s, speed, yaw_rate))
    gt, gv, gw = (np.asarray(x, float) for x in (gps_t_s, gps_speed, gps_yaw_rate))
    if len(t) < 5 or len(gt) < 5:
        return TimeOffset(0.0, math.inf, False, "too few samples to compare the clocks")
    span = gt[-1] - gt[0]
    lo = t[0] - span + cfg.min_overlap * (t[-1] - t[0])
    hi = t[-1] - cfg.min_overlap * (t[-1] - t[0])
    taus = np.arange(lo, hi + cfg.coarse_step_s, cfg.coarse_step_s)
    need = cfg.min_overlap * len(t)

    def curve(grid: np.ndarray) -> np.ndarray:
        out = np.full(len(grid), np.inf)
        for i, tau in enumerate(grid):
            chi2, _, n = _misfit(tau, t, v, w, gt, gv, gw, cfg)
            if n >= need:
                out[i] = chi2
        return out

    coarse = curve(taus)
    if not np.isfinite(coarse).any():
        return TimeOffset(0.0, math.inf, False, "the GPS does not overlap the video at any "
                          "offset")
    best = taus[int(np.argmin(coarse))]
    fine_t = np.arange(best - 2 * cfg.coarse_step_s, best + 2 * cfg.coarse_step_s,
                       cfg.fine_step_s)
    fine = curve(fine_t)
    i = int(np.argmin(fine))
    return _judge(fine_t, fine, i, taus, coarse, t, v, w, gt, gv, gw, cfg)


def _judge(fine_t, fine, i, taus, coarse, t, v, w, gt, gv, gw, cfg: SyncConfig
           ) -> TimeOffset:
    """The offset at the fine minimum with its one-sigma, or why it is not observable."""
    tau = float(fine_t[i])
    chi2_min, r, _ = _misfit(tau, t, v, w, gt, gv, gw, cfg)
    # misfit per residual (1 if the noise levels are right), scaling the curve's width
    scale = max(float(np.sum(r ** 2)) / max(len(r) - 2, 1), 1e-6)
    # residual correlation along each profile: fewer independent samples than pairs
    half = len(r) // 2
    rho = np.nanmean([_lag1(r[:half]), _lag1(r[half:])])
    inflate = (1 + max(rho, 0.0)) / (1 - min(max(rho, 0.0), 0.95))
    lo, hi = max(i - 5, 0), min(i + 6, len(fine_t))
    ok = np.isfinite(fine[lo:hi])
    if ok.sum() >= 3:
        curv = np.polyfit(fine_t[lo:hi][ok], fine[lo:hi][ok], 2)[0]
    else:
        curv = 0.0
    std = math.sqrt(scale * inflate / curv) if curv > 0 else math.inf
    rivals = taus[(np.abs(taus - tau) > cfg.rival_gap_s)
                  & (coarse < chi2_min + cfg.rival_chi2 * scale * inflate)]
    spread_v = float(np.ptp(np.interp(t - tau, gt, gv)))
    spread_w = math.degrees(float(np.ptp(np.interp(t - tau, gt, gw))))
    why = (f"speed varies by {spread_v:.1f} m/s and the heading rate by {spread_w:.1f} deg/s "
           "over the clip")
    if not std <= cfg.max_std_s:
        return TimeOffset(tau, std, False, f"the motion is too uniform to tell the clocks "
                          f"apart ({why}; one-sigma {std:.2f} s)")
    if rivals.size:
        return TimeOffset(tau, std, False, f"offsets {tau:+.2f} s and {float(rivals[0]):+.2f} s "
                          f"fit alike ({why})")
    return TimeOffset(tau, std, True, why)


def _lag1(x: np.ndarray) -> float:
    if len(x) < 4 or np.std(x) == 0:
        return 0.0
    return float(np.corrcoef(x[:-1], x[1:])[0, 1])
