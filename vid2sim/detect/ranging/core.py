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
from dataclasses import dataclass

import numpy as np

from vid2sim.base.defaults import MAD_TO_SIGMA
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
from vid2sim.detect.ranging.groups import (
    BoxSizes,
    FitColumns,
    RangeOutput,
    TrackGroup,
    track_groups,
    track_pieces,
)
from vid2sim.detect.ranging.horizon import (
    choose_horizon,
    frame_horizon_offsets,
    lane_horizon_offsets,
    pitch_for_horizon,
)
from vid2sim.detect.ranging.parallax import EgoPath, standing_range_rate
from vid2sim.detect.ranging.scalefilter import (
    RangeMeasurements,
    filter_range_adaptive,
    log_width_var,
    rigid_runs,
)
from vid2sim.detect.ranging.smoother import smooth_track
from vid2sim.detect.ranging.surface import (
    StandingTracks,
    TrackGround,
    find_standing_tracks,
    track_grounds,
)

# The absolute-cue fit leaves the width free with this spread [m]: its sides then say where
# the vehicle is laterally but nothing about its range (that is the filter's scale cue).
FREE_WIDTH_STD_M = 10.0
# Relative step of the finite differences of the log-width model.
LOG_WIDTH_FD_STEP = 1e-3


def _log_width_model(camera: Camera, fit: BoxFit, ba: BoxArrays, road_z: np.ndarray
                     ) -> dict[str, np.ndarray]:
    """Each box's predicted log width about its own fit: ln w = a + b (Z - Z_fit) +
    e (ln W - ln W_fit), from the outline's projection (finite differences)."""
    def log_width(x: np.ndarray, w: np.ndarray) -> np.ndarray:
        e = predict_edges(camera, x, fit.lateral_m, w, fit.height_m, fit.length_m, ba.outline,
                          road_z)
        return np.log(np.maximum(e[:, 2] - e[:, 0], 1e-3))

    step = LOG_WIDTH_FD_STEP
    a = log_width(fit.range_m, fit.width_m)
    b = (log_width(fit.range_m * (1 + step), fit.width_m) - a) / (fit.range_m * step)
    e = (log_width(fit.range_m, fit.width_m * (1 + step)) - a) / math.log1p(step)
    return {"a": a, "b": b, "e": e, "c": np.log(fit.width_m)}


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


# --------------------------------------------------------------------------- the steps


def _tracks(boxes: list[TrackedBox]) -> dict[int, np.ndarray]:
    """Each track's box indices in time order (then frame)."""
    tids = np.array([b.track_id for b in boxes])
    t = np.array([b.t_s for b in boxes], dtype=float)
    frames = np.array([b.frame for b in boxes])
    order = np.argsort(tids, kind="stable")
    out = {}
    for members in np.split(order, np.flatnonzero(np.diff(tids[order])) + 1):
        out[int(tids[members[0]])] = members[np.lexsort((frames[members], t[members]))]
    return out


def _horizon_boxes(boxes: list[TrackedBox], camera: Camera, config: RangingConfig,
                   horizon: tuple[float, str, list[Note]], hints_px: list[float] | None,
                   hint_frames: list[int] | None) -> tuple[Camera, float, BoxArrays, list[Note]]:
    """The camera at the chosen horizon's pitch and the boxes with the slow per-frame horizon
    of the lane markings removed."""
    h = horizon[0]
    pitch = pitch_for_horizon(camera, h)
    cam = camera.with_pitch(pitch)
    ba = BoxArrays.from_boxes(boxes, cam, config)
    out: list[Note] = []
    if hint_frames is not None and hints_px is not None:
        hf = np.asarray(hint_frames, dtype=float)
        hr = np.asarray(hints_px, dtype=float)
        ok = np.isfinite(hr) & np.isfinite(hf)
        slow_px = lane_horizon_offsets(np.array([b.frame for b in boxes]),
                                       np.array([b.t_s for b in boxes], dtype=float),
                                       hf[ok], hr[ok], h, config)
        if np.any(slow_px != 0):
            ba = ba.shifted(slow_px)
            out.append(Note.estimate(
                f"per-frame horizon from lane markings within "
                f"{config.lane_horizon_window_s:g} s: {slow_px.min():+.1f} to "
                f"{slow_px.max():+.1f} px about {h:.1f} px"))
    return cam, pitch, ba, out


