"""Ego-motion association cost: how well a detection continues a track's last box when the
camera moves forward (the association stage of :mod:`vid2sim.detect.tracking.tracker` for sparse
input and for what IoU leaves unmatched), and the per-track motion figures it is centred on
(closing rate from box growth, drift across the focus of expansion).

Pure numpy: the tracker calls these with its :class:`~vid2sim.detect.tracking.tracker.TrackerConfig`,
which provides the priors (:class:`MotionPriors`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from vid2sim.core.boxes import border_cut

CHI2_99 = {2: 9.210, 3: 11.345, 4: 13.277}
"""99 % quantiles of the chi-square distribution by degrees of freedom: the gate of
:func:`expansion_cost` (DeepSORT gates its Mahalanobis distance the same way)."""

PASSED_CLOSING = 0.9
"""Fraction of its range a vehicle has closed (closing rate x time) when it counts as passed
by the camera: its box would have grown tenfold."""

EDGE_NOISE_FLOOR_PX = 1.0
"""Added to every box edge's noise [px]: the detector's boxes are quantised to about a pixel
of its input, whatever the box size."""

MIN_DT_S = 1e-3
"""Shortest time between two boxes the cost is evaluated for [s]: keeps the priors, which
scale with the elapsed time, from collapsing to zero width."""

LN_SCALE_GRID_SIGMAS = 3.0
"""The free fit searches ln r over +-this many prior standard deviations about its centre:
beyond 3 sigma the prior alone exceeds the 2-4 edge gate."""

SCALE_GRID_POINTS = 61
"""Samples of ln r over that span (0.1 sigma apart: finer than the edge noise resolves)."""

MIN_STD_PX = 1e-3
"""Floor of the translation prior's standard deviation [px], so it never divides by zero."""

MIN_REMAINING_RANGE = 1e-3
"""Floor of the range left (1 - closing, as a fraction) when a static hypothesis's scale is
computed; hypotheses closing beyond ``PASSED_CLOSING`` are refused anyway."""

MAX_OWN_CLOSING = 10.0
"""A track's own closing (rate x time) is clipped below at -this before it sets the scale
prior: a box shrinking faster than e^-2.4 is noise, not a prior to centre on."""


class MotionPriors(Protocol):
    """The noise and prior parameters :func:`expansion_cost` needs (the fields of the same
    names of :class:`~vid2sim.detect.tracking.tracker.TrackerConfig`, which documents them)."""

    edge_noise_ratio: float
    lateral_speed_mps: float
    vehicle_height_m: float
    growth_rate_per_s: float
    shrink_rate_per_s: float
    border_margin_px: float
    moving_penalty: float


