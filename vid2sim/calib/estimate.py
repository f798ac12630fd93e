"""The calibration procedure: start from the priors, fit every cue, drop outliers, report.

1. **Start.** Principal point at the image centre (or the prior's), focal length from the
   prior's field of view, no distortion; pitch and yaw from the lane segments' vanishing
   point; the lens's first guess from the plumb lines alone.
2. **Road points.** Flow points whose earlier pixel lies on the road ahead (2-25 camera
   heights ahead, within one height beside the camera: the ego's lane, where the road is a
   plane and no kerb or parked car stands), at most a few hundred per pair.
3. **Rounds.** The pairs' motion alone (camera held), then the mount and height, then
   everything: after each round, points beyond a few robust sigmas of their pair, pairs whose
   scatter is several times the others', points whose image grows more than Lucas-Kanade
   follows, and chains far from straight are dropped.
4. **Report.** Covariance, the cue each parameter owes most to, whether the data alone
   determine it (else its source is the named prior and a warning says so).

The lane width is folded in afterwards (:func:`with_lane_widths`), since it is measured on
frames re-read with the estimated camera: a Gaussian update of the fitted globals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from vid2sim.base.defaults import MAD_TO_SIGMA
from vid2sim.calib import solve as fit
from vid2sim.calib.calibconfig import CalibrationConfig
from vid2sim.calib.cues import CalibrationInput
from vid2sim.calib.groundmotion import (
    GLOBALS,
    G,
    P,
    PairSet,
    growth,
    initial_motion,
    pack_pairs,
    predict_b,
    road_points,
)
from vid2sim.calib.lines import chain_rms, non_radial_chains, pack_chains, road_vanishing_point

#: Largest growth of a road point's image between a pair's frames that its track is trusted
#: with (the homography-guided tracks of :mod:`vid2sim.detect.tracking.groundflow` show no
#: bias up to 20 % on KITTI raw 0001).
MAX_GROWTH = 0.2
#: Chains pointing within this angle of the road's vanishing point are not plumb lines.
RADIAL_CHAIN_DEG = 20.0
#: A chain straighter than this many times the median chain's RMS is kept.
CHAIN_TRIM = 2.0
#: Fewest road points that make a pair worth fitting.
MIN_PAIR_POINTS = 6
#: Function evaluations of the early rounds (they only need to get near; the last one
#: converges).
EARLY_ROUND_EVALUATIONS = 25
#: A pair whose robust scatter exceeds this many times the median pair's is dropped.
BAD_PAIR_SCATTER = 3.0


@dataclass(slots=True)
class Solution:
    """The fitted globals with their covariance and what fixed them."""

    g: np.ndarray
    cov: np.ndarray
    m: np.ndarray
    problem: fit.Problem
    cue: dict[str, str] = field(default_factory=dict)
    observable: dict[str, bool] = field(default_factory=dict)
    flow_rms_px: float = float("nan")
    n_points: int = 0
    n_chains: int = 0
    n_vp_frames: int = 0
    #: why an estimated parameter was refused and held at its prior (name -> reason)
    refused: dict[str, str] = field(default_factory=dict)


def _prior(inp: CalibrationInput, cfg: CalibrationConfig) -> tuple[np.ndarray, np.ndarray,
                                                                   np.ndarray, np.ndarray]:
    """Principal point, prior mean and spread of the globals, and which are fixed."""
    v = inp.prior.values
    c = np.array([v.get("cx", (inp.width_px - 1) / 2.0), v.get("cy", (inp.height_px - 1) / 2.0)])
    f0 = (inp.width_px / 2.0) / math.tan(math.radians(cfg.hfov_prior_deg) / 2.0)
    mean = np.array([math.log(v.get("fx", f0)), v.get("k1", 0.0), v.get("k2", 0.0),
                     math.radians(v.get("pitch_deg", 0.0)), math.radians(v.get("yaw_deg", 0.0)),
                     math.radians(v.get("roll_deg", 0.0)),
                     math.log(v.get("height_m", cfg.height_prior_m))])
    std = np.array([cfg.log_f_prior_std, cfg.k1_prior_std, cfg.k2_prior_std,
                    math.radians(cfg.mount_prior_deg), math.radians(cfg.mount_prior_deg),
                    math.radians(cfg.roll_prior_deg), cfg.log_h_prior_std])
    keys = ("fx", "k1", "k2", "pitch_deg", "yaw_deg", "roll_deg", "height_m")
    fixed = np.array([k in v for k in keys])
    for key, (value, sigma) in inp.prior.soft.items():
        if key in v or key not in keys or not (math.isfinite(value) and sigma > 0):
            continue
        i = keys.index(key)
        log = key in ("fx", "height_m")
        mean[i] = math.log(value) if log else value
        std[i] = min(std[i], sigma / value if log else sigma)
    return c, mean, std, fixed


def _motion_arrays(inp: CalibrationInput, ps: PairSet, cfg: CalibrationConfig) -> dict:
    """The GPS motion per pair as the problem's arrays (empty without GPS)."""
    if not inp.motion:
        return {}
    by_frame = {s.frame_a: s for s in inp.motion}
    rows = [by_frame.get(int(fa)) for fa in ps.frame_a]
    d = np.array([s.distance_m if s else np.nan for s in rows])
    return {"gps_d": d,
            "gps_d_std": np.array([s.distance_std_m if s else 1.0 for s in rows]),
            "gps_dpsi": np.array([s.yaw_change_rad if s else 0.0 for s in rows]),
            "gps_dpsi_std": np.array([max(s.yaw_std_rad, 1e-6) if s else 1.0 for s in rows])}


