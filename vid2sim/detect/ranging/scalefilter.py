"""Range filter of one track that fuses the box's scale change with the absolute range cues.

A box's width w changes with range as w ~ f W / (Z + d): the ratio of two frames' widths
measures Z2 / Z1, i.e. Z-dot / Z, with no need to know the vehicle's width W, and is untouched
by the body's pitch, the road's height under the vehicle and the horizon, which blur the
ground cue. So the filter's state carries the log width c = ln W as an unknown constant of
the track, next to range and range rate: each frame's ln(w_px) is a measurement of
c - ln(Z + d) (linearised about the frame's own fit), whose absolute level the filter learns
from the absolute cues, and whose changes it takes at their pixel noise.

The absolute cues (the bottom edge on the road, the top edge against the track's height: the
single-frame fit with the width left free) are a second measurement of Z with their whole
variance (the part common to a track, road height and horizon, included): they set the range's
level together with the width's prior, the width's changes set its rate. (A constant
relative bias of the absolute cues as a fourth state was tried and dropped: the level is then
fixed by priors alone, and on a manoeuvring lead the filter's lag fed the bias state until the
range read half its truth on synthetic clips.) State (Z, Z-dot, c); white-noise acceleration
on Z (Bar-Shalom, Li & Kirubarajan 2001, sec. 6.2.2), a slow random walk on c (the visible
outline's widest part changes with the viewing angle); Kalman filter and Rauch-Tung-Striebel
smoother, run for all candidate acceleration noises at once (vectorised), the most likely one
kept as in :func:`vid2sim.detect.ranging.smoother.smooth_track_adaptive`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vid2sim.detect.ranging.boxfit import BoxArrays
from vid2sim.detect.ranging.config import RangingConfig
from vid2sim.detect.ranging.smoother import (
    DIFFUSE_PRIOR,
    INNOVATION_GATE_NIS,
    INVERSE_RATIO_CLAMP,
)

# Random walk of the log width [1/sqrt(s)]: the part of the outline that makes the box's
# sides (rear face, wheel arches, mirrors; the flank once a car turns a few degrees) and what
# of it a partial occlusion hides change within seconds by several per cent. 0.02 / sqrt(s)
# lets c move 6 % in 10 s. On the KITTI tracking labels as 10 Hz tracks it gave a lead
# range-rate RMSE of 0.63 m/s (0.005: 0.69; 0.01: 0.67) and 1.65 m/s over all vehicles
# below 40 m (1.72; 1.70); python benchmarks/bench_ranging.py --kitti-rate.
LOG_WIDTH_WALK_PER_SQRT_S = 0.02
# Smallest variance of a state (numerical: keeps the predicted covariance invertible).
STATE_VAR_FLOOR = 1e-10


@dataclass
class RangeMeasurements:
    """One track's per-frame measurements, in time order.

    ``abs_m`` / ``abs_var_m2``: range from the absolute cues and its frame-to-frame variance
    (NaN where there is none). ``log_w`` / ``log_w_var``: ln of the box width [ln px] and its variance (NaN
    where a side is cut); the width model about the frame's fit (range ``lin_x_m``, log width
    ``lin_c``) is ``lin_a - ln((Z + d) / (lin_x_m + d)) + lin_e * (c - lin_c)`` with d such
    that its slope at the fit is ``lin_b`` (d = -1 / lin_b - lin_x_m). ``rate_mps`` /
    ``rate_var``: for a standing vehicle, the range rate the ego's own motion gives it and its
    variance (None, or NaN where there is none: a moving vehicle).
    """

    t_s: np.ndarray
    abs_m: np.ndarray
    abs_var_m2: np.ndarray
    log_w: np.ndarray
    log_w_var: np.ndarray
    lin_x_m: np.ndarray
    lin_c: np.ndarray
    lin_a: np.ndarray
    lin_b: np.ndarray
    lin_e: np.ndarray
    start_m: float
    log_width_prior: float
    log_width_prior_var: float
    rate_mps: np.ndarray | None = None
    rate_var: np.ndarray | None = None


@dataclass
class FilteredRange:
    """Smoothed range, rate and their spreads at the measurement times, the log width and
    the acceleration noise chosen."""

    range_m: np.ndarray
    range_rate_mps: np.ndarray
    range_std_m: np.ndarray
    log_width: np.ndarray
    accel_noise_mps2: float
    log_likelihood: float


def _update(x: np.ndarray, p: np.ndarray, h: np.ndarray, innov: np.ndarray, r: np.ndarray,
            gate: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Kalman update of G states at once with one scalar measurement each.

    ``x`` (G, 3), ``p`` (G, 3, 3), ``h`` (3,) or (G, 3), ``innov`` (G,), ``r`` (G,). With
    ``gate`` an innovation beyond the gate inflates its noise to sit at the gate. Returns the
    new state, covariance and each candidate's log-likelihood increment.
    """
    h = np.broadcast_to(h, x.shape)
    ph = np.einsum("gij,gj->gi", p, h)
    s = np.einsum("gi,gi->g", h, ph) + r
    nis = innov * innov / s
    ll = -0.5 * (nis + np.log(s))
    if gate:
        far = nis > INNOVATION_GATE_NIS
        # Beyond the gate the log-likelihood continues linearly in |innovation| (Huber's
        # loss): a gated frame still counts against the noise level that needed the gate,
        # or the calmest filter, gating every manoeuvre away, would look the most likely.
        huber = -0.5 * (2.0 * np.sqrt(INNOVATION_GATE_NIS * nis) - INNOVATION_GATE_NIS
                        + np.log(s))
        ll = np.where(far, huber, ll)
        s = np.where(far, s + r * (nis / INNOVATION_GATE_NIS - 1.0), s)
    k = ph / s[:, None]
    x = x + k * innov[:, None]
    p = p - k[:, :, None] * ph[:, None, :]
    return x, 0.5 * (p + np.transpose(p, (0, 2, 1))), ll


