"""Horizon estimation: camera file, lane markings and vehicle consistency fused; the slow
per-frame drift from lane markings and the fast body pitch from the vehicles' cues."""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Callable

import numpy as np

from vid2sim.base.defaults import IMAGE_FOLDER_FPS, MAD_TO_SIGMA
from vid2sim.core.camera import Camera
from vid2sim.core.records import Note, TrackedBox, VehicleCategory
from vid2sim.detect.ranging.boxfit import (
    FIT_BLOCK_BOXES,
    BoxArrays,
    BoxFit,
    fit_boxes,
    predict_edges,
)
from vid2sim.detect.ranging.config import RangingConfig
from vid2sim.detect.ranging.smoother import _kf_rts_cv

# A size prior this tight [m] holds the size fixed at the value given (the width-only fit of
# the per-frame pitch uses each track's learnt size as known).
FIXED_SIZE_STD_M = 1e-3
# Prior spread of the body-pitch offset's rate [px/s], in units of the pitch jitter [px]:
# ten jitters a second is diffuse (the filter's first frames decide).
PITCH_OFFSET_RATE_PRIOR_JITTERS = 10.0


def _by_block(n: int, columns: Callable[[slice], tuple[np.ndarray, ...]]
              ) -> tuple[np.ndarray, ...]:
    """``columns`` of the boxes ``[i, i + FIT_BLOCK_BOXES)`` one block after another,
    concatenated: a whole clip's fit, with its per-box covariance matrices, is never held
    at once (each box is fitted on its own, so the columns are the same)."""
    parts = [columns(slice(i, i + FIT_BLOCK_BOXES)) for i in range(0, n, FIT_BLOCK_BOXES)]
    return tuple(np.concatenate(c) for c in zip(*parts, strict=True))


def pitch_for_horizon(camera: Camera, horizon_y_px: float) -> float:
    """Camera pitch [deg] that puts the horizon at row ``horizon_y_px`` (other angles kept)."""
    pitch = camera.pitch_deg + math.degrees(
        math.atan((camera.horizon_y_px() - horizon_y_px) / camera.fy))
    for _ in range(3):  # Newton on the exact horizon (roll and distortion make it non-linear)
        h0 = camera.with_pitch(pitch).horizon_y_px()
        h1 = camera.with_pitch(pitch + 1e-3).horizon_y_px()
        if not (np.isfinite(h0) and np.isfinite(h1)) or h1 == h0:
            break
        pitch += (horizon_y_px - h0) * 1e-3 / (h1 - h0)
    return float(pitch)