def _motion_std(m: np.ndarray, cfg: CalibrationConfig) -> np.ndarray:
    return np.column_stack((cfg.slip_std * np.abs(m[:, P["s"]]) + 0.01,
                            np.full(len(m), math.radians(cfg.body_pitch_std_deg)),
                            np.full(len(m), math.radians(cfg.pitch_change_std_deg))))


def _cap_points(road: np.ndarray, ps: PairSet, n_max: int) -> np.ndarray:
    """At most ``n_max`` road points per pair, spread evenly through its list."""
    out = road.copy()
    for k in range(ps.n_pairs):
        idx = np.flatnonzero(road & (ps.pair == k))
        if len(idx) > n_max:
            out[idx] = False
            out[idx[np.linspace(0, len(idx) - 1, n_max).astype(int)]] = True
    return out


def _start(inp: CalibrationInput, cfg: CalibrationConfig) -> tuple[fit.Problem, np.ndarray,
                                                                  np.ndarray, int]:
    """The problem at its starting point: globals, the pairs' first motion, VP frames."""
    c, mean, std, fixed = _prior(inp, cfg)
    g = mean.copy()
    f0 = math.exp(g[G["log_f"]])
    vp, vp_std, n_vp = road_vanishing_point(inp.lines, f0, c, g[G["k1"]], g[G["k2"]],
                                            cfg.vp_floor_px)
    if n_vp:
        if not fixed[G["pitch"]]:
            g[G["pitch"]] = math.atan((c[1] - vp[1]) / f0)
        if not fixed[G["yaw"]]:
            g[G["yaw"]] = math.atan((c[0] - vp[0]) / f0)
    pts, mask = pack_chains(inp.lines, cfg.chain_points)
    if n_vp and len(pts):
        keep = non_radial_chains(pts, mask, vp, RADIAL_CHAIN_DEG)
        pts, mask = pts[keep], mask[keep]
    pr = fit.Problem(c=c, prior_mean=mean, prior_std=std, fixed=fixed,
                     flow_noise_px=cfg.flow_noise_px, chain_noise_px=cfg.chain_noise_px,
                     vp=vp if n_vp else None, vp_std=vp_std if n_vp else None,
                     chains=(pts, mask) if len(pts) else None)
    ps = pack_pairs(inp.pairs)
    m = np.zeros((ps.n_pairs, len(fit.PAIR_PARAMS)))
    if ps.n_pairs:
        road = _cap_points(road_points(g, c, ps, cfg.ground_range_h, cfg.ground_half_width_h),
                           ps, cfg.max_points_per_pair)
        m = initial_motion(g, c, ps, road)
        gps = _motion_arrays(inp, ps, cfg)
        for name, arr in gps.items():
            setattr(pr, name, arr)
        if gps:
            has = np.isfinite(gps["gps_d"])
            m[has, P["s"]] = gps["gps_d"][has]
            m[has, P["dpsi"]] = gps["gps_dpsi"][has]
        pr.pairs = ps.subset_points(road)
        pr.pairs = pr.pairs.subset_points(_moves_like_road(g, m, pr.pairs, c))
        pr.motion_std = _motion_std(m, cfg)
    return pr, g, m, n_vp


