"""Monocular range, lateral offset and range rate of tracked vehicles (boxes -> metres).

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

import logging
import math
from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from vid2sim.camera import Camera, PitchSource
from vid2sim.detect.lead import assign_lanes_and_lead
from vid2sim.records import Note, NoteKind, RangedBox, RangingResult, TrackedBox

log = logging.getLogger(__name__)

# --------------------------------------------------------------------------- configuration


@dataclass(frozen=True)
class VehiclePrior:
    """Size of a vehicle class seen from behind [m]: mean and one-sigma spread."""

    width_m: float
    width_std_m: float
    length_m: float
    height_m: float
    height_std_m: float
    length_std_m: float = 0.5


# Why these numbers: the body width (ISO 612) of European passenger cars runs from about
# 1.60 m (city cars) to 1.90 m (large saloons, SUVs); new registrations average 1.77-1.80 m
# since 2015 and about 1.70 m around 2000 (ICCT European Vehicle Market Statistics), and the
# fleet on the road is on average 10-12 years old, so its mean is near 1.75 m with a spread
# of 0.12 m (segment mix), which also covers mirrors that a box takes in or not. Vans (Transit/Sprinter
# class) are about 2.0 m, trucks and buses are legally at most 2.55 m wide (EU 96/53/EC) and
# mostly near that limit; motorcycles with rider about 0.8 m. Heights: cars 1.45-1.65 m,
# vans about 2 m, trucks/buses 3-4 m. Lengths only matter for the side of a laterally offset
# vehicle that shows in its box; they are unknowns of the fit with the class spread (cars
# 3.6 m city cars to 5.0 m saloons, vans 4.5-6 m, rigid trucks 6-12 m, buses 12-18 m), so
# a car far to the side, whose box is mostly its flank, does not read as a near one.
DEFAULT_PRIORS: dict[str, VehiclePrior] = {
    "car": VehiclePrior(1.75, 0.12, 4.4, 1.50, 0.12, 0.45),
    "van": VehiclePrior(2.00, 0.12, 5.2, 2.10, 0.30, 0.6),
    "truck": VehiclePrior(2.70, 0.20, 8.0, 3.20, 0.60, 2.0),
    "bus": VehiclePrior(2.75, 0.15, 12.0, 3.10, 0.30, 2.0),
    "motorcycle": VehiclePrior(0.80, 0.15, 2.1, 1.40, 0.20, 0.2),
}


# Trust in a camera file's pitch [deg] (RangingConfig.camera_pitch_std_deg).
CALIBRATED_PITCH_STD_DEG = 0.25
GUESSED_PITCH_STD_DEG = 1.0


@dataclass(frozen=True)
class RangingConfig:
    """Everything ``range_tracks`` assumes, in one explicit object.

    Parameters
    ----------
    priors : dict
        Per-class :class:`VehiclePrior`; unknown classes use ``priors["car"]``.
    edge_noise_px, edge_noise_frac : float
        One-sigma error of a box edge from a detector: a constant plus a fraction of the box
        size (edges of big boxes wander more in absolute pixels).
    road_height_std_m : float
        One-sigma height of the road under a vehicle relative to the plane through the ego
        wheels [m]: cross-fall (2.5 % over a lane is 0.09 m), crests, sags and kerbs. It
        caps the ground cue's accuracy at about road_height_std_m / camera height in
        relative range at any distance.
    road_height_std_per_lateral_m : float
        Growth of that spread per metre of lateral offset beyond the ego lane [m/m]: a
        crowned road falls 2-3 % to the gutter, and a parking strip or a kerb adds 0.1-0.15 m,
        so the ground under a car parked 8 m to the side is known to about 0.2 m.
    fleet_width_mean_std_m : float
        How far the mean car width of the fleet in a video may lie from the prior's mean
        [m]: regions and model years differ by a few centimetres, and boxes that take the
        mirrors in or leave them out by about 0.1 m. It limits how far the vehicles alone
        can move the horizon (the width cue's scale is only as good as this mean).
    horizon_jitter_deg : float
        One-sigma frame-to-frame pitch of the ego body on its suspension [deg]; it moves the
        horizon and so adds to the noise of the ground cue (about 0.15 deg on normal roads).
    camera_pitch_std_deg : float or None
        Trust in the camera file's pitch [deg]. None: 0.25 deg for a rig calibration (a KITTI
        calibration file: the camera's mounting is measured, what remains is the body's
        pitch to the road from load and tyres, a few tenths of a degree), 1 deg otherwise (a
        dash-cam mounting is rarely known better than about a degree).
    lane_horizon_std_px : float
        One-sigma error of a lane-marking horizon estimate from one frame [px].
    border_margin_px : float
        An edge this close to the image border counts as cut by it.
    min_ground_margin_px : float
        The ground cue needs the bottom edge at least this far below the horizon.
    width_learning_max_range_m : float
        The track's own width is learnt only from frames nearer than this, where the ground
        cue is sharp.
    accel_noise_grid_mps2 : tuple
        Candidate spectral densities of the longitudinal relative acceleration (white-noise
        acceleration model) [m^2/s^3]; each track takes the smallest one whose likelihood is
        within ``accel_noise_margin_loglik`` of the most likely.
    accel_noise_margin_loglik : float
        A larger acceleration noise must raise the log-likelihood by more than this (2 is
        the 95 % point of a likelihood-ratio test with one parameter, chi2/2 = 1.92):
        errors of a track's range that drift slowly (cues whose weights change with range)
        look like motion, and a filter left free to follow them makes a noisy range rate.
    lateral_accel_noise_mps2 : float
        The same for the lateral motion [m^2/s^3].
    initial_range_rate_std_mps : float
        Prior spread of a new track's range rate [m/s].
    lane_width_m : float
        Width of a lane [m]; the ego corridor is +-lane_width_m/2 about the camera.
    lane_hysteresis_m : float
        A vehicle changes lane only once its centre is this far past the boundary.
    lead_switch_frames : int
        Frames another ego-lane vehicle must be nearer before it takes over as lead.
    max_range_m : float
        Positions beyond this are not trusted (reported, but never a lead).
    width_tail_sigmas : float
        A box wider than the width prior by more than this many sigmas is more likely a
        vehicle turned off the ego axis (its side in the box) than a wide one: beyond it the
        width prior is Cauchy rather than Gaussian; ``inf`` for a Gaussian prior.
    per_frame_pitch : bool
        Estimate the body pitch of every frame (braking dive, bumps) from the disagreement
        of ground and width cues of all vehicles in the frame, and correct the boxes' rows.
    pitch_accel_noise_px : float
        Process noise of that per-frame horizon offset (white-noise acceleration model)
        [px^2/s^3]; about (2 pi 1 Hz)^2 * 0.15 deg of suspension pitch at 1.5 Hz.
    body_pitch_correlation_s : float
        Correlation time of the body pitch [s] (a car body pitches at 1-2 Hz and its
        dampers settle it in about half a second).
    inverse_range_update : bool
        The track filter takes each frame's range as 1/range, where monocular noise is
        additive (see :func:`_kf_rts_cv`); False takes range itself.
    horizon_vehicle_max_lateral_m : float
        The horizon from vehicles uses those whose centre is at most this far to the side
        [m] (the ego lane and the next ones, 1.5 lanes): beside the road the ground lies
        lower. On the composite clips with the lane markings withheld, all vehicles put the
        lead's range 13.3 % long, these 3.1 %.
    lane_horizon_window_s : float
        Half-width of the window [s] over which per-frame lane-marking horizons give the
        slowly changing horizon of each frame (see :func:`lane_horizon_offsets`).
    lane_horizon_min_frames : int
        Lane-marking horizons a window needs; with fewer, that frame keeps the video's one.
    """

    priors: dict[str, VehiclePrior] = field(default_factory=lambda: dict(DEFAULT_PRIORS))
    edge_noise_px: float = 1.0
    edge_noise_frac: float = 0.02
    road_height_std_m: float = 0.10
    road_height_std_per_lateral_m: float = 0.03
    fleet_width_mean_std_m: float = 0.08
    horizon_jitter_deg: float = 0.15
    camera_pitch_std_deg: float | None = None
    lane_horizon_std_px: float = 4.0
    border_margin_px: float = 2.0
    min_ground_margin_px: float = 3.0
    width_learning_max_range_m: float = 40.0
    accel_noise_grid_mps2: tuple[float, ...] = (0.05, 0.15, 0.4, 1.0, 2.5, 6.0)
    accel_noise_margin_loglik: float = 2.0
    lateral_accel_noise_mps2: float = 0.3
    initial_range_rate_std_mps: float = 8.0
    lane_width_m: float = 3.6
    lane_hysteresis_m: float = 0.3
    lead_switch_frames: int = 3
    max_range_m: float = 150.0
    width_tail_sigmas: float = 2.0
    per_frame_pitch: bool = True
    pitch_accel_noise_px: float = 600.0
    body_pitch_correlation_s: float = 0.5
    inverse_range_update: bool = True
    lane_horizon_window_s: float = 1.5
    horizon_vehicle_max_lateral_m: float = 5.4
    lane_horizon_min_frames: int = 5

    def prior_for(self, category: str) -> VehiclePrior:
        return self.priors.get(category, self.priors["car"])

    def pitch_std_for(self, camera: Camera) -> float:
        """One-sigma error of ``camera.pitch_deg`` [deg] (see ``camera_pitch_std_deg``)."""
        if self.camera_pitch_std_deg is not None:
            return self.camera_pitch_std_deg
        calibrated = camera.pitch_source is PitchSource.CALIBRATION
        return CALIBRATED_PITCH_STD_DEG if calibrated else GUESSED_PITCH_STD_DEG


# --------------------------------------------------------------------------- box geometry


@dataclass
class BoxArrays:
    """Boxes as columns (pixels) with the cut flags of each edge."""

    x1: np.ndarray
    y1: np.ndarray
    x2: np.ndarray
    y2: np.ndarray
    cut_left: np.ndarray
    cut_right: np.ndarray
    cut_top: np.ndarray
    cut_bottom: np.ndarray

    @classmethod
    def from_boxes(cls, boxes: list[TrackedBox], camera: Camera, margin_px: float) -> BoxArrays:
        a = np.array([(b.x1, b.y1, b.x2, b.y2) for b in boxes], dtype=float).reshape(-1, 4)
        w, h = camera.image_width - 1, camera.image_height - 1
        return cls(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 0] <= margin_px,
                   a[:, 2] >= w - margin_px, a[:, 1] <= margin_px, a[:, 3] >= h - margin_px)


def _predict_edges(camera: Camera, x_m: np.ndarray, y_m: np.ndarray, w_m: np.ndarray,
                   h_m: np.ndarray, l_m: np.ndarray) -> np.ndarray:
    """(N, 4) pixel box (u1, v1, u2, v2) of vehicles whose rear is at range ``x_m``, centre
    at lateral ``y_m``, aligned with the ego axis and standing on the road."""
    sx = np.array([0, 0, 0, 0, 1, 1, 1, 1], dtype=float)
    sy = np.array([-0.5, 0.5, -0.5, 0.5, -0.5, 0.5, -0.5, 0.5])
    sz = np.array([0, 0, 1, 1, 0, 0, 1, 1], dtype=float)
    px = x_m[:, None] + sx[None, :] * l_m[:, None]
    py = y_m[:, None] + sy[None, :] * w_m[:, None]
    pz = sz[None, :] * h_m[:, None]
    pts = np.stack([px, py, pz], axis=-1).reshape(-1, 3)
    uv, _ = camera.project(pts)
    uv = uv.reshape(-1, 8, 2)
    with np.errstate(invalid="ignore"):
        return np.stack([uv[..., 0].min(1), uv[..., 1].min(1), uv[..., 0].max(1),
                         uv[..., 1].max(1)], axis=1)


@dataclass
class BoxFit:
    """Single-frame position of each box: estimates and their covariance."""

    range_m: np.ndarray
    lateral_m: np.ndarray
    width_m: np.ndarray
    cov: np.ndarray  # (N, 6, 6) over (log range, lateral, width, height, length, row offset)
    cov_white: np.ndarray  # the part of ``cov`` that is independent from frame to frame
    ground_ok: np.ndarray
    width_ok: np.ndarray
    valid: np.ndarray
    length_m: np.ndarray
    height_m: np.ndarray

    @property
    def range_var_m2(self) -> np.ndarray:
        return self.cov[:, 0, 0] * self.range_m ** 2

    @property
    def lateral_var_m2(self) -> np.ndarray:
        return self.cov[:, 1, 1]

    @property
    def width_var_m2(self) -> np.ndarray:
        return self.cov[:, 2, 2]

    @property
    def height_var_m2(self) -> np.ndarray:
        return self.cov[:, 3, 3]

    @property
    def range_lateral_cov_m2(self) -> np.ndarray:
        return self.cov[:, 0, 1] * self.range_m

    @property
    def range_white_var_m2(self) -> np.ndarray:
        return self.cov_white[:, 0, 0] * self.range_m ** 2

    @property
    def lateral_white_var_m2(self) -> np.ndarray:
        return self.cov_white[:, 1, 1]


#: Boxes fitted at once by :func:`fit_boxes` (their temporaries: ~2 kB each).
FIT_BLOCK_BOXES = 4096


def fit_boxes(camera: Camera, ba: BoxArrays, width_m: np.ndarray, width_std_m: np.ndarray,
              prior_h: np.ndarray, prior_h_std: np.ndarray, length_m: np.ndarray,
              config: RangingConfig, *, use_ground: bool = True, use_height: bool = True,
              length_std_m: np.ndarray | None = None,
              pitch_noise_inflation: np.ndarray | float = 1.0,
              road_height_std_m: np.ndarray | None = None, iterations: int = 12) -> BoxFit:
    """Fuse the cues of each box into a position by weighted least squares.

    The unknowns per box are (log range, lateral, width, height); the residuals are the
    observed minus the predicted box edges, each divided by its pixel noise, plus the size
    priors. Minimising them is the inverse-variance fusion of the ground cue (bottom edge vs
    horizon: Z = f H / (y_bottom - y_horizon) for a level camera), the width cue
    (Z = f W / w_px) and the height cue, with the noise of each propagated from pixels to
    metres by the Jacobian, so the ground cue's range error grows as Z^2 / (f H) per pixel
    (Hartley & Zisserman, Multiple View Geometry, 2nd ed., ch. 5 on first-order error
    propagation). Log range keeps the range positive and the model nearly linear (edges scale
    as 1/Z).

    Parameters
    ----------
    camera : Camera
        The camera with the pitch to use.
    ba : BoxArrays
        Boxes and their cut flags.
    width_m, width_std_m, prior_h, prior_h_std, length_m : ndarray
        Size prior of each box's vehicle [m].
    config : RangingConfig
        Noise settings.
    use_ground, use_height : bool
        Switch the ground and height cues off (for the horizon estimate from widths).
    length_std_m : ndarray, optional
        Spread of the length prior [m]; the length is then a fifth unknown (it sets how much
        of a laterally offset vehicle's side shows). None keeps ``length_m`` fixed.
    pitch_noise_inflation : ndarray or float
        Factor on the body-pitch share of the frame-to-frame variance (``cov_white``) for a
        filter that takes it as white (see :func:`colored_noise_factor`).
    road_height_std_m : ndarray, optional
        Per-box spread of the road height under the vehicle [m]; None takes the config's.

    Returns
    -------
    BoxFit
        ``valid`` is False where the cues left the range unobservable.
    """
    n = len(ba.x1)
    if n > FIT_BLOCK_BOXES:
        # Each box is fitted on its own: in blocks, so the fit's temporaries stay the same
        # size however long the video (29,000 boxes at once took 60 MB more; issue 16).
        def part(a, sl):
            return a[sl] if isinstance(a, np.ndarray) else a

        fits = [fit_boxes(camera, BoxArrays(*(getattr(ba, k)[sl] for k in ba.__dataclass_fields__)),
                          width_m[sl], width_std_m[sl], prior_h[sl], prior_h_std[sl],
                          length_m[sl], config, use_ground=use_ground, use_height=use_height,
                          length_std_m=part(length_std_m, sl),
                          pitch_noise_inflation=part(pitch_noise_inflation, sl),
                          road_height_std_m=part(road_height_std_m, sl), iterations=iterations)
                for sl in (slice(i, i + FIT_BLOCK_BOXES) for i in range(0, n, FIT_BLOCK_BOXES))]
        return BoxFit(*(np.concatenate([getattr(f, k) for f in fits])
                        for k in BoxFit.__dataclass_fields__))
    bw = np.maximum(ba.x2 - ba.x1, 1.0)
    bh = np.maximum(ba.y2 - ba.y1, 1.0)
    horizon = camera.horizon_y_px()
    jitter_px = camera.fy * math.tan(math.radians(config.horizon_jitter_deg))
    sig_u = config.edge_noise_px + config.edge_noise_frac * bw
    pix_v = config.edge_noise_px + config.edge_noise_frac * bh
    ground_ok = (~ba.cut_bottom) & (ba.y2 > horizon + config.min_ground_margin_px)
    if not use_ground:
        ground_ok = np.zeros(n, dtype=bool)
    width_ok = ~(ba.cut_left | ba.cut_right)
    height_ok = (~(ba.cut_top | ba.cut_bottom)) & use_height
    obs = np.stack([ba.x1, ba.y1, ba.x2, ba.y2], axis=1)

    # Initial guess: ground cue where usable, else width cue; lateral from the centre column.
    f = camera.fx
    rng0 = f * width_m / bw
    if ground_ok.any():
        pts, ok = camera.pixel_to_ground(np.column_stack(((ba.x1 + ba.x2) / 2, ba.y2)))
        g = ground_ok & ok & np.isfinite(pts[:, 0]) & (pts[:, 0] > 0.5)
        rng0 = np.where(g, pts[:, 0], rng0)
    rng0 = np.clip(rng0, 1.0, 3 * config.max_range_m)
    # A road dz higher than the plane moves a vehicle's bottom edge by f dz / Z pixels; Z is
    # only known after the fit, so take the first guess (the ground cue's own range where it
    # is usable, not the width cue's: a turned vehicle's wide box would say "near" and so
    # blur the very cue that has to range it).
    road_std = config.road_height_std_m if road_height_std_m is None else road_height_std_m
    rays = camera.pixel_rays_veh(np.column_stack(((ba.x1 + ba.x2) / 2, np.full(n, horizon))))
    lat0 = rays[:, 1] / np.maximum(rays[:, 0], 1e-6) * (rng0 + length_m / 2)
    # Away from the ego's lane the ego's road plane says less about the ground: cross-fall
    # (2-3 % from the crown), gutters, kerbs and parking strips.
    beyond = np.maximum(np.abs(lat0) - config.lane_width_m / 2, 0.0)
    road_std = np.hypot(road_std, config.road_height_std_per_lateral_m * beyond)
    # The body's pitch jitter and the road's height under the vehicle move the top and the
    # bottom edge together: one vertical offset per box [px], a sixth unknown with that
    # prior, and each edge keeps only its own pixel noise. The box height (top to bottom)
    # is then a clean cue against the vehicle's height, the bottom edge against the horizon
    # is as blurred by the offset as before (Z = f H / (y_bottom - y_horizon)).
    road_px = camera.fy * road_std / rng0
    sig_off = np.hypot(jitter_px, road_px)
    sig = np.stack([sig_u, pix_v, sig_u, pix_v], axis=1)
    # The top edge is a cue only with the bottom edge beside it (box height against the
    # vehicle's height): a car's roof sits near the camera's own height, i.e. near the
    # horizon, so alone it would say little about range.
    use = np.stack([~ba.cut_left, height_ok & ground_ok, ~ba.cut_right, ground_ok], axis=1)
    if length_std_m is None:
        length_std_m = np.full(n, 1e-4)
    # Width: what the box says at the ground cue's range (at least the prior), so that the
    # reweighting below sees a turned vehicle's wide box from the first step on rather than
    # being pulled by it towards the camera first (a redescending prior needs a fair start).
    w_init = width_m.copy()
    if ground_ok.any():
        w_init = np.where(g, np.clip(bw * rng0 / f, width_m, 3.0 * width_m), width_m)
    theta = np.column_stack((np.log(rng0), lat0, w_init, prior_h, length_m, np.zeros(n)))
    prior_mean = np.column_stack((width_m, prior_h, length_m, np.zeros(n)))
    prior_std = np.column_stack((width_std_m, prior_h_std, length_std_m, sig_off))
    n_par = 6
    steps = np.full(n_par, 1e-3)

    # Apparent width is heavy-tailed upwards: a vehicle turned away from the ego axis (at a
    # junction, parked across or at an angle, changing lanes) shows part of its side, and its
    # box is W cos(yaw) + L sin(yaw) wide, never narrower than its rear. So a width far above
    # the class prior is more likely a turned vehicle than a wide one: its width prior is
    # Cauchy beyond ``config.width_tail_sigmas`` (iteratively reweighted), and the range
    # then rests on the ground cue instead of a box width inflated by the vehicle's side.
    w_prior_weight = np.ones(n)
    c_tail = config.width_tail_sigmas

    def update_weights(th: np.ndarray, i: np.ndarray) -> None:
        s = (th[:, 2] - prior_mean[i, 0]) / prior_std[i, 0]
        w_prior_weight[i] = np.where(s > 0, 1.0 / (1.0 + (s / c_tail) ** 2), 1.0)

    def residuals(th: np.ndarray, i: np.ndarray) -> np.ndarray:
        pred = _predict_edges(camera, np.exp(th[:, 0]), th[:, 1], th[:, 2], th[:, 3],
                              th[:, 4])
        pred[:, 1] += th[:, 5]
        pred[:, 3] += th[:, 5]
        r_edges = np.where(use[i], (obs[i] - pred) / sig[i], 0.0)
        r_prior = (prior_mean[i] - th[:, 2:6]) / prior_std[i]
        r_prior[:, 0] *= np.sqrt(w_prior_weight[i])
        return np.nan_to_num(np.concatenate([r_edges, r_prior], axis=1), nan=0.0)

    def jacobian(th: np.ndarray, i: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        r0 = residuals(th, i)
        jac = np.zeros((len(i), 4 + 4, n_par))
        for k in range(n_par):
            th_k = th.copy()
            th_k[:, k] += steps[k]
            jac[:, :, k] = -(residuals(th_k, i) - r0) / steps[k]
        return r0, jac

    # Gauss-Newton; boxes leave the active set once converged (most need 3-5 steps).
    active = np.arange(n)
    for _ in range(iterations):
        if active.size == 0:
            break
        if math.isfinite(c_tail):
            update_weights(theta[active], active)
        r0, jac = jacobian(theta[active], active)
        jtj = np.einsum("nik,nil->nkl", jac, jac) + 1e-9 * np.eye(n_par)
        jtr = np.einsum("nik,ni->nk", jac, r0)
        delta = np.linalg.solve(jtj, jtr[..., None])[..., 0]
        delta[:, 0] = np.clip(delta[:, 0], -0.5, 0.5)
        th = theta[active] + delta
        th[:, 0] = np.clip(th[:, 0], 0.0, math.log(3 * config.max_range_m))
        th[:, 2:5] = np.maximum(th[:, 2:5], 0.2)
        theta[active] = th
        active = active[(np.abs(delta[:, 0]) > 1e-5) | (np.abs(delta[:, 1]) > 1e-4)]
    _, jac = jacobian(theta, np.arange(n))
    jtj = np.einsum("nik,nil->nkl", jac, jac) + 1e-9 * np.eye(n_par)
    cov = np.linalg.inv(jtj)
    # Frame-to-frame (white) part: pixel noise and body pitch jitter only. The vehicle's size
    # and the road height under it change slowly, so their errors are common to all frames
    # of a track: they scale the range but do not disturb its rate, and a filter that took
    # them for white noise would trust the measurements too little and lag behind braking.
    # Sandwich form: the same estimate, its covariance under the white noise alone,
    # cov (J^T D J) cov with D the white share of each (scaled) residual's variance.
    # The body pitch is not white: it lasts about half a second, so it enters with the
    # inflation factor that gives its slow part the right weight in the filter.
    d = np.ones((n, 4 + 4))
    d[:, 4:7] = 0.0  # size priors: common to the track
    d[:, 7] = pitch_noise_inflation * jitter_px ** 2 / sig_off ** 2  # road height: common
    cov_white = cov @ np.einsum("nik,ni,nil->nkl", jac, d, jac) @ cov
    rng = np.exp(theta[:, 0])
    # Unobservable range: the log-range spread stays near what the priors alone allow, or
    # the fit ran onto its range bounds (weak cues that disagree have no interior optimum).
    on_bound = (theta[:, 0] <= 1e-6) | (theta[:, 0] >= math.log(3 * config.max_range_m) - 1e-6)
    valid = (np.sqrt(np.maximum(cov[:, 0, 0], 0)) < 0.5) & np.isfinite(rng) & ~on_bound
    return BoxFit(rng, theta[:, 1], theta[:, 2], cov, cov_white, ground_ok, width_ok, valid,
                  theta[:, 4], theta[:, 3])


def colored_noise_factor(dt_s: float, correlation_s: float) -> float:
    """Factor on the variance of a first-order Markov noise (correlation time
    ``correlation_s``) sampled every ``dt_s``, such that white noise of that variance has the
    same low-frequency power: (1 + rho) / (1 - rho) with rho = exp(-dt / tau). A smoother that
    averages over many frames sees correlated errors average out that much more slowly
    (Bar-Shalom et al. 2001, sec. 8.2 on coloured measurement noise)."""
    if not (dt_s > 0 and correlation_s > 0):
        return 1.0
    rho = math.exp(-dt_s / correlation_s)
    return (1.0 + rho) / (1.0 - rho)


# --------------------------------------------------------------------------- horizon


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

    For each well-seen car (box not cut, at least 20 px high, width cue range 5-60 m, within
    ``config.horizon_vehicle_max_lateral_m`` of the camera's axis) the
    width cue alone gives its range; the row where that range meets the road, compared with
    the observed bottom edge, says how far the true horizon lies from the assumed one (a pitch
    change shifts all rows near the image centre alike). The median over tracks of each
    track's median offset is robust to a few odd boxes and gives every vehicle one vote.

    Returns
    -------
    (horizon_y_px or None, one-sigma [px], number of tracks used)
    """
    ba = ba or BoxArrays.from_boxes(boxes, camera, config.border_margin_px)
    cat = np.array([b.category for b in boxes])
    sel = ((cat == "car") & ~(ba.cut_left | ba.cut_right | ba.cut_top | ba.cut_bottom)
           & (ba.y2 - ba.y1 >= 20) & (ba.x2 - ba.x1 >= 12))
    if sel.sum() == 0:
        return None, math.inf, 0
    idx = np.flatnonzero(sel)
    sub = BoxArrays(*(getattr(ba, k)[idx] for k in ba.__dataclass_fields__))
    p = config.prior_for("car")
    ones = np.ones(len(idx))
    fit = fit_boxes(camera, sub, p.width_m * ones, p.width_std_m * ones, p.height_m * ones,
                    p.height_std_m * ones, p.length_m * ones, config, use_ground=False,
                    use_height=False, length_std_m=p.length_std_m * ones)
    pred = _predict_edges(camera, fit.range_m, fit.lateral_m, fit.width_m, p.height_m * ones,
                          fit.length_m)
    offset = sub.y2 - pred[:, 3]
    # Only vehicles on the ego's road (its lane and the next ones): parked cars and those
    # beyond a kerb stand on ground that is rarely level with the ego's lane (a crowned road
    # falls 2-3 % to the gutter, parking strips and kerbs add 0.1-0.15 m). In KITTI raw 0001
    # they put the horizon at 180 px where the lane markings and the calibration say 173.
    near = np.abs(fit.lateral_m) < config.horizon_vehicle_max_lateral_m
    keep = fit.valid & (fit.range_m > 5) & (fit.range_m < 60) & np.isfinite(offset) & near
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
    gap_px = camera.fy * camera.height_m / 20.0
    per_vehicle = math.hypot(gap_px * p.width_std_m / p.width_m,
                             camera.fy * config.road_height_std_m / 20.0)
    mad = 1.4826 * float(np.median(np.abs(per_track - med))) if n > 2 else 10.0
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
    if hints.size >= 3:
        h_lane = float(np.median(hints))
        mad = 1.4826 * float(np.median(np.abs(hints - h_lane)))
        std_lane = max(mad, config.lane_horizon_std_px) / math.sqrt(hints.size) + 1.0
        estimates.append((h_lane, std_lane, "lane markings"))
        notes.append(Note.estimate(f"lane markings: horizon {h_lane:.1f} px from {hints.size} "
                                   "frames"))
    h_veh, std_veh, n_veh = horizon_from_vehicles(boxes, camera, config)
    if h_veh is not None and n_veh >= 3:
        # One iteration at the new pitch: the width cue itself depends slightly on pitch.
        cam2 = camera.with_pitch(pitch_for_horizon(camera, h_veh))
        h2, std2, n2 = horizon_from_vehicles(boxes, cam2, config)
        if h2 is not None:
            h_veh, std_veh, n_veh = h2, std2, n2
        estimates.append((h_veh, std_veh, "vehicle consistency"))
        notes.append(Note.estimate(f"vehicle consistency: horizon {h_veh:.1f} px from {n_veh} "
                                   "vehicles"))
    if len(estimates) > 2 and abs(estimates[1][0] - estimates[2][0]) > 3 * math.hypot(
            estimates[1][1], estimates[2][1]):
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


# --------------------------------------------------------------------------- Kalman + RTS


@dataclass
class SmoothedTrack:
    """Smoothed states of one track at its measurement times."""

    range_m: np.ndarray
    range_rate_mps: np.ndarray
    lateral_m: np.ndarray
    lateral_rate_mps: np.ndarray
    range_std_m: np.ndarray
    accel_noise_mps2: float
    log_likelihood: float


def _kf_rts_cv(t_s: list[float], z: list[float], r: list[float], valid: list[bool], q: float,
               v0_std: float, inverse: bool = False
               ) -> tuple[list[float], list[float], list[float], float]:
    """Constant-velocity Kalman filter + RTS smoother on one axis, in plain floats.

    The 2x2 algebra is written out: numpy's per-call overhead on 2x2 matrices would cost ten
    times more than the arithmetic on a long video. Process noise is the discretised
    continuous white-noise acceleration (Bar-Shalom, Li & Kirubarajan, Estimation with
    Applications to Tracking and Navigation, 2001, sec. 6.2.2): Q = q [[dt^3/3, dt^2/2],
    [dt^2/2, dt]]. The smoother is Rauch, Tung & Striebel (AIAA J. 3(8), 1965).

    With ``inverse`` the measurement variance r (given at the reading z) is moved to the
    predicted range x as r (x/z)^4. A monocular range comes from pixel sizes and offsets,
    so its error is additive in 1/z: its variance grows as z^4, and a variance evaluated at
    the noisy reading itself gives the short readings of a far track more weight than the
    long ones, which pulled far tracks 10-15 % short and their range rates towards zero.
    (An extended Kalman update on 1/z does the same but breaks down for a vehicle passing
    alongside, whose rear range crosses zero.)

    Returns smoothed position, rate, position std and the innovation log-likelihood.
    """
    n = len(t_s)
    first = valid.index(True) if True in valid else 0
    x, v = z[first], 0.0
    pxx, pxv, pvv = r[first] * 1e4 + 1e4, 0.0, v0_std ** 2
    # Filtered and predicted states/covariances, needed by the backward pass.
    fx, fv, fpxx, fpxv, fpvv = [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n
    ppxx, ppxv, ppvv, dts = [0.0] * n, [0.0] * n, [0.0] * n, [0.0] * n
    px_, pv_ = [0.0] * n, [0.0] * n
    loglik = 0.0
    for k in range(n):
        dt = t_s[k] - t_s[k - 1] if k else 0.0
        dts[k] = dt
        # predict: F = [[1, dt], [0, 1]]
        x = x + dt * v
        pxx, pxv = (pxx + 2 * dt * pxv + dt * dt * pvv + q * dt ** 3 / 3,
                    pxv + dt * pvv + q * dt * dt / 2)
        pvv = pvv + q * dt
        px_[k], pv_[k], ppxx[k], ppxv[k], ppvv[k] = x, v, pxx, pxv, pvv
        if valid[k]:
            rk = r[k]
            if inverse and k > first and z[k] > 0 and x > 0:
                # The variance at the predicted range, not at the noisy reading.
                rk *= min(max((x / z[k]) ** 4, 1 / 16), 16.0)
            innov = z[k] - x
            s = pxx + rk
            nis = innov * innov / s
            if nis > 16.0 and k > first:
                # Robust: an innovation beyond 4 sigma inflates that frame's noise until it
                # sits at 4 sigma, so one bad box does not throw the track.
                s = pxx + rk * nis / 16.0
            elif k > first:
                loglik -= 0.5 * (nis + math.log(s))
            kx, kv = pxx / s, pxv / s
            x, v = x + kx * innov, v + kv * innov
            pxx, pxv, pvv = pxx - kx * pxx, pxv - kx * pxv, pvv - kv * pxv
        fx[k], fv[k], fpxx[k], fpxv[k], fpvv[k] = x, v, pxx, pxv, pvv
    sx, sv, sxx = fx[:], fv[:], fpxx[:]
    sxv, svv = fpxv[:], fpvv[:]
    for k in range(n - 2, -1, -1):
        dt = dts[k + 1]
        # C = P_f F^T P_p^-1 with the 2x2 inverse written out.
        a, b, d = ppxx[k + 1], ppxv[k + 1], ppvv[k + 1]
        det = a * d - b * b
        if det <= 0:
            continue
        m11, m12 = fpxx[k] + dt * fpxv[k], fpxv[k]  # P_f F^T, rows (x, v)
        m21, m22 = fpxv[k] + dt * fpvv[k], fpvv[k]
        c11, c12 = (m11 * d - m12 * b) / det, (m12 * a - m11 * b) / det
        c21, c22 = (m21 * d - m22 * b) / det, (m22 * a - m21 * b) / det
        ex, ev = sx[k + 1] - px_[k + 1], sv[k + 1] - pv_[k + 1]
        sx[k] = fx[k] + c11 * ex + c12 * ev
        sv[k] = fv[k] + c21 * ex + c22 * ev
        # P_s = P_f + C (P_s,k+1 - P_p,k+1) C^T
        dxx, dxv, dvv = sxx[k + 1] - a, sxv[k + 1] - b, svv[k + 1] - d
        t11, t12 = c11 * dxx + c12 * dxv, c11 * dxv + c12 * dvv
        t21, t22 = c21 * dxx + c22 * dxv, c21 * dxv + c22 * dvv
        sxx[k] = fpxx[k] + t11 * c11 + t12 * c12
        sxv[k] = fpxv[k] + t11 * c21 + t12 * c22
        svv[k] = fpvv[k] + t21 * c21 + t22 * c22
    return sx, sv, [math.sqrt(max(p, 0.0)) for p in sxx], loglik


def smooth_track(t_s: np.ndarray, z: np.ndarray, r: np.ndarray, valid: np.ndarray,
                 q_long: float, q_lat: float, v0_std: float, inverse: bool = False
                 ) -> SmoothedTrack:
    """Constant-velocity Kalman filter and RTS smoother for one track.

    State (range, range rate) and (lateral, lateral rate), filtered as two independent axes
    (the range-lateral correlation of one box's fit is small next to the motion); irregular
    time steps and frames without a valid measurement (only predicted) are handled;
    innovations beyond 4 sigma are down-weighted.

    Parameters
    ----------
    t_s : (N,) times [s], non-decreasing
    z : (N, 2) measured range and lateral [m]
    r : (N, 2, 2) measurement covariances [m^2] (the diagonal is used)
    valid : (N,) whether each measurement exists
    q_long, q_lat : white-noise acceleration spectral densities [m^2/s^3]
    v0_std : prior spread of the range rate [m/s] (a quarter of it for the lateral rate)
    inverse : update the range in inverse range (see :func:`_kf_rts_cv`)
    """
    t = [float(v) for v in t_s]
    ok = [bool(v) for v in valid]
    zx = [float(v) if np.isfinite(v) else 0.0 for v in z[:, 0]]
    zy = [float(v) if np.isfinite(v) else 0.0 for v in z[:, 1]]
    rx = [max(float(v), 1e-6) if np.isfinite(v) else 1e6 for v in r[:, 0, 0]]
    ry = [max(float(v), 1e-6) if np.isfinite(v) else 1e6 for v in r[:, 1, 1]]
    x, vx, sdx, ll = _kf_rts_cv(t, zx, rx, ok, q_long, v0_std, inverse=inverse)
    y, vy, _, _ = _kf_rts_cv(t, zy, ry, ok, q_lat, v0_std / 4)
    return SmoothedTrack(np.array(x), np.array(vx), np.array(y), np.array(vy), np.array(sdx),
                         q_long, ll)


def smooth_track_adaptive(t_s: np.ndarray, z: np.ndarray, r: np.ndarray, valid: np.ndarray,
                          config: RangingConfig) -> SmoothedTrack:
    """Run :func:`smooth_track` for each candidate acceleration noise and keep the one whose
    range innovations are the most likely (a calm follower and a hard braker need different
    ones: maximum-likelihood choice of the process noise, as in adaptive Kalman filtering),
    preferring the calmer one unless the likelihood clearly says otherwise."""
    fits = [smooth_track(t_s, z, r, valid, q, config.lateral_accel_noise_mps2,
                         config.initial_range_rate_std_mps, inverse=config.inverse_range_update)
            for q in sorted(config.accel_noise_grid_mps2)]
    top = max(f.log_likelihood for f in fits)
    return next(f for f in fits if f.log_likelihood >= top - config.accel_noise_margin_loglik)


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
                         & (loose.range_m < 60))
    if sel.size == 0:
        return out
    sub = BoxArrays(*(getattr(ba, k)[sel] for k in ba.__dataclass_fields__))
    tiny = np.full(sel.size, 1e-3)
    wfit = fit_boxes(camera, sub, width_m[sel], tiny, height_m[sel], tiny, length_m[sel],
                     config, use_ground=False, use_height=False,
                     length_std_m=None if length_std_m is None else length_std_m[sel])
    pred = _predict_edges(camera, wfit.range_m, wfit.lateral_m, width_m[sel], height_m[sel],
                          wfit.length_m)
    offset = sub.y2 - pred[:, 3]
    # Noise of one offset: the width cue's frame-to-frame range noise seen as rows
    # (d row / d ln Z = -(row - horizon)), plus the bottom edge's own pixel noise.
    gap = np.maximum(sub.y2 - camera.horizon_y_px(), 1.0)
    var = (gap ** 2) * wfit.cov_white[:, 0, 0] + (
        config.edge_noise_px + config.edge_noise_frac * (sub.y2 - sub.y1)) ** 2
    ok = np.isfinite(offset) & np.isfinite(var) & wfit.valid
    tids = np.array([boxes[i].track_id for i in sel])
    for tid in np.unique(tids[ok]):
        m = ok & (tids == tid)
        if m.sum() < 5:  # too short to know its constant part
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
                                   config.pitch_accel_noise_px, jitter_px * 10)
    by_frame = dict(zip(all_frames, smoothed, strict=True))
    out[:] = [by_frame[b.frame] for b in boxes]
    return np.clip(out, -5 * jitter_px, 5 * jitter_px)


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
        sec_per_frame = 0.1
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
                 config: RangingConfig | None = None) -> RangingResult:
    """Range, lateral offset and range rate of every tracked box.

    Parameters
    ----------
    boxes : list of TrackedBox
        Tracker output (any order); a track with one box is ranged from that frame alone.
    camera : Camera
        The camera; its pitch is only a prior for the horizon estimate.
    horizon_hints_px : list of float, optional
        Per-frame horizon rows from lane markings (:class:`vid2sim.detect.lanes.HorizonEstimator`).
    horizon_hint_frames : list of int, optional
        The frame of each hint: with them, each frame's horizon follows the hints about it
        (:func:`lane_horizon_offsets`); without, all frames share the hints' median.
    config : RangingConfig, optional
        Priors and noise settings.

    Returns
    -------
    RangingResult
        One :class:`RangedBox` per input box in the input order; lead and lane assigned.
    """
    config = config or RangingConfig()
    warnings: list[Note] = []
    if not boxes:
        h = camera.horizon_y_px()
        return RangingResult([], camera.pitch_deg, h, "camera file", {},
                             [Note.warning("no boxes to range")])
    unknown = sorted({b.category for b in boxes} - set(config.priors))
    if unknown:
        warnings.append(Note.warning(f"no size prior for {', '.join(unknown)}: used the car "
                                     "prior"))

    horizon, source, notes = choose_horizon(boxes, camera, config, horizon_hints_px)
    warnings.extend(n for n in notes if n.kind is NoteKind.WARNING)
    pitch = pitch_for_horizon(camera, horizon)
    cam = camera.with_pitch(pitch)
    ba = BoxArrays.from_boxes(boxes, cam, config.border_margin_px)
    frame_box = np.array([b.frame for b in boxes])
    t_box = np.array([b.t_s for b in boxes], dtype=float)
    if horizon_hint_frames is not None and horizon_hints_px is not None:
        hf = np.asarray(horizon_hint_frames, dtype=float)
        hr = np.asarray(horizon_hints_px, dtype=float)
        ok = np.isfinite(hr) & np.isfinite(hf)
        slow_px = lane_horizon_offsets(frame_box, t_box, hf[ok], hr[ok], horizon, config)
        if np.any(slow_px != 0):
            ba = BoxArrays(ba.x1, ba.y1 - slow_px, ba.x2, ba.y2 - slow_px, ba.cut_left,
                           ba.cut_right, ba.cut_top, ba.cut_bottom)
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
    loose = fit_boxes(cam, ba, w0, np.full(len(boxes), 1.0), h0, np.full(len(boxes), 1.0),
                      l0, config, length_std_m=l0_std)
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
        if w_est < prior_w - 4.0 * prior_sd:
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
            ba = BoxArrays(ba.x1, ba.y1 - frame_offset_px, ba.x2, ba.y2 - frame_offset_px,
                           ba.cut_left, ba.cut_right, ba.cut_top, ba.cut_bottom)
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

    # 3) Per-track Kalman filter + RTS smoother.
    n = len(boxes)
    out_range = np.full(n, np.nan)
    out_rate = np.full(n, np.nan)
    out_lat = np.full(n, np.nan)
    out_lat_rate = np.full(n, np.nan)
    out_std = np.full(n, np.nan)
    for members in np.split(order, splits):
        members = members[np.lexsort((frame_box[members], t_box[members]))]
        if not fit.valid[members].any():
            # Nothing but weak cues (e.g. a car alongside, cut at the bottom and a side):
            # report the single-frame fit with its large spread rather than nothing.
            out_range[members] = fit.range_m[members]
            out_lat[members] = fit.lateral_m[members]
            out_std[members] = np.sqrt(np.maximum(fit.range_var_m2[members], 0))
            continue
        z = np.column_stack((fit.range_m[members], fit.lateral_m[members]))
        r = np.zeros((len(members), 2, 2))
        # The filter sees only the frame-to-frame noise; the common part (size prior, road
        # height) is added back to the reported spread.
        r[:, 0, 0] = fit.range_white_var_m2[members]
        r[:, 1, 1] = fit.lateral_white_var_m2[members]
        common = np.maximum(fit.range_var_m2[members] - fit.range_white_var_m2[members], 0)
        sm = smooth_track_adaptive(t_box[members], z, r, fit.valid[members], config)
        out_range[members] = sm.range_m
        out_lat[members] = sm.lateral_m
        out_std[members] = np.sqrt(sm.range_std_m ** 2 + common)
        if len(members) > 1:
            out_rate[members] = sm.range_rate_mps
            out_lat_rate[members] = sm.lateral_rate_mps

    lanes, is_lead = assign_lanes_and_lead(boxes, out_range, out_lat, config)
    ranged = [
        RangedBox(frame=b.frame, t_s=b.t_s, track_id=b.track_id, category=b.category,
                  score=b.score, x1=b.x1, y1=b.y1, x2=b.x2, y2=b.y2,
                  range_m=float(out_range[i]), lateral_m=float(out_lat[i]),
                  range_rate_mps=float(out_rate[i]), range_std_m=float(out_std[i]),
                  is_lead=bool(is_lead[i]), width_m=float(w_track[i]),
                  lateral_rate_mps=float(out_lat_rate[i]), lane=lanes[i])
        for i, b in enumerate(boxes)]
    return RangingResult(ranged, pitch, horizon, source, width_by_track, warnings + [
        n for n in notes if n.kind is not NoteKind.WARNING])
