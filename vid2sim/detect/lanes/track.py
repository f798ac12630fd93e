"""The ego lane over a clip: per-frame lane-marking measurements filtered in time.

Each frame (:class:`~vid2sim.core.records.LaneObservation`) offers lines; which of them bound the
ego's lane, and whether the ego has changed lanes, is decided against the track:

1. **Lateral position.** The state is the camera's lateral position ``L`` [m, positive left]
   on a grid of lanes of the measured width ``w`` whose lane 0 is the lane the clip starts
   in, and its rate. A line at offset ``c`` says ``L = w / 2 - c (mod w)``; a pair of lines
   one lane apart says ``L = -(a + b) / 2 (mod w)`` without needing ``w``. The candidate
   nearest to the prediction (pairs first) within a gate is the measurement, so a car's
   shadow taken for a line in one frame is rejected, and crossing a line (a lane change)
   keeps ``L`` continuous.
2. **Filter.** A constant-velocity Kalman filter forward and a Rauch-Tung-Striebel smoother
   backward (the whole clip is known when the scenario is built).
3. **Lanes.** The lane index is ``L / w`` rounded, with hysteresis; each change is a
   :class:`~vid2sim.core.records.LaneChange` at the moment ``L`` crossed the boundary.

Cost is linear in the number of frames; nothing but the observations is kept.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np

from vid2sim.base.defaults import LANE_WIDTH_M
from vid2sim.core.lead import gap_to
from vid2sim.core.records import LaneBoundary, LaneChange, LaneObservation, LaneTrack, MarkingKind
from vid2sim.detect.lanes.geometry import with_yaw_correction


@dataclass(frozen=True, slots=True)
class LaneTrackConfig:
    """Tuning of the lane track (sources in the comments)."""

    #: lane width before any pair of boundaries was seen [m] (vid2sim.base.defaults)
    default_lane_width_m: float = LANE_WIDTH_M
    #: a pair of lines is the ego lane when its width is within this of the track's [m]
    width_gate_m: float = 0.5
    #: a measurement farther than this from the prediction is an outlier [m]; a quarter lane
    #: is far more than a driver's wander in 0.1 s and far less than half a lane
    gate_m: float = 0.5
    #: white lateral acceleration of the ego against its lane [m/s^2]: lane keeping
    #: wanders at 0.1-0.3 m/s^2, a lane change peaks at 1-2 m/s^2 (ISO 3888 double lane
    #: change ~4 m/s^2 is an emergency)
    accel_std_mps2: float = 1.0
    #: one-sigma of a line's position where it is seen (``x_e``) [m]: 3 cm scatter of the
    #: dashed line's world position at 8 m on KITTI raw 0001 (benchmarks/bench_lanes.py),
    #: rounded up
    measurement_floor_m: float = 0.05
    #: one-sigma of a frame's heading of the lines [rad]: 0.022 rad against the OXTS yaw on
    #: KITTI raw 0001 (benchmarks/bench_lanes.py)
    heading_std_rad: float = 0.025
    #: the heading against the lane wanders as a random walk of this one-sigma [rad/s^0.5]:
    #: lane keeping corrects a few hundredths of a radian within a second
    heading_rate_std_radps: float = 0.05
    #: with the ego's speed known, the lateral rate not explained by the heading (slope,
    #: camera yaw error) drifts by this [m/s^1.5]
    rate_drift_std_mps2: float = 0.05
    #: lines are read this far beyond their nearest paint, and at most this far [m]
    x_eval_margin_m: float = 1.0
    x_eval_max_m: float = 15.0
    #: plausible lane widths between line centres [m] (lane_markings.LaneMarkingConfig)
    lane_width_range_m: tuple[float, float] = (2.2, 4.5)
    #: uncertainty of the lane width used for single-line measurements [m]
    width_std_m: float = 0.15
    #: after this many frames in a row whose candidates all miss the gate, the track takes
    #: the newest pair of lines (it had lost the lane)
    reinit_after: int = 5
    #: farther than this from any accepted measurement the offset is unknown [s]
    max_gap_s: float = 2.0
    #: a lane change counts once the ego is this far past the boundary [m]
    hysteresis_m: float = 0.3
    #: a line within this of where the track expects a boundary is that boundary [m]
    associate_m: float = 0.4
    #: frames over which a boundary's kind is voted (1 s at 10 fps)
    kind_window: int = 10
    #: smoothing window of the lane width [frames]
    width_window: int = 31


def _lines(obs: LaneObservation) -> list[LaneBoundary]:
    out = [ln for ln in (obs.left, obs.right) if ln is not None]
    return out + list(obs.lines_left) + list(obs.lines_right)


def _rolling_median(values: np.ndarray, window: int, default: float) -> np.ndarray:
    """Median of the finite values within ``window`` samples around each sample; where none
    is near, the nearest earlier or later one; ``default`` where there is none at all."""
    n = len(values)
    ok = np.isfinite(values)
    if not ok.any():
        return np.full(n, default)
    half = window // 2
    out = np.full(n, np.nan)
    idx = np.flatnonzero(ok)
    for i in range(n):
        lo, hi = np.searchsorted(idx, [i - half, i + half + 1])
        if hi > lo:
            out[i] = np.median(values[idx[lo:hi]])
    filled = np.isfinite(out)
    return np.interp(np.arange(n), np.flatnonzero(filled), out[filled])


@dataclass(frozen=True, slots=True)
class _Candidate:
    """One reading of the ego's place in its lane from one frame's lines.

    ``value_m``: the ego's offset from the middle of the lane the lines bound, at x = 0
    (known modulo the lane width); ``z_m``: the same, from the lines' positions at ``x_e_m``
    where they were seen (``z = L - heading * x_e`` in the filter's terms, far less noisy
    than the extrapolation to x = 0); ``heading_rad``: the lines' direction; ``sigma_m``:
    one-sigma of ``z_m``.
    """

    value_m: float
    z_m: float
    x_e_m: float
    heading_rad: float
    sigma_m: float
    is_pair: bool


def _x_eval(ln: LaneBoundary, cfg: LaneTrackConfig) -> float:
    near = ln.x_near_m if math.isfinite(ln.x_near_m) else cfg.x_eval_max_m
    return float(min(max(near + cfg.x_eval_margin_m, 0.0), cfg.x_eval_max_m))


def _candidates(obs: LaneObservation, width_m: float, cfg: LaneTrackConfig
                ) -> tuple[list[_Candidate], list[_Candidate]]:
    """Readings from pairs of lines one lane apart, and from single lines next to the
    camera (which need the lane width)."""
    lines = [ln for ln in _lines(obs) if abs(ln.offset_m) <= 1.2 * width_m]
    pairs, singles = [], []
    for a in lines:
        xa = _x_eval(a, cfg)
        ya = a.offset_m + a.heading_rad * xa
        sig = math.hypot(cfg.measurement_floor_m, 0.5 * cfg.width_std_m)
        singles.append(_Candidate(0.5 * width_m - a.offset_m, 0.5 * width_m - ya, xa,
                                  a.heading_rad, sig / max(a.confidence, 0.2), False))
        for b in lines:
            if b.offset_m >= a.offset_m or \
                    abs((a.offset_m - b.offset_m) - width_m) > cfg.width_gate_m:
                continue
            xe = max(xa, _x_eval(b, cfg))
            y_mid = 0.5 * (a.offset_m + b.offset_m + (a.heading_rad + b.heading_rad) * xe)
            conf = max(min(a.confidence, b.confidence), 0.2)
            pairs.append(_Candidate(-0.5 * (a.offset_m + b.offset_m), -y_mid, xe,
                                    0.5 * (a.heading_rad + b.heading_rad),
                                    cfg.measurement_floor_m / math.sqrt(2.0) / conf, True))
    return pairs, singles


def _nearest(value: float, width: float, target: float) -> float:
    """``value + n * width`` nearest to ``target``."""
    return value + width * round((target - value) / width)


def lane_track(observations: list[LaneObservation], config: LaneTrackConfig | None = None,
               speed_mps: np.ndarray | None = None) -> LaneTrack:
    """Filter per-frame lane observations into the ego lane over the clip.

    Parameters
    ----------
    observations : list of LaneObservation
        In time order (one per measured frame).
    config : LaneTrackConfig, optional
    speed_mps : array, optional
        The ego's speed at each observation [m/s] (e.g. from GPS; NaN where unknown). With
        it the lateral motion is tied to the heading against the lane
        (``dL/dt = -v * heading``), which steadies both; without it the lateral rate is free.

    Returns
    -------
    LaneTrack
    """
    cfg = config or LaneTrackConfig()
    n = len(observations)
    t = np.array([o.t_s for o in observations], float)
    frames = np.array([o.frame for o in observations], int)
    raw = np.array([o.ego_offset_m for o in observations], float)
    lo, hi = cfg.lane_width_range_m
    widths = np.array([o.lane_width_m if lo <= o.lane_width_m <= hi else np.nan
                       for o in observations], float)
    width = _rolling_median(widths, cfg.width_window, cfg.default_lane_width_m)
    v_raw = np.full(n, np.nan) if speed_mps is None else np.asarray(speed_mps, float)
    v = np.nan_to_num(v_raw, nan=0.0)
    # Without the speed the free lateral rate carries the lane changes; with it, only what
    # the heading does not explain (measurement biases, slope).
    rate_std = np.where(np.isfinite(v_raw), cfg.rate_drift_std_mps2, cfg.accel_std_mps2)

    filt = _forward_filter(observations, t, width, v, rate_std, cfg)
    x_s, p_s = _rts_smooth(filt)
    accepted = filt.accepted
    lateral = x_s[:, 0].copy()
    std = np.sqrt(np.maximum(p_s[:, 0, 0], 0.0))
    # Far from any accepted measurement the filter only extrapolates: unknown.
    t_acc = t[accepted]
    if t_acc.size:
        lateral[gap_to(t, t_acc) > cfg.max_gap_s] = np.nan
    else:
        lateral[:] = np.nan
    std[~np.isfinite(lateral)] = np.nan

    lane, changes = _lanes(t, lateral, width, cfg.hysteresis_m)
    offset = lateral - lane * width
    heading = np.where(np.isfinite(lateral), x_s[:, 1], np.nan)
    curvature, left_kind, right_kind, n_left, n_right, found = _associate(
        observations, offset, width, cfg)
    return LaneTrack(
        frame=frames, t_s=t, found=found & accepted, ego_offset_raw_m=raw,
        ego_offset_m=offset, offset_std_m=std, lateral_m=lateral, lane=lane,
        lane_width_m=width, heading_rad=heading, curvature_inv_m=curvature,
        left_kind=left_kind, right_kind=right_kind, lines_left=n_left, lines_right=n_right,
        lane_changes=changes, observations=list(observations))


@dataclass(slots=True)
class _Filtered:
    """The forward pass of :func:`lane_track`'s Kalman filter on (lateral position L,
    heading, free lateral rate): filtered and predicted states and covariances per
    observation, the transition used to reach each, and which observations were accepted."""

    x_f: np.ndarray
    p_f: np.ndarray
    x_p: np.ndarray
    p_p: np.ndarray
    f_all: np.ndarray
    accepted: np.ndarray


def _forward_filter(observations: list[LaneObservation], t: np.ndarray, width: np.ndarray,
                    v: np.ndarray, rate_std: np.ndarray, cfg: LaneTrackConfig) -> _Filtered:
    """Kalman filter over the observations with gated association of the measured lines
    (a pair of boundaries beats any single line; after ``reinit_after`` misses the filter
    restarts on the best pair)."""
    n = len(observations)
    out = _Filtered(np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan),
                    np.full((n, 3), np.nan), np.full((n, 3, 3), np.nan), np.zeros((n, 3, 3)),
                    np.zeros(n, bool))
    x = p = None
    misses = 0
    for i, obs in enumerate(observations):
        w = float(width[i])
        pairs, singles = _candidates(obs, w, cfg)
        if x is not None:
            dt = max(t[i] - t[i - 1], 1e-3)
            out.f_all[i], q = _transition(dt, v[i], rate_std[i], cfg)
            x = out.f_all[i] @ x
            p = out.f_all[i] @ p @ out.f_all[i].T + q
        elif pairs:
            # Start on the first pair of boundaries; the clip's first lane is lane 0.
            c = min(pairs, key=lambda c: abs(_nearest(c.value_m, w, 0.0)))
            x = np.array([_nearest(c.value_m, w, 0.0), c.heading_rad, 0.0])
            p = np.diag([c.sigma_m ** 2 + (cfg.heading_std_rad * c.x_e_m) ** 2,
                         cfg.heading_std_rad ** 2, 0.5 ** 2])
        if x is None:
            continue
        out.x_p[i], out.p_p[i] = x, p
        best = _best_candidate(pairs, singles, x, p, w, cfg)
        if best is None and (pairs or singles):
            misses += 1
            if misses >= cfg.reinit_after and pairs:
                c = min(pairs, key=lambda c: c.sigma_m)
                best = (0.0, c, _nearest(c.value_m, w, x[0]) - c.value_m)
                p = np.diag([1.0, cfg.heading_std_rad ** 2, 0.5 ** 2])
        if best is not None:
            misses = 0
            x, p = _update(x, p, best[1], best[2], cfg)
            out.accepted[i] = True
        out.x_f[i], out.p_f[i] = x, p
    return out


def _transition(dt: float, v: float, rate_std: float, cfg: LaneTrackConfig
                ) -> tuple[np.ndarray, np.ndarray]:
    """State transition and process noise over ``dt``: the lateral position moves with
    ``-v * heading`` and the free rate (white-noise acceleration of the rate, a random walk
    of the heading)."""
    f = np.array([[1.0, -v * dt, dt], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    qr = rate_std ** 2
    q = np.diag([qr * dt ** 3 / 3.0, cfg.heading_rate_std_radps ** 2 * dt, qr * dt])
    q[0, 2] = q[2, 0] = qr * dt ** 2 / 2.0
    return f, q


def _best_candidate(pairs: list, singles: list, x: np.ndarray, p: np.ndarray, w: float,
                    cfg: LaneTrackConfig):
    """The measured line (shifted by whole lanes to the prediction) with the smallest
    normalised innovation inside the gate, ``(score, candidate, shift)``; pairs first."""
    best = None
    for group in (pairs, singles):
        for c in group:
            shift = _nearest(c.value_m, w, x[0]) - c.value_m
            if abs(c.value_m + shift - x[0]) > cfg.gate_m:
                continue
            innov = c.value_m + shift - x[0]
            score = innov * innov / (p[0, 0] + c.sigma_m ** 2)
            if best is None or score < best[0]:
                best = (score, c, shift)
        if best is not None:
            break  # a pair beats any single line
    return best


def _update(x: np.ndarray, p: np.ndarray, c, shift: float, cfg: LaneTrackConfig
            ) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update with one line: ``z = L - heading * x_e``, and the heading itself."""
    h = np.array([[1.0, -c.x_e_m, 0.0], [0.0, 1.0, 0.0]])
    z = np.array([c.z_m + shift, c.heading_rad])
    r = np.diag([c.sigma_m ** 2, cfg.heading_std_rad ** 2])
    s_mat = h @ p @ h.T + r
    gain = p @ h.T @ np.linalg.inv(s_mat)
    return x + gain @ (z - h @ x), (np.eye(3) - gain @ h) @ p


