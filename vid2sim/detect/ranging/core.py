"""range_tracks: monocular range, lateral offset and range rate of tracked vehicles.

Per box, three cues are fused by weighted least squares in one measurement model: the box's
bottom edge on the flat road (ground cue, needs the horizon), its pixel width against the
vehicle's width (width cue, a per-class prior refined per track) and, weakly, its pixel height
against a height prior. Each cue is a residual of the projected 3D vehicle box, so a pitched
camera, lens distortion, the side of a laterally offset car that widens its box, and boxes cut
by the image border (whose cut edge simply drops out) need no special cases. Per track, a
Kalman filter with a Rauch-Tung-Striebel smoother turns the per-frame positions into smoothed
range, lateral offset and their rates. The horizon is estimated from lane markings and from the
agreement of ground and width cues across vehicles rather than taken from the camera file.

Frames: vehicle frame x forward, y left, z up, origin on the road below the camera; range_m is
the x of the vehicle's rear, lateral_m the y of its centre.
"""

from __future__ import annotations

import math

import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.core.records import LaneTrack, Note, NoteKind, RangedBox, RangingResult, TrackedBox
from vid2sim.detect.ranging.boxfit import (
    BoxArrays,
    BoxFit,
    colored_noise_factor,
    fit_boxes,
    predict_edges,
)
from vid2sim.detect.ranging.config import RangingConfig
from vid2sim.detect.ranging.horizon import (
    choose_horizon,
    frame_horizon_offsets,
    lane_horizon_offsets,
    pitch_for_horizon,
)
from vid2sim.detect.ranging.scalefilter import (
    RangeMeasurements,
    filter_range_adaptive,
    log_width_var,
)
from vid2sim.detect.ranging.smoother import smooth_track

# The absolute-cue fit leaves the width free with this spread [m]: its sides then say where
# the vehicle is laterally but nothing about its range (that is the filter's scale cue).
FREE_WIDTH_STD_M = 10.0
# Relative step of the finite differences of the log-width model.
LOG_WIDTH_FD_STEP = 1e-3


def _log_width_model(camera: Camera, fit: BoxFit, ba: BoxArrays) -> dict[str, np.ndarray]:
    """Each box's predicted log width about its own fit: ln w = a + b (Z - Z_fit) +
    e (ln W - ln W_fit), from the outline's projection (finite differences)."""
    def log_width(x: np.ndarray, w: np.ndarray) -> np.ndarray:
        e = predict_edges(camera, x, fit.lateral_m, w, fit.height_m, fit.length_m, ba.outline)
        return np.log(np.maximum(e[:, 2] - e[:, 0], 1e-3))

    step = LOG_WIDTH_FD_STEP
    a = log_width(fit.range_m, fit.width_m)
    b = (log_width(fit.range_m * (1 + step), fit.width_m) - a) / (fit.range_m * step)
    e = (log_width(fit.range_m, fit.width_m * (1 + step)) - a) / math.log1p(step)
    return {"a": a, "b": b, "e": e, "c": np.log(fit.width_m)}


def _track_pieces(t_s: np.ndarray, valid: np.ndarray, max_gap_s: float, index: np.ndarray
                  ) -> list[np.ndarray]:
    """Split one time-ordered track (``index`` its boxes) into pieces that the range filter
    takes on their own: consecutive usable measurements more than ``max_gap_s`` apart start a
    new piece, each unusable box joins the piece of its nearest usable one in time, and boxes
    further than ``max_gap_s`` from any usable one form single-box pieces (their own fit)."""
    if not valid.any():
        return [index]
    seen = np.flatnonzero(valid)
    piece_of_seen = np.concatenate(([0], np.cumsum(np.diff(t_s[seen]) > max_gap_s)))
    # Nearest usable box in time for every box.
    pos = np.clip(np.searchsorted(t_s[seen], t_s), 1, seen.size - 1) if seen.size > 1 else (
        np.zeros(t_s.size, dtype=int))
    if seen.size > 1:
        left, right = seen[pos - 1], seen[pos]
        nearest = np.where(np.abs(t_s - t_s[left]) <= np.abs(t_s[right] - t_s), pos - 1, pos)
    else:
        nearest = pos
    label = piece_of_seen[nearest]
    far = np.abs(t_s - t_s[seen[nearest]]) > max_gap_s
    pieces = [index[(label == k) & ~far] for k in range(int(piece_of_seen[-1]) + 1)]
    pieces += [index[[i]] for i in np.flatnonzero(far)]
    return [pc for pc in pieces if pc.size]