def _initial_state(m: RangeMeasurements, g: int, v0_std_mps: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """G copies of the diffuse start: range from the first fit, width from its prior."""
    x = np.zeros((g, 3))
    x[:, 0], x[:, 2] = m.start_m, m.log_width_prior
    p = np.zeros((g, 3, 3))
    p[:, 0, 0] = DIFFUSE_PRIOR * (1.0 + m.start_m ** 2)
    p[:, 1, 1] = v0_std_mps ** 2
    # A floor keeps the covariance invertible for the smoother when the width is known exactly.
    p[:, 2, 2] = max(m.log_width_prior_var, STATE_VAR_FLOOR)
    return x, p


def _predict(x: np.ndarray, p: np.ndarray, dt: float, q: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray]:
    """Constant-velocity prediction over ``dt`` with white-noise acceleration ``q`` (one per
    candidate) and the log width's random walk."""
    x = x.copy()
    x[:, 0] += dt * x[:, 1]
    p01 = p[:, 0, :] + dt * p[:, 1, :]  # rows of F P
    p = p.copy()
    p[:, 0, :] = p01
    p[:, :, 0] = p[:, :, 0] + dt * p[:, :, 1]
    p[:, 0, 0] += q * dt ** 3 / 3
    p[:, 0, 1] += q * dt ** 2 / 2
    p[:, 1, 0] += q * dt ** 2 / 2
    p[:, 1, 1] += q * dt
    p[:, 2, 2] += LOG_WIDTH_WALK_PER_SQRT_S ** 2 * dt
    return x, p


def _update_absolute(x: np.ndarray, p: np.ndarray, m: RangeMeasurements, k: int,
                     first: bool, inverse: bool):
    """The absolute range cue; with ``inverse`` its variance moved from the reading to the
    predicted range as (Z / reading)^4 (its error is additive in 1/Z; see
    :func:`vid2sim.detect.ranging.smoother._kf_rts_cv`)."""
    g = x.shape[0]
    r = np.full(g, float(m.abs_var_m2[k]))
    if inverse and not first and m.abs_m[k] > 0:
        ratio = np.clip((np.maximum(x[:, 0], 1e-3) / m.abs_m[k]) ** 4,
                        1 / INVERSE_RATIO_CLAMP, INVERSE_RATIO_CLAMP)
        r = r * ratio
    return _update(x, p, np.array([1.0, 0.0, 0.0]), m.abs_m[k] - x[:, 0], r, gate=not first)


def _update_width(x: np.ndarray, p: np.ndarray, m: RangeMeasurements, k: int, first: bool):
    """Extended Kalman update on the 1/(Z + d) law that the linear model's slope b implies
    (d = -1/b - Z_fit): a filter far from the frame's own fit must not read the width
    against a tangent (it ran away from the truth on far leads)."""
    g = x.shape[0]
    d_eff = -1.0 / m.lin_b[k] - m.lin_x_m[k]
    zd = np.maximum(x[:, 0] + d_eff, 0.1)
    h = np.zeros((g, 3))
    h[:, 0], h[:, 2] = -1.0 / zd, m.lin_e[k]
    pred = (m.lin_a[k] - np.log(zd / (m.lin_x_m[k] + d_eff))
            + m.lin_e[k] * (x[:, 2] - m.lin_c[k]))
    return _update(x, p, h, m.log_w[k] - pred, np.full(g, float(m.log_w_var[k])),
                   gate=not first)


def _update_rate(x: np.ndarray, p: np.ndarray, m: RangeMeasurements, k: int):
    """The range rate a standing vehicle has from the ego's own measured motion
    (:func:`vid2sim.detect.ranging.parallax.standing_range_rate`), at its noise."""
    g = x.shape[0]
    return _update(x, p, np.array([0.0, 1.0, 0.0]), m.rate_mps[k] - x[:, 1],
                   np.full(g, float(m.rate_var[k])), gate=False)


def _rts(xs_f: np.ndarray, ps_f: np.ndarray, xs_p: np.ndarray, ps_p: np.ndarray,
         dts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rauch-Tung-Striebel backward pass over the filtered and predicted states."""
    xs, ps = xs_f.copy(), ps_f.copy()
    for k in range(len(dts) - 2, -1, -1):
        f = np.eye(3)
        f[0, 1] = dts[k + 1]
        # C = P_f F^T P_p^-1, i.e. C^T = P_p^-1 (F P_f) (both symmetric).
        try:
            c = np.transpose(np.linalg.solve(ps_p[k + 1] + STATE_VAR_FLOOR * np.eye(3),
                                             f @ ps_f[k]), (0, 2, 1))
        except np.linalg.LinAlgError:
            continue
        xs[k] = xs_f[k] + np.einsum("gij,gj->gi", c, xs[k + 1] - xs_p[k + 1])
        ps[k] = ps_f[k] + c @ (ps[k + 1] - ps_p[k + 1]) @ np.transpose(c, (0, 2, 1))
    return xs, ps


def filter_range(m: RangeMeasurements, accel_noise_grid: tuple[float, ...], v0_std_mps: float,
                 inverse: bool = True) -> list[FilteredRange]:
    """Filter and smooth one track for every acceleration noise of ``accel_noise_grid``.

    Per frame: predict, then the absolute range (``inverse``: see :func:`_update_absolute`),
    the box's log width and, for a standing vehicle, the range rate the ego's motion gives.
    The noise level is chosen on the absolute cue's innovations alone: the width's slow
    changes from turning and occlusion would read as manoeuvres.
    """
    q = np.asarray(accel_noise_grid, dtype=float)
    g, n = q.size, len(m.t_s)
    x, p = _initial_state(m, g, v0_std_mps)
    xs_f, ps_f = np.zeros((n, g, 3)), np.zeros((n, g, 3, 3))
    xs_p, ps_p = np.zeros((n, g, 3)), np.zeros((n, g, 3, 3))
    dts = np.zeros(n)
    loglik = np.zeros(g)
    have_abs = np.isfinite(m.abs_m) & np.isfinite(m.abs_var_m2)
    have_w = np.isfinite(m.log_w) & np.isfinite(m.log_w_var)
    have_rate = (np.isfinite(m.rate_mps) & np.isfinite(m.rate_var) if m.rate_mps is not None
                 else np.zeros(n, dtype=bool))
    first = True
    for k in range(n):
        dt = float(m.t_s[k] - m.t_s[k - 1]) if k else 0.0
        dts[k] = dt
        if dt > 0:
            x, p = _predict(x, p, dt, q)
        xs_p[k], ps_p[k] = x, p
        if have_abs[k]:
            x, p, ll = _update_absolute(x, p, m, k, first, inverse)
            if not first:
                loglik += ll
            first = False
        if have_w[k]:
            x, p, _ = _update_width(x, p, m, k, first)
            first = False
        if have_rate[k]:
            x, p, _ = _update_rate(x, p, m, k)
        xs_f[k], ps_f[k] = x, p
    xs, ps = _rts(xs_f, ps_f, xs_p, ps_p, dts)
    return [FilteredRange(xs[:, j, 0].copy(), xs[:, j, 1].copy(),
                          np.sqrt(np.maximum(ps[:, j, 0, 0], 0.0)), xs[:, j, 2].copy(),
                          float(q[j]), float(loglik[j])) for j in range(g)]


def filter_range_adaptive(m: RangeMeasurements, accel_noise_grid: tuple[float, ...],
                          v0_std_mps: float, margin_loglik: float, inverse: bool = True
                          ) -> FilteredRange:
    """:func:`filter_range` for each candidate noise; the calmest one whose likelihood is
    within ``margin_loglik`` of the most likely."""
    fits = sorted(filter_range(m, accel_noise_grid, v0_std_mps, inverse),
                  key=lambda f: f.accel_noise_mps2)
    top = max(f.log_likelihood for f in fits)
    return next(f for f in fits if f.log_likelihood >= top - margin_loglik)


def log_width_var(sig_left_px: np.ndarray, sig_right_px: np.ndarray, width_px: np.ndarray
                  ) -> np.ndarray:
    """Variance of ln(width) of a box whose sides have independent pixel noise."""
    return (sig_left_px ** 2 + sig_right_px ** 2) / np.maximum(width_px, 1.0) ** 2


def rigid_scale_breaks(t_s: np.ndarray, width_px: np.ndarray, height_px: np.ndarray,
                       whole: np.ndarray, range_m: np.ndarray, edge_noise_px: float,
                       edge_noise_frac: float, max_receding_mps: float, sigmas: float
                       ) -> np.ndarray:
    """Where one time-ordered track stops being one rigid vehicle: True at a box whose width
    AND height shrank from the track's previous whole box (no side cut) by more than any
    vehicle leaving the ego can make them shrink.

    A rigid vehicle's image size goes as 1 / Z, so over dt its box can shrink by at most
    Z / (Z + u dt), u the fastest it recedes (``max_receding_mps``), Z the earlier box's
    single-frame range; ``sigmas`` times the two boxes' edge noise is allowed on top. A
    box that shrinks more in both directions is another, further object the tracker took
    up (after an occlusion, across a gap), and a range filter that joined the two would turn
    the jump into a speed. A box that grows is not tested: an approaching vehicle's growth
    has no useful bound at short range.
    """
    n = len(t_s)
    out = np.zeros(n, dtype=bool)
    seen = np.flatnonzero(whole & (width_px > 0) & (height_px > 0) & np.isfinite(range_m)
                          & (range_m > 0))
    if seen.size < 2:
        return out
    a, b = seen[:-1], seen[1:]
    dt = t_s[b] - t_s[a]
    limit = np.log1p(max_receding_mps * np.maximum(dt, 0.0) / range_m[a])

    def shrink_sigmas(size: np.ndarray) -> np.ndarray:
        s = (edge_noise_px + edge_noise_frac * size) * math.sqrt(2.0) / size
        ds = -np.log(size[b] / size[a]) - limit
        return ds / np.hypot(s[a], s[b])

    out[b] = (shrink_sigmas(width_px) > sigmas) & (shrink_sigmas(height_px) > sigmas)
    return out


def rigid_runs(members: np.ndarray, ba: BoxArrays, t_box: np.ndarray, range_m: np.ndarray,
               config: RangingConfig) -> list[np.ndarray]:
    """One track's boxes (``members``, time order) split where they stop being one rigid
    vehicle (:func:`rigid_scale_breaks`); ``range_m``: every box's single-frame range."""
    whole = ~(ba.cut_left[members] | ba.cut_right[members] | ba.cut_top[members]
              | ba.cut_bottom[members])
    breaks = rigid_scale_breaks(t_box[members], ba.x2[members] - ba.x1[members],
                                ba.y2[members] - ba.y1[members], whole, range_m[members],
                                config.edge_noise_px, config.edge_noise_frac,
                                config.filter_max_receding_mps,
                                config.filter_scale_break_sigmas)
    return np.split(members, np.flatnonzero(breaks))