def _rts_smooth(filt: _Filtered) -> tuple[np.ndarray, np.ndarray]:
    """Rauch-Tung-Striebel smoother over the forward pass."""
    x_s, p_s = filt.x_f.copy(), filt.p_f.copy()
    for i in range(len(x_s) - 2, -1, -1):
        if not (np.isfinite(filt.x_f[i, 0]) and np.isfinite(filt.x_p[i + 1, 0])):
            continue
        c_mat = filt.p_f[i] @ filt.f_all[i + 1].T @ np.linalg.inv(filt.p_p[i + 1])
        x_s[i] = filt.x_f[i] + c_mat @ (x_s[i + 1] - filt.x_p[i + 1])
        p_s[i] = filt.p_f[i] + c_mat @ (p_s[i + 1] - filt.p_p[i + 1]) @ c_mat.T
    return x_s, p_s


def _lanes(t: np.ndarray, lateral: np.ndarray, width: np.ndarray, hysteresis_m: float
           ) -> tuple[np.ndarray, list[LaneChange]]:
    """Lane index per sample (0 = the clip's first lane, +1 per lane to the left) with
    hysteresis, and the changes at the moments the boundary was crossed."""
    n = len(t)
    lane = np.zeros(n, int)
    changes: list[LaneChange] = []
    current = 0
    for i in range(n):
        if not np.isfinite(lateral[i]):
            lane[i] = current
            continue
        w = width[i]
        rel = lateral[i] - current * w
        while abs(rel) > 0.5 * w + hysteresis_m:
            step = 1 if rel > 0 else -1
            boundary = (current + 0.5 * step) * w
            # The crossing: the last sample at or before i on the old side of the boundary.
            k = i
            while k > 0 and np.isfinite(lateral[k - 1]) and \
                    (lateral[k - 1] - boundary) * step > 0:
                k -= 1
            if k > 0 and np.isfinite(lateral[k - 1]):
                a, b = lateral[k - 1] - boundary, lateral[k] - boundary
                frac = a / (a - b) if a != b else 0.0
                t_cross = float(t[k - 1] + frac * (t[k] - t[k - 1]))
            else:
                t_cross = float(t[k])
            changes.append(LaneChange(t_s=t_cross, from_lane=current, to_lane=current + step))
            lane[k:i] = current + step
            current += step
            rel = lateral[i] - current * w
        lane[i] = current
    return lane, changes