def _size_from_track(values_m: np.ndarray, var_m2: np.ndarray, white_var_m2: np.ndarray,
                     prior_m: float, prior_std_m: float) -> tuple[float, float]:
    """A vehicle's size from its track's single-frame fits and the class prior.

    The frames' weighted mean has the white (pixel) part of their variance shrinking with
    the number of frames but the common part (road height under the vehicle, horizon) only
    once: a sag ahead that makes every frame read the car narrower is one error, not many.
    The result is the Gaussian product of that mean with the class prior.
    """
    if not values_m.size:
        return prior_m, prior_std_m
    var = np.maximum(var_m2, 1e-6)
    white = np.clip(white_var_m2, 0.0, var)
    wts = 1.0 / var
    mean = float(np.sum(wts * values_m) / np.sum(wts))
    common = float(np.sum(wts * (var - white)) / np.sum(wts))
    mean_var = common + 1.0 / float(np.sum(1.0 / np.maximum(white, 1e-6)))
    info = 1.0 / prior_std_m ** 2 + 1.0 / mean_var
    est = (prior_m / prior_std_m ** 2 + mean / mean_var) / info
    return est, math.sqrt(1.0 / info)


# --------------------------------------------------------------------------- main entry


def range_tracks(boxes: list[TrackedBox], camera: Camera, *,
                 horizon_hints_px: list[float] | None = None,
                 horizon_hint_frames: list[int] | None = None,
                 config: RangingConfig | None = None,
                 lanes: LaneTrack | None = None,
                 horizon: tuple[float, str, list[Note]] | None = None) -> RangingResult:
    """Range, lateral offset and range rate of every tracked box.

    Parameters
    ----------
    boxes : list of TrackedBox
        Tracker output (any order); a track with one box is ranged from that frame alone.
    camera : Camera
        The camera; its pitch is only a prior for the horizon estimate.
    horizon_hints_px : list of float, optional
        Per-frame horizon rows from lane markings (:class:`vid2sim.detect.lanes.vanishing.HorizonEstimator`).
    horizon_hint_frames : list of int, optional
        The frame of each hint: with them, each frame's horizon follows the hints about it
        (:func:`lane_horizon_offsets`); without, all frames share the hints' median.
    config : RangingConfig, optional
        Priors and noise settings.
    lanes : LaneTrack, optional
        The ego lane from the lane markings, kept in the result for the lane assignment
        (:mod:`vid2sim.detect.assign`), which counts lanes and the lead from it.
    horizon : tuple, optional
        What :func:`choose_horizon` returns for these boxes, hints and camera, when the
        caller has it already (it costs a second on a minute of 720p video); else computed.

    Returns
    -------
    RangingResult
        One :class:`RangedBox` per input box in the input order; lanes and the lead not yet
        assigned (``lane`` None, ``is_lead`` False).
    """
    config = config or RangingConfig()
    warnings: list[Note] = []
    if not boxes:
        h = camera.horizon_y_px()
        return RangingResult([], camera.pitch_deg, h, "camera file", {},
                             [Note.warning("no boxes to range")], lanes=lanes)
    unknown = sorted({b.category for b in boxes} - set(config.priors))
    if unknown:
        warnings.append(Note.warning(f"no size prior for {', '.join(unknown)}: used the car "
                                     "prior"))

    horizon, source, notes = (horizon if horizon is not None
                              else choose_horizon(boxes, camera, config, horizon_hints_px))
    warnings.extend(n for n in notes if n.kind is NoteKind.WARNING)
    pitch = pitch_for_horizon(camera, horizon)
    cam = camera.with_pitch(pitch)
    ba = BoxArrays.from_boxes(boxes, cam, config)
    frame_box = np.array([b.frame for b in boxes])
    t_box = np.array([b.t_s for b in boxes], dtype=float)
    if horizon_hint_frames is not None and horizon_hints_px is not None:
        hf = np.asarray(horizon_hint_frames, dtype=float)
        hr = np.asarray(horizon_hints_px, dtype=float)
        ok = np.isfinite(hr) & np.isfinite(hf)
        slow_px = lane_horizon_offsets(frame_box, t_box, hf[ok], hr[ok], horizon, config)
        if np.any(slow_px != 0):
            ba = ba.shifted(slow_px)
            notes.append(Note.estimate(
                f"per-frame horizon from lane markings within "
                f"{config.lane_horizon_window_s:g} s: {slow_px.min():+.1f} to "
                f"{slow_px.max():+.1f} px about {horizon:.1f} px"))
    priors = [config.prior_for(b.category) for b in boxes]
    w0 = np.array([p.width_m for p in priors])
    w0_std = np.array([p.width_std_m for p in priors])
    h0 = np.array([p.height_m for p in priors])
    h0_std = np.array([p.height_std_m for p in priors])
    l0 = np.array([p.length_m for p in priors])
    l0_std = np.array([p.length_std_m for p in priors])
    track_ids = np.array([b.track_id for b in boxes])

    # 1) Each track's own width and height: fit with loose size priors on frames where the
    # ground cue is sharp and no side is cut, then combine with the class prior (Gaussian
    # product). Once known, the box's width and height follow the range frame by frame
    # with nothing but pixel noise: the cues that make the range rate.
    loose_std = np.full(len(boxes), config.loose_size_std_m)
    loose = fit_boxes(cam, ba, w0, loose_std, h0, loose_std, l0, config, length_std_m=l0_std)
    learn = (loose.valid & loose.ground_ok & loose.width_ok
             & (loose.range_m < config.width_learning_max_range_m))
    learn_h = learn & ~(ba.cut_top | ba.cut_bottom)
    w_track = w0.copy()
    w_track_std = w0_std.copy()
    h_track = h0.copy()
    h_track_std = h0_std.copy()
    road_std = np.full(len(boxes), config.road_height_std_m)
    width_by_track: dict[int, float] = {}
    order = np.argsort(track_ids, kind="stable")
    splits = np.flatnonzero(np.diff(track_ids[order])) + 1
    for members in np.split(order, splits):
        tid = int(track_ids[members[0]])
        m = members[learn[members]]
        prior_w, prior_sd = w0[members[0]], w0_std[members[0]]
        w_est, w_sd = _size_from_track(loose.width_m[m], loose.width_var_m2[m],
                                       loose.cov_white[m, 2, 2], prior_w, prior_sd)
        mh = members[learn_h[members]]
        h_track[members], h_track_std[members] = _size_from_track(
            loose.height_m[mh], loose.height_var_m2[mh], loose.cov_white[mh, 3, 3],
            h0[members[0]], h0_std[members[0]])
        if w_est < prior_w - config.narrow_width_sigmas * prior_sd:
            # No vehicle of the class is that narrow (4 sigma: 1.27 m for a car; partial
            # occlusion, which also narrows a box, rarely goes that far for a whole track):
            # the road under this one lies below the ego's plane (a sag, a dip; a box wider
            # than the class may be a turned vehicle instead, so that side is left alone).
            # Its width is the class prior, and its
            # ground cue counts with the road offset that the disagreement implies,
            # dz = H (W_prior / W_ground - 1), as the road height's spread.
            road_std[members] = max(config.road_height_std_m,
                                    cam.height_m * abs(prior_w / max(w_est, 0.1) - 1.0))
            w_est, w_sd = prior_w, prior_sd
            # Its height was read off the same misleading ground cue.
            h_track[members], h_track_std[members] = h0[members[0]], h0_std[members[0]]
        w_track[members], w_track_std[members] = w_est, w_sd
        width_by_track[tid] = round(w_est, 3)

    # 2) Per-frame horizon offset (body pitch), then the final per-frame fit.
    frame_offset_px = np.zeros(len(boxes))
    if config.per_frame_pitch:
        frame_offset_px = frame_horizon_offsets(boxes, cam, ba, loose, w_track, h_track, l0,
                                                config, l0_std)
        if np.any(frame_offset_px != 0):
            ba = ba.shifted(frame_offset_px)
    # Each track's frame spacing sets how strongly its measurements share the body pitch.
    inflation = np.ones(len(boxes))
    for members in np.split(order, splits):
        t_m = np.unique(t_box[members])
        if t_m.size > 1:
            inflation[members] = colored_noise_factor(float(np.median(np.diff(t_m))),
                                                      config.body_pitch_correlation_s)
    fit = fit_boxes(cam, ba, w_track, w_track_std, h_track, h_track_std, l0, config,
                    length_std_m=l0_std, pitch_noise_inflation=inflation,
                    road_height_std_m=road_std)
    if (~fit.valid).any():
        warnings.append(Note.warning(
            f"{int((~fit.valid).sum())} boxes gave no usable range cue (cut by the border on "
            "too many sides); their range comes from the track filter"))

    # 3) Per-track filter: the absolute cues (a fit with the width left free: ground and top
    # edge) and the box's scale change (its log width against the outline's, with the
    # track's width an unknown of the filter); see scalefilter.py.
    n = len(boxes)
    gfit = fit_boxes(cam, ba, w_track, np.full(n, FREE_WIDTH_STD_M), h_track, h_track_std, l0,
                     config, length_std_m=l0_std, pitch_noise_inflation=inflation,
                     road_height_std_m=road_std, ground_allowed=fit.ground_ok)
    lin = _log_width_model(cam, fit, ba)
    bw = np.maximum(ba.x2 - ba.x1, 1.0)
    sig_u = config.edge_noise_px + config.edge_noise_frac * bw
    log_w = np.where(fit.width_ok, np.log(bw), np.nan)
    log_w_var = log_width_var(sig_u, sig_u, bw)
    out_range = np.full(n, np.nan)
    out_rate = np.full(n, np.nan)
    out_lat = np.full(n, np.nan)
    out_lat_rate = np.full(n, np.nan)
    out_std = np.full(n, np.nan)
    # The scale cue only where the box is as wide as the track's vehicle: a box much wider
    # (a turning car showing its side) or narrower (partly hidden) changes width for reasons
    # other than range, which the single-frame fit's robust width prior already discounts.
    width_dev = np.abs(fit.width_m - w_track) / np.maximum(w0_std, 1e-3)
    log_w_ok = (fit.valid & np.isfinite(lin["b"]) & (lin["b"] < 0)
                & (width_dev <= config.width_tail_sigmas)
                & (lin["e"] >= config.scale_cue_min_width_share))
    # The absolute measurement: where the scale cue carries the width, the fit with the width
    # left free (no cue counted twice); elsewhere (a turned, half-hidden or oblique vehicle)
    # the single-frame fit of all cues, the learnt width's included, at its frame-to-frame
    # noise as before the scale cue.
    abs_m = np.where(log_w_ok, gfit.range_m, fit.range_m)
    abs_var = np.where(log_w_ok, gfit.range_var_m2, fit.range_white_var_m2)
    abs_ok = np.where(log_w_ok, gfit.valid, fit.valid) & np.isfinite(abs_m)
    for members in np.split(order, splits):
        members = members[np.lexsort((frame_box[members], t_box[members]))]
        for piece in _track_pieces(t_box[members], fit.valid[members], config.filter_max_gap_s,
                                   members):
            if not fit.valid[piece].any():
                # Nothing but weak cues (e.g. a car alongside, cut at the bottom and a side):
                # report the single-frame fit with its large spread rather than nothing.
                out_range[piece] = fit.range_m[piece]
                out_lat[piece] = fit.lateral_m[piece]
                out_std[piece] = np.sqrt(np.maximum(fit.range_var_m2[piece], 0))
                continue
            first = piece[np.argmax(fit.valid[piece])]
            meas = RangeMeasurements(
                t_s=t_box[piece],
                abs_m=np.where(abs_ok[piece], abs_m[piece], np.nan),
                # With the scale cue, its whole variance, the part common to the track (road
                # height under the vehicle, horizon) included: that part does not average out
                # over frames, and the width's level (the filter's c) is as uncertain; the
                # rate comes from the scale change.
                abs_var_m2=abs_var[piece],
                log_w=np.where(log_w_ok[piece], log_w[piece], np.nan),
                log_w_var=log_w_var[piece], lin_x_m=fit.range_m[piece],
                lin_c=lin["c"][piece], lin_a=lin["a"][piece], lin_b=lin["b"][piece],
                lin_e=lin["e"][piece], start_m=float(fit.range_m[first]),
                log_width_prior=float(np.log(w_track[first])),
                log_width_prior_var=float((w_track_std[first] / w_track[first]) ** 2))
            fr = filter_range_adaptive(meas, config.accel_noise_grid_mps2,
                                       config.initial_range_rate_std_mps,
                                       config.accel_noise_margin_loglik,
                                       inverse=config.inverse_range_update)
            # The lateral offset: a constant-velocity filter of its own.
            z = np.column_stack((fit.range_m[piece], fit.lateral_m[piece]))
            r = np.zeros((len(piece), 2, 2))
            r[:, 0, 0] = fit.range_white_var_m2[piece]
            r[:, 1, 1] = fit.lateral_white_var_m2[piece]
            sm = smooth_track(t_box[piece], z, r, fit.valid[piece],
                              min(config.accel_noise_grid_mps2),
                              config.lateral_accel_noise_mps2,
                              config.initial_range_rate_std_mps)
            out_range[piece] = fr.range_m
            out_lat[piece] = sm.lateral_m
            out_std[piece] = fr.range_std_m
            if len(piece) > 1:
                out_rate[piece] = fr.range_rate_mps
                out_lat_rate[piece] = sm.lateral_rate_mps

    # Lanes and the lead are assigned in one pass once every input is known
    # (vid2sim.detect.assign, run by the pipeline or the build after the road's course).
    ranged = [
        RangedBox(frame=b.frame, t_s=b.t_s, track_id=b.track_id, category=b.category,
                  score=b.score, x1=b.x1, y1=b.y1, x2=b.x2, y2=b.y2,
                  range_m=float(out_range[i]), lateral_m=float(out_lat[i]),
                  range_rate_mps=float(out_rate[i]), range_std_m=float(out_std[i]),
                  is_lead=False, width_m=float(w_track[i]),
                  lateral_rate_mps=float(out_lat_rate[i]))
        for i, b in enumerate(boxes)]
    return RangingResult(ranged, pitch, horizon, source, width_by_track, warnings + [
        n for n in notes if n.kind is not NoteKind.WARNING], lanes=lanes)