def _learn_sizes(cam: Camera, ba: BoxArrays, sizes: BoxSizes, tracks: dict[int, np.ndarray],
                 config: RangingConfig) -> BoxFit:
    """Each track's own width and height (into ``sizes``); returns the loose fit.

    Fit with loose size priors on frames where the ground cue is sharp and no side is cut,
    then combine with the class prior (Gaussian product). Once known, the box's width and
    height follow the range frame by frame with nothing but pixel noise: the cues that make
    the range rate.
    """
    s = sizes
    loose_std = np.full(len(s.w0), config.loose_size_std_m)
    loose = fit_boxes(cam, ba, s.w0, loose_std, s.h0, loose_std, s.l0, config,
                      length_std_m=s.l0_std)
    learn = (loose.valid & loose.ground_ok & loose.width_ok
             & (loose.range_m < config.width_learning_max_range_m))
    learn_h = learn & ~(ba.cut_top | ba.cut_bottom)
    for tid, members in tracks.items():
        i0 = members[0]
        m, mh = members[learn[members]], members[learn_h[members]]
        w_est, w_sd = _size_from_track(loose.width_m[m], loose.width_var_m2[m],
                                       loose.cov_white[m, 2, 2], s.w0[i0], s.w0_std[i0])
        s.h[members], s.h_std[members] = _size_from_track(
            loose.height_m[mh], loose.height_var_m2[mh], loose.cov_white[mh, 3, 3],
            s.h0[i0], s.h0_std[i0])
        if w_est < s.w0[i0] - config.narrow_width_sigmas * s.w0_std[i0]:
            # No vehicle of the class is that narrow (4 sigma: 1.27 m for a car; partial
            # occlusion, which also narrows a box, rarely goes that far for a whole track):
            # the road under this one lies below the ego's plane (a sag, a dip; a box wider
            # than the class may be a turned vehicle instead, so that side is left alone).
            # Its width is the class prior, and its ground cue counts with the road offset
            # that the disagreement implies, dz = H (W_prior / W_ground - 1), as the road
            # height's spread; its height was read off the same misleading ground cue.
            s.road_std[members] = max(config.road_height_std_m,
                                      cam.height_m * abs(s.w0[i0] / max(w_est, 0.1) - 1.0))
            w_est, w_sd = s.w0[i0], s.w0_std[i0]
            s.h[members], s.h_std[members] = s.h0[i0], s.h0_std[i0]
        s.w[members], s.w_std[members] = w_est, w_sd
        s.width_by_track[tid] = round(w_est, 3)
    return loose


def _pitch_inflation(t_box: np.ndarray, tracks: dict[int, np.ndarray],
                     config: RangingConfig) -> np.ndarray:
    """Each track's frame spacing sets how strongly its measurements share the body pitch."""
    inflation = np.ones(len(t_box))
    for members in tracks.values():
        t_m = np.unique(t_box[members])
        if t_m.size > 1:
            inflation[members] = colored_noise_factor(float(np.median(np.diff(t_m))),
                                                      config.body_pitch_correlation_s)
    return inflation