def horizon_from_vehicles(boxes: list[TrackedBox], camera: Camera, config: RangingConfig,
                          ba: BoxArrays | None = None) -> tuple[float | None, float, int]:
    """Horizon row that makes ground-cue ranges agree with width-cue ranges.

    For each well-seen car (box not cut, at least 20 x 12 px, width cue range 5-60 m, within
    ``config.horizon_vehicle_max_lateral_m`` of the camera's axis) the
    width cue alone gives its range; the row where that range meets the road, compared with
    the observed bottom edge, says how far the true horizon lies from the assumed one (a pitch
    change shifts all rows near the image centre alike). The median over tracks of each
    track's median offset is robust to a few odd boxes and gives every vehicle one vote.

    Returns
    -------
    (horizon_y_px or None, one-sigma [px], number of tracks used)
    """
    ba = ba or BoxArrays.from_boxes(boxes, camera, config)
    cat = np.array([b.category for b in boxes])
    min_h_px, min_w_px = config.horizon_vehicle_min_box_px
    sel = ((cat == VehicleCategory.CAR) & ~(ba.cut_left | ba.cut_right | ba.cut_top | ba.cut_bottom)
           & (ba.y2 - ba.y1 >= min_h_px) & (ba.x2 - ba.x1 >= min_w_px))
    if sel.sum() == 0:
        return None, math.inf, 0
    idx = np.flatnonzero(sel)
    sub = ba.subset(idx)
    p = config.prior_for(VehicleCategory.CAR)
    ones = np.ones(len(idx))

    def width_cue(sl: slice) -> tuple[np.ndarray, ...]:
        part, one = sub.subset(sl), ones[sl]
        fit = fit_boxes(camera, part, p.width_m * one, p.width_std_m * one, p.height_m * one,
                        p.height_std_m * one, p.length_m * one, config, use_ground=False,
                        use_height=False, length_std_m=p.length_std_m * one)
        pred = predict_edges(camera, fit.range_m, fit.lateral_m, fit.width_m, p.height_m * one,
                             fit.length_m, part.outline)
        return fit.range_m, fit.lateral_m, fit.valid, part.y2 - pred[:, 3]

    fit_range_m, fit_lateral_m, fit_valid, offset = _by_block(len(idx), width_cue)
    # Only vehicles on the ego's road (its lane and the next ones): parked cars and those
    # beyond a kerb stand on ground that is rarely level with the ego's lane (a crowned road
    # falls 2-3 % to the gutter, parking strips and kerbs add 0.1-0.15 m). In KITTI raw 0001
    # they put the horizon at 180 px where the lane markings and the calibration say 173.
    near = np.abs(fit_lateral_m) < config.horizon_vehicle_max_lateral_m
    near_m, far_m = config.horizon_vehicle_range_m
    keep = (fit_valid & (fit_range_m > near_m) & (fit_range_m < far_m) & np.isfinite(offset)
            & near)
    by_track: dict[int, list[float]] = defaultdict(list)
    for i, off in zip(idx[keep], offset[keep], strict=True):
        by_track[boxes[i].track_id].append(float(off))
    if not by_track:
        return None, math.inf, 0
    per_track = np.array([np.median(v) for v in by_track.values()])
    med = float(np.median(per_track))
    n = len(per_track)
    # Spread: the scatter over tracks, never below what one vehicle's own width (class spread)
    # and road height are expected to give (a few vehicles that happen to agree prove
    # little), plus the floor that the local fleet's mean width, off the prior's mean, shifts
    # every vehicle alike by (f H / Z * sigma_mean / W at a typical 20 m).
    typical_m = config.horizon_typical_range_m
    gap_px = camera.fy * camera.height_m / typical_m
    per_vehicle = math.hypot(gap_px * p.width_std_m / p.width_m,
                             camera.fy * config.road_height_std_m / typical_m)
    mad = (MAD_TO_SIGMA * float(np.median(np.abs(per_track - med))) if n > 2
           else config.horizon_few_tracks_mad_px)
    floor = gap_px * config.fleet_width_mean_std_m / p.width_m
    std = math.hypot(max(mad, per_vehicle) / math.sqrt(n), floor)
    return camera.horizon_y_px() + med, std, n


def choose_horizon(boxes: list[TrackedBox], camera: Camera, config: RangingConfig,
                   horizon_hints_px: list[float] | None) -> tuple[float, str, list[Note]]:
    """Fuse the horizon estimates by inverse variance: camera file, lane markings, vehicles.

    Returns the row [px], the source with the largest weight, and notes for the summary.
    """
    notes: list[Note] = []
    h_cam = camera.horizon_y_px()
    std_cam = camera.fy * math.tan(math.radians(config.pitch_std_for(camera)))
    estimates = [(h_cam, std_cam, "camera file")]
    hints = np.array([h for h in (horizon_hints_px or []) if h is not None and np.isfinite(h)])
    if hints.size >= config.lane_horizon_min_hints:
        h_lane = float(np.median(hints))
        mad = MAD_TO_SIGMA * float(np.median(np.abs(hints - h_lane)))
        std_lane = (max(mad, config.lane_horizon_std_px) / math.sqrt(hints.size)
                    + config.lane_horizon_floor_px)
        estimates.append((h_lane, std_lane, "lane markings"))
        notes.append(Note.estimate(f"lane markings: horizon {h_lane:.1f} px from {hints.size} "
                                   "frames"))
    h_veh, std_veh, n_veh = horizon_from_vehicles(boxes, camera, config)
    if h_veh is not None and n_veh >= config.horizon_min_vehicles:
        # One iteration at the new pitch: the width cue itself depends slightly on pitch.
        cam2 = camera.with_pitch(pitch_for_horizon(camera, h_veh))
        h2, std2, n2 = horizon_from_vehicles(boxes, cam2, config)
        if h2 is not None:
            h_veh, std_veh, n_veh = h2, std2, n2
        estimates.append((h_veh, std_veh, "vehicle consistency"))
        notes.append(Note.estimate(f"vehicle consistency: horizon {h_veh:.1f} px from {n_veh} "
                                   "vehicles"))
    if len(estimates) > 2 and abs(estimates[1][0] - estimates[2][0]) > (
            config.horizon_disagreement_sigmas * math.hypot(
            estimates[1][1], estimates[2][1])):
        # Lane markings are pure geometry; the vehicle estimate leans on size priors and on
        # parked cars standing level with the road. When they disagree, keep the markings.
        notes.append(Note.warning(
            f"lane-marking and vehicle horizons disagree ({estimates[1][0]:.1f} vs "
            f"{estimates[2][0]:.1f} px): kept the lane markings (a slope, kerb parking or "
            "unusual vehicle sizes?)"))
        estimates.pop(2)
    w = np.array([1.0 / s ** 2 for _, s, _ in estimates])
    h = float(np.sum(w * np.array([e[0] for e in estimates])) / w.sum())
    source = estimates[int(np.argmax(w))][2]
    return h, source, notes