def expansion_cost(prev_px: np.ndarray, dt_s: np.ndarray, dets_px: np.ndarray, *,
                   foe_px: tuple[float, float] | None, image_size_px: tuple[int, int] | None,
                   config: MotionPriors, n_grid: int = SCALE_GRID_POINTS,
                   static_rates_per_px_s: np.ndarray | None = None,
                   closing_rate_per_s: np.ndarray | None = None,
                   drift_px_s: np.ndarray | None = None) -> np.ndarray:
    """Gated cost of continuing each last-seen box with each detection under ego motion.

    A camera moving forward sees a vehicle at lateral offset X, height Y and range Z at
    x - x_foe = f X / Z, y - y_foe = f Y / Z: when X and Y stay put (a parked car, a car in
    another lane), every box edge e moves to ``foe + r (e - foe)`` with r = Z_before / Z_now
    the same for all four edges. Each pair is scored by

        J = min over r, t of  sum_edges (e_det - foe - r (e_prev - foe) - t)^2 / s_edge^2
                              + |t|^2 / s_t^2 + (ln r)^2 / s_lnr^2

    with s_edge the detector's edge noise (``edge_noise_ratio`` box heights), t a translation
    for the vehicle's own lateral motion (s_t = ``lateral_speed_mps`` dt in vehicle heights)
    and ln r the log scale change (s_lnr = ``growth_rate_per_s`` dt when growing,
    ``shrink_rate_per_s`` dt when shrinking): the priors grow with the
    time since the track was last seen, so the gate opens for sparse input and stays tight
    for dense video. An edge on the image border (a vehicle cut by the frame) only bounds
    where the true edge is: it adds a one-sided residual, and none when cut in both boxes;
    a pair needs one edge per axis seen in both boxes.

    Parameters
    ----------
    prev_px : ndarray (n, 4)
        Last detected box of each track (x1, y1, x2, y2) [px].
    dt_s : ndarray (n,)
        Time since each track's last detection [s].
    dets_px : ndarray (m, 4)
        Detection boxes [px].
    foe_px : (float, float) or None
        Focus of expansion [px] (the image centre serves for a forward camera); None scales
        each box about its own centre.
    image_size_px : (int, int) or None
        Image width and height [px], to find edges cut by the border.
    config : MotionPriors
        Noise and prior parameters (a :class:`~vid2sim.detect.tracking.tracker.TrackerConfig`).
    n_grid : int
        Samples of ln r over +-3 s_lnr.
    static_rates_per_px_s : ndarray (k,), optional
        Ego-motion hypotheses: closing speed over (focal length x vehicle height), so that
        a static vehicle of box height h [px] is approached at ``rate * h`` ranges per
        second [1/(px s)]. Under each, a pair costs the lesser of the static fit (r fixed by
        the rate and the last box height, no prior) and the free fit plus
        ``moving_penalty``: one ego speed must explain every parked car, which tells a row
        of parked cars grown by the ego's approach from the same row shifted by one car.
    closing_rate_per_s : ndarray (n,), optional
        Each track's own measured closing speed over range [1/s] (NaN: unknown): the free
        fit's scale prior is centred on the ratio it predicts, and a track it carries past
        the camera (``closing dt >= 0.9``) matches nothing.
    drift_px_s : ndarray (n, 2), optional
        Each track's own image motion not explained by expansion (x, y) [px/s], e.g. a lead
        car drifting across the lane: the translation prior is centred on ``drift dt``.

    Returns
    -------
    ndarray (n, m), or (k, n, m) with ``static_rates_per_px_s``
        J divided by its 99 % chi-square gate (number of usable edges as degrees of freedom):
        at most 1 for a plausible pair; inf where the pair is impossible.
    """
    prev = np.asarray(prev_px, dtype=float).reshape(-1, 4)
    dets = np.asarray(dets_px, dtype=float).reshape(-1, 4)
    n, m = len(prev), len(dets)
    if n == 0 or m == 0:
        return np.full((n, m), np.inf)
    dt = np.maximum(np.asarray(dt_s, dtype=float).reshape(-1), MIN_DT_S)
    pairs = _Pairs.of(prev, dets, dt, foe_px, image_size_px, config, drift_px_s)
    # A track's own closing rate (1/Z dynamics: r = 1 / (1 - c dt)) centres its scale prior;
    # a track whose own approach has carried it past the camera cannot be continued.
    own = (np.zeros(n) if closing_rate_per_s is None
           else np.nan_to_num(np.asarray(closing_rate_per_s, dtype=float).reshape(-1)) * dt)
    passed = own >= PASSED_CLOSING
    ln_r0 = -np.log(1.0 - np.clip(own, -MAX_OWN_CLOSING, PASSED_CLOSING))      # (n,)
    # ln r in units of s_lnr
    u = np.linspace(-LN_SCALE_GRID_SIGMAS, LN_SCALE_GRID_SIGMAS, n_grid)
    rate = np.where(u > 0, config.growth_rate_per_s, config.shrink_rate_per_s)
    r = np.exp(ln_r0[:, None] + u[None, :] * rate[None, :] * dt[:, None])[:, None, :, None]
    j_free = (pairs.edge_cost(r) + u[None, None, :] ** 2).min(axis=2)
    gate, usable = pairs.gate()
    ok = usable & ~passed[:, None]
    if static_rates_per_px_s is None:
        return np.where(ok, j_free / gate, np.inf)
    h_prev = np.maximum(prev[:, 3] - prev[:, 1], 1.0)
    out = []
    for rate_px in static_rates_per_px_s:
        # a static object at range Z = f H / h closes by v dt: r = 1 / (1 - v dt / Z)
        closing = rate_px * dt * h_prev                              # v dt / Z, (n,)
        r_static = 1.0 / np.maximum(1.0 - closing, MIN_REMAINING_RANGE)
        j_static = np.where((closing < PASSED_CLOSING)[:, None],
                            pairs.edge_cost(r_static[:, None, None, None])[:, :, 0], np.inf)
        j = np.minimum(j_static, j_free + config.moving_penalty)
        out.append(np.where(ok, j / gate, np.inf))
    return np.array(out).reshape(len(out), n, m)


