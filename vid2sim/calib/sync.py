"""The GPS clock against the video's: match the visual ego-motion's profile to the GPS's.

The road's flow gives, per frame pair, the ego's forward motion in camera heights and its
heading change in units of the provisional focal length: the speed and the heading change
up to one unknown scale each. The GPS gives both in metres and radians on its own clock.
For a trial offset ``tau`` (video time of the GPS's t = 0) the GPS is read at each pair's
two frame times minus ``tau``, each visual profile gets its best scale (least squares), and
the
misfit, in units of its own noise, is summed; the offset is the minimum over a coarse then a
fine grid. Its one-sigma comes from the misfit's curvature there, inflated for the residuals'
correlation from pair to pair (they are smooth profiles, not independent samples).

When the ego drives at a steady speed along a straight road, every offset fits alike (the
profiles have no feature to line up): the offset is then reported as not observable, with
the numbers that say why.
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
    :param yaw_rate_noise: one-sigma of a pair's heading change per second between its
        frames, visual against GPS [rad/s]
    :param max_std_s: an offset less certain than this is not observable [s]
    :param rival_chi2: another minimum farther than ``rival_gap_s`` within this much of
        the best misfit (in sigmas squared) makes the offset ambiguous
    :param rival_gap_s: see ``rival_chi2``
    :param min_explained: the fitted visual profiles must explain at least this share of
        the GPS profiles' variance beyond their noise (else they do not show the same
        motion: a rendered road without texture, a parked car)
    :param min_gps_speed_mps, min_speed_ratio: where the GPS moves faster than this and
        the visual speed (at the provisional camera, within a factor of two of the truth)
        stays below this share of it, the flow did not follow the road
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
    min_explained: float = 0.6
    min_gps_speed_mps: float = 1.0
    min_speed_ratio: float = 0.2


def _gps_increments(tau: float, t_a: np.ndarray, t_b: np.ndarray, gps_t: np.ndarray,
                    gps_v: np.ndarray, gps_h: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                               np.ndarray]:
    """Mean speed and heading change over each pair's two frames, from the GPS read at
    the pairs' times minus ``tau``, and which pairs lie inside the GPS's span."""
    ua, ub = t_a - tau, t_b - tau
    inside = (ua >= gps_t[0]) & (ub <= gps_t[-1])
    speed = 0.5 * (np.interp(ua, gps_t, gps_v) + np.interp(ub, gps_t, gps_v))
    dpsi = np.interp(ub, gps_t, gps_h) - np.interp(ua, gps_t, gps_h)
    return speed, dpsi, inside


def _misfit(tau: float, t_a: np.ndarray, t_b: np.ndarray, v_vis: np.ndarray,
            dpsi_vis: np.ndarray, gps_t: np.ndarray, gps_v: np.ndarray, gps_h: np.ndarray,
            cfg: SyncConfig) -> tuple[float, np.ndarray, int]:
    """Chi-square of the best-fitted visual profiles against the GPS's at offset ``tau``
    (averaged over the overlapping pairs and scaled to all of them, so that offsets with
    less overlap compare fairly), the normalised residuals, and the pairs used.

    The visual speed gets a scale and an intercept (a flow bias that grows with speed
    would otherwise read as a time shift of a braking or speeding-up ego); the heading
    change a scale (straight is zero in both)."""
    vg, hg, inside = _gps_increments(tau, t_a, t_b, gps_t, gps_v, gps_h)
    n = int(inside.sum())
    if n < 4:
        return math.inf, np.zeros(0), 0
    vg, hg, vv, hv = vg[inside], hg[inside], v_vis[inside], dpsi_vis[inside]
    design = np.column_stack((vv, np.ones(n)))
    coef = np.linalg.lstsq(design, vg, rcond=None)[0]
    if coef[0] <= 0:  # a focal length and a height are positive: so are both scales
        coef = np.array([0.0, float(np.mean(vg))])
    b = max(float(np.dot(hv, hg) / max(np.dot(hv, hv), 1e-18)), 0.0)
    dt = np.maximum(t_b - t_a, 1e-3)[inside]
    sv = cfg.speed_noise_mps + cfg.speed_noise_frac * np.abs(vg)
    r = np.concatenate(((design @ coef - vg) / sv, (b * hv - hg) / (cfg.yaw_rate_noise * dt)))
    return float(np.mean(r ** 2)) * 2 * len(t_a), r, n


def estimate_time_offset(t_a_s: np.ndarray, t_b_s: np.ndarray, speed: np.ndarray,
                         yaw_change: np.ndarray, gps_t_s: np.ndarray, gps_speed: np.ndarray,
                         gps_heading: np.ndarray, config: SyncConfig | None = None
                         ) -> TimeOffset:
    """Offset of the GPS clock (``gps_t_s``: seconds from its first fix) against the video's
    (``t_a_s``, ``t_b_s``: each pair's two frame times), i.e. the video time of the first fix.

    ``speed`` and ``yaw_change`` are the pairs' visual speed and heading change in any
    scale; ``gps_speed`` [m/s] and ``gps_heading`` [rad, counter-clockwise, unwrapped] the
    GPS's at its times."""
    cfg = config or SyncConfig()
    ta, tb, v, w = (np.asarray(x, float) for x in (t_a_s, t_b_s, speed, yaw_change))
    gt, gv, gw = (np.asarray(x, float) for x in (gps_t_s, gps_speed, gps_heading))
    t = 0.5 * (ta + tb)
    if len(t) < 5 or len(gt) < 5:
        return TimeOffset(0.0, math.inf, False, "too few samples to compare the clocks")
    span = gt[-1] - gt[0]
    lo = gt[0] + t[0] - span + cfg.min_overlap * (t[-1] - t[0])
    hi = gt[0] + t[-1] - cfg.min_overlap * (t[-1] - t[0])
    taus = np.arange(lo - gt[0], hi - gt[0] + cfg.coarse_step_s, cfg.coarse_step_s)
    need = cfg.min_overlap * len(t)

    def curve(grid: np.ndarray) -> np.ndarray:
        out = np.full(len(grid), np.inf)
        for i, tau in enumerate(grid):
            chi2, _, n = _misfit(tau, ta, tb, v, w, gt, gv, gw, cfg)
            if n >= need:
                out[i] = chi2
        return out

    moving = float(np.median(np.abs(gv)))
    if moving > cfg.min_gps_speed_mps and float(np.median(np.abs(v))) < (
            cfg.min_speed_ratio * moving):
        return TimeOffset(0.0, math.inf, False, f"the road's flow shows the ego almost still "
                          f"({float(np.median(np.abs(v))):.1f} m/s at the provisional camera) "
                          f"while the GPS says {moving:.1f} m/s: too little road texture to "
                          "follow")
    coarse = curve(taus)
    if not np.isfinite(coarse).any():
        return TimeOffset(0.0, math.inf, False, "the GPS does not overlap the video at any "
                          "offset")
    best = taus[int(np.argmin(coarse))]
    fine_t = np.arange(best - 2 * cfg.coarse_step_s, best + 2 * cfg.coarse_step_s,
                       cfg.fine_step_s)
    fine = curve(fine_t)
    i = int(np.argmin(fine))
    return _judge(fine_t, fine, i, taus, coarse, (ta, tb, v, w, gt, gv, gw), cfg)


def _judge(fine_t, fine, i, taus, coarse, data: tuple, cfg: SyncConfig) -> TimeOffset:
    """The offset at the fine minimum with its one-sigma, or why it is not observable."""
    tau = float(fine_t[i])
    ta, tb, v, w, gt, gv, gw = data
    t = 0.5 * (ta + tb)
    chi2_min, r, _ = _misfit(tau, ta, tb, v, w, gt, gv, gw, cfg)
    # misfit per residual: above 1 the noise levels were too small and the curve's width
    # grows with it; below 1 they are kept (they are floors for what the profiles do not
    # model: flow biases, a GPS's smoothing)
    scale = max(float(np.sum(r ** 2)) / max(len(r) - 2, 1), 1.0)
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
    rate = np.gradient(gw, gt) if len(gt) > 2 else np.zeros(len(gt))
    spread_w = math.degrees(float(np.ptp(np.interp(t - tau, gt, rate))))
    why = (f"speed varies by {spread_v:.1f} m/s and the heading rate by {spread_w:.1f} deg/s "
           "over the clip")
    explained, features = _explained(tau, data, cfg)
    if features == 0:
        return TimeOffset(tau, std, False, f"the motion is too uniform to tell the clocks "
                          f"apart ({why}: within the noise of both)")
    if explained < cfg.min_explained:
        return TimeOffset(tau, std, False, f"the visual motion does not follow the GPS's at any "
                          f"offset (at best {100 * explained:.0f} % of the GPS's speed and "
                          f"heading changes beyond their noise explained; {why})")
    if not std <= cfg.max_std_s:
        return TimeOffset(tau, std, False, f"the motion is too uniform to tell the clocks "
                          f"apart ({why}; one-sigma {std:.2f} s)")
    if rivals.size:
        return TimeOffset(tau, std, False, f"offsets {tau:+.2f} s and {float(rivals[0]):+.2f} s "
                          f"fit alike ({why})")
    return TimeOffset(tau, std, True, why)


def _explained(tau: float, data: tuple, cfg: SyncConfig) -> tuple[float, float]:
    """Share of the GPS profiles' variance beyond their noise that the fitted visual
    profiles explain at ``tau``, and that variance in units of the noise (0: the profiles
    have no feature to line up)."""
    ta, tb, v, w, gt, gv, gw = data
    vg, hg, inside = _gps_increments(tau, ta, tb, gt, gv, gw)
    if inside.sum() < 4:
        return 0.0, 0.0
    vg, hg, vv, hv = vg[inside], hg[inside], v[inside], w[inside]
    dt = np.maximum(tb - ta, 1e-3)[inside]
    out, weight = 0.0, 0.0
    for obs, gps, noise in ((vv, vg, cfg.speed_noise_mps), (hv, hg, cfg.yaw_rate_noise * dt)):
        signal = float(np.var(gps)) - float(np.mean(np.square(noise)))
        if signal <= 0:
            continue
        design = np.column_stack((obs, np.ones(len(obs))))
        fit = design @ np.linalg.lstsq(design, gps, rcond=None)[0]
        share = 1.0 - float(np.mean((gps - fit) ** 2) - np.mean(np.square(noise))) / signal
        out += signal / float(np.mean(np.square(noise))) * min(max(share, 0.0), 1.0)
        weight += signal / float(np.mean(np.square(noise)))
    return (out / weight if weight > 0 else 0.0), weight


def _lag1(x: np.ndarray) -> float:
    if len(x) < 4 or np.std(x) == 0:
        return 0.0
    return float(np.corrcoef(x[:-1], x[1:])[0, 1])