def frame_horizon_offsets(boxes: list[TrackedBox], camera: Camera, ba: BoxArrays,
                          loose: BoxFit, width_m: np.ndarray, height_m: np.ndarray,
                          length_m: np.ndarray, config: RangingConfig,
                          length_std_m: np.ndarray | None = None) -> np.ndarray:
    """Per-box horizon shift [px, down positive] of its frame from the body pitch.

    The width cue does not care about pitch, the ground cue does: the row where a vehicle's
    width-cue range meets the road, against its observed bottom edge, measures the horizon
    shift of that frame (plus a constant per vehicle from its size and road height, removed
    by subtracting the track's median). All vehicles of a frame are combined by inverse
    variance, shrunk towards zero by the expected pitch jitter, and smoothed over time with a
    constant-velocity Kalman/RTS smoother, since a body pitches at about 1-2 Hz.
    """
    n = len(boxes)
    out = np.zeros(n)
    sel = np.flatnonzero(loose.valid & loose.ground_ok & loose.width_ok & ~ba.cut_top
                         & (loose.range_m < config.pitch_offset_max_range_m))
    if sel.size == 0:
        return out
    sub = ba.subset(sel)
    tiny = np.full(sel.size, FIXED_SIZE_STD_M)

    def width_cue(sl: slice) -> tuple[np.ndarray, ...]:
        part, i = sub.subset(sl), sel[sl]
        wfit = fit_boxes(camera, part, width_m[i], tiny[sl], height_m[i], tiny[sl], length_m[i],
                         config, use_ground=False, use_height=False,
                         length_std_m=None if length_std_m is None else length_std_m[i])
        pred = predict_edges(camera, wfit.range_m, wfit.lateral_m, width_m[i], height_m[i],
                             wfit.length_m, part.outline)
        return part.y2 - pred[:, 3], wfit.cov_white[:, 0, 0], wfit.valid

    offset, white_log_range_var, fit_valid = _by_block(sel.size, width_cue)
    # Noise of one offset: the width cue's frame-to-frame range noise seen as rows
    # (d row / d ln Z = -(row - horizon)), plus the bottom edge's own pixel noise.
    gap = np.maximum(sub.y2 - camera.horizon_y_px(), 1.0)
    var = (gap ** 2) * white_log_range_var + (
        config.edge_noise_px + config.edge_noise_frac * (sub.y2 - sub.y1)) ** 2
    ok = np.isfinite(offset) & np.isfinite(var) & fit_valid
    tids = np.array([boxes[i].track_id for i in sel])
    for tid in np.unique(tids[ok]):
        m = ok & (tids == tid)
        if m.sum() < config.pitch_offset_min_track_boxes:  # too short to know its constant part
            ok &= ~m
            continue
        offset[m] -= np.median(offset[m])
    if not ok.any():
        return out
    frames = np.array([boxes[i].frame for i in sel])
    t_by_frame: dict[int, float] = {}
    for b in boxes:
        t_by_frame.setdefault(b.frame, b.t_s)
    all_frames = sorted(t_by_frame)
    info = defaultdict(float)
    wsum = defaultdict(float)
    for f, o, v in zip(frames[ok], offset[ok], var[ok], strict=True):
        info[int(f)] += 1.0 / v
        wsum[int(f)] += o / v
    jitter_px = camera.fy * math.tan(math.radians(config.horizon_jitter_deg))
    z = [wsum[f] / info[f] if info[f] > 0 else 0.0 for f in all_frames]
    r = [1.0 / info[f] if info[f] > 0 else 1e6 for f in all_frames]
    valid = [info[f] > 0 for f in all_frames]
    # Prior: the offset is zero-mean with the jitter's spread; the smoother below has no
    # mean reversion, so fold the prior in per frame as a shrinkage first.
    z = [zi * jitter_px ** 2 / (jitter_px ** 2 + ri) for zi, ri in zip(z, r, strict=True)]
    r = [ri * jitter_px ** 2 / (jitter_px ** 2 + ri) for ri in r]
    smoothed, _, _, _ = _kf_rts_cv([t_by_frame[f] for f in all_frames], z, r, valid,
                                   config.pitch_accel_noise_px,
                                   jitter_px * PITCH_OFFSET_RATE_PRIOR_JITTERS)
    by_frame = dict(zip(all_frames, smoothed, strict=True))
    out[:] = [by_frame[b.frame] for b in boxes]
    limit_px = config.pitch_offset_clip_jitters * jitter_px
    return np.clip(out, -limit_px, limit_px)