@dataclass(frozen=True, slots=True)
class _Pairs:
    """Every (track box, detection) pair of :func:`expansion_cost` about the FOE: edges
    relative to it (``a`` before, ``b`` now, (n, m, 1, 4)), which edges are seen in both
    boxes and fitted exactly (``v``) or as a vehicle's inner side (``vi``), which are cut in
    one box only, and the edge and translation noise."""

    a: np.ndarray
    b: np.ndarray
    both: np.ndarray
    cut_prev: np.ndarray
    cut_det: np.ndarray
    prev_only: np.ndarray
    det_only: np.ndarray
    v: np.ndarray
    vi: np.ndarray
    s_edge: np.ndarray
    s_t: np.ndarray
    k: np.ndarray
    t0: np.ndarray

    @classmethod
    def of(cls, prev: np.ndarray, dets: np.ndarray, dt: np.ndarray,
           foe_px: tuple[float, float] | None, image_size_px: tuple[int, int] | None,
           config: MotionPriors, drift_px_s: np.ndarray | None) -> _Pairs:
        n, m = len(prev), len(dets)
        if foe_px is None:
            centre_p = np.stack([(prev[:, 0] + prev[:, 2]) / 2,
                                 (prev[:, 1] + prev[:, 3]) / 2], 1)
            foe = np.broadcast_to(np.tile(centre_p, 2)[:, None, :], (n, m, 4))
        else:
            foe = np.broadcast_to(np.array([foe_px[0], foe_px[1]] * 2, float), (n, m, 4))
        a = (prev[:, None, :] - foe)[:, :, None, :]                      # (n, m, 1, 4)
        b = (dets[None, :, :] - foe)[:, :, None, :]
        cut_prev = border_cut(prev, image_size_px, config.border_margin_px)[:, None, :]
        cut_det = border_cut(dets, image_size_px, config.border_margin_px)[None, :, :]
        both = ~cut_prev & ~cut_det                                      # (n, m, 4) two-sided
        h_prev = np.maximum(prev[:, 3] - prev[:, 1], 1.0)
        h_det = np.maximum(dets[:, 3] - dets[:, 1], 1.0)
        scale = np.sqrt(h_prev[:, None] * h_det[None, :])                # (n, m) [px]
        s_edge = (config.edge_noise_ratio * scale + EDGE_NOISE_FLOOR_PX)[:, :, None]
        s_t = ((config.lateral_speed_mps / config.vehicle_height_m) * dt[:, None] * scale
               + MIN_STD_PX)[:, :, None]
        inner = _inner_edges(a, both)
        t0 = (np.zeros((n, 2)) if drift_px_s is None
              else np.nan_to_num(np.asarray(drift_px_s, dtype=float).reshape(n, 2)))
        # One edge cut: the true edge lies further out than the box says, so the prediction
        # only bounds it (one-sided residual); both cut: no information.
        return cls(a=a, b=b, both=both, cut_prev=cut_prev, cut_det=cut_det,
                   prev_only=(cut_prev & ~cut_det)[:, :, None, :],
                   det_only=(~cut_prev & cut_det)[:, :, None, :],
                   v=(both & ~inner)[:, :, None, :],                     # edges fitted exactly
                   vi=inner[:, :, None, :], s_edge=s_edge, s_t=s_t,
                   k=(s_edge / s_t) ** 2,                                # ridge of the t prior
                   t0=(t0 * dt[:, None])[:, None, None, :])              # (n, 1, 1, 2) [px]

    def edge_cost(self, r: np.ndarray) -> np.ndarray:
        """Edge misfit plus translation prior for scale ratios r (n, 1, G, 1) -> (n, m, G)."""
        a, b, v, s_t, t0 = self.a, self.b, self.v, self.s_t, self.t0
        res = b - r * a                                              # (n, m, G, 4)
        j = np.zeros(res.shape[:3])
        t = np.zeros(res.shape)
        for i, axis in enumerate((slice(0, 4, 2), slice(1, 4, 2))):   # x edges, y edges
            ra, va = res[..., axis], v[..., axis]
            t_axis = ((ra * va).sum(-1) + self.k * t0[..., i]) / (va.sum(-1) + self.k)
            t[..., axis] = t_axis[..., None]
            j += (t_axis - t0[..., i]) ** 2 / s_t ** 2
        e = res - t                                                  # observed - predicted
        j += ((e * v) ** 2).sum(-1) / self.s_edge ** 2
        e_unscaled = b - a - t                                       # the inner edge at r = 1
        e_inner = np.where(e * e_unscaled <= 0, 0.0,
                           np.sign(e) * np.minimum(np.abs(e), np.abs(e_unscaled)))
        j += ((e_inner * self.vi) ** 2).sum(-1) / self.s_edge ** 2
        # prev cut: the observed edge must lie at or beyond the prediction; det cut: within
        over = np.where(self.prev_only, np.maximum(0.0, -OUTWARD * e), 0.0)
        over += np.where(self.det_only, np.maximum(0.0, OUTWARD * e), 0.0)
        return j + (over ** 2).sum(-1) / self.s_edge ** 2

    def gate(self) -> tuple[np.ndarray, np.ndarray]:
        """The 99 % chi-square gate of each pair (usable edges as degrees of freedom) and
        whether it is usable at all (an edge per axis seen in both boxes)."""
        n_x = self.both[:, :, 0::2].sum(-1)
        n_y = self.both[:, :, 1::2].sum(-1)
        dof = n_x + n_y + (self.cut_prev ^ self.cut_det).sum(-1)
        gate = np.vectorize(lambda d: CHI2_99.get(int(d), np.inf), otypes=[float])(dof)
        return gate, (n_x >= 1) & (n_y >= 1)


