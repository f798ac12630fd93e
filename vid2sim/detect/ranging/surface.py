"""The ground under each car: standing vehicles found and fitted, and the road surface they
stand on carried over to the vehicles that move.

The road is not one plane through the ego's wheels: a parked row, a kerb strip, the far side
of a crown sit 0.1-0.5 m off it (the parked row of KITTI raw 0001: 0.29-0.46 m below it, by
its lidar tracklets), and a bottom edge on ground 0.35 m lower reads a car 1.65 / 2.0 = 18 %
near on a 1.65 m camera. A standing vehicle seen from a moving ego measures the height of
its own ground (:mod:`vid2sim.detect.ranging.parallax`); a moving vehicle cannot (its range
and its ground trade against its speed), so it takes the ground the standing vehicles beside
it measured at its lateral offset, with the spread of those measurements, and where none
stands near it the ego's plane with the spread that grows beside the ego's lane.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.detect.ranging.boxfit import BoxArrays
from vid2sim.detect.ranging.config import RangingConfig
from vid2sim.detect.ranging.parallax import EgoPath, StandingFit, fit_standing_track


@dataclass(frozen=True)
class TrackGround:
    """The ground a track's vehicle stands on: height above the ego's road plane [m], its
    one-sigma spread and where it came from ("standing fit", "standing neighbours",
    "ego plane")."""

    height_m: float
    std_m: float
    source: str


@dataclass
class StandingTracks:
    """Tracks fitted as standing vehicles: the accepted fits, and every tried track's
    reason when it was not accepted."""


    fits: dict[int, StandingFit] = field(default_factory=dict)
    rejected: dict[int, str] = field(default_factory=dict)
    #: the direction of the ego's travel in the ranging frame the fits used [rad]
    travel_yaw_rad: float = 0.0


def road_std_at(lateral_m: float, config: RangingConfig) -> float:
    """Spread of the ground height under a vehicle at ``lateral_m`` relative to the ego's
    road plane [m] (the config's road height spread growing beyond the ego's lane)."""
    beyond = max(abs(lateral_m) - config.lane_width_m / 2, 0.0)
    return math.hypot(config.road_height_std_m, config.road_height_std_per_lateral_m * beyond)


def scale_sigmas(free: StandingFit, prior_mean: np.ndarray, prior_std: np.ndarray,
                 camera_height_m: float, ground_std_m: float) -> float:
    """How many sigmas the data's own scale lies from 1.

    A vehicle moving along the ego's axis at u fits as a standing one with every length
    scaled by k = v / (v - u): its width, height, length and the camera's height above its
    ground alike (the monocular scale ambiguity). ``free`` is the standing fit with the size
    priors let go, so that its sizes are the data's; the generalised least-squares mean of
    the log ratios of those four to their priors estimates ln k (Aitken's estimator, with
    their covariance: the priors' relative variances plus the fit's).
    """
    th = free.theta
    vals = np.array([th[2], th[3], th[4], camera_height_m - th[5]])
    mean = np.array([prior_mean[0], prior_mean[1], prior_mean[2], camera_height_m])
    std = np.array([prior_std[0], prior_std[1], prior_std[2], ground_std_m])
    if not free.converged or np.any(vals <= 0) or not np.all(np.isfinite(free.cov)):
        return math.inf
    # the logs' covariance: the priors' relative spreads and the fit's (full: a width and a
    # length seen obliquely trade against each other), d ln(H_cam - dz) = -d dz / (H_cam - dz)
    jac = np.zeros((4, 6))
    jac[0, 2], jac[1, 3], jac[2, 4], jac[3, 5] = 1 / vals[0], 1 / vals[1], 1 / vals[2], -1 / vals[3]
    cov = np.diag((std / mean) ** 2) + jac @ free.cov @ jac.T
    y = np.log(vals / mean)
    ones = np.ones(4)
    ci1 = np.linalg.solve(cov, ones)
    info = float(ones @ ci1)
    log_k = float(ci1 @ y) / info
    return abs(log_k) * math.sqrt(info)


def standing_verdict(fit: StandingFit, free: StandingFit | None, prior_mean: np.ndarray,
                     prior_std: np.ndarray, camera_height_m: float, ground_std_m: float,
                     config: RangingConfig, ground_ref_m: float = 0.0) -> str | None:
    """None when ``fit`` (with the class priors) is a plausible standing vehicle whose data
    alone (``free``: the same fit with the size priors let go) need no other scale, else the
    reason it is not. Without ``free`` the scale test is left out (a vehicle moving along the
    ego's travel expands from the same focus as a standing one). ``ground_ref_m``: the road
    surface's height where the vehicle stands, which its ground may leave by at most
    ``config.standing_max_ground_m`` (0: the ego's road plane)."""
    if not fit.converged:
        return "the standing fit did not converge"
    if not fit.chi2_per_dof <= config.standing_max_chi2:
        return f"its boxes fit no single place (chi2/dof {fit.chi2_per_dof:.1f})"
    z = np.abs(fit.theta[2:5] - prior_mean[:3]) / prior_std[:3]
    if np.any(z > config.standing_size_sigmas):
        name = ("width", "height", "length")[int(np.argmax(z))]
        return (f"standing, its {name} would be {fit.theta[2 + int(np.argmax(z))]:.2f} m "
                f"({z.max():.0f} sigma from its class)")
    if abs(fit.ground_m - ground_ref_m) > config.standing_max_ground_m:
        where = "the ego's road" if ground_ref_m == 0.0 else (
            f"the road surface there ({ground_ref_m:+.2f} m)")
        return f"standing, its ground would be {fit.ground_m:+.2f} m, too far off {where}"
    if free is None:
        return None
    k = scale_sigmas(free, prior_mean, prior_std, camera_height_m - ground_ref_m, ground_std_m)
    bound = (config.standing_scale_sigmas if abs(fit.theta[1]) <= config.standing_road_half_width_m
             else config.standing_scale_sigmas_beside_road)
    if k > bound:
        return f"its own size and ground scale together ({k:.1f} sigma): moving along the road"
    return None


def _track_problem(ba: BoxArrays, idx: np.ndarray, camera: Camera, config: RangingConfig
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edges, their noise (pixel noise, and the body's pitch jitter on the rows) and which
    are usable, for one track's boxes."""
    sub = ba.subset(idx)
    jitter_px = camera.fy * math.tan(math.radians(config.horizon_jitter_deg))
    su = config.edge_noise_px + config.edge_noise_frac * (sub.x2 - sub.x1)
    sv = np.hypot(config.edge_noise_px + config.edge_noise_frac * (sub.y2 - sub.y1), jitter_px)
    obs = np.column_stack((sub.x1, sub.y1, sub.x2, sub.y2))
    use = np.column_stack((~sub.cut_left, ~sub.cut_top, ~sub.cut_right, ~sub.cut_bottom))
    return obs, np.column_stack((su, sv, su, sv)), use


def find_standing_tracks(camera: Camera, ba: BoxArrays, t_s: np.ndarray,
                         members_by_track: dict[int, np.ndarray], start_range_m: np.ndarray,
                         start_lateral_m: np.ndarray, prior_mean: np.ndarray,
                         prior_std: np.ndarray, path: EgoPath, config: RangingConfig
                         ) -> StandingTracks:
    """Fit every track the ego's motion can test as a standing vehicle and keep those that
    are one (see the module docstring and :func:`standing_verdict`), with the direction of
    the ego's travel estimated from them (:func:`estimate_travel_yaw`).

    ``members_by_track``: each track's box indices in time order; ``start_*``: a first
    range and lateral offset per box (the single-frame fit); ``prior_mean`` / ``prior_std``:
    (N, 3) class priors of width, height and length per box.
    """
    out = StandingTracks(travel_yaw_rad=path.travel_yaw_rad)
    problems = {}
    for tid, idx in members_by_track.items():
        why = _untestable(t_s[idx], path, config)
        if why:
            out.rejected[tid] = why
        else:
            problems[tid] = _StandingProblem.build(camera, ba, t_s, idx, start_range_m,
                                                   start_lateral_m, prior_mean, prior_std,
                                                   path, config)
    fits = {tid: pr.fit(camera, path.travel_yaw_rad, config) for tid, pr in problems.items()}
    # the direction of travel from every track that fits one place with a plausible car
    # (the scale test is not needed here: a vehicle moving along the ego's travel expands
    # from the same focus as a standing one)
    first = {t for t, f in fits.items()
             if problems[t].verdict(f, camera, path.travel_yaw_rad, config, False) is None}
    if len(first) >= config.travel_yaw_min_tracks:
        out.travel_yaw_rad = estimate_travel_yaw(camera, {t: problems[t] for t in first},
                                                 {t: fits[t] for t in first},
                                                 path.travel_yaw_rad, config)
        if out.travel_yaw_rad != path.travel_yaw_rad:
            fits = {tid: pr.fit(camera, out.travel_yaw_rad, config, fits[tid].theta)
                    for tid, pr in problems.items()}
    for tid, fit in fits.items():
        fit, why = _verdict_chain(camera, problems[tid], fit, out.travel_yaw_rad, config)
        if why:
            out.rejected[tid] = why
        else:
            out.fits[tid] = fit
    _admit_on_the_surface(camera, problems, fits, out, config)
    return out


def _verdict_chain(camera: Camera, problem: _StandingProblem, fit: StandingFit,
                   travel_yaw_rad: float, config: RangingConfig
                   ) -> tuple[StandingFit, str | None]:
    """A track's standing fit as it is, else refitted without one side, else crosswise: the
    first plausible one, or the reason none is."""
    why = problem.verdict(fit, camera, travel_yaw_rad, config)
    if why:
        fit, why = _one_sided(camera, problem, fit, why, travel_yaw_rad, config)
    if why:
        fit, why = _crosswise(camera, problem, fit, why, travel_yaw_rad, config)
    return fit, why


def _admit_on_the_surface(camera: Camera, problems: dict[int, _StandingProblem],
                          fits: dict[int, StandingFit], out: StandingTracks,
                          config: RangingConfig) -> None:
    """The rejected tracks tried again against the road surface the accepted ones measured.

    The bound on a standing vehicle's ground is for what stands off the road under it
    (kerbs, strips, crowns); far to the side of a road that falls across, the road itself
    has left the ego's plane (KITTI raw 0001: 3.5 % to the left, 0.75 m at the car park 21 m
    away, whose tracklets stand 0.5-0.6 m below). So a rejected track beside the ego's lane
    is judged again with the cross slope's height at its offset
    (:func:`cross_slopes`, from the accepted fits) as the reference of that bound, of its
    ground prior and of the scale test; it stands if then plausible."""
    slopes = cross_slopes([(float(f.theta[1]), f.ground_m, f.ground_std_m)
                           for f in out.fits.values()], config)
    for tid in list(out.rejected):
        if tid not in fits:
            continue  # untestable
        lat = float(fits[tid].theta[1])
        slope = slopes[1 if lat > 0 else -1]
        if slope is None or abs(lat) <= config.lane_width_m / 2:
            continue
        ref = slope.at(lat)[0]
        if abs(ref) < config.surface_floor_std_m:
            continue
        pr = problems[tid]
        mean = pr.prior_mean.copy()
        mean[3] = ref
        moved = replace(pr, prior_mean=mean, ground_ref_m=ref,
                        start=np.append(pr.start[:5], ref))
        fit, why = _verdict_chain(camera, moved, moved.fit(camera, out.travel_yaw_rad, config),
                                  out.travel_yaw_rad, config)
        if why is None:
            out.fits[tid] = fit
            del out.rejected[tid]


def _one_sided(camera: Camera, problem: _StandingProblem, fit: StandingFit, why: str,
               travel_yaw_rad: float, config: RangingConfig) -> tuple[StandingFit, str | None]:
    """A track whose standing fit needs an implausible size, refitted without its left or
    its right box edges: one side of a box may lie on another vehicle for many frames (two
    parked cars in one box, a neighbour hiding a flank), which no robust weight of single
    edges discounts; the other side, the rows and the size priors still place it. The
    better plausible one-sided fit, else the reason of the two-sided one."""
    if "sigma from its class" not in why:
        return fit, why
    best: tuple[float, StandingFit] | None = None
    for side in (0, 2):
        one = replace(problem, use=problem.use.copy())
        one.use[:, side] = False
        f = one.fit(camera, travel_yaw_rad, config, fit.theta)
        if one.verdict(f, camera, travel_yaw_rad, config) is None and (best is None or f.chi2_per_dof < best[0]):
            best = (f.chi2_per_dof, f)
    return (best[1], None) if best is not None else (fit, why)


def _crosswise(camera: Camera, problem: _StandingProblem, fit: StandingFit, why: str,
               travel_yaw_rad: float, config: RangingConfig) -> tuple[StandingFit, str | None]:
    """A track beside the road that fits no standing vehicle parallel to the ego's travel,
    refitted as one parked crosswise (a car park's bays, perpendicular parking): its box is
    then its flank (a car's length) and its nearest face, which the parallel model can only
    explain by an implausible size or a common scale (a moving car). The crosswise fit if it
    is a plausible standing vehicle, else the reason of the parallel one."""
    if abs(float(problem.start[1])) <= config.standing_road_half_width_m:
        return fit, why  # in the driving lanes a vehicle stands along the road
    cross = replace(problem, body_yaw_rad=math.pi / 2)
    start = problem.start.copy()
    f = cross.fit(camera, travel_yaw_rad, config, start)
    if cross.verdict(f, camera, travel_yaw_rad, config) is None:
        return f, None
    return fit, why


#: Levenberg-Marquardt steps of each warm-started fit of the direction-of-travel search (a
#: tenth of a degree moves the optimum a few centimetres: it converges in 3-6).
YAW_SEARCH_ITERATIONS = 8


@dataclass
class _StandingProblem:
    """One track's standing fit, set up once and solved for any direction of travel."""

    obs: np.ndarray
    sig: np.ndarray
    use: np.ndarray
    outline: np.ndarray
    poses_at: object
    start: np.ndarray
    prior_mean: np.ndarray
    prior_std: np.ndarray
    ground_std_m: float
    #: the vehicle's heading relative to the ego's travel (0 parallel, pi / 2 crosswise)
    body_yaw_rad: float = 0.0
    #: the road surface's height where it stands, the reference of its ground's bound [m]
    ground_ref_m: float = 0.0

    @classmethod
    def build(cls, camera: Camera, ba: BoxArrays, t_s: np.ndarray, idx: np.ndarray,
              start_range_m: np.ndarray, start_lateral_m: np.ndarray, prior_mean: np.ndarray,
              prior_std: np.ndarray, path: EgoPath, config: RangingConfig
              ) -> _StandingProblem:
        ref = len(idx) // 2
        t_track, t_ref = t_s[idx], float(t_s[idx][ref])
        obs, sig, use = _track_problem(ba, idx, camera, config)
        g_std = (road_std_at(float(np.median(start_lateral_m[idx])), config)
                 * config.standing_ground_prior_factor)
        i0 = idx[ref]
        return cls(obs, sig, use, ba.outline[idx],
                   lambda yaw: replace(path, travel_yaw_rad=yaw).relative_poses(t_track, t_ref),
                   np.array([start_range_m[i0], start_lateral_m[i0], *prior_mean[i0], 0.0]),
                   np.append(prior_mean[i0], 0.0), np.append(prior_std[i0], g_std), g_std)

    def fit(self, camera: Camera, travel_yaw_rad: float, config: RangingConfig,
            start: np.ndarray | None = None, max_iterations: int | None = None
            ) -> StandingFit:
        return fit_standing_track(camera, self.obs, self.sig, self.use, self.outline,
                                  self.poses_at(travel_yaw_rad),
                                  self.start if start is None else start, self.prior_mean,
                                  self.prior_std, config.standing_robust_sigmas,
                                  travel_yaw_rad, max_iterations, self.body_yaw_rad)

    def verdict(self, fit: StandingFit, camera: Camera, travel_yaw_rad: float,
                config: RangingConfig, scale_test: bool = True) -> str | None:
        free = None
        if scale_test:
            free_std = self.prior_std * np.array([config.standing_free_prior_factor] * 3 + [1.0])
            free = replace(self, prior_std=free_std).fit(camera, travel_yaw_rad, config,
                                                         fit.theta)
        return standing_verdict(fit, free, self.prior_mean, self.prior_std, camera.height_m,
                                self.ground_std_m, config, self.ground_ref_m)

    def cost(self, fit: StandingFit) -> float:
        """The fit's robust residual sum (chi2 per degree of freedom times the degrees)."""
        return fit.chi2_per_dof * max(int(self.use.sum()) - 6, 1)


def estimate_travel_yaw(camera: Camera, problems: dict[int, _StandingProblem],
                        fits: dict[int, StandingFit], yaw0_rad: float,
                        config: RangingConfig) -> float:
    """The direction of the ego's travel in the ranging frame from standing vehicles.

    Seen from a camera that translates, every standing point moves in the image along a line
    from the focus of expansion, the image of the direction of travel (Longuet-Higgins &
    Prazdny, Proc. R. Soc. Lond. B 208, 1980): one track's line leaves the focus free along
    it, tracks at other bearings pin it. The yaw that minimises the standing fits' summed
    robust residual over ``yaw0_rad +- config.travel_yaw_search_deg`` (five points, then the
    vertex of the parabola through the best three), unless that vertex is not a minimum
    inside the range.
    """
    half = math.radians(config.travel_yaw_search_deg)
    grid = yaw0_rad + half * np.linspace(-1.0, 1.0, 5)

    def total(yaw: float) -> float:
        return sum(pr.cost(pr.fit(camera, float(yaw), config, fits[t].theta,
                                  YAW_SEARCH_ITERATIONS)) for t, pr in problems.items())

    costs = np.array([total(y) for y in grid])
    k = int(np.clip(np.argmin(costs), 1, len(grid) - 2))
    y3, c3 = grid[k - 1:k + 2], costs[k - 1:k + 2]
    curvature = c3[0] - 2 * c3[1] + c3[2]
    if not curvature > 0:
        return float(grid[int(np.argmin(costs))])
    step = grid[1] - grid[0]
    vertex = float(y3[1] + 0.5 * step * (c3[0] - c3[2]) / curvature)
    return float(np.clip(vertex, grid[0], grid[-1]))


def _untestable(t_s: np.ndarray, path: EgoPath, config: RangingConfig) -> str | None:
    """Why the ego's motion cannot test a track as standing, or None."""
    if len(t_s) < config.standing_min_boxes:
        return f"only {len(t_s)} boxes"
    if not path.covers(t_s):
        return "the ego's trajectory does not cover it"
    if path.noise_m is None or path.noise_m > config.standing_max_ego_noise_m:
        return "the ego's trajectory is not known well enough"
    poses = path.relative_poses(np.array([t_s.min(), t_s.max()]), float(t_s.min()))
    travel = float(np.hypot(*poses[1, :2]))
    if travel < config.standing_min_travel_m:
        return f"the ego moved {travel:.1f} m while it was seen"
    return None


@dataclass(frozen=True)
class CrossSlope:
    """The road's fall across the ego's travel on one side [m of height per m of lateral
    offset], from the standing vehicles' grounds: its one-sigma error, the robust spread of
    one vehicle's ground about it [m] and how many grounds measured it."""

    slope: float
    slope_std: float
    scatter_m: float
    n: int

    def at(self, lateral_m: float) -> tuple[float, float]:
        """The ground height [m] and its one-sigma spread at ``lateral_m``."""
        return (self.slope * lateral_m,
                math.hypot(lateral_m * self.slope_std, self.scatter_m))


def fit_cross_slope(lateral_m: np.ndarray, ground_m: np.ndarray, std_m: np.ndarray,
                    config: RangingConfig) -> CrossSlope | None:
    """The plane through the ego's lane (its markings measure the ground there: height 0)
    that tilts across the road to the standing vehicles' grounds, g = s y, or None with fewer
    than ``config.surface_cross_slope_min_tracks`` of them.

    Robust (iteratively reweighted least squares with Cauchy weights at
    ``config.surface_robust_sigmas`` of the residuals' scale, 1.4826 MAD): a standing fit
    whose bottom a hedge or a kerb hides reads its ground up to half a car's height too high,
    and one such must not tilt the plane. The slope's error is the scatter over the lever arm
    sqrt(sum w y^2); the scatter (at least ``config.surface_floor_std_m``) is how far one car's
    ground departs from the plane.
    """
    y, g = np.asarray(lateral_m, float), np.asarray(ground_m, float)
    if y.size < config.surface_cross_slope_min_tracks:
        return None
    sd = np.maximum(np.asarray(std_m, float), config.surface_floor_std_m)
    slope = float(np.median(g / y))
    w = np.ones_like(y)
    scale = config.surface_floor_std_m
    for _ in range(20):
        r = g - slope * y
        scale = max(1.4826 * float(np.median(np.abs(r - np.median(r)))),
                    config.surface_floor_std_m)
        w = 1.0 / (1.0 + (r / (config.surface_robust_sigmas * scale)) ** 2)
        w = w / (sd ** 2 + scale ** 2) * scale ** 2
        new = float(np.sum(w * y * g) / np.sum(w * y * y))
        if abs(new - slope) < 1e-6:
            slope = new
            break
        slope = new
    slope_std = scale / math.sqrt(float(np.sum(w * y * y)))
    return CrossSlope(slope, slope_std, scale, int(y.size))


def cross_slopes(known: list[tuple[float, float, float]], config: RangingConfig
                 ) -> dict[int, CrossSlope | None]:
    """The road's cross slope left (+1) and right (-1) of the ego's lane from the standing
    vehicles' (lateral, ground, spread) beyond it: on each side the surface next to the
    ego's lane, the standing vehicles within ``config.surface_band_m`` laterally of the
    nearest one (a parking strip, the next lane; further out a hedge, a car park or a
    verge is another surface, not the road's slope). A side without enough of them takes
    the other side's (one plane through the ego's lane: no crown is seen, so none is
    assumed)."""
    half = config.lane_width_m / 2
    out: dict[int, CrossSlope | None] = {}
    for side in (1, -1):
        pts = np.array([k for k in known if side * k[0] > half]).reshape(-1, 3)
        if pts.size:
            pts = pts[np.abs(pts[:, 0]) <= np.abs(pts[:, 0]).min() + config.surface_band_m]
        out[side] = fit_cross_slope(pts[:, 0], pts[:, 1], pts[:, 2], config)
    return {side: out[side] or out[-side] for side in (1, -1)}


def _bayes(prior_std: float, mean: float, spread: float, floor: float) -> tuple[float, float]:
    """The ego plane (height 0, ``prior_std``) updated by a measurement ``mean`` +- ``spread``."""
    info = 1.0 / prior_std ** 2 + 1.0 / spread ** 2
    return (mean / spread ** 2) / info, max(math.sqrt(1.0 / info), floor)


def track_grounds(standing: StandingTracks, lateral_by_track: dict[int, float],
                  config: RangingConfig) -> dict[int, TrackGround]:
    """The ground under every track.

    A standing track: its own fit's. A moving one in the ego's lane: the ego's plane, which
    the lane markings measure (the horizon of the lane they bound). Any other: the ego's
    plane with the spread that grows beside the ego's lane as the prior, updated by the
    standing tracks within ``config.surface_lateral_window_m`` of its lateral offset (their
    inverse-variance mean, spread by the mean's error and their scatter), so that one weak
    far fit cannot lift a car by its whole prior range; where none stands that near, by the
    road's cross slope the standing tracks measured (:func:`cross_slopes`) at its offset,
    with the slope's error times the offset and the cars' scatter about it.
    """
    out: dict[int, TrackGround] = {}
    known = [(float(lateral_by_track[t]), f.ground_m, f.ground_std_m)
             for t, f in standing.fits.items() if t in lateral_by_track]
    # the slope from the fits' own lateral offsets (the single-frame offsets of a car on
    # lower ground read it nearer the ego by the same ratio as its range)
    slopes = cross_slopes([(float(f.theta[1]), f.ground_m, f.ground_std_m)
                           for t, f in standing.fits.items() if t in lateral_by_track], config)
    for tid, lat in lateral_by_track.items():
        if tid in standing.fits:
            f = standing.fits[tid]
            out[tid] = TrackGround(f.ground_m, max(f.ground_std_m, config.surface_floor_std_m),
                                   "standing fit")
            continue
        prior = road_std_at(lat, config)
        near = [(g, sd) for y, g, sd in known
                if abs(y - lat) <= config.surface_lateral_window_m]
        slope = slopes[1 if lat > 0 else -1]
        if abs(lat) <= config.lane_width_m / 2 or (not near and slope is None):
            out[tid] = TrackGround(0.0, prior, "ego plane")
            continue
        if not near:
            mean, spread = slope.at(lat)
            out[tid] = TrackGround(*_bayes(prior, mean, spread, config.surface_floor_std_m),
                                   "road cross slope")
            continue
        g = np.array([v[0] for v in near])
        w = 1.0 / np.maximum(np.array([v[1] for v in near]), config.surface_floor_std_m) ** 2
        mean = float(np.sum(w * g) / np.sum(w))
        spread = math.hypot(1.0 / math.sqrt(float(np.sum(w))),
                            float(np.std(g)) if len(g) > 1 else 0.0)
        out[tid] = TrackGround(*_bayes(prior, mean, spread, config.surface_floor_std_m),
                               "standing neighbours")
    return out