#: A point whose image moved less than this share of what the road at its pixel would
#: (or more than its inverse), at the start, is not on the road: a car driving ahead, the
#: bonnet, a reflection in the windscreen move with the ego. The band is wide since the
#: starting camera (a prior) may be off by a factor of two in focal length x height.
ROAD_MOTION_BAND = (0.25, 4.0)
#: ... judged only where the road's predicted motion exceeds this [px].
ROAD_MOTION_MIN_PX = 1.5


def _moves_like_road(g: np.ndarray, m: np.ndarray, ps: PairSet, c: np.ndarray) -> np.ndarray:
    """Mask of points whose motion is like the road's at their pixel (or too small to
    tell), with the starting camera and motion. A car driving ahead in the ego lane covers
    the very road the flow is measured on, and its points would pull the fit towards no
    turn and no forward motion (on a composite clip with a car 9-38 m ahead they put roll
    at 3.5 deg where it was 0.9)."""
    pred, ok = predict_b(g, m, ps, c)
    want = np.linalg.norm(pred - ps.points_a, axis=1)
    got = np.linalg.norm(ps.points_b - ps.points_a, axis=1)
    lo, hi = ROAD_MOTION_BAND
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = got / want
    return ~ok | (want < ROAD_MOTION_MIN_PX) | ((ratio >= lo) & (ratio <= hi))


def _reject(pr: fit.Problem, g: np.ndarray, m: np.ndarray, cfg: CalibrationConfig) -> None:
    """Drop outlying points, pairs and chains (in place)."""
    ps = pr.pairs
    if ps is not None and len(ps.pair):
        pred, ok = predict_b(g, m, ps, pr.c)
        err = np.linalg.norm(ps.points_b - pred, axis=1)
        keep = ok & (growth(g, m, ps, pr.c) <= MAX_GROWTH)
        scatter = np.full(ps.n_pairs, np.nan)
        for k in range(ps.n_pairs):
            sel = (ps.pair == k) & keep
            if sel.sum() < MIN_PAIR_POINTS:
                keep[ps.pair == k] = False
                continue
            scatter[k] = MAD_TO_SIGMA * float(np.median(err[sel]))
            keep[sel] &= err[sel] <= cfg.outlier_sigmas * max(scatter[k], cfg.flow_noise_px)
        if np.isfinite(scatter).any():
            typical = max(float(np.nanmedian(scatter)), cfg.flow_noise_px)
            keep &= ~(scatter > BAD_PAIR_SCATTER * typical)[ps.pair]
        pr.pairs = ps.subset_points(keep)
    if pr.chains is not None and len(pr.chains[0]):
        f = math.exp(g[G["log_f"]])
        rms = chain_rms(*pr.chains, f, pr.c, g[G["k1"]], g[G["k2"]])
        keep = rms <= CHAIN_TRIM * max(float(np.median(rms)), cfg.chain_noise_px)
        pr.chains = (pr.chains[0][keep], pr.chains[1][keep]) if keep.any() else None


def _free(*names: str) -> np.ndarray:
    mask = np.zeros(len(GLOBALS), bool)
    for n in names:
        mask[G[n]] = True
    return mask


def _plumb_start(pr: fit.Problem, g: np.ndarray) -> np.ndarray:
    """The lens from the plumb lines alone (everything else held), trimmed twice."""
    if pr.chains is None or pr.fixed[G["k1"]]:
        return g
    alone = replace(pr, pairs=None, gps_d=None, vp=None, lane_log_h=None, motion_std=None)
    for _ in range(2):
        g, _, _, _ = fit.solve(alone, g, np.zeros((0, len(fit.PAIR_PARAMS))), _free("k1"))
        f = math.exp(g[G["log_f"]])
        rms = chain_rms(*alone.chains, f, alone.c, g[G["k1"]], g[G["k2"]])
        keep = rms <= CHAIN_TRIM * float(np.median(rms))
        alone.chains = (alone.chains[0][keep], alone.chains[1][keep])
    pr.chains = alone.chains
    return g


def _refresh_vp(pr: fit.Problem, inp: CalibrationInput, g: np.ndarray,
                cfg: CalibrationConfig) -> int:
    """The vanishing point again through the current lens (the segments bow with it)."""
    if pr.vp is None:
        return 0
    vp, vp_std, n = road_vanishing_point(inp.lines, math.exp(g[G["log_f"]]), pr.c,
                                         g[G["k1"]], g[G["k2"]], cfg.vp_floor_px)
    if n:
        pr.vp, pr.vp_std = vp, vp_std
    return n