def _associate(observations: list[LaneObservation], offset: np.ndarray, width: np.ndarray,
               cfg: LaneTrackConfig):
    """Per frame: the lines at the track's boundaries (their curvature and kinds,
    voted over a window) and the number of lines beyond them."""
    n = len(observations)
    curvature = np.full(n, np.nan)
    found = np.zeros(n, bool)
    n_left = np.zeros(n, int)
    n_right = np.zeros(n, int)
    kinds_l: list[str] = []
    kinds_r: list[str] = []
    for i, obs in enumerate(observations):
        if not np.isfinite(offset[i]):
            kinds_l.append("")
            kinds_r.append("")
            continue
        lines = _lines(obs)
        want = (0.5 * width[i] - offset[i], -0.5 * width[i] - offset[i])
        picked: list[LaneBoundary | None] = []
        for target in want:
            near = [ln for ln in lines if abs(ln.offset_m - target) <= cfg.associate_m]
            picked.append(min(near, key=lambda ln: abs(ln.offset_m - target)) if near else None)
        left, right = picked
        found[i] = left is not None and right is not None
        seen = [ln for ln in picked if ln is not None]
        if seen:
            curvature[i] = float(np.mean([ln.curvature_inv_m for ln in seen]))
        kinds_l.append(left.kind if left is not None else "")
        kinds_r.append(right.kind if right is not None else "")
        n_left[i] = sum(1 for ln in lines if ln.offset_m > want[0] + cfg.associate_m)
        n_right[i] = sum(1 for ln in lines if ln.offset_m < want[1] - cfg.associate_m)
    return (curvature, _vote(kinds_l, cfg.kind_window),
            _vote(kinds_r, cfg.kind_window), n_left, n_right, found)


def _vote(kinds: list[str], window: int) -> list[str]:
    """The most common known kind among the neighbouring frames ("" where none is known)."""
    out = []
    half = window // 2
    for i in range(len(kinds)):
        votes = Counter(k for k in kinds[max(0, i - half):i + half + 1]
                        if k and k != MarkingKind.UNKNOWN.value)
        if votes:
            out.append(votes.most_common(1)[0][0])
        else:
            out.append(MarkingKind.UNKNOWN.value if kinds[i] else "")
    return out


def track_lanes(observations: list[LaneObservation], yaw_correction_rad: float = 0.0,
                config: LaneTrackConfig | None = None) -> LaneTrack:
    """:func:`lane_track` of observations measured with a camera yaw that was corrected
    afterwards by ``yaw_correction_rad`` (new minus old, positive left): the streaming
    stage's call, before the ego's speed is known."""
    if yaw_correction_rad:
        observations = [with_yaw_correction(o, yaw_correction_rad) for o in observations]
    return lane_track(observations, config)
