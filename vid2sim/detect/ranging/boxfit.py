"""Single-frame box fit: the cues of each box (ground, width, height) fused into a position.

Frames: vehicle frame x forward, y left, z up, origin on the road below the camera; range_m
is the x of the vehicle's rear, lateral_m the y of its centre.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.core.outline import OUTLINE_COLUMNS, outline_boxes, shape_matrix_for
from vid2sim.core.records import TrackedBox
from vid2sim.detect.ranging.config import RangingConfig

# Solver settings of :func:`fit_boxes` (numerical choices, not properties of the world).
# A ground point nearer than this [m] is a bottom edge at or below the camera's own bumper:
# no starting range from it.
MIN_GROUND_POINT_M = 0.5
# Starting ranges are clipped to [1 m, RANGE_BOUND_FACTOR * max_range_m]; the fit itself runs
# between 1 m (log range 0) and that far end, and a fit on a bound is not valid.
MIN_INITIAL_RANGE_M = 1.0
RANGE_BOUND_FACTOR = 3.0
# A starting width is at most this many times the prior (a box far wider is a turned car).
MAX_WIDTH_INIT_FACTOR = 3.0
# Finite-difference step of the Jacobian, in the parameters' units (log range, metres, px).
FD_STEP = 1e-3
# Largest Gauss-Newton step in log range (a factor 1.65): keeps a far start from jumping past
# the camera.
MAX_LOG_RANGE_STEP = 0.5
# Sizes stay above this [m] (a width or height of zero would make the edges degenerate).
MIN_SIZE_M = 0.2
# A box has converged when its step is below these (log range: 10 ppm; lateral: 0.1 mm).
CONVERGED_LOG_RANGE = 1e-5
CONVERGED_LATERAL_M = 1e-4
# Length spread [m] that holds the length at its prior when no spread is given.
FIXED_LENGTH_STD_M = 1e-4
# The ground-contact check takes the width cue's farthest plausible range: the width prior
# this many sigmas wider than its mean (2: one vehicle in forty is wider).
GROUND_CHECK_WIDTH_SIGMAS = 2.0
# Fixed-point steps of that range (the box width's 1/range law converges in 3-4).
GROUND_CHECK_ITERATIONS = 5
_WIDEST = OUTLINE_COLUMNS["widest_m"]
_CONTACT = OUTLINE_COLUMNS["contact_m"]


@dataclass
class BoxArrays:
    """Boxes as columns (pixels) with the cut flags of each edge and each box's outline.

    ``outline`` holds one row of :func:`vid2sim.core.outline.shape_matrix` per box: the shape of
    its class (where the tyres, the widest section and the mirrors lie; see
    :mod:`vid2sim.core.outline`).
    """

    x1: np.ndarray
    y1: np.ndarray
    x2: np.ndarray
    y2: np.ndarray
    cut_left: np.ndarray
    cut_right: np.ndarray
    cut_top: np.ndarray
    cut_bottom: np.ndarray
    outline: np.ndarray

    @classmethod
    def from_boxes(cls, boxes: list[TrackedBox], camera: Camera, config: RangingConfig
                   ) -> BoxArrays:
        """Boxes of the tracker with the edges that the image border cuts.

        An edge counts as cut when it lies within ``config.border_margin_px`` of the border
        (the tracker's margin: a detector stops the box of a cut vehicle a few pixels short
        of the border) or within ``config.border_noise_sigmas`` of its own edge noise, so
        that a near lead's last rows above the border never pass for its ground contact.
        """
        a = np.array([(b.x1, b.y1, b.x2, b.y2) for b in boxes], dtype=float).reshape(-1, 4)
        w, h = camera.image_width - 1, camera.image_height - 1
        k = config.border_noise_sigmas
        mu = np.maximum(config.border_margin_px,
                        k * (config.edge_noise_px + config.edge_noise_frac * (a[:, 2] - a[:, 0])))
        mv = np.maximum(config.border_margin_px,
                        k * (config.edge_noise_px + config.edge_noise_frac * (a[:, 3] - a[:, 1])))
        shapes = shape_matrix_for([b.category for b in boxes], config.outlines)
        return cls(a[:, 0], a[:, 1], a[:, 2], a[:, 3], a[:, 0] <= mu, a[:, 2] >= w - mu,
                   a[:, 1] <= mv, a[:, 3] >= h - mv, shapes)

    def subset(self, index: np.ndarray) -> BoxArrays:
        """The boxes at ``index`` (integer or boolean)."""
        return BoxArrays(*(getattr(self, k)[index] for k in self.__dataclass_fields__))

    def shifted(self, rows_px: np.ndarray) -> BoxArrays:
        """The boxes moved up by ``rows_px`` (a horizon correction, down positive)."""
        return replace(self, y1=self.y1 - rows_px, y2=self.y2 - rows_px)


def predict_edges(camera: Camera, x_m: np.ndarray, y_m: np.ndarray, w_m: np.ndarray,
                  h_m: np.ndarray, l_m: np.ndarray, outline: np.ndarray,
                  z_m: np.ndarray | float = 0.0) -> np.ndarray:
    """(N, 4) pixel box (u1, v1, u2, v2) of vehicles whose rear is at range ``x_m``, centre
    at lateral ``y_m``, aligned with the ego axis and standing on ground ``z_m`` above the
    ego's road plane: the hull of their outlines (``outline``: rows of
    :func:`vid2sim.core.outline.shape_matrix`)."""
    return outline_boxes(camera, x_m, y_m, w_m, h_m, l_m, outline, z_m=z_m)


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
    def width_var_m2(self) -> np.ndarray:
        return self.cov[:, 2, 2]

    @property
    def height_var_m2(self) -> np.ndarray:
        return self.cov[:, 3, 3]

    @property
    def range_white_var_m2(self) -> np.ndarray:
        return self.cov_white[:, 0, 0] * self.range_m ** 2

    @property
    def lateral_white_var_m2(self) -> np.ndarray:
        return self.cov_white[:, 1, 1]


#: Boxes fitted at once by :func:`fit_boxes` (their temporaries: ~2 kB each), so that its
#: memory is the same however long the video (29,000 boxes at once took 60 MB more; issue 16).
FIT_BLOCK_BOXES = 4096
N_PARAMS = 6  # log range, lateral, width, height, length, row offset


@dataclass
class _FitProblem:
    """The weighted least-squares problem of :func:`fit_boxes`, one row per box: observed
    edges, their noise and which count, the priors of (width, height, length, row offset),
    the ground height under each box, the start and the noise shares the covariance needs."""

    obs: np.ndarray
    sig: np.ndarray
    use: np.ndarray
    outline: np.ndarray
    prior_mean: np.ndarray
    prior_std: np.ndarray
    road_z: np.ndarray
    theta0: np.ndarray
    sig_off: np.ndarray
    jitter_px: float
    ground_ok: np.ndarray
    width_ok: np.ndarray
    max_range_m: float


def fit_boxes(camera: Camera, ba: BoxArrays, width_m: np.ndarray, width_std_m: np.ndarray,
              prior_h: np.ndarray, prior_h_std: np.ndarray, length_m: np.ndarray,
              config: RangingConfig, *, use_ground: bool = True, use_height: bool = True,
              length_std_m: np.ndarray | None = None,
              pitch_noise_inflation: np.ndarray | float = 1.0,
              road_height_std_m: np.ndarray | None = None,
              ground_allowed: np.ndarray | None = None, road_z_m: np.ndarray | None = None,
              iterations: int = 12) -> BoxFit:
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
    ground_allowed : ndarray, optional
        Where the ground cue may be used (e.g. another fit's ``ground_ok``); given, it replaces
        the check of the contact row against the width cue (which needs a width prior).
    road_z_m : ndarray, optional
        Height of the ground under each vehicle above the ego's road plane [m] (the road
        surface model of :mod:`vid2sim.detect.ranging.surface`); None: the ego's plane.

    Returns
    -------
    BoxFit
        ``valid`` is False where the cues left the range unobservable.
    """
    n = len(ba.x1)
    if n > FIT_BLOCK_BOXES:
        return _fit_in_blocks(camera, ba, width_m, width_std_m, prior_h, prior_h_std, length_m,
                              config, use_ground=use_ground, use_height=use_height,
                              length_std_m=length_std_m,
                              pitch_noise_inflation=pitch_noise_inflation,
                              road_height_std_m=road_height_std_m,
                              ground_allowed=ground_allowed, road_z_m=road_z_m,
                              iterations=iterations)
    road_z = np.zeros(n) if road_z_m is None else np.asarray(road_z_m, dtype=float)
    if length_std_m is None:
        length_std_m = np.full(n, FIXED_LENGTH_STD_M)
    ground_ok, g, height_ok = _usable_cues(camera, ba, width_m, width_std_m, prior_h,
                                           prior_h_std, length_m, length_std_m, config,
                                           use_ground, use_height, ground_allowed, road_z)
    prob = _fit_problem(camera, ba, width_m, width_std_m, prior_h, prior_h_std, length_m,
                        length_std_m, config, road_height_std_m, road_z, ground_ok, g,
                        height_ok)
    theta = _gauss_newton(camera, prob, config.width_tail_sigmas, iterations)
    return _box_fit(camera, prob, theta, config, pitch_noise_inflation)