def _ground_under_tracks(cam: Camera, ba: BoxArrays, t_box: np.ndarray, fit: BoxFit,
                         sizes: BoxSizes, tracks: dict[int, np.ndarray], config: RangingConfig,
                         path: EgoPath | None) -> tuple[StandingTracks, dict[int, TrackGround]]:
    """Standing tracks fitted from the ego's motion (with a trajectory), and the ground under
    every track (into ``sizes``: ground height, road spread, and a standing vehicle's own
    size)."""
    standing = StandingTracks()
    if path is not None:
        standing = find_standing_tracks(
            cam, ba, t_box, tracks, fit.range_m, fit.lateral_m,
            np.column_stack((sizes.w0, sizes.h0, sizes.l0)),
            np.column_stack((sizes.w0_std, sizes.h0_std, sizes.l0_std)), path, config)
    lateral = {tid: float(np.median(fit.lateral_m[m])) for tid, m in tracks.items()}
    grounds = track_grounds(standing, lateral, config)
    for tid, members in tracks.items():
        gr = grounds[tid]
        if gr.source == "ego plane":
            continue  # the road's spread as before: the lateral growth is fit_boxes' own
        sizes.road_z[members] = gr.height_m
        sizes.road_std[members] = gr.std_m
        if tid in standing.fits:
            f = standing.fits[tid]
            sd = np.sqrt(np.maximum(np.diag(f.cov), 0.0))
            sizes.w[members], sizes.w_std[members] = f.theta[2], max(sd[2], SIZE_FLOOR_STD_M)
            sizes.h[members], sizes.h_std[members] = f.theta[3], max(sd[3], SIZE_FLOOR_STD_M)
            sizes.l0[members], sizes.l0_std[members] = f.theta[4], max(sd[4], SIZE_FLOOR_STD_M)
            sizes.width_by_track[tid] = round(float(f.theta[2]), 3)
    return standing, grounds


#: Least spread of a standing fit's range taken by the filter [m]: the outline model's own
#: error of where a box's edge lies on a car (0.1 m).
STANDING_RANGE_FLOOR_STD_M = 0.1
#: Least spread of a size a standing fit measured [m]: the outline model's own error (a
#: car's mirrors, its rear face's inset) is a few centimetres whatever the parallax says.
SIZE_FLOOR_STD_M = 0.03


@dataclass
class _Cues:
    """Per box: the single-frame fit, the absolute measurement for the filter, the scale
    cue and, for standing vehicles, the range rate from the ego's motion."""

    fit: BoxFit
    abs_m: np.ndarray
    abs_var: np.ndarray
    abs_ok: np.ndarray
    log_w: np.ndarray
    log_w_var: np.ndarray
    log_w_ok: np.ndarray
    lin: dict[str, np.ndarray]
    rate_mps: np.ndarray
    rate_var: np.ndarray


def _filter_cues(cam: Camera, ba: BoxArrays, fit: BoxFit, sizes: BoxSizes,
                 inflation: np.ndarray, config: RangingConfig) -> _Cues:
    """The filter's measurements: the absolute cues (a fit with the width left free: ground
    and top edge) and the box's scale change (its log width against the outline's, with the
    track's width an unknown of the filter); see scalefilter.py."""
    n = len(ba.x1)
    s = sizes
    gfit = fit_boxes(cam, ba, s.w, np.full(n, FREE_WIDTH_STD_M), s.h, s.h_std, s.l0, config,
                     length_std_m=s.l0_std, pitch_noise_inflation=inflation,
                     road_height_std_m=s.road_std, ground_allowed=fit.ground_ok,
                     road_z_m=s.road_z)
    lin = _log_width_model(cam, fit, ba, s.road_z)
    bw = np.maximum(ba.x2 - ba.x1, 1.0)
    sig_u = config.edge_noise_px + config.edge_noise_frac * bw
    # The scale cue only where the box is as wide as the track's vehicle: a box much wider
    # (a turning car showing its side) or narrower (partly hidden) changes width for reasons
    # other than range, which the single-frame fit's robust width prior already discounts.
    width_dev = np.abs(fit.width_m - s.w) / np.maximum(s.w0_std, 1e-3)
    log_w_ok = (fit.valid & np.isfinite(lin["b"]) & (lin["b"] < 0)
                & (width_dev <= config.width_tail_sigmas)
                & (lin["e"] >= config.scale_cue_min_width_share))
    # The absolute measurement: where the scale cue carries the width, the fit with the width
    # left free (no cue counted twice), with its whole variance (the part common to the
    # track, road height and horizon, included: it does not average out over frames, and
    # the width's level is as uncertain; the rate comes from the scale change); elsewhere (a
    # turned, half-hidden or oblique vehicle) the single-frame fit of all cues, the learnt
    # width's included, at its frame-to-frame noise as before the scale cue.
    abs_m = np.where(log_w_ok, gfit.range_m, fit.range_m)
    return _Cues(fit, abs_m, np.where(log_w_ok, gfit.range_var_m2, fit.range_white_var_m2),
                 np.where(log_w_ok, gfit.valid, fit.valid) & np.isfinite(abs_m),
                 np.where(fit.width_ok, np.log(bw), np.nan), log_width_var(sig_u, sig_u, bw),
                 log_w_ok, lin, np.full(n, np.nan), np.full(n, np.nan))