def _fit_rounds(pr: fit.Problem, g: np.ndarray, m: np.ndarray, has_flow: bool,
                cfg: CalibrationConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict,
                                                 dict]:
    """The rounds of fits with rejection between them, then the covariance of the last."""
    rounds = [_free(), _free("pitch", "yaw", "log_h"),
              _free("log_f", "k1", "pitch", "yaw", "roll", "log_h")]
    if not has_flow:
        rounds = [_free("log_f", "k1", "pitch", "yaw", "roll", "log_h")]
    for free in rounds:
        g, m, _, _ = fit.solve(pr, g, m, free, max_nfev=EARLY_ROUND_EVALUATIONS)
        _reject(pr, g, m, cfg)
    g, m, (res, lay), spans = fit.solve(pr, g, m, rounds[-1])
    cov, cue, observable = fit.covariance(pr, g, m, res, lay, spans, cfg.useful_std())
    return g, m, cov, cue, observable


def _k1_refused(pr: fit.Problem, g: np.ndarray, cov: np.ndarray, cfg: CalibrationConfig
                ) -> str | None:
    """Why the estimated k1 is refused (within ``k1_exclusion_sigmas`` honest sigmas of
    0), or None to keep it. The honest sigma adds the plumb lines' systematic scatter."""
    i = G["k1"]
    if pr.fixed[i]:
        return None
    sd = math.sqrt(max(float(cov[i, i]), 0.0) + cfg.k1_systematic_std ** 2)
    if abs(float(g[i])) >= cfg.k1_exclusion_sigmas * sd:
        return None
    return (f"k1 {g[i]:+.3f} +- {sd:.3f} does not exclude 0 (within "
            f"{cfg.k1_exclusion_sigmas:g} sigma): held at 0, no distortion")


def _without_distortion(pr: fit.Problem, g: np.ndarray, m: np.ndarray, cfg: CalibrationConfig
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict, dict]:
    """The final fit again with k1 and k2 held at 0 (not a camera file's value: the
    fixed flags are restored, and k1 reported as the prior)."""
    held = pr.fixed.copy()
    mean = pr.prior_mean.copy()
    pr.fixed[[G["k1"], G["k2"]]] = True
    pr.prior_mean[[G["k1"], G["k2"]]] = 0.0
    g = g.copy()
    g[[G["k1"], G["k2"]]] = 0.0
    try:
        g, m, (res, lay), spans = fit.solve(pr, g, m, _free("log_f", "pitch", "yaw", "roll",
                                                           "log_h"))
        cov, cue, observable = fit.covariance(pr, g, m, res, lay, spans, cfg.useful_std())
    finally:
        pr.fixed, pr.prior_mean = held, mean
    observable["k1"] = observable["k2"] = False
    return g, m, cov, cue, observable


def solve_camera(inp: CalibrationInput, cfg: CalibrationConfig | None = None) -> Solution:
    """Fit the camera to the cues (see the module docstring)."""
    cfg = cfg or CalibrationConfig()
    pr, g, m, n_vp = _start(inp, cfg)
    g = _plumb_start(pr, g)
    n_vp = _refresh_vp(pr, inp, g, cfg) or n_vp
    has_flow = pr.pairs is not None and len(pr.pairs.pair) > 0
    g, m, cov, cue, observable = _fit_rounds(pr, g, m, has_flow, cfg)
    refused = {}
    why = _k1_refused(pr, g, cov, cfg)
    if why is not None:
        k1_std2 = float(cov[G["k1"], G["k1"]]) + cfg.k1_systematic_std ** 2
        g, m, cov, cue, observable = _without_distortion(pr, g, m, cfg)
        cov[G["k1"], G["k1"]] = k1_std2
        refused["k1"] = why
    elif not pr.fixed[G["k1"]]:
        cov[G["k1"], G["k1"]] += cfg.k1_systematic_std ** 2
    sol = Solution(g=g, cov=cov, m=m, problem=pr, cue=cue, observable=observable,
                   n_vp_frames=n_vp, n_chains=0 if pr.chains is None else len(pr.chains[0]),
                   refused=refused)
    if pr.pairs is not None and len(pr.pairs.pair):
        pred, _ = predict_b(g, m, pr.pairs, pr.c)
        sol.flow_rms_px = float(np.sqrt(np.mean(np.sum((pr.pairs.points_b - pred) ** 2, 1))))
        sol.n_points = len(pr.pairs.pair)
    return sol
