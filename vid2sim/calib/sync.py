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

The two clocks need not tick alike either: a video file's frame rate is a label, and a
camera that captures at another rate than its container says (KITTI raw: frames every
0.1032 s played at 10 fps, 3.2 %; 29.97 fps labelled 30, 0.1 %; 24 fps film labelled 25,
4.2 %; dropped frames) puts GPS second ``u`` at video time ``tau + u / rate``. One offset
then lines up the middle of the clip and misplaces its ends. Where the motion has features
far enough apart to pin two times, the rate is fitted with the offset (a second, joint grid
about the middle of the overlap, where the two are least correlated) within a bound; where
it has not (one braking, one turn), the offset alone is kept and its one-sigma grows by what
an unknown rate within the bound moves the first fix.

When the ego drives at a steady speed along a straight road, every offset fits alike (the
profiles have no feature to line up): the offset is then reported as not observable, with
the numbers that say why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from vid2sim.base.errors import ImpossibleValueError
from vid2sim.core.calibration import TimeOffset
from vid2sim.core.records import GpsTrace


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
    :param max_rate_dev: bound on the clock rate's departure from 1 (0: offset only): the
        frame-rate mislabels of real files, 24 fps film as 25 (4.2 %), KITTI raw's 9.69 fps
        as 10 (3.2 %), 29.97 as 30 (0.1 %); a quartz clock's drift is ppm, so a clip that
        needs more is not a label but a wrong match
    :param rate_step: grid step of the rate in the joint fit
    :param rate_window_s: half-width of the joint fit's grid of the middle's video time
        about the offset-only fit's [s] (its one-sigma on KITTI raw 0001: 0.1 s)
    :param max_rate_std: a rate less certain than this is not observable (the offset
        alone is kept): beyond it the data pin the rate no better than the bound does
        (a uniform spread over +-5 %: 2.9 %)
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
    max_rate_dev: float = 0.05
    rate_step: float = 0.005
    rate_window_s: float = 0.6
    max_rate_std: float = 0.029

    def check(self) -> None:
        """Raise :class:`ImpossibleValueError` for settings no sync can run with."""
        steps = (self.coarse_step_s, self.fine_step_s, self.rate_step, self.rate_window_s)
        if not all(math.isfinite(x) and x > 0 for x in steps):
            raise ImpossibleValueError(None, "sync grid steps and window must be > 0")
        if not (0.0 <= self.max_rate_dev < 0.5 and self.min_overlap > 0):
            raise ImpossibleValueError(None, f"sync max_rate_dev {self.max_rate_dev:g} must be "
                                       "0-0.5 and min_overlap > 0")


@dataclass(frozen=True, slots=True)
class _Profiles:
    """The pairs' video times and visual motion, and the GPS's series on its own clock."""

    ta: np.ndarray
    tb: np.ndarray
    v: np.ndarray
    w: np.ndarray
    gt: np.ndarray
    gv: np.ndarray
    gh: np.ndarray

    @property
    def t(self) -> np.ndarray:
        return 0.5 * (self.ta + self.tb)