def _carry_scale(cam: Camera, ba: BoxArrays, cues: _Cues, sizes: BoxSizes, t_box: np.ndarray,
                 tracks: dict[int, np.ndarray], inflation: np.ndarray,
                 config: RangingConfig) -> int:
    """Into ``cues``: for boxes whose ground contact is out of view (a near vehicle's bottom
    below the image), the range the track learnt while its bottom was visible, carried by
    the box's size. A rigid vehicle's image size changes as 1 / Z: the ratio of the full fit
    (ground cue included) to the fit of the box's sides alone, over the nearest frames that
    had both, scales the sides-alone range of the cut frames. So neither the width prior nor
    the top edge, whose lever below a camera at a car's roof height is a few centimetres,
    takes over a range the track has measured. Returns the boxes so ranged."""
    fit = cues.fit
    side = fit_boxes(cam, ba, sizes.w, sizes.w_std, sizes.h, sizes.h_std, sizes.l0, config,
                     use_ground=False, use_height=False, length_std_m=sizes.l0_std,
                     pitch_noise_inflation=inflation, road_height_std_m=sizes.road_std,
                     road_z_m=sizes.road_z)
    ref = fit.valid & fit.ground_ok & fit.width_ok & side.valid
    cut = ~fit.ground_ok & ba.cut_bottom & side.valid & fit.width_ok
    carried = 0
    for members in tracks.values():
        m_cut, m_ref = members[cut[members]], members[ref[members]]
        if not (m_cut.size and m_ref.size):
            continue
        ratio = fit.range_m[m_ref] / side.range_m[m_ref]
        for i in m_cut:
            near = np.argsort(np.abs(t_box[m_ref] - t_box[i]), kind="stable")[
                :config.carry_frames]
            if np.min(np.abs(t_box[m_ref[near]] - t_box[i])) > config.filter_max_gap_s:
                continue
            k = float(np.median(ratio[near]))
            k_sd = max(MAD_TO_SIGMA * float(np.median(np.abs(ratio[near] - k)))
                       / math.sqrt(near.size), config.carry_floor_rel)
            cues.abs_m[i] = k * side.range_m[i]
            cues.abs_var[i] = k ** 2 * side.range_white_var_m2[i] + (k_sd * cues.abs_m[i]) ** 2
            cues.abs_ok[i] = True
            cues.log_w_ok[i] = False  # the sides' scale is in it already
            carried += 1
    return carried


def _standing_rates(cues: _Cues, t_box: np.ndarray, standing: StandingTracks,
                    tracks: dict[int, np.ndarray], path: EgoPath | None,
                    config: RangingConfig) -> None:
    """Into ``cues``: the range rate every box of a standing track has from the ego's
    measured speed and yaw rate, with its noise (speed error, and the yaw rate times the
    lateral offset's spread)."""
    if path is None:
        return
    for tid, fit in standing.fits.items():
        members = tracks[tid]
        v, w = path.speed_yaw_rate(t_box[members])
        cues.rate_mps[members] = standing_range_rate(fit.range_m, fit.lateral_m, v, w)
        lat_sd = math.sqrt(max(fit.cov[1, 1], 0.0))
        cues.rate_var[members] = config.ego_speed_std_mps ** 2 + (w * lat_sd) ** 2
        # Its place: the one fit of all its boxes (their widths, bearings and rows from the
        # known baseline), at that fit's spread; its scale change is already in it.
        cues.abs_m[members] = fit.range_m
        cues.abs_var[members] = max(fit.cov[0, 0], 0.0) + STANDING_RANGE_FLOOR_STD_M ** 2
        cues.abs_ok[members] = True
        cues.log_w_ok[members] = False