def _fit_in_blocks(camera: Camera, ba: BoxArrays, width_m: np.ndarray, width_std_m: np.ndarray,
                   prior_h: np.ndarray, prior_h_std: np.ndarray, length_m: np.ndarray,
                   config: RangingConfig, **options) -> BoxFit:
    """:func:`fit_boxes` in blocks of :data:`FIT_BLOCK_BOXES` (each box is fitted on its own,
    so the result is bitwise the same, with flat memory)."""
    n = len(ba.x1)

    def part(a, sl):
        return a[sl] if isinstance(a, np.ndarray) else a

    fits = [fit_boxes(camera, BoxArrays(*(getattr(ba, k)[sl] for k in ba.__dataclass_fields__)),
                      width_m[sl], width_std_m[sl], prior_h[sl], prior_h_std[sl], length_m[sl],
                      config, **{k: part(v, sl) for k, v in options.items()})
            for sl in (slice(i, i + FIT_BLOCK_BOXES) for i in range(0, n, FIT_BLOCK_BOXES))]
    return BoxFit(*(np.concatenate([getattr(f, k) for f in fits])
                    for k in BoxFit.__dataclass_fields__))


def _bearing(camera: Camera, ba: BoxArrays) -> np.ndarray:
    """Tangent of each box centre column's bearing (lateral per metre ahead)."""
    n = len(ba.x1)
    rays = camera.pixel_rays_veh(np.column_stack(((ba.x1 + ba.x2) / 2,
                                                  np.full(n, camera.horizon_y_px()))))
    return rays[:, 1] / np.maximum(rays[:, 0], 1e-6)