def _gps_increments(tau: float, prof: _Profiles, rate: float = 1.0
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean speed and heading change over each pair's two frames, from the GPS read at
    GPS time ``rate (t - tau)`` of each frame's video time ``t``, and which pairs lie
    inside the GPS's span."""
    ua, ub = rate * (prof.ta - tau), rate * (prof.tb - tau)
    gt = prof.gt
    inside = (ua >= gt[0]) & (ub <= gt[-1])
    speed = 0.5 * (np.interp(ua, gt, prof.gv) + np.interp(ub, gt, prof.gv))
    dpsi = np.interp(ub, gt, prof.gh) - np.interp(ua, gt, prof.gh)
    return speed, dpsi, inside


def _misfit(tau: float, prof: _Profiles, cfg: SyncConfig, rate: float = 1.0
            ) -> tuple[float, np.ndarray, int]:
    """Chi-square of the best-fitted visual profiles against the GPS's at offset ``tau``
    and clock ``rate`` (averaged over the overlapping pairs and scaled to all of them, so
    that offsets with less overlap compare fairly), the normalised residuals, and the
    pairs used.

    The visual speed gets a scale and an intercept (a flow bias that grows with speed
    would otherwise read as a time shift of a braking or speeding-up ego); the heading
    change a scale (straight is zero in both). The scales absorb the rate's effect on the
    speed and heading change per video second."""
    vg, hg, inside = _gps_increments(tau, prof, rate)
    n = int(inside.sum())
    if n < 4:
        return math.inf, np.zeros(0), 0
    vg, hg, vv, hv = vg[inside], hg[inside], prof.v[inside], prof.w[inside]
    design = np.column_stack((vv, np.ones(n)))
    coef = np.linalg.lstsq(design, vg, rcond=None)[0]
    if coef[0] <= 0:  # a focal length and a height are positive: so are both scales
        coef = np.array([0.0, float(np.mean(vg))])
    b = max(float(np.dot(hv, hg) / max(np.dot(hv, hv), 1e-18)), 0.0)
    dt = np.maximum(prof.tb - prof.ta, 1e-3)[inside]
    sv = cfg.speed_noise_mps + cfg.speed_noise_frac * np.abs(vg)
    r = np.concatenate(((design @ coef - vg) / sv, (b * hv - hg) / (cfg.yaw_rate_noise * dt)))
    return float(np.mean(r ** 2)) * 2 * len(prof.ta), r, n


def estimate_time_offset(t_a_s: np.ndarray, t_b_s: np.ndarray, speed: np.ndarray,
                         yaw_change: np.ndarray, gps_t_s: np.ndarray, gps_speed: np.ndarray,
                         gps_heading: np.ndarray, config: SyncConfig | None = None
                         ) -> TimeOffset:
    """Offset of the GPS clock (``gps_t_s``: seconds from its first fix) against the video's
    (``t_a_s``, ``t_b_s``: each pair's two frame times), i.e. the video time of the first fix,
    and the clocks' rate where the motion pins it (:class:`TimeOffset`).

    ``speed`` and ``yaw_change`` are the pairs' visual speed and heading change in any
    scale; ``gps_speed`` [m/s] and ``gps_heading`` [rad, counter-clockwise, unwrapped] the
    GPS's at its times."""
    cfg = config or SyncConfig()
    cfg.check()
    prof = _Profiles(*(np.asarray(x, float) for x in (t_a_s, t_b_s, speed, yaw_change,
                                                     gps_t_s, gps_speed, gps_heading)))
    if len(prof.ta) < 5 or len(prof.gt) < 5:
        return TimeOffset(0.0, math.inf, False, "too few samples to compare the clocks")
    moving = float(np.median(np.abs(prof.gv)))
    if moving > cfg.min_gps_speed_mps and float(np.median(np.abs(prof.v))) < (
            cfg.min_speed_ratio * moving):
        return TimeOffset(0.0, math.inf, False, f"the road's flow shows the ego almost still "
                          f"({float(np.median(np.abs(prof.v))):.1f} m/s at the provisional "
                          f"camera) while the GPS says {moving:.1f} m/s: too little road "
                          "texture to follow")
    off = _offset_only(prof, cfg)
    if not off.observable or cfg.max_rate_dev <= 0:
        return off
    return _with_rate(off, prof, cfg)


def _offset_only(prof: _Profiles, cfg: SyncConfig) -> TimeOffset:
    """The offset at clock rate 1: a coarse grid over every offset that overlaps enough,
    then a fine one about its best."""
    t, gt = prof.t, prof.gt
    span = gt[-1] - gt[0]
    lo = t[0] - span + cfg.min_overlap * (t[-1] - t[0])
    hi = t[-1] - cfg.min_overlap * (t[-1] - t[0])
    taus = np.arange(lo, hi + cfg.coarse_step_s, cfg.coarse_step_s)
    coarse = _curve(taus, prof, cfg)
    if not np.isfinite(coarse).any():
        return TimeOffset(0.0, math.inf, False, "the GPS does not overlap the video at any "
                          "offset")
    best = taus[int(np.argmin(coarse))]
    fine_t = np.arange(best - 2 * cfg.coarse_step_s, best + 2 * cfg.coarse_step_s,
                       cfg.fine_step_s)
    fine = _curve(fine_t, prof, cfg)
    return _judge(fine_t, fine, int(np.argmin(fine)), taus, coarse, prof, cfg)


def _curve(grid: np.ndarray, prof: _Profiles, cfg: SyncConfig, rate: float = 1.0
           ) -> np.ndarray:
    """The misfit at each trial offset (infinite where too few pairs overlap)."""
    need = cfg.min_overlap * len(prof.ta)
    out = np.full(len(grid), np.inf)
    for i, tau in enumerate(grid):
        chi2, _, n = _misfit(float(tau), prof, cfg, rate)
        if n >= need:
            out[i] = chi2
    return out


def _noise_scale(r: np.ndarray) -> tuple[float, float]:
    """The misfit per residual (above 1 the noise levels were too small and the curve's
    width grows with it; below 1 they are kept: they are floors for what the profiles do
    not model, flow biases, a GPS's smoothing) and the inflation for the residuals'
    correlation along each profile (fewer independent samples than pairs)."""
    scale = max(float(np.sum(r ** 2)) / max(len(r) - 2, 1), 1.0)
    half = len(r) // 2
    rho = np.nanmean([_lag1(r[:half]), _lag1(r[half:])])
    return scale, (1 + max(rho, 0.0)) / (1 - min(max(rho, 0.0), 0.95))


def _judge(fine_t, fine, i, taus, coarse, prof: _Profiles, cfg: SyncConfig) -> TimeOffset:
    """The offset at the fine minimum with its one-sigma, or why it is not observable."""
    tau = float(fine_t[i])
    chi2_min, r, _ = _misfit(tau, prof, cfg)
    scale, inflate = _noise_scale(r)
    lo, hi = max(i - 5, 0), min(i + 6, len(fine_t))
    ok = np.isfinite(fine[lo:hi])
    if ok.sum() >= 3:
        curv = np.polyfit(fine_t[lo:hi][ok], fine[lo:hi][ok], 2)[0]
    else:
        curv = 0.0
    std = math.sqrt(scale * inflate / curv) if curv > 0 else math.inf
    rivals = taus[(np.abs(taus - tau) > cfg.rival_gap_s)
                  & (coarse < chi2_min + cfg.rival_chi2 * scale * inflate)]
    t, gt = prof.t, prof.gt
    spread_v = float(np.ptp(np.interp(t - tau, gt, prof.gv)))
    rate = np.gradient(prof.gh, gt) if len(gt) > 2 else np.zeros(len(gt))
    spread_w = math.degrees(float(np.ptp(np.interp(t - tau, gt, rate))))
    why = (f"speed varies by {spread_v:.1f} m/s and the heading rate by {spread_w:.1f} deg/s "
           "over the clip")
    explained, features = _explained(tau, prof, cfg)
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


def _explained(tau: float, prof: _Profiles, cfg: SyncConfig) -> tuple[float, float]:
    """Share of the GPS profiles' variance beyond their noise that the fitted visual
    profiles explain at ``tau``, and that variance in units of the noise (0: the profiles
    have no feature to line up)."""
    vg, hg, inside = _gps_increments(tau, prof)
    if inside.sum() < 4:
        return 0.0, 0.0
    vg, hg, vv, hv = vg[inside], hg[inside], prof.v[inside], prof.w[inside]
    dt = np.maximum(prof.tb - prof.ta, 1e-3)[inside]
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


# --------------------------------------------------------------------------- the clock rate


def _with_rate(off: TimeOffset, prof: _Profiles, cfg: SyncConfig) -> TimeOffset:
    """The offset-only fit ``off`` refined by a fitted clock rate where the motion pins it;
    else ``off`` with its one-sigma grown by what an unknown rate within the bound moves
    the first fix, and why the rate was not fitted."""
    fit, why_not = _joint_fit(off.offset_s, prof, cfg)
    if fit is not None:
        tau, std, rate, rate_std = fit
        return TimeOffset(tau, std, True, f"{off.reason}; clock rate {rate:.4f} +- "
                          f"{rate_std:.4f} GPS s per video s", rate, rate_std, True)
    lever = _lever_s(off.offset_s, prof, cfg)
    spread = cfg.max_rate_dev / math.sqrt(3.0)  # a rate anywhere within the bound
    std = math.hypot(off.std_s, lever * spread)
    return replace(off, std_s=std, reason=f"{off.reason}; clock rate not fitted ({why_not}): "
                   f"taken as 1, the one-sigma grown by {lever:.1f} s x {100 * spread:.1f} %",
                   rate_std=spread)


def _lever_s(tau: float, prof: _Profiles, cfg: SyncConfig) -> float:
    """GPS seconds from the first fix to the middle of the pairs it overlaps at ``tau``:
    what a rate error multiplies into the first fix's video time."""
    _, _, inside = _gps_increments(tau, prof)
    t = prof.t[inside] if inside.any() else prof.t
    return max(float(np.median(t)) - tau, 0.0)


def _joint_fit(tau1: float, prof: _Profiles, cfg: SyncConfig
               ) -> tuple[tuple[float, float, float, float] | None, str]:
    """(offset, its one-sigma, rate, its one-sigma) of the joint grid, or why the rate is
    not observable.

    The grid runs over the video time ``m`` of GPS time ``u_ref`` (the middle of the pairs
    at ``tau1``) and the rate: ``tau = m - u_ref / rate``. The misfit is not a quadratic
    bowl in the rate (sharp at its floor, flat shoulders), so the one-sigmas are profile
    intervals: half the span of offsets and rates whose misfit is within one (scaled and
    inflated as the offset's) of the least."""
    u_ref = _lever_s(tau1, prof, cfg)
    m_grid = tau1 + u_ref + np.arange(-cfg.rate_window_s, cfg.rate_window_s + 1e-9,
                                      cfg.fine_step_s)
    n_r = round(cfg.max_rate_dev / cfg.rate_step)
    rates = 1.0 + cfg.rate_step * np.arange(-n_r, n_r + 1)
    chi2 = np.array([_curve(m_grid - u_ref / r, prof, cfg, r) for r in rates])
    if not np.isfinite(chi2).any():
        return None, "no trial rate overlaps the GPS enough"
    ir, im = np.unravel_index(int(np.argmin(chi2)), chi2.shape)
    if ir in (0, len(rates) - 1):
        return None, (f"the best rate lies at the bound, {rates[ir]:.3f}: a clock off by more "
                      f"than {100 * cfg.max_rate_dev:.0f} % is no frame-rate label")
    rate, m = float(rates[ir]), float(m_grid[im])
    _, r, _ = _misfit(m - u_ref / rate, prof, cfg, rate)
    scale, inflate = _noise_scale(r)
    within = chi2 <= chi2[ir, im] + scale * inflate
    rr, mm = np.meshgrid(rates, m_grid, indexing="ij")
    if within[:, [0, -1]].any():
        return None, "the one-sigma region of the offset reaches the edge of its grid"
    if within[0].any() and within[-1].any():
        return None, (f"every rate within +-{100 * cfg.max_rate_dev:.0f} % fits within one "
                      "sigma: the motion's features are too few or too close together to "
                      "pin two times")
    rate_std = 0.5 * (float(np.ptp(rr[within])) + cfg.rate_step)
    if rate_std > cfg.max_rate_std:
        return None, (f"one-sigma {100 * rate_std:.1f} % against the bound's "
                      f"{100 * cfg.max_rate_std:.1f} %: the motion's features are too few or "
                      "too close together to pin two times")
    taus = mm - u_ref / rr
    tau_std = 0.5 * (float(np.ptp(taus[within])) + cfg.fine_step_s)
    return (m - u_ref / rate, tau_std, rate, rate_std), ""


def on_video_clock(trace: GpsTrace, rate: float) -> GpsTrace:
    """The trace with each fix ``u`` GPS seconds after the first re-timed to ``u / rate``
    and its reported speed to metres per video second (x ``rate``), so that an offset
    alone puts it on the video clock and the distance between two frames is the drive's."""
    if rate == 1.0 or not trace.fixes:
        return trace
    first = min(f.t_utc_s for f in trace.fixes)
    fixes = [replace(f, t_utc_s=first + (f.t_utc_s - first) / rate,
                     speed_mps=None if f.speed_mps is None else f.speed_mps * rate)
             for f in trace.fixes]
    return replace(trace, fixes=fixes)