def _filter_piece(piece: np.ndarray, t_box: np.ndarray, cues: _Cues, sizes: BoxSizes,
                  config: RangingConfig, out: RangeOutput) -> None:
    """One piece of a track through the range filter and the lateral smoother (into
    ``out``)."""
    fit = cues.fit
    if not fit.valid[piece].any():
        # Nothing but weak cues (e.g. a car alongside, cut at the bottom and a side): report
        # the single-frame fit with its large spread rather than nothing.
        out.range_m[piece] = fit.range_m[piece]
        out.lateral[piece] = fit.lateral_m[piece]
        out.std[piece] = np.sqrt(np.maximum(fit.range_var_m2[piece], 0))
        return
    first = piece[np.argmax(fit.valid[piece])]
    lin = cues.lin
    meas = RangeMeasurements(
        t_s=t_box[piece], abs_m=np.where(cues.abs_ok[piece], cues.abs_m[piece], np.nan),
        abs_var_m2=cues.abs_var[piece],
        log_w=np.where(cues.log_w_ok[piece], cues.log_w[piece], np.nan),
        log_w_var=cues.log_w_var[piece], lin_x_m=fit.range_m[piece], lin_c=lin["c"][piece],
        lin_a=lin["a"][piece], lin_b=lin["b"][piece], lin_e=lin["e"][piece],
        start_m=float(fit.range_m[first]), log_width_prior=float(np.log(sizes.w[first])),
        log_width_prior_var=float((sizes.w_std[first] / sizes.w[first]) ** 2),
        rate_mps=cues.rate_mps[piece], rate_var=cues.rate_var[piece])
    fr = filter_range_adaptive(meas, config.accel_noise_grid_mps2,
                               config.initial_range_rate_std_mps,
                               config.accel_noise_margin_loglik,
                               inverse=config.inverse_range_update)
    # The lateral offset: a constant-velocity filter of its own.
    z = np.column_stack((fit.range_m[piece], fit.lateral_m[piece]))
    r = np.zeros((len(piece), 2, 2))
    r[:, 0, 0] = fit.range_white_var_m2[piece]
    r[:, 1, 1] = fit.lateral_white_var_m2[piece]
    sm = smooth_track(t_box[piece], z, r, fit.valid[piece], min(config.accel_noise_grid_mps2),
                      config.lateral_accel_noise_mps2, config.initial_range_rate_std_mps)
    out.range_m[piece] = fr.range_m
    out.lateral[piece] = sm.lateral_m
    out.std[piece] = fr.range_std_m
    if len(piece) > 1:
        out.rate[piece] = fr.range_rate_mps
        out.lateral_rate[piece] = sm.lateral_rate_mps


def _ground_notes(standing: StandingTracks, grounds: dict[int, TrackGround]) -> list[Note]:
    """What the standing fits and the road surface found, for the summary."""
    if not standing.fits and not standing.rejected:
        return []
    by_source: dict[str, int] = {}
    for g in grounds.values():
        by_source[g.source] = by_source.get(g.source, 0) + 1
    hs = [f.ground_m for f in standing.fits.values()]
    text = (f"{len(standing.fits)} of {len(standing.fits) + len(standing.rejected)} tracks "
            "ranged as standing vehicles from the ego's motion"
            + (f" (their ground {min(hs):+.2f} to {max(hs):+.2f} m off the ego's road)"
               if hs else "")
            + "; ground under the tracks from " + ", ".join(
                f"{k}: {v}" for k, v in sorted(by_source.items())))
    return [Note.estimate(text)]


def _single_frame_fit(cam: Camera, ba: BoxArrays, sizes: BoxSizes, inflation: np.ndarray,
                      config: RangingConfig) -> BoxFit:
    """Every box's fit of all cues at its track's sizes, on the ground under it."""
    return fit_boxes(cam, ba, sizes.w, sizes.w_std, sizes.h, sizes.h_std, sizes.l0, config,
                     length_std_m=sizes.l0_std, pitch_noise_inflation=inflation,
                     road_height_std_m=sizes.road_std, road_z_m=sizes.road_z)


