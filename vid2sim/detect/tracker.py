"""Multi-object tracking of vehicle boxes: a Kalman filter per track, ByteTrack-style association.

Association follows ByteTrack (Zhang et al., ECCV 2022): detections are split by score; the
confident ones are matched first to every live track (tracked or recently lost), then the
weak ones (which are often partly occluded vehicles) are matched to the tracks still
unmatched, so a vehicle fading behind another keeps its track instead of spawning false
ones. Matching is a min-cost assignment on 1 - IoU (scipy's Hungarian solver) with a gate.

Sparse input (a 2 frames/s video, ``--detect-every`` with long gaps, a track lost for a
while) breaks IoU: a car 8 m away beside a camera moving at 10 m/s doubles in size and
slides hundreds of pixels in 0.5 s, and a row of parked cars then looks like the same row
shifted by one car. Three additions handle it:

* an ego-motion association stage (:func:`expansion_cost`): a vehicle that is parked or
  drives parallel to the ego keeps its lateral offset and height, so its box scales about
  the focus of expansion (FOE) by the range ratio. The cost is a chi-square over the box
  edges: either "static", the ratio fixed by one ego closing rate shared by every vehicle
  in the frame (searched per frame) and the box height, or "moving", any ratio under a
  prior centred on the track's own measured closing rate, plus a penalty; a translation
  for lateral motion is allowed; priors grow with the elapsed time; border-cut edges only
  bound the fit. In sparse input (detected frames ``sparse_interval_s`` or more apart) it
  runs before the IoU stages, in dense video after them for what IoU left unmatched.
* tracks end when their own closing rate says the camera has passed them, so a car that
  left the view at the side is not revived by the next car to appear.
* confirmation that knows the detection rate: a tentative track is deleted as a false
  detection only when a detected frame less than ``sparse_interval_s`` after its birth fails
  to see it again (at 10 frames/s a real car is seen in the next frame; at 2 frames/s it may
  already have left the view). A track born in sparse input, or on the last detected frame
  of the video, that is never seen again is thus kept with its one confident box.

Assignments price an unmatched track or detection at half the gate, so a pair is made only
when it beats leaving both alone and pairs beyond the gate never steer the solution.

The Kalman state is (cx, cy, a, h, vcx, vcy, va, vh): box centre [px], aspect w/h, height
[px] and their rates per frame, with noise proportional to the box height (as in SORT and
ByteTrack), so a 20 px far car and a 200 px near car are filtered alike.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import linear_sum_assignment

from vid2sim.records import Detection, TrackedBox


@dataclass(frozen=True, slots=True)
class TrackerConfig:
    """Tracker thresholds.

    :param high_score: detections at or above go to the first association stage
    :param low_score: detections below are ignored; between the two they go to stage two
    :param new_track_score: minimum score of an unmatched detection to start a track
    :param weak_start_score: an unmatched weaker detection (at least this score) starts a
        weak tentative track, which must then be found on ``weak_confirm_hits`` detected
        frames in a row (a small, far vehicle scores 0.2-0.45 frame after frame; a false
        detection of that score rarely repeats at the same place)
    :param weak_confirm_hits: detections in a row that confirm a weak tentative track
    :param iou_high: minimum IoU to match a confident detection (stage one)
    :param iou_low: minimum IoU to match a weak detection (stage two; stricter because weak
        boxes are noisier)
    :param iou_tentative: minimum IoU to match a not yet confirmed track
    :param weak_revive_s: a confirmed track lost for at most this long may be taken up again
        by a weak detection [s]: one missed frame (a far car scoring 0.13-0.26 frame after
        frame, once below the detector's floor) must not end it
    :param iou_weak_revive: minimum IoU of such a weak detection with the lost track's
        predicted box (stricter than ``iou_low``: the track was not seen on the last frame)
    :param max_lost_s: a track unmatched for longer than this is ended [s]
    :param min_hits: detections needed before a track is confirmed (in dense input; see
        ``sparse_interval_s``)
    :param sparse_interval_s: a tentative track is dropped when a detected frame less than
        this long after its birth misses it; after longer intervals it is kept [s]
    :param edge_noise_ratio: one-sigma error of a detected box edge as a fraction of the box
        height (localisation noise of the detector)
    :param lateral_speed_mps: one-sigma speed of a vehicle across the camera's line of sight
        not explained by the ego's forward motion (drift in lane, a slow lane change) [m/s]
    :param vehicle_height_m: typical vehicle height, converts lateral speed to box heights
        per second [m]
    :param growth_rate_per_s: one-sigma rate of growth of the log box size, i.e. closing
        speed over range (10 m/s at 10 m gives 1/s) [1/s]
    :param shrink_rate_per_s: the same for shrinking boxes: with the camera moving forward
        the static world grows, a box shrinks only behind a vehicle faster than the ego, and
        by little (3 m/s faster at 10 m gives 0.3/s) [1/s]
    :param border_margin_px: a box edge this close to the image border is taken as cut by it
        (detectors stop the box of a cut vehicle a few pixels short of the border)
    :param moving_penalty: extra chi-square cost of explaining a pair as a moving vehicle
        rather than a static one approached at the ego speed common to the frame (2 ln of
        the odds static : moving, 2 for odds of about 3 : 1)
    :param closing_time_constant_s: time constant of the filter on each track's closing
        rate (box growth) [s]
    :param max_static_rate_per_s: largest ego-motion hypothesis searched, as closing speed
        over range for a box 100 px high (30 m/s at 10 m: 3/s) [1/s]
    """

    high_score: float = 0.45
    low_score: float = 0.1
    new_track_score: float = 0.5
    weak_start_score: float = 0.25
    weak_confirm_hits: int = 4
    iou_high: float = 0.2
    iou_low: float = 0.4
    iou_tentative: float = 0.3
    weak_revive_s: float = 0.35
    iou_weak_revive: float = 0.5
    max_lost_s: float = 1.2
    min_hits: int = 2
    sparse_interval_s: float = 0.2
    edge_noise_ratio: float = 0.1
    lateral_speed_mps: float = 0.5
    vehicle_height_m: float = 1.5
    growth_rate_per_s: float = 1.0
    shrink_rate_per_s: float = 0.3
    border_margin_px: float = 8.0
    moving_penalty: float = 2.0
    closing_time_constant_s: float = 0.3
    max_static_rate_per_s: float = 4.0


# --------------------------------------------------------------------------- geometry


def iou_matrix(boxes_a: np.ndarray, boxes_b: np.ndarray) -> np.ndarray:
    """Pairwise IoU of two sets of (x1, y1, x2, y2) boxes, shape (len(a), len(b))."""
    a = np.asarray(boxes_a, dtype=float).reshape(-1, 4)
    b = np.asarray(boxes_b, dtype=float).reshape(-1, 4)
    ix1 = np.maximum(a[:, None, 0], b[None, :, 0])
    iy1 = np.maximum(a[:, None, 1], b[None, :, 1])
    ix2 = np.minimum(a[:, None, 2], b[None, :, 2])
    iy2 = np.minimum(a[:, None, 3], b[None, :, 3])
    inter = np.clip(ix2 - ix1, 0, None) * np.clip(iy2 - iy1, 0, None)
    area_a = (a[:, 2] - a[:, 0]) * (a[:, 3] - a[:, 1])
    area_b = (b[:, 2] - b[:, 0]) * (b[:, 3] - b[:, 1])
    union = area_a[:, None] + area_b[None, :] - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)


def xyxy_to_xyah(box: np.ndarray) -> np.ndarray:
    """(x1, y1, x2, y2) -> (cx, cy, w/h, h)."""
    x1, y1, x2, y2 = box
    h = max(y2 - y1, 1e-6)
    return np.array([(x1 + x2) / 2, (y1 + y2) / 2, (x2 - x1) / h, h])


def xyah_to_xyxy(state: np.ndarray) -> np.ndarray:
    """(cx, cy, w/h, h, ...) -> (x1, y1, x2, y2)."""
    cx, cy, a, h = state[:4]
    w = a * h
    return np.array([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2])


def buffered_iou(box_px: np.ndarray, std_px: tuple[float, float], boxes_px: np.ndarray,
                 n_sigma: float = 2.0) -> np.ndarray:
    """IoU of one predicted box with many boxes, all grown by the prediction's uncertainty.

    Both sides are widened by ``n_sigma`` standard deviations of the predicted centre in x
    and y (the "buffered IoU" idea of C-BIoU, Yang et al. WACV 2023, with the buffer taken
    from the Kalman covariance instead of a fixed ratio). A track predicted over several
    frames (``--detect-every N``, a short occlusion, a new track with unknown velocity) thus
    still overlaps the car's new box, while a well-tracked box keeps a tight gate.
    """
    bx, by = n_sigma * std_px[0], n_sigma * std_px[1]
    grow = np.array([-bx, -by, bx, by])
    return iou_matrix((np.asarray(box_px, float) + grow)[None], np.asarray(boxes_px) + grow)[0]


def match(cost: np.ndarray, max_cost: float) -> tuple[list[tuple[int, int]], list[int], list[int]]:
    """Min-cost one-to-one assignment, rejecting pairs costlier than ``max_cost``.

    Returns matched (row, col) pairs, unmatched rows, unmatched columns.
    """
    n_rows, n_cols = cost.shape
    if n_rows == 0 or n_cols == 0:
        return [], list(range(n_rows)), list(range(n_cols))
    # Leaving a row or a column unmatched costs half the gate, so a pair is made only if it
    # is cheaper than leaving both sides alone, and pairs beyond the gate never steer the
    # solution: the square problem [[cost, unmatched rows], [unmatched columns, 0]].
    big = 1e6
    half = max_cost / 2.0
    full = np.full((n_rows + n_cols, n_cols + n_rows), big)
    full[:n_rows, :n_cols] = np.where(cost <= max_cost, cost, big)
    full[:n_rows, n_cols:][np.diag_indices(n_rows)] = half
    full[n_rows:, :n_cols][np.diag_indices(n_cols)] = half
    full[n_rows:, n_cols:] = 0.0
    rows, cols = linear_sum_assignment(full)
    pairs = [(int(r), int(c)) for r, c in zip(rows, cols, strict=True)
             if r < n_rows and c < n_cols and cost[r, c] <= max_cost]
    used_r = {r for r, _ in pairs}
    used_c = {c for _, c in pairs}
    return (pairs, [r for r in range(n_rows) if r not in used_r],
            [c for c in range(n_cols) if c not in used_c])


# 99 % quantiles of the chi-square distribution by degrees of freedom (the gate of
# :func:`expansion_cost`; DeepSORT gates its Mahalanobis distance the same way)
_CHI2_99 = {2: 9.210, 3: 11.345, 4: 13.277}
# Fraction of its range a vehicle has closed (closing rate x time) when it counts as passed
# by the camera: its box would have grown tenfold.
PASSED_CLOSING = 0.9


def border_cut(boxes_px: np.ndarray, image_size_px: tuple[int, int] | None,
               margin_px: float) -> np.ndarray:
    """Which edges (x1, y1, x2, y2) of each box lie on the image border, shape (n, 4)."""
    b = np.asarray(boxes_px, dtype=float).reshape(-1, 4)
    if image_size_px is None:
        return np.zeros(b.shape, dtype=bool)
    w, h = image_size_px
    return np.stack([b[:, 0] <= margin_px, b[:, 1] <= margin_px,
                     b[:, 2] >= w - margin_px, b[:, 3] >= h - margin_px], axis=1)


def expansion_cost(prev_px: np.ndarray, dt_s: np.ndarray, dets_px: np.ndarray, *,
                   foe_px: tuple[float, float] | None, image_size_px: tuple[int, int] | None,
                   config: TrackerConfig, n_grid: int = 61,
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
    config : TrackerConfig
        Noise and prior parameters.
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
    dt = np.maximum(np.asarray(dt_s, dtype=float).reshape(-1), 1e-3)
    if foe_px is None:
        centre_p = np.stack([(prev[:, 0] + prev[:, 2]) / 2, (prev[:, 1] + prev[:, 3]) / 2], 1)
        foe = np.broadcast_to(np.tile(centre_p, 2)[:, None, :], (n, m, 4))
    else:
        foe = np.broadcast_to(np.array([foe_px[0], foe_px[1]] * 2, float), (n, m, 4))
    a = (prev[:, None, :] - foe)[:, :, None, :]                      # (n, m, 1, 4)
    b = (dets[None, :, :] - foe)[:, :, None, :]
    cut_prev = border_cut(prev, image_size_px, config.border_margin_px)[:, None, :]
    cut_det = border_cut(dets, image_size_px, config.border_margin_px)[None, :, :]
    both = ~cut_prev & ~cut_det                                      # (n, m, 4) two-sided
    # One edge cut: the true edge lies further out than the box says, so the prediction
    # only bounds it (one-sided residual); both cut: no information.
    prev_only = (cut_prev & ~cut_det)[:, :, None, :]
    det_only = (~cut_prev & cut_det)[:, :, None, :]
    outward = np.array([-1.0, -1.0, 1.0, 1.0])                       # x1, y1 out = smaller
    h_prev = np.maximum(prev[:, 3] - prev[:, 1], 1.0)
    h_det = np.maximum(dets[:, 3] - dets[:, 1], 1.0)
    scale = np.sqrt(h_prev[:, None] * h_det[None, :])                # (n, m) [px]
    s_edge = (config.edge_noise_ratio * scale + 1.0)[:, :, None]
    s_t = ((config.lateral_speed_mps / config.vehicle_height_m) * dt[:, None] * scale
           + 1e-3)[:, :, None]
    # A track's own closing rate (1/Z dynamics: r = 1 / (1 - c dt)) centres its scale prior;
    # a track whose own approach has carried it past the camera cannot be continued.
    own = (np.zeros(n) if closing_rate_per_s is None
           else np.nan_to_num(np.asarray(closing_rate_per_s, dtype=float).reshape(-1)) * dt)
    passed = own >= PASSED_CLOSING
    ln_r0 = -np.log(1.0 - np.clip(own, -10.0, PASSED_CLOSING))      # (n,)
    u = np.linspace(-3.0, 3.0, n_grid)                               # ln r in units of s_lnr
    rate = np.where(u > 0, config.growth_rate_per_s, config.shrink_rate_per_s)
    r = np.exp(ln_r0[:, None] + u[None, :] * rate[None, :] * dt[:, None])[:, None, :, None]
    # The inner edge of a box off to one side of the FOE (the edge nearer to it) is the far
    # end of the vehicle's visible side, up to a car length deeper than the rear face that
    # sets the outer edges, so it scales by anything between 1 and r.
    same_side = (a[..., 0::2].prod(-1) > 0)[..., 0], (a[..., 1::2].prod(-1) > 0)[..., 0]
    inner = np.zeros(both.shape, dtype=bool)
    for axis, side in zip((0, 1), same_side, strict=True):
        first_inner = np.abs(a[:, :, 0, axis]) < np.abs(a[:, :, 0, axis + 2])
        inner[..., axis] = side & first_inner
        inner[..., axis + 2] = side & ~first_inner
    inner &= both
    v = (both & ~inner)[:, :, None, :]                               # edges fitted exactly
    vi = inner[:, :, None, :]
    k = (s_edge / s_t) ** 2                                          # ridge of the t prior
    t0 = (np.zeros((n, 2)) if drift_px_s is None
          else np.nan_to_num(np.asarray(drift_px_s, dtype=float).reshape(n, 2)))
    t0 = (t0 * dt[:, None])[:, None, None, :]                        # (n, 1, 1, 2) [px]

    def edge_cost(r: np.ndarray) -> np.ndarray:
        """Edge misfit plus translation prior for scale ratios r (n, 1, G, 1) -> (n, m, G)."""
        res = b - r * a                                              # (n, m, G, 4)
        j = np.zeros(res.shape[:3])
        t = np.zeros(res.shape)
        for i, axis in enumerate((slice(0, 4, 2), slice(1, 4, 2))):   # x edges, y edges
            ra, va = res[..., axis], v[..., axis]
            t_axis = ((ra * va).sum(-1) + k * t0[..., i]) / (va.sum(-1) + k)
            t[..., axis] = t_axis[..., None]
            j += (t_axis - t0[..., i]) ** 2 / s_t ** 2
        e = res - t                                                  # observed - predicted
        j += ((e * v) ** 2).sum(-1) / s_edge ** 2
        e_unscaled = b - a - t                                       # the inner edge at r = 1
        e_inner = np.where(e * e_unscaled <= 0, 0.0,
                           np.sign(e) * np.minimum(np.abs(e), np.abs(e_unscaled)))
        j += ((e_inner * vi) ** 2).sum(-1) / s_edge ** 2
        # prev cut: the observed edge must lie at or beyond the prediction; det cut: within
        over = np.where(prev_only, np.maximum(0.0, -outward * e), 0.0)
        over += np.where(det_only, np.maximum(0.0, outward * e), 0.0)
        return j + (over ** 2).sum(-1) / s_edge ** 2

    j_free = (edge_cost(r) + u[None, None, :] ** 2).min(axis=2)
    n_x = both[:, :, 0::2].sum(-1)
    n_y = both[:, :, 1::2].sum(-1)
    dof = n_x + n_y + (cut_prev ^ cut_det).sum(-1)
    gate = np.vectorize(lambda d: _CHI2_99.get(int(d), np.inf), otypes=[float])(dof)
    ok = (n_x >= 1) & (n_y >= 1) & ~passed[:, None]
    if static_rates_per_px_s is None:
        return np.where(ok, j_free / gate, np.inf)
    out = []
    for rate_px in static_rates_per_px_s:
        # a static object at range Z = f H / h closes by v dt: r = 1 / (1 - v dt / Z)
        closing = rate_px * dt * h_prev                              # v dt / Z, (n,)
        r_static = 1.0 / np.maximum(1.0 - closing, 1e-3)
        j_static = np.where((closing < 0.9)[:, None],
                            edge_cost(r_static[:, None, None, None])[:, :, 0], np.inf)
        j = np.minimum(j_static, j_free + config.moving_penalty)
        out.append(np.where(ok, j / gate, np.inf))
    return np.array(out).reshape(len(out), n, m)


# --------------------------------------------------------------------------- Kalman filter


class BoxKalman:
    """Constant-velocity Kalman filter on (cx, cy, a, h); time step in frames.

    Noise standard deviations are fractions of the box height per frame: 1/20 for position,
    1/160 for velocity (the values SORT/DeepSORT/ByteTrack use), a fixed small value for the
    aspect ratio, which changes slowly.
    """

    STD_POSITION = 1.0 / 20.0
    STD_VELOCITY = 1.0 / 160.0

    def __init__(self, box_px: np.ndarray):
        z = xyxy_to_xyah(box_px)
        self.mean = np.concatenate([z, np.zeros(4)])
        h = z[3]
        std = np.array([2 * self.STD_POSITION * h, 2 * self.STD_POSITION * h, 1e-2,
                        2 * self.STD_POSITION * h, 10 * self.STD_VELOCITY * h,
                        10 * self.STD_VELOCITY * h, 1e-5, 10 * self.STD_VELOCITY * h])
        self.cov = np.diag(std ** 2)

    def predict(self, dt_frames: float) -> None:
        """Propagate by ``dt_frames`` frames (may be fractional or several)."""
        if dt_frames <= 0:
            return
        f = np.eye(8)
        f[:4, 4:] = np.eye(4) * dt_frames
        h = max(self.mean[3], 1.0)
        std_q = np.array([self.STD_POSITION * h, self.STD_POSITION * h, 1e-2,
                          self.STD_POSITION * h, self.STD_VELOCITY * h, self.STD_VELOCITY * h,
                          1e-5, self.STD_VELOCITY * h])
        self.mean = f @ self.mean
        # random-walk noise grows linearly with the elapsed frames
        self.cov = f @ self.cov @ f.T + np.diag(std_q ** 2) * dt_frames
        self.mean[3] = max(self.mean[3], 1.0)
        self.mean[2] = max(self.mean[2], 1e-3)

    def update(self, box_px: np.ndarray) -> None:
        """Correct with a measured box (x1, y1, x2, y2) [px]."""
        z = xyxy_to_xyah(box_px)
        h = max(self.mean[3], 1.0)
        r = np.diag(np.array([self.STD_POSITION * h, self.STD_POSITION * h, 1e-1,
                              self.STD_POSITION * h]) ** 2)
        hm = np.zeros((4, 8))
        hm[:, :4] = np.eye(4)
        s = hm @ self.cov @ hm.T + r
        k = np.linalg.solve(s, hm @ self.cov).T
        self.mean = self.mean + k @ (z - hm @ self.mean)
        self.cov = (np.eye(8) - k @ hm) @ self.cov

    @property
    def box_px(self) -> np.ndarray:
        """Current box estimate (x1, y1, x2, y2) [px]."""
        return xyah_to_xyxy(self.mean)

    def position_std_px(self) -> tuple[float, float]:
        """One-sigma uncertainty of the box centre (x, y) [px]."""
        return float(np.sqrt(self.cov[0, 0])), float(np.sqrt(self.cov[1, 1]))


# --------------------------------------------------------------------------- tracks


@dataclass(slots=True)
class _Track:
    track_id: int
    kf: BoxKalman
    frame: int
    last_seen_t_s: float
    score: float
    last_box_px: np.ndarray
    last_seen_frame: int
    born_t_s: float
    closing_rate_per_s: float = float("nan")  # own approach speed over range, from boxes
    drift_px_s: np.ndarray = field(default_factory=lambda: np.zeros(2))  # see expansion_cost
    hits: int = 1
    weak: bool = False  # started from a weak detection: needs weak_confirm_hits in a row
    state: str = "tracked"  # "tracked" (matched last detected frame) or "lost"
    votes: dict[str, float] = field(default_factory=lambda: defaultdict(float))

    @property
    def category(self) -> str:
        return max(self.votes.items(), key=lambda kv: (kv[1], kv[0]))[0]


class Tracker:
    """Online multi-vehicle tracker.

    Call :meth:`update` once per frame in order; it returns the boxes of the tracks alive in
    that frame. Tracks start tentative and are confirmed after ``min_hits`` detections. A
    tentative track missed by a detected frame is deleted (a false detection) when that
    frame came less than ``sparse_interval_s`` after the track's birth, else confirmed (a
    vehicle seen once in sparse input, which may have left the view since). :meth:`finalize`
    drops the never-confirmed tracks from the collected rows, except those born on the last
    detected frame (they had no chance of a second look), and fixes each track's category to
    its score-weighted majority vote.

    Parameters
    ----------
    config : TrackerConfig, optional
        Thresholds.
    image_size_px : (int, int), optional
        Frame width and height [px]: the focus of expansion is taken at the image centre and
        box edges on the border are recognised as cut. Without it each box scales about its
        own centre in the ego-motion stage.
    """

    def __init__(self, config: TrackerConfig | None = None,
                 image_size_px: tuple[int, int] | None = None):
        self.config = config or TrackerConfig()
        self.image_size_px = image_size_px
        self.foe_px = (None if image_size_px is None
                       else (image_size_px[0] / 2.0, image_size_px[1] / 2.0))
        self._tracks: list[_Track] = []
        self._next_id = 1
        self._hits: dict[int, int] = {}
        self._confirmed: set[int] = set()
        self._votes: dict[int, dict[str, float]] = {}
        self._last_detect_t_s: float | None = None

    # ----------------------------------------------------------------- public

    def update(self, frame: int, t_s: float, detections: list[Detection] | None
               ) -> list[TrackedBox]:
        """Advance to ``frame`` (time ``t_s`` [s]) and return the boxes alive there.

        Parameters
        ----------
        frame : int
            Frame index; must increase from call to call.
        t_s : float
            Frame time [s], used for the lost-track timeout and the ego-motion gate.
        detections : list of Detection or None
            Boxes found in this frame, or None when the detector did not run on it: tracks
            are then only predicted and carried with their last score.

        Returns
        -------
        list of TrackedBox
            One row per tracked (not lost) track: the detection box on a matched frame, the
            predicted box on a carried frame.
        """
        for track in self._tracks:
            track.kf.predict(frame - track.frame)
            track.frame = frame
        if detections is None:
            return [self._row(t, frame, t_s, t.kf.box_px, t.score)
                    for t in self._tracks if t.state == "tracked"]

        cfg = self.config
        # Sparse input: boxes move too far between detected frames for IoU to come first.
        sparse = (self._last_detect_t_s is not None
                  and t_s - self._last_detect_t_s >= cfg.sparse_interval_s)
        self._last_detect_t_s = t_s
        dets = [d for d in detections if d.score >= cfg.low_score]
        high = [d for d in dets if d.score >= cfg.high_score]
        low = [d for d in dets if d.score < cfg.high_score]
        rows: list[TrackedBox] = []
        matched: set[int] = set()

        def hit(track: _Track, det: Detection, restart: bool = False) -> None:
            rows.append(self._hit(track, det, frame, t_s, restart))
            matched.add(id(track))

        # A track whose own approach has since carried it past the camera (range down to a
        # tenth) has left the view: no box may revive it.
        self._tracks = [t for t in self._tracks if not (
            t.state == "lost"
            and (t.closing_rate_per_s * (t_s - t.last_seen_t_s) >= PASSED_CLOSING
                 or self._left_through_side(t)))]

        def iou_stages(high: list[Detection], low: list[Detection]):
            confirmed = [t for t in self._tracks
                         if id(t) not in matched and t.track_id in self._confirmed]
            tentative = [t for t in self._tracks
                         if id(t) not in matched and t.track_id not in self._confirmed]
            # Stage 1: confident detections against all confirmed tracks, tracked or lost.
            pairs, free_tracks, free_high = self._associate(confirmed, high, cfg.iou_high)
            for ti, di in pairs:
                hit(confirmed[ti], high[di])
            # Stage 2: weak detections against tracks seen on the previous detected frame;
            # a weak box revives a lost track only after a short gap and on a close overlap.
            remaining = [confirmed[i] for i in free_tracks if confirmed[i].state == "tracked"]
            pairs, _, free_low = self._associate(remaining, low, cfg.iou_low)
            for ti, di in pairs:
                hit(remaining[ti], low[di])
            brief = [confirmed[i] for i in free_tracks if confirmed[i].state == "lost"
                     and t_s - confirmed[i].last_seen_t_s <= cfg.weak_revive_s]
            if brief and free_low:
                left = [low[i] for i in free_low]
                pairs, _, free_left = self._associate(brief, left, cfg.iou_weak_revive)
                for ti, di in pairs:
                    hit(brief[ti], left[di])
                free_low = [free_low[i] for i in free_left]
            # Stage 3: tentative tracks get one chance with the leftover confident detections.
            left_high = [high[i] for i in free_high]
            pairs, free_tent, free_new = self._associate(tentative, left_high,
                                                         cfg.iou_tentative)
            for ti, di in pairs:
                hit(tentative[ti], left_high[di])
            # Stage 4: weak tentative tracks also with the leftover weak detections.
            weak_tracks = [tentative[i] for i in free_tent if tentative[i].weak]
            left_low = [low[i] for i in free_low]
            usable = [i for i, d in enumerate(left_low) if d.score >= cfg.weak_start_score]
            pairs, _, _ = self._associate(weak_tracks, [left_low[i] for i in usable],
                                          cfg.iou_tentative)
            for ti, di in pairs:
                hit(weak_tracks[ti], left_low[usable[di]])
            used = {usable[di] for _, di in pairs}
            return ([left_high[i] for i in free_new],
                    [d for i, d in enumerate(left_low) if i not in used])

        def motion_stage(high: list[Detection], low: list[Detection]):
            # The ego-motion model (large image motion between sparse detections, or after a
            # gap); weak boxes again only for confirmed tracks seen on the previous frame.
            # Weak tentative tracks only by IoU (stages 3-4): the motion model's wide gates
            # would let them take boxes from the confirmed tracks they lie near.
            unmatched = [t for t in self._tracks if id(t) not in matched
                         and not (t.weak and t.track_id not in self._confirmed)]
            pairs, _, free_high, rate = self._associate_motion(unmatched, high, t_s)
            for ti, di in pairs:
                hit(unmatched[ti], high[di], restart=True)
            unmatched = [t for t in unmatched if id(t) not in matched and t.state == "tracked"
                         and t.track_id in self._confirmed]
            pairs, _, free_low, _ = self._associate_motion(unmatched, low, t_s, rate)
            for ti, di in pairs:
                hit(unmatched[ti], low[di], restart=True)
            return [high[i] for i in free_high], [low[i] for i in free_low]

        # Dense video: IoU on the Kalman prediction first, the motion model for what is left.
        # Sparse input: the motion model first (IoU would join a row of parked cars shifted
        # by one car), IoU on the prediction for what is left (e.g. crossing traffic).
        stages = (motion_stage, iou_stages) if sparse else (iou_stages, motion_stage)
        left_high, left_low = high, low
        for stage in stages:
            left_high, left_low = stage(left_high, left_low)

        # Misses: a confirmed track goes lost; a tentative one is a false detection if the
        # vehicle, were it real, should have been seen again by now, else it is kept.
        dead: set[int] = set()
        for track in self._tracks:
            if id(track) in matched:
                continue
            if track.track_id in self._confirmed:
                track.state = "lost"
            elif track.weak or t_s - track.born_t_s < cfg.sparse_interval_s:
                dead.add(id(track))
            else:
                self._confirmed.add(track.track_id)
                track.state = "lost"
        # New tracks from confident leftovers.
        for det in left_high:
            if det.score >= cfg.new_track_score:
                track = self._start(det, frame, t_s)
                rows.append(self._row(track, frame, t_s, np.asarray(det.box_px), det.score))
        for det in left_low + [d for d in left_high if d.score < cfg.new_track_score]:
            if det.score >= cfg.weak_start_score:
                track = self._start(det, frame, t_s, weak=True)
                rows.append(self._row(track, frame, t_s, np.asarray(det.box_px), det.score))
        self._tracks = [t for t in self._tracks if id(t) not in dead
                        and t_s - t.last_seen_t_s <= cfg.max_lost_s]
        rows.sort(key=lambda r: r.track_id)
        return rows

    def finalize(self, rows: list[TrackedBox]) -> list[TrackedBox]:
        """Clean the rows collected from :meth:`update` over a whole video.

        Drops rows of tracks never confirmed, except tracks born on the last detected frame
        (seen once with a confident score and never given a second look), sets every row's
        category to its track's score-weighted majority vote, and renumbers track ids 1, 2,
        ... in order of first appearance.
        """
        keep = set(self._confirmed)
        keep |= {t.track_id for t in self._tracks
                 if t.born_t_s == self._last_detect_t_s and not t.weak}
        new_id: dict[int, int] = {}
        out = []
        for r in sorted(rows, key=lambda r: (r.frame, r.track_id)):
            if r.track_id not in keep:
                continue
            if r.track_id not in new_id:
                new_id[r.track_id] = len(new_id) + 1
            votes = self._votes[r.track_id]
            category = max(votes.items(), key=lambda kv: (kv[1], kv[0]))[0]
            out.append(TrackedBox(frame=r.frame, t_s=r.t_s, track_id=new_id[r.track_id],
                                  category=category, score=r.score, x1=r.x1, y1=r.y1,
                                  x2=r.x2, y2=r.y2))
        return out

    # ----------------------------------------------------------------- internals

    def _left_through_side(self, track: _Track) -> bool:
        """A lost track last seen cut by the left or right border whose predicted centre
        has since moved out of the image: the vehicle left the view at the side (passed or
        turned away), and a box that appears later is another vehicle."""
        if self.image_size_px is None:
            return False
        cut = border_cut(track.last_box_px[None, :], self.image_size_px,
                         self.config.border_margin_px)[0]
        if not (cut[0] or cut[2]):
            return False
        box = track.kf.box_px
        centre = 0.5 * (box[0] + box[2])
        return bool(centre < 0 or centre > self.image_size_px[0])

    @staticmethod
    def _associate(tracks: list[_Track], dets: list[Detection], min_iou: float):
        if not tracks or not dets:
            return [], list(range(len(tracks))), list(range(len(dets)))
        boxes = np.array([d.box_px for d in dets], dtype=float)
        iou = np.vstack([buffered_iou(t.kf.box_px, t.kf.position_std_px(), boxes)
                         for t in tracks])
        return match(1.0 - iou, 1.0 - min_iou)

    def _associate_motion(self, tracks: list[_Track], dets: list[Detection], t_s: float,
                          rate_per_px_s: float | None = None):
        """Match on :func:`expansion_cost`, searching the ego-motion rate shared by all
        static vehicles (or using ``rate_per_px_s``): the rate whose assignment costs least,
        counting each pair left unmatched at the gate's cost of 1, wins.

        Returns pairs, unmatched tracks, unmatched detections and the rate used.
        """
        if not tracks or not dets:
            return [], list(range(len(tracks))), list(range(len(dets))), rate_per_px_s
        if rate_per_px_s is None:
            # reference box height 100 px; 81 hypotheses from a standing ego upwards
            rates = np.linspace(0.0, self.config.max_static_rate_per_s, 81) / 100.0
        else:
            rates = np.array([rate_per_px_s])
        costs = expansion_cost(np.array([t.last_box_px for t in tracks]),
                               np.array([t_s - t.last_seen_t_s for t in tracks]),
                               np.array([d.box_px for d in dets], dtype=float),
                               foe_px=self.foe_px, image_size_px=self.image_size_px,
                               config=self.config, static_rates_per_px_s=rates,
                               closing_rate_per_s=np.array([t.closing_rate_per_s
                                                            for t in tracks]),
                               drift_px_s=np.array([t.drift_px_s for t in tracks]))
        n_pairs = min(len(tracks), len(dets))
        best = None
        for rate, cost in zip(rates, costs, strict=True):
            found = match(np.where(np.isfinite(cost), cost, 1e6), 1.0)
            total = sum(cost[r, c] for r, c in found[0]) + (n_pairs - len(found[0]))
            if best is None or total < best[0] - 1e-9:
                best = (total, found, float(rate))
        pairs, free_tracks, free_dets = best[1]
        return pairs, free_tracks, free_dets, best[2]

    def _start(self, det: Detection, frame: int, t_s: float, weak: bool = False) -> _Track:
        box = np.asarray(det.box_px, dtype=float)
        track = _Track(track_id=self._next_id, kf=BoxKalman(box), frame=frame,
                       last_seen_t_s=t_s, score=det.score, last_box_px=box, last_seen_frame=frame,
                       born_t_s=t_s, weak=weak)
        track.votes[det.category] += det.score
        self._next_id += 1
        self._hits[track.track_id] = 1
        if self.config.min_hits <= 1 and not weak:
            self._confirmed.add(track.track_id)
        self._votes[track.track_id] = track.votes
        self._tracks.append(track)
        return track

    def _hit(self, track: _Track, det: Detection, frame: int, t_s: float,
             restart: bool = False) -> TrackedBox:
        box = np.asarray(det.box_px, dtype=float)
        if restart:
            # joined by the ego-motion stage, typically far from the constant-velocity
            # prediction: restart the filter at the new box with the velocity of the jump
            # rather than let a stale state pull the estimate back
            dt_frames = max(frame - track.last_seen_frame, 1)
            velocity = (xyxy_to_xyah(box) - xyxy_to_xyah(track.last_box_px)) / dt_frames
            track.kf = BoxKalman(box)
            track.kf.mean[4:] = velocity
            track.kf.mean[6] = 0.0
        else:
            track.kf.update(box)
        dt_s = t_s - track.last_seen_t_s
        # first-order filters: box noise over 0.1 s makes single measurements jumpy
        alpha = dt_s / (dt_s + self.config.closing_time_constant_s) if dt_s > 0 else 0.0
        measured = self._closing_rate(track.last_box_px, box, dt_s)
        if np.isfinite(measured):
            previous = track.closing_rate_per_s
            track.closing_rate_per_s = (measured if not np.isfinite(previous)
                                        else previous + alpha * (measured - previous))
        drift = self._drift(track.last_box_px, box, dt_s)
        if drift is not None:
            first = self._hits[track.track_id] == 1
            track.drift_px_s = drift if first else track.drift_px_s + alpha * (
                drift - track.drift_px_s)
        track.state = "tracked"
        track.last_seen_t_s = t_s
        track.last_box_px = box
        track.last_seen_frame = frame
        track.score = det.score
        track.votes[det.category] += det.score
        self._hits[track.track_id] += 1
        need = self.config.weak_confirm_hits if track.weak else self.config.min_hits
        if self._hits[track.track_id] >= need:
            self._confirmed.add(track.track_id)
        return self._row(track, frame, t_s, box, det.score)

    def _drift(self, before_px: np.ndarray, after_px: np.ndarray, dt_s: float
               ) -> np.ndarray | None:
        """Image motion of the box centre beyond scaling about the FOE [px/s] (x, y), from
        two boxes not cut by the border; None when not measurable."""
        if dt_s <= 0 or border_cut(np.array([before_px, after_px]), self.image_size_px,
                                   self.config.border_margin_px).any():
            return None
        h_before, h_after = before_px[3] - before_px[1], after_px[3] - after_px[1]
        if h_before <= 0 or h_after <= 0:
            return None
        c_before = np.array([before_px[0] + before_px[2], before_px[1] + before_px[3]]) / 2
        c_after = np.array([after_px[0] + after_px[2], after_px[1] + after_px[3]]) / 2
        foe = c_before if self.foe_px is None else np.asarray(self.foe_px, dtype=float)
        return (c_after - (foe + h_after / h_before * (c_before - foe))) / dt_s

    def _closing_rate(self, before_px: np.ndarray, after_px: np.ndarray, dt_s: float
                      ) -> float:
        """Closing speed over the latest range [1/s] from the growth of two boxes (size ~
        1/range, so v / Z_after = (h_after / h_before - 1) / dt), from heights, else widths,
        when not cut by the border; NaN when not measurable."""
        if dt_s <= 0:
            return float("nan")
        cut = border_cut(np.array([before_px, after_px]), self.image_size_px,
                         self.config.border_margin_px)
        for lo, hi in ((1, 3), (0, 2)):
            if not cut[:, [lo, hi]].any():
                size_before = before_px[hi] - before_px[lo]
                size_after = after_px[hi] - after_px[lo]
                if size_before > 0 and size_after > 0:
                    return float((size_after / size_before - 1.0) / dt_s)
        return float("nan")

    @staticmethod
    def _row(track: _Track, frame: int, t_s: float, box: np.ndarray, score: float
             ) -> TrackedBox:
        x1, y1, x2, y2 = (float(v) for v in box)
        return TrackedBox(frame=frame, t_s=float(t_s), track_id=track.track_id,
                          category=track.category, score=float(score),
                          x1=x1, y1=y1, x2=x2, y2=y2)