def lane_horizon_offsets(frames: np.ndarray, t_s: np.ndarray, hint_frames: np.ndarray,
                         hint_rows_px: np.ndarray, horizon_y_px: float,
                         config: RangingConfig) -> np.ndarray:
    """Slow per-frame horizon shift [px, down positive] from the lane markings.

    The horizon a flat-ground range needs is that of the road ahead, and it drifts: the
    body settles under braking and load, and on a grade change the camera turns against
    the road it sees. In KITTI raw 0001 the OXTS pitch rises by 0.5 deg in 11 s (6 px at
    f = 721 px), and a constant horizon turns such a drift into a range error growing with
    range squared over time, i.e. into range rate (closing speeds read slow). Each frame's
    lane-marking vanishing row measures the horizon with about 4-5 px of scatter; the median
    of those within ``lane_horizon_window_s`` of a frame follows the drift (composite clip:
    a 6.2 px drift over the clip seen as 4.5 px, residual scatter 1.9 px), and the faster
    body pitch is left to :func:`frame_horizon_offsets`.

    Parameters
    ----------
    frames, t_s : (N,) ndarray
        Frame index and time [s] of each box.
    hint_frames, hint_rows_px : (M,) ndarray
        Frames with a lane-marking horizon and its row [px].
    horizon_y_px : float
        The video's horizon the offsets are relative to.
    config : RangingConfig
        Window and minimum count.

    Returns
    -------
    (N,) ndarray
        Offset per box; 0 where the window holds fewer than ``lane_horizon_min_frames``.
    """
    out = np.zeros(len(frames))
    if len(hint_frames) < config.lane_horizon_min_frames or len(frames) == 0:
        return out
    # Seconds per frame from the boxes' own clock (frame numbers are what the hints carry).
    uf, first, inverse = np.unique(frames, return_index=True, return_inverse=True)
    if uf.size > 1:
        sec_per_frame = float(np.median(np.diff(t_s[first]) / np.diff(uf)))
    else:
        sec_per_frame = 1.0 / IMAGE_FOLDER_FPS  # one frame: any spacing will do
    half = config.lane_horizon_window_s / max(sec_per_frame, 1e-3)
    order = np.argsort(hint_frames, kind="stable")
    hf, hr = hint_frames[order].astype(float), hint_rows_px[order].astype(float)
    lo = np.searchsorted(hf, uf - half, side="left")
    hi = np.searchsorted(hf, uf + half, side="right")
    per_frame = np.zeros(uf.size)
    for k in np.flatnonzero(hi - lo >= config.lane_horizon_min_frames):
        per_frame[k] = np.median(hr[lo[k]:hi[k]]) - horizon_y_px
    out[:] = per_frame[inverse.reshape(-1)]
    return out