OUTWARD = np.array([-1.0, -1.0, 1.0, 1.0])
"""The outward direction of each box edge (x1, y1, x2, y2): x1 and y1 out = smaller."""


def _inner_edges(a: np.ndarray, both: np.ndarray) -> np.ndarray:
    """The inner edge of a box off to one side of the FOE (the edge nearer to it) is the far
    end of the vehicle's visible side, up to a car length deeper than the rear face that
    sets the outer edges, so it scales by anything between 1 and r."""
    same_side = (a[..., 0::2].prod(-1) > 0)[..., 0], (a[..., 1::2].prod(-1) > 0)[..., 0]
    inner = np.zeros(both.shape, dtype=bool)
    for axis, side in zip((0, 1), same_side, strict=True):
        first_inner = np.abs(a[:, :, 0, axis]) < np.abs(a[:, :, 0, axis + 2])
        inner[..., axis] = side & first_inner
        inner[..., axis + 2] = side & ~first_inner
    return inner & both


def closing_rate(before_px: np.ndarray, after_px: np.ndarray, dt_s: float,
                 image_size_px: tuple[int, int] | None, margin_px: float) -> float:
    """Closing speed over the latest range [1/s] from the growth of two boxes (size ~
    1/range, so v / Z_after = (h_after / h_before - 1) / dt), from heights, else widths,
    when not cut by the border (edges within ``margin_px`` of it); NaN when not measurable."""
    if dt_s <= 0:
        return float("nan")
    cut = border_cut(np.array([before_px, after_px]), image_size_px, margin_px)
    for lo, hi in ((1, 3), (0, 2)):
        if not cut[:, [lo, hi]].any():
            size_before = before_px[hi] - before_px[lo]
            size_after = after_px[hi] - after_px[lo]
            if size_before > 0 and size_after > 0:
                return float((size_after / size_before - 1.0) / dt_s)
    return float("nan")


def drift(before_px: np.ndarray, after_px: np.ndarray, dt_s: float,
          foe_px: tuple[float, float] | None, image_size_px: tuple[int, int] | None,
          margin_px: float) -> np.ndarray | None:
    """Image motion of the box centre beyond scaling about the FOE [px/s] (x, y), from
    two boxes not cut by the border; None when not measurable. Without a FOE the box scales
    about its own centre."""
    if dt_s <= 0 or border_cut(np.array([before_px, after_px]), image_size_px,
                               margin_px).any():
        return None
    h_before, h_after = before_px[3] - before_px[1], after_px[3] - after_px[1]
    if h_before <= 0 or h_after <= 0:
        return None
    c_before = np.array([before_px[0] + before_px[2], before_px[1] + before_px[3]]) / 2
    c_after = np.array([after_px[0] + after_px[2], after_px[1] + after_px[3]]) / 2
    foe = c_before if foe_px is None else np.asarray(foe_px, dtype=float)
    return (c_after - (foe + h_after / h_before * (c_before - foe))) / dt_s