def _contact_below_image(camera: Camera, ba: BoxArrays, width_m: np.ndarray,
                         width_std_m: np.ndarray, prior_h: np.ndarray, length_m: np.ndarray,
                         length_std_m: np.ndarray, config: RangingConfig,
                         road_z: np.ndarray) -> np.ndarray:
    """Boxes whose ground contact cannot be in the image: even at the farthest range the
    width cue allows (the width prior 2 sigma wide) the contact projects below the image,
    so the bottom rows are the car's body cut by the border, however many pixels short of
    the border the detector stopped."""
    bw = np.maximum(ba.x2 - ba.x1, 1.0)
    widest = ba.outline[:, _WIDEST]
    bearing = _bearing(camera, ba)
    max_fit_range_m = RANGE_BOUND_FACTOR * config.max_range_m
    wide = width_m + GROUND_CHECK_WIDTH_SIGMAS * width_std_m
    long_ = length_m + GROUND_CHECK_WIDTH_SIGMAS * length_std_m
    far = np.clip(camera.fx * wide / bw - widest, MIN_INITIAL_RANGE_M, max_fit_range_m)
    for _ in range(GROUND_CHECK_ITERATIONS):
        # The range at which the outline (with the side a laterally offset vehicle shows) is
        # as wide as the box: box widths scale about as 1 / range.
        pred = predict_edges(camera, far, bearing * (far + long_ / 2), wide, prior_h, long_,
                             ba.outline, road_z)
        pw = pred[:, 2] - pred[:, 0]
        far = np.where(np.isfinite(pw) & (pw > 0),
                       np.clip(far * pw / bw, MIN_INITIAL_RANGE_M, max_fit_range_m), far)
    row = predict_edges(camera, far, bearing * (far + long_ / 2), wide, prior_h, long_,
                        ba.outline, road_z)[:, 3]
    return np.isfinite(row) & (row > camera.image_height - 1 - config.border_margin_px)