def _sizes_by_group(cam: Camera, ba: BoxArrays, sizes: BoxSizes, groups: list[TrackGroup],
                    config: RangingConfig) -> FitColumns:
    """Each track's own size (into ``sizes``), a group of tracks at a time; of the loose fit
    only the columns the per-frame pitch reads."""
    loose = FitColumns.empty(len(ba.x1))
    for g in groups:
        part = sizes.subset(g.index)
        loose.put(g.index, _learn_sizes(cam, ba.subset(g.index), part, g.tracks, config))
        sizes.put(g.index, part)
    return loose


def _first_fit_columns(cam: Camera, ba: BoxArrays, sizes: BoxSizes, inflation: np.ndarray,
                       groups: list[TrackGroup], config: RangingConfig) -> FitColumns:
    """The single-frame fit of every box, a group of tracks at a time (the standing
    vehicles' start)."""
    first = FitColumns.empty(len(ba.x1))
    for g in groups:
        first.put(g.index, _single_frame_fit(cam, ba.subset(g.index), sizes.subset(g.index),
                                             inflation[g.index], config))
    return first


def _range_group(cam: Camera, ba: BoxArrays, t_box: np.ndarray, sizes: BoxSizes,
                 inflation: np.ndarray, g: TrackGroup, standing: StandingTracks,
                 grounds: dict[int, TrackGround], config: RangingConfig,
                 path: EgoPath | None, out: RangeOutput) -> tuple[int, int]:
    """One group of tracks: the single-frame fit on the ground under each car, the filter's
    cues, every track through the range filter (into ``out``); without a trajectory the
    ground under its tracks (into ``grounds``). Returns the boxes with no usable cue and
    those ranged by their track's scale."""
    gba, gs, gt, ginf = ba.subset(g.index), sizes.subset(g.index), t_box[g.index], inflation[
        g.index]
    fit = _single_frame_fit(cam, gba, gs, ginf, config)
    if path is None:
        grounds.update(_ground_under_tracks(cam, gba, gt, fit, gs, g.tracks, config, None)[1])
    cues = _filter_cues(cam, gba, fit, gs, ginf, config)
    carried = _carry_scale(cam, gba, cues, gs, gt, g.tracks, ginf, config)
    _standing_rates(cues, gt, StandingTracks(
        fits={t: f for t, f in standing.fits.items() if t in g.tracks}), g.tracks, path, config)
    part = RangeOutput.empty(g.index.size)
    for members in g.tracks.values():
        # a track that changes object (its box shrinks faster than a rigid vehicle can) is
        # filtered in separate runs
        for run in rigid_runs(members, gba, gt, fit.range_m, config):
            for piece in track_pieces(gt[run], fit.valid[run], config.filter_max_gap_s, run):
                _filter_piece(piece, gt, cues, gs, config, part)
    out.put(g.index, part)
    return int((~fit.valid).sum()), carried


def _range_by_group(cam: Camera, ba: BoxArrays, t_box: np.ndarray, sizes: BoxSizes,
                    inflation: np.ndarray, tracks: dict[int, np.ndarray],
                    groups: list[TrackGroup], config: RangingConfig, path: EgoPath | None
                    ) -> tuple[RangeOutput, StandingTracks, dict[int, TrackGround], int, int]:
    """Every track ranged, a group at a time, after the standing vehicles and the ground
    under the tracks (with a trajectory: from the first single-frame fits of all groups);
    the boxes with no usable cue and those ranged by their track's scale are counted."""
    standing, grounds = StandingTracks(), {}
    if path is not None:
        first = _first_fit_columns(cam, ba, sizes, inflation, groups, config)
        standing, grounds = _ground_under_tracks(cam, ba, t_box, first, sizes, tracks, config,
                                                 path)
        del first
    out = RangeOutput.empty(len(t_box))
    no_cue = carried = 0
    for g in groups:
        n_bad, n_carried = _range_group(cam, ba, t_box, sizes, inflation, g, standing, grounds,
                                        config, path, out)
        no_cue, carried = no_cue + n_bad, carried + n_carried
    return out, standing, grounds, no_cue, carried


