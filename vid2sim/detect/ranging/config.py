"""Ranging settings: per-class vehicle size priors and :class:`RangingConfig`."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

from vid2sim.core.camera import Camera, PitchSource
from vid2sim.core.outline import CLASS_SHAPES, CUBOID, OutlineShape
from vid2sim.core.records import VehicleCategory


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
DEFAULT_PRIORS: dict[VehicleCategory, VehiclePrior] = {
    VehicleCategory.CAR: VehiclePrior(1.75, 0.12, 4.4, 1.50, 0.12, 0.45),
    VehicleCategory.TRUCK: VehiclePrior(2.70, 0.20, 8.0, 3.20, 0.60, 2.0),
    VehicleCategory.BUS: VehiclePrior(2.75, 0.15, 12.0, 3.10, 0.30, 2.0),
    VehicleCategory.MOTORCYCLE: VehiclePrior(0.80, 0.15, 2.1, 1.40, 0.20, 0.2),
    # Trams: 2.30-2.65 m wide (2.65 m is the German BOStrab section 34 limit, which most
    # new low-floor trams use: Siemens Avenio 2.65 m, Alstom Citadis 2.40-2.65 m, Bombardier
    # Flexity 2.30-2.65 m), 3.4-3.6 m high over the rail head without the pantograph,
    # 20-45 m long (Karlsruhe's NET 2012: 37 m).
    VehicleCategory.TRAM: VehiclePrior(2.55, 0.12, 30.0, 3.50, 0.10, 8.0),
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
        Per-class :class:`VehiclePrior`; unknown classes use the car's.
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
        An edge this close to the image border counts as cut by it: the tracker's margin
        (``TrackerConfig.border_margin_px``, 8 px), since a detector stops the box of a cut
        vehicle a few pixels short of the border. At 2 px a lead standing still 4 m ahead
        had its bottom rows taken for its ground contact and read +1.2 to +1.7 m/s (issue 13).
    border_noise_sigmas : float
        An edge also counts as cut within this many sigmas of its own edge noise
        (``edge_noise_px + edge_noise_frac * size``): a big box's edge wanders further.
    outlines : dict
        Per-class :class:`vid2sim.core.outline.OutlineShape`: where a vehicle's tyre contact,
        widest section and mirrors lie, i.e. what its box hugs (unknown classes take the
        car's). :data:`vid2sim.core.outline.CUBOID` for every class ranges boxes that are
        projected cuboids (KITTI label boxes) instead of detector boxes.
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
    lane_horizon_min_hints : int
        Lane-marking horizons the whole video needs before they count as an estimate (3:
        the fewest whose median and MAD say anything).
    lane_horizon_floor_px : float
        Floor added to the lane-marking horizon's spread [px]: however many frames agree,
        the markings' vanishing row carries a common error of about a pixel (curvature,
        lens distortion left in the frame).
    horizon_vehicle_min_box_px : tuple of float
        Smallest (height, width) of a box that votes for the horizon from vehicles [px]:
        below 20 x 12 px one pixel of edge noise is over 5 % of the size cue.
    horizon_vehicle_range_m : tuple of float
        Width-cue ranges of the vehicles that vote for the horizon [m]: nearer than 5 m the
        box is often cut or the bumper hides the road; beyond 60 m a pixel of bottom edge
        is worth more than the horizon shift sought.
    horizon_min_vehicles : int
        Tracks the horizon from vehicles needs before it counts (3: one odd car cannot
        outvote the camera file alone).
    horizon_typical_range_m : float
        Range [m] at which the vehicle horizon's spread floors are evaluated (the middle of
        the 5-60 m votes, where most cars of a street scene are seen).
    horizon_few_tracks_mad_px : float
        Scatter [px] assumed for the horizon from vehicles when two or fewer tracks vote
        (no MAD can be computed): about a degree at f = 600 px, i.e. no better than a
        guessed mounting.
    horizon_disagreement_sigmas : float
        Lane-marking and vehicle horizons further apart than this many combined sigmas
        disagree, and the markings are kept (3: a 0.3 % false alarm for Gaussian errors).
    pitch_offset_max_range_m : float
        Vehicles further than this [m] do not vote for a frame's body pitch (the same limit
        as ``horizon_vehicle_range_m``'s far end, for the same reason).
    pitch_offset_min_track_boxes : int
        Boxes a track needs before its median (the constant part of its pitch offsets: its
        size and road height) is known well enough to subtract.
    pitch_offset_clip_jitters : float
        A frame's body-pitch offset is clipped to this many ``horizon_jitter_deg`` sigmas
        (5: a braking dive of 0.8 deg is 5 sigma of 0.15 deg; beyond it, a wrong box).
    narrow_width_sigmas : float
        A track whose learnt width lies more than this many class sigmas below the prior is
        taken as standing on lower ground instead (4 sigma: 1.27 m for a car; partial
        occlusion rarely narrows a whole track that far).
    loose_size_std_m : float
        Spread of the size priors [m] of the first, loose fit from which each track learns
        its own width and height: 1 m, wide enough that the cues decide.
    scale_cue_min_width_share : float
        The box's scale change is a range cue only where its width is mostly the vehicle's
        width, d ln(w_px) / d ln(W) >= this: the box of a car well to the side is made by
        its flank, whose apparent length changes with the bearing as the ego passes, and
        its scale change then says little about range.
    filter_max_gap_s : float
        A track without a usable measurement for longer than this [s] is filtered in
        separate pieces: across a longer gap its range and rate are unknown, and carrying
        them over extrapolates a passing car through the camera (a track kept alive by the
        tracker is bridged for at most about a second).
    filter_max_receding_mps : float
        The fastest a vehicle draws away from the ego [m/s] (20: 72 km/h faster than the
        ego); a track whose whole box shrinks faster in width and height than that allows
        has become another object and is filtered in separate pieces.
    filter_scale_break_sigmas : float
        How many edge-noise sigmas beyond that bound a shrink must go, in both width and
        height, to split the track (3).
    top_alone_max_rel_error : float
        The top edge is a cue without the bottom edge (a near lead whose tyres are below the
        image) only when the vehicle's height is known to better than this share of its
        lever below (or above) the camera, sigma_H < 0.25 |H_cam - H|: a height learnt on the
        track, not the class prior (0.12 m against a lever of 0.15 m would be worth nothing
        and drive the fit to its bounds).
    max_log_range_std : float
        A single-frame fit whose log-range spread exceeds this is unobservable (0.5: the
        range is known to no better than a factor 1.65 either way).
    carry_frames : int
        A box whose bottom is below the image takes the ratio of the full fit to the fit of
        its sides alone from this many of its track's nearest frames that had both (10: a
        second at 10 fps; the ratio changes slowly as the bearing does).
    carry_floor_rel : float
        Least relative spread of that carried scale (0.02: the sides' pixel noise of a
        near car is 1-2 % of its width, and the ratio's drift over a second as much).
    standing_min_boxes : int
        Boxes a track needs before the ego's motion tests it as standing (5: half a second
        at 10 fps; fewer say little about one place in the world).
    standing_min_travel_m : float
        The ego must travel this far while a track is seen [m] for its parallax to range it
        (3 m: the baseline a 1 px bearing change resolves to 10 % at 30 m on KITTI's
        camera, f = 721 px, a car 8 m to the side).
    standing_max_ego_noise_m : float
        The ego's trajectory must be known to this [m] (one sigma, the trace stage's
        estimate): the baseline's error is the range's (the assembly's same bound; an
        INS/RTK such as KITTI's OXTS is known to a few cm, a phone GPS to 2-5 m).
    standing_max_chi2 : float
        Robust normalised residual above which a track's boxes fit no single place in the
        world (a vehicle crossing, turning, accelerating): the parked cars of KITTI raw 0001
        fit at 0.4-4.6 (bench_tracklets.py), a box noise model off by a factor 2-3 at most.
    standing_size_sigmas : float
        A standing fit whose width, height or length lies further than this many class
        sigmas from its class is no standing vehicle of that class (a tram moving at 9 m/s
        behind a 10 m/s ego fits as a 104 m long, 3.2 m wide standing tram; a box over two
        parked cars as a 2.8 m wide car: 9 sigma). Not 4: a high car among cars (2.17 m:
        5.6 sigma of the car prior) and a car whose flank its neighbour hides (width and
        length trade against each other seen obliquely) are standing cars too.
    standing_max_ground_m : float
        The ground a standing vehicle may stand on, off the ego's road plane [m]: kerbs,
        parking strips and crowns reach 0.5 m (KITTI raw 0001's parked row: 0.29-0.46 m
        below, the car park behind it 0.58 m, from the lidar tracklets).
    standing_scale_sigmas : float
        Sigmas of the common scale (:func:`vid2sim.detect.ranging.surface.scale_sigmas`)
        beyond which a track is a vehicle moving along the road, not a standing one (3: a
        car at 12 % of the ego's speed along its axis still passes: the monocular scale
        ambiguity, which the class priors alone resolve to about 4.5 %).
    standing_road_half_width_m : float
        Vehicles whose standing fit puts them within this lateral distance of the ego [m]
        are in the driving lanes (the ego's lane and the next ones: 1.5 lanes of 3.6 m),
        where most vehicles move: they need the scale test at ``standing_scale_sigmas``;
        beyond it (parking strips, kerbs, car parks), where most stand, at
        ``standing_scale_sigmas_beside_road``.
    standing_scale_sigmas_beside_road : float
        The scale test's bound beside the driving lanes (6, the size test's own: a small
        city car parked at the kerb, 1.45 x 3.40 m, fits 4-5.5 sigma small against the
        fleet's priors, KITTI raw 0001, and is no less standing for it).
    travel_yaw_search_deg : float
        The direction of the ego's travel is sought within this of its prior [deg] (the
        lane markings' and the camera file's axes differ by 0.5 deg on KITTI raw 0001; a
        dash-cam file is good to about a degree).
    travel_yaw_min_tracks : int
        Standing tracks the direction of travel needs before it is estimated from them
        (3: two lines meet in one point, a third checks it).
    standing_free_prior_factor : float
        The scale test fits each track once more with its size priors this many times as
        wide (10: a car's width then free within +-1.2 m), so that its sizes are what the
        boxes and the baseline alone say.
    standing_robust_sigmas : float
        Scale of the Cauchy weights of a standing fit's edges [sigmas]: an edge on another
        car (occlusion, a box over two cars) pulls no more than a few sigmas' worth (3: the
        usual choice of Cauchy IRLS, 95 % efficiency at Gaussian noise needs 2.4).
    standing_ground_prior_factor : float
        The standing fit's prior on its ground height is the road's spread at its lateral
        offset times this (2: the parallax, not the prior, should decide).
    ego_speed_std_mps : float
        One-sigma error of the ego's speed from its trajectory [m/s], the noise of the range
        rate a standing vehicle has (0.1: the smoothed OXTS trace of KITTI raw 0001 against
        its measured forward speed vf, RMSE 0.05 m/s, tests/geo/test_trace.py).
    surface_lateral_window_m : float
        A moving vehicle takes the ground of the standing vehicles within this lateral
        distance of it [m] (2: half a lane either way, the width of a parking strip).
    surface_floor_std_m : float
        Least spread of a ground height from standing vehicles [m]: the road under one car
        differs from its neighbour's by a few centimetres even on a smooth strip (camber,
        drainage gutters, 0.03 m).
    surface_cross_slope_min_tracks : int
        Standing vehicles beside the ego's lane that it takes to measure the road's cross
        slope for the moving vehicles no standing one is near (3: two points and the ego's
        lane fix a line with one to spare against an outlier).
    surface_robust_sigmas : float
        Cauchy scale of that fit, in residual sigmas (2.385: 95 % efficiency on Gaussian
        residuals, Holland & Welsch 1977); a car whose bottom a hedge hides reads its ground
        up to half its height too high.
    surface_band_m : float
        Lateral width of the surface next to the ego's lane whose standing vehicles give the
        cross slope [m] (4: a parking strip and a lane's width of scatter about it).
    """

    priors: dict[str, VehiclePrior] = field(default_factory=lambda: dict(DEFAULT_PRIORS))
    outlines: dict[str, OutlineShape] = field(default_factory=lambda: dict(CLASS_SHAPES))
    edge_noise_px: float = 1.0
    edge_noise_frac: float = 0.02
    road_height_std_m: float = 0.10
    road_height_std_per_lateral_m: float = 0.03
    fleet_width_mean_std_m: float = 0.08
    horizon_jitter_deg: float = 0.15
    camera_pitch_std_deg: float | None = None
    lane_horizon_std_px: float = 4.0
    border_margin_px: float = 8.0
    border_noise_sigmas: float = 2.0
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
    lane_horizon_min_hints: int = 3
    lane_horizon_floor_px: float = 1.0
    horizon_vehicle_min_box_px: tuple[float, float] = (20.0, 12.0)
    horizon_vehicle_range_m: tuple[float, float] = (5.0, 60.0)
    horizon_min_vehicles: int = 3
    horizon_typical_range_m: float = 20.0
    horizon_few_tracks_mad_px: float = 10.0
    horizon_disagreement_sigmas: float = 3.0
    pitch_offset_max_range_m: float = 60.0
    pitch_offset_min_track_boxes: int = 5
    pitch_offset_clip_jitters: float = 5.0
    narrow_width_sigmas: float = 4.0
    loose_size_std_m: float = 1.0
    scale_cue_min_width_share: float = 0.7
    filter_max_gap_s: float = 2.0
    filter_max_receding_mps: float = 20.0
    filter_scale_break_sigmas: float = 3.0
    top_alone_max_rel_error: float = 0.25
    max_log_range_std: float = 0.5
    carry_frames: int = 10
    carry_floor_rel: float = 0.02
    standing_min_boxes: int = 5
    standing_min_travel_m: float = 3.0
    standing_max_ego_noise_m: float = 0.5
    standing_max_chi2: float = 9.0
    standing_size_sigmas: float = 6.0
    standing_max_ground_m: float = 0.8
    standing_scale_sigmas: float = 3.0
    standing_road_half_width_m: float = 5.4
    standing_scale_sigmas_beside_road: float = 6.0
    standing_robust_sigmas: float = 3.0
    standing_free_prior_factor: float = 10.0
    travel_yaw_search_deg: float = 1.5
    travel_yaw_min_tracks: int = 3
    standing_ground_prior_factor: float = 2.0
    ego_speed_std_mps: float = 0.1
    surface_lateral_window_m: float = 2.0
    surface_floor_std_m: float = 0.03
    surface_cross_slope_min_tracks: int = 3
    surface_robust_sigmas: float = 2.385
    surface_band_m: float = 4.0

    def prior_for(self, category: VehicleCategory) -> VehiclePrior:
        return self.priors.get(category, self.priors[VehicleCategory.CAR])

    def pitch_std_for(self, camera: Camera) -> float:
        """One-sigma error of ``camera.pitch_deg`` [deg] (see ``camera_pitch_std_deg``)."""
        if self.camera_pitch_std_deg is not None:
            return self.camera_pitch_std_deg
        calibrated = camera.pitch_source is PitchSource.CALIBRATION
        return CALIBRATED_PITCH_STD_DEG if calibrated else GUESSED_PITCH_STD_DEG


def cuboid_config(config: RangingConfig | None = None) -> RangingConfig:
    """``config`` (default: the defaults) with every class's outline a cuboid: for boxes that
    are projections of 3D boxes (KITTI label 2D boxes), the model before issue 13."""
    cfg = config or RangingConfig()
    return replace(cfg, outlines={k: CUBOID for k in {*cfg.outlines, *cfg.priors}})