def _ground_points(camera: Camera, ba: BoxArrays, road_z: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Forward distance [m] of each box's bottom-centre pixel on the ground under it (the
    plane ``road_z`` above the ego's road) and whether its ray meets that ground ahead."""
    rays = camera.pixel_rays_veh(np.column_stack(((ba.x1 + ba.x2) / 2, ba.y2)))
    down = rays[:, 2] < -1e-9
    x = np.full(len(rays), np.nan)
    x[down] = (camera.height_m - road_z[down]) / -rays[down, 2] * rays[down, 0]
    return x, down


def _usable_cues(camera: Camera, ba: BoxArrays, width_m: np.ndarray, width_std_m: np.ndarray,
                 prior_h: np.ndarray, prior_h_std: np.ndarray, length_m: np.ndarray,
                 length_std_m: np.ndarray, config: RangingConfig, use_ground: bool,
                 use_height: bool, ground_allowed: np.ndarray | None, road_z: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which boxes use the ground cue, which of them start from it, and which use the top
    edge (see :func:`fit_boxes`)."""
    n = len(ba.x1)
    horizon = camera.horizon_y_px()
    width_ok = ~(ba.cut_left | ba.cut_right)
    bottom_cut = ba.cut_bottom.copy()
    if ground_allowed is not None:
        bottom_cut |= ~np.asarray(ground_allowed, dtype=bool)
    elif width_ok.any():
        bottom_cut |= width_ok & _contact_below_image(camera, ba, width_m, width_std_m, prior_h,
                                                      length_m, length_std_m, config, road_z)
    ground_ok = (~bottom_cut) & (ba.y2 > horizon + config.min_ground_margin_px)
    if not use_ground:
        ground_ok = np.zeros(n, dtype=bool)
    g = np.zeros(n, dtype=bool)
    if ground_ok.any():
        x, ok = _ground_points(camera, ba, road_z)
        g = ground_ok & ok & np.isfinite(x) & (x > MIN_GROUND_POINT_M)
    # The top edge alone (bottom not usable) ranges only a vehicle whose height is known well
    # against its lever below the camera: its range error is about sigma_H / |H_cam - H|.
    lever = np.abs(camera.height_m - road_z - prior_h)
    top_alone_ok = prior_h_std < config.top_alone_max_rel_error * lever
    height_ok = (~ba.cut_top) & use_height & (ground_ok | top_alone_ok)
    return ground_ok, g, height_ok


def _fit_problem(camera: Camera, ba: BoxArrays, width_m: np.ndarray, width_std_m: np.ndarray,
                 prior_h: np.ndarray, prior_h_std: np.ndarray, length_m: np.ndarray,
                 length_std_m: np.ndarray, config: RangingConfig,
                 road_height_std_m: np.ndarray | None, road_z: np.ndarray,
                 ground_ok: np.ndarray, g: np.ndarray, height_ok: np.ndarray) -> _FitProblem:
    """The start, the noise of every edge and the priors of each box (see :func:`fit_boxes`)."""
    n = len(ba.x1)
    bw = np.maximum(ba.x2 - ba.x1, 1.0)
    bh = np.maximum(ba.y2 - ba.y1, 1.0)
    jitter_px = camera.fy * math.tan(math.radians(config.horizon_jitter_deg))
    sig_u = config.edge_noise_px + config.edge_noise_frac * bw
    pix_v = config.edge_noise_px + config.edge_noise_frac * bh
    widest = ba.outline[:, _WIDEST]
    f = camera.fx
    # Initial guess: ground cue where usable, else width cue; lateral from the centre column.
    # The bottom edge is the tyres' contact and the sides the widest section, each that far
    # ahead of the rear face.
    rng0 = f * width_m / bw - widest
    if g.any():
        x, _ = _ground_points(camera, ba, road_z)
        rng0 = np.where(g, x - ba.outline[:, _CONTACT], rng0)
    rng0 = np.clip(rng0, MIN_INITIAL_RANGE_M, RANGE_BOUND_FACTOR * config.max_range_m)
    # A road dz higher than the plane moves a vehicle's bottom edge by f dz / Z pixels; Z is
    # only known after the fit, so take the first guess (the ground cue's own range where it
    # is usable, not the width cue's: a turned vehicle's wide box would say "near" and so
    # blur the very cue that has to range it).
    road_std = config.road_height_std_m if road_height_std_m is None else road_height_std_m
    lat0 = _bearing(camera, ba) * (rng0 + length_m / 2)
    # Away from the ego's lane the ego's road plane says less about the ground: cross-fall
    # (2-3 % from the crown), gutters, kerbs and parking strips.
    beyond = np.maximum(np.abs(lat0) - config.lane_width_m / 2, 0.0)
    road_std = np.hypot(road_std, config.road_height_std_per_lateral_m * beyond)
    # The body's pitch jitter and the road's height under the vehicle move the top and the
    # bottom edge together: one vertical offset per box [px], a sixth unknown with that
    # prior, and each edge keeps only its own pixel noise. The box height (top to bottom)
    # is then a clean cue against the vehicle's height, the bottom edge against the horizon
    # is as blurred by the offset as before (Z = f H / (y_bottom - y_horizon)).
    sig_off = np.hypot(jitter_px, camera.fy * road_std / rng0)
    # Width: what the box says at the ground cue's range (at least the prior), so that the
    # reweighting sees a turned vehicle's wide box from the first step on rather than being
    # pulled by it towards the camera first (a redescending prior needs a fair start).
    w_init = width_m.copy()
    if g.any():
        w_init = np.where(g, np.clip(bw * (rng0 + widest) / f, width_m,
                                     MAX_WIDTH_INIT_FACTOR * width_m), width_m)
    return _FitProblem(
        obs=np.stack([ba.x1, ba.y1, ba.x2, ba.y2], axis=1),
        sig=np.stack([sig_u, pix_v, sig_u, pix_v], axis=1),
        # the top edge against the vehicle's height: with the bottom edge a clean cue; alone
        # (a near lead whose bottom is cut) only for a height its track has learnt
        use=np.stack([~ba.cut_left, height_ok, ~ba.cut_right, ground_ok], axis=1),
        outline=ba.outline,
        prior_mean=np.column_stack((width_m, prior_h, length_m, np.zeros(n))),
        prior_std=np.column_stack((width_std_m, prior_h_std, length_std_m, sig_off)),
        road_z=road_z,
        theta0=np.column_stack((np.log(rng0), lat0, w_init, prior_h, length_m, np.zeros(n))),
        sig_off=sig_off, jitter_px=jitter_px, ground_ok=ground_ok,
        width_ok=~(ba.cut_left | ba.cut_right), max_range_m=config.max_range_m)


def _residuals(camera: Camera, prob: _FitProblem, th: np.ndarray, i: np.ndarray,
               w_prior_weight: np.ndarray) -> np.ndarray:
    """Normalised residuals (4 edges, 4 priors) of boxes ``i`` at parameters ``th``."""
    pred = predict_edges(camera, np.exp(th[:, 0]), th[:, 1], th[:, 2], th[:, 3], th[:, 4],
                         prob.outline[i], prob.road_z[i])
    pred[:, 1] += th[:, 5]
    pred[:, 3] += th[:, 5]
    r_edges = np.where(prob.use[i], (prob.obs[i] - pred) / prob.sig[i], 0.0)
    r_prior = (prob.prior_mean[i] - th[:, 2:6]) / prob.prior_std[i]
    r_prior[:, 0] *= np.sqrt(w_prior_weight[i])
    return np.nan_to_num(np.concatenate([r_edges, r_prior], axis=1), nan=0.0)


def _jacobian(camera: Camera, prob: _FitProblem, th: np.ndarray, i: np.ndarray,
              w_prior_weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Residuals and their forward-difference Jacobian: the base point and its N_PARAMS
    steps in one residuals call (one outline projection of 7 n boxes instead of 7 of n: a
    third of the fit's time on KITTI)."""
    m = len(i)
    th_all = np.tile(th, (N_PARAMS + 1, 1))
    for k in range(N_PARAMS):
        th_all[(k + 1) * m:(k + 2) * m, k] += FD_STEP
    r_all = _residuals(camera, prob, th_all, np.tile(i, N_PARAMS + 1),
                       w_prior_weight).reshape(N_PARAMS + 1, m, 4 + 4)
    r0 = r_all[0]
    return r0, np.moveaxis(-(r_all[1:] - r0) / FD_STEP, 0, -1)


def _gauss_newton(camera: Camera, prob: _FitProblem, tail_sigmas: float, iterations: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton over all boxes at once; boxes leave the active set once converged (most
    need 3-5 steps). Returns the parameters and the final width-prior weights.

    Apparent width is heavy-tailed upwards: a vehicle turned away from the ego axis (at a
    junction, parked across or at an angle, changing lanes) shows part of its side, and its
    box is W cos(yaw) + L sin(yaw) wide, never narrower than its rear. So a width far above
    the class prior is more likely a turned vehicle than a wide one: its width prior is
    Cauchy beyond ``tail_sigmas`` (iteratively reweighted), and the range then rests on the
    ground cue instead of a box width inflated by the vehicle's side.
    """
    theta = prob.theta0.copy()
    n = len(theta)
    w_prior_weight = np.ones(n)
    max_log_range = math.log(RANGE_BOUND_FACTOR * prob.max_range_m)
    active = np.arange(n)
    for _ in range(iterations):
        if active.size == 0:
            break
        if math.isfinite(tail_sigmas):
            s = (theta[active, 2] - prob.prior_mean[active, 0]) / prob.prior_std[active, 0]
            w_prior_weight[active] = np.where(s > 0, 1.0 / (1.0 + (s / tail_sigmas) ** 2), 1.0)
        r0, jac = _jacobian(camera, prob, theta[active], active, w_prior_weight)
        jtj = np.einsum("nik,nil->nkl", jac, jac) + 1e-9 * np.eye(N_PARAMS)
        jtr = np.einsum("nik,ni->nk", jac, r0)
        delta = np.linalg.solve(jtj, jtr[..., None])[..., 0]
        delta[:, 0] = np.clip(delta[:, 0], -MAX_LOG_RANGE_STEP, MAX_LOG_RANGE_STEP)
        th = theta[active] + delta
        th[:, 0] = np.clip(th[:, 0], 0.0, max_log_range)
        th[:, 2:5] = np.maximum(th[:, 2:5], MIN_SIZE_M)
        theta[active] = th
        active = active[(np.abs(delta[:, 0]) > CONVERGED_LOG_RANGE)
                        | (np.abs(delta[:, 1]) > CONVERGED_LATERAL_M)]
    return theta, w_prior_weight


def _box_fit(camera: Camera, prob: _FitProblem, fitted: tuple[np.ndarray, np.ndarray],
             config: RangingConfig, pitch_noise_inflation: np.ndarray | float) -> BoxFit:
    """The fit's covariance, its frame-to-frame part and validity (see :func:`fit_boxes`).

    Frame-to-frame (white) part: pixel noise and body pitch jitter only. The vehicle's size
    and the road height under it change slowly, so their errors are common to all frames of
    a track: they scale the range but do not disturb its rate, and a filter that took them
    for white noise would trust the measurements too little and lag behind braking.
    Sandwich form: the same estimate, its covariance under the white noise alone,
    cov (J^T D J) cov with D the white share of each (scaled) residual's variance. The body
    pitch is not white: it lasts about half a second, so it enters with the inflation factor
    that gives its slow part the right weight in the filter.
    """
    theta, w_prior_weight = fitted
    n = len(theta)
    _, jac = _jacobian(camera, prob, theta, np.arange(n), w_prior_weight)
    jtj = np.einsum("nik,nil->nkl", jac, jac) + 1e-9 * np.eye(N_PARAMS)
    cov = np.linalg.inv(jtj)
    d = np.ones((n, 4 + 4))
    d[:, 4:7] = 0.0  # size priors: common to the track
    d[:, 7] = pitch_noise_inflation * prob.jitter_px ** 2 / prob.sig_off ** 2  # road: common
    cov_white = cov @ np.einsum("nik,ni,nil->nkl", jac, d, jac) @ cov
    rng = np.exp(theta[:, 0])
    # Unobservable range: the log-range spread stays near what the priors alone allow, or
    # the fit ran onto its range bounds (weak cues that disagree have no interior optimum).
    max_log_range = math.log(RANGE_BOUND_FACTOR * config.max_range_m)
    on_bound = (theta[:, 0] <= 1e-6) | (theta[:, 0] >= max_log_range - 1e-6)
    valid = ((np.sqrt(np.maximum(cov[:, 0, 0], 0)) < config.max_log_range_std)
             & np.isfinite(rng) & ~on_bound)
    return BoxFit(rng, theta[:, 1], theta[:, 2], cov, cov_white, prob.ground_ok,
                  prob.width_ok, valid, theta[:, 4], theta[:, 3])


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