def _ranged_boxes(boxes: list[TrackedBox], out: RangeOutput, sizes: BoxSizes
                  ) -> list[RangedBox]:
    """One :class:`RangedBox` per input box (lanes and the lead not yet assigned)."""
    return [
        RangedBox(frame=b.frame, t_s=b.t_s, track_id=b.track_id, category=b.category,
                  score=b.score, x1=b.x1, y1=b.y1, x2=b.x2, y2=b.y2,
                  range_m=float(out.range_m[i]), lateral_m=float(out.lateral[i]),
                  range_rate_mps=float(out.rate[i]), range_std_m=float(out.std[i]),
                  is_lead=False, width_m=float(sizes.w[i]),
                  lateral_rate_mps=float(out.lateral_rate[i]))
        for i, b in enumerate(boxes)]


# --------------------------------------------------------------------------- main entry


def range_tracks(boxes: list[TrackedBox], camera: Camera, *,
                 horizon_hints_px: list[float] | None = None,
                 horizon_hint_frames: list[int] | None = None,
                 config: RangingConfig | None = None,
                 lanes: LaneTrack | None = None,
                 horizon: tuple[float, str, list[Note]] | None = None,
                 ego_path: EgoPath | None = None) -> RangingResult:
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
    ego_path : EgoPath, optional
        The ego's trajectory (GPS/OXTS) on the boxes' clock: tracks that stand still are then
        ranged from the ego's own motion and measure the ground they stand on
        (:mod:`vid2sim.detect.ranging.surface`); without it every track is ranged as before.

    Returns
    -------
    RangingResult
        One :class:`RangedBox` per input box in the input order; lanes and the lead not yet
        assigned (``lane`` None, ``is_lead`` False).
    """
    config = config or RangingConfig()
    if not boxes:
        h = camera.horizon_y_px()
        return RangingResult([], camera.pitch_deg, h, "camera file", {},
                             [Note.warning("no boxes to range")], lanes=lanes)
    warnings: list[Note] = []
    unknown = sorted({b.category for b in boxes} - set(config.priors))
    if unknown:
        warnings.append(Note.warning(f"no size prior for {', '.join(unknown)}: used the car "
                                     "prior"))
    horizon = (horizon if horizon is not None
               else choose_horizon(boxes, camera, config, horizon_hints_px))
    notes = list(horizon[2])
    warnings.extend(n for n in notes if n.kind is NoteKind.WARNING)
    cam, pitch, ba, more = _horizon_boxes(boxes, camera, config, horizon, horizon_hints_px,
                                          horizon_hint_frames)
    notes += more
    t_box = np.array([b.t_s for b in boxes], dtype=float)
    tracks = _tracks(boxes)
    groups = track_groups(tracks)
    sizes = BoxSizes.from_priors(boxes, config)
    loose = _sizes_by_group(cam, ba, sizes, groups, config)
    # Per-frame horizon offset (body pitch): all vehicles of a frame together.
    if config.per_frame_pitch:
        frame_offset_px = frame_horizon_offsets(boxes, cam, ba, loose, sizes.w, sizes.h,
                                                sizes.l0, config, sizes.l0_std)
        if np.any(frame_offset_px != 0):
            ba = ba.shifted(frame_offset_px)
    del loose
    inflation = _pitch_inflation(t_box, tracks, config)
    out, standing, grounds, no_cue, carried = _range_by_group(cam, ba, t_box, sizes, inflation,
                                                              tracks, groups, config, ego_path)
    if no_cue:
        warnings.append(Note.warning(
            f"{no_cue} boxes gave no usable range cue (cut by the border on "
            "too many sides); their range comes from the track filter"))
    if carried:
        notes.append(Note.estimate(
            f"{carried} boxes with their bottom below the image ranged by the scale their "
            "track learnt while its bottom was visible"))
    # Lanes and the lead are assigned in one pass once every input is known
    # (vid2sim.detect.assign, run by the pipeline or the build after the road's course).
    ranged = _ranged_boxes(boxes, out, sizes)
    notes += _ground_notes(standing, grounds)
    return RangingResult(
        ranged, pitch, horizon[0], horizon[1], sizes.width_by_track,
        warnings + [n for n in notes if n.kind is not NoteKind.WARNING], lanes=lanes,
        ground_m_by_track={t: (round(g.height_m, 3), round(g.std_m, 3), g.source)
                           for t, g in grounds.items()},
        standing_tracks=frozenset(standing.fits))
