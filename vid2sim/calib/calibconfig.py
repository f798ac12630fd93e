"""The tuned numbers of camera self-calibration, each with its reason and source."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vid2sim.base.errors import ImpossibleValueError
from vid2sim.core.camera import DEFAULT_HEIGHT_M, DEFAULT_HFOV_DEG


@dataclass(frozen=True, slots=True)
class CalibrationConfig:
    """Priors, noise levels and sampling of :func:`vid2sim.calib.calibrate`.

    Priors (used where the video cannot tell, and always named in a warning then):

    :param hfov_prior_deg: horizontal field of view a camera is assumed to have before the
        data speaks: the project's default camera's (:data:`vid2sim.core.camera.
        DEFAULT_HFOV_DEG`; consumer dash-cams record 90-140 deg diagonally, 75-110 deg
        across after their own crop; phone main cameras 63-75 deg across)
    :param log_f_prior_std: one-sigma of ln(focal length) about it (0.35: 50-120 deg within
        two sigma)
    :param height_prior_m: camera above the road: the default camera's (a windscreen
        dash-cam in a passenger car sits 1.2-1.4 m high, in an SUV or van 1.5-2.0 m, a
        roof rig such as KITTI's 1.65 m)
    :param log_h_prior_std: one-sigma of ln(height) about it (0.2)
    :param k1_prior_std: one-sigma of the radial coefficient k1 about 0 (real lenses -0.4 to
        +0.1 after the maker's correction, OpenCV's model at normalised radius)
    :param k2_prior_std: one-sigma of k2 about 0 (second-order terms of consumer lenses
        stay within a tenth of k1's size)
    :param mount_prior_deg: one-sigma of pitch and yaw of the mount (dash-cams are aimed by
        eye within a few degrees)
    :param roll_prior_deg: one-sigma of the roll (a suction mount levels to ~1-2 deg)
    :param lane_width_prior_m: lane width where no map says it: urban lanes 3.0-3.25 m,
        rural and main roads 3.5 m (RASt 06), US 3.3-3.6 m (FHWA 11-12 ft)
    :param lane_width_prior_std_m: its one-sigma across roads

    Noise of the measurements:

    :param flow_noise_px: one-sigma of a tracked point's position in the later frame [px]
        (Lucas-Kanade on compressed video: 0.4-0.6 px scatter of good road tracks on KITTI
        raw 0001 about the fitted ground motion)
    :param chain_noise_px: one-sigma of an edge chain's mean position across it [px]
    :param vp_floor_px: a floor on the vanishing point's spread [px]: bends and grades move
        the road's vanishing point by a few pixels for seconds
    :param gps_speed_std_mps: GPS speed noise per flow pair [m/s] (Doppler speed of
        consumer receivers 0.05-0.2 m/s; speeds from smoothed positions are as good)
    :param gps_scale_std: relative error of GPS distances that all pairs share (antenna
        offset and smoothing; 1 %)
    :param gps_yaw_rate_std: heading-rate noise of a smoothed GPS course [rad/s]
    :param body_pitch_std_deg: spread of the body's pitch about the mount's in one frame
        (suspension, 0.3-0.5 deg on KITTI's OXTS)
    :param pitch_change_std_deg: spread of the body pitch change between a pair's frames
    :param slip_std: sideways motion of the ego per metre driven (lane changes: 1 m/s
        sideways at 10-20 m/s)

    Sampling:

    :param pair_interval_s: time between a flow pair's two frames [s] (one frame at 10 fps,
        two at 30 fps: the road moves a few pixels)
    :param pair_every_s: a flow pair starts every this many seconds (the time sync needs
        the motion's profile at this resolution)
    :param max_pairs: flow pairs in the joint fit (more only cost time)
    :param max_points_per_pair: road points per pair in the joint fit
    :param line_frames: frames with edge chains and road segments
    :param chain_points: points per edge chain in the fit (the detect wing's reduction)
    :param ground_range_h: road points used lie this many camera heights ahead (near,
        far): nearer the motion blurs, farther the flow is below a pixel
    :param ground_half_width_h: and within this many heights beside the camera: the ego's
        lane, where the road is a plane (kerbs, track beds and parked cars beside it stand
        above it and read as roll and distortion: 2.5 heights put roll at +1.1 to +2.1 deg
        on re-imaged KITTI raw 0001 clips of roll -0.4 to +0.5 deg, 1.0 within 0.6 deg)
    :param outlier_sigmas: a point whose residual exceeds this many robust sigmas of its
        pair is dropped (cars, shadows, bad tracks)
    :param k1_systematic_std: the lens's k1 scatters about the truth beyond the fit's own
        one-sigma, which counts only the edges' pixel noise: on 9 real KITTI raw 0001 clips
        (untouched and re-imaged) k1 read -0.06..+0.21 off (RMS 0.09) where the fit said
        +-0.014-0.04, since the world's long edges (kerbs on bends, wires, rails) are not
        all straight; added in quadrature to k1's one-sigma
    :param k1_exclusion_sigmas: an estimated k1 within this many (honest) sigmas of 0 is
        refused and the lens held distortion-free (the plumb lines then tell a bow from
        the world's own curves no better than chance; a k1 of -0.06 on KITTI's rectified
        frames put near cars 1 % closer at the image bottom)
    :param vehicle_mask_pad: where vehicle boxes are known (the build's detector or
        imported boxes), flow points inside a box widened by this share of its size on each
        side are not road: a car driving ahead in the ego lane moves with the ego, and on
        composite clips with a car 13-25 m ahead its points were a quarter of the fitted
        "road" and put the focal length 48 % short (masked with the true box: 2 %); the
        box moves a few pixels within a pair's 0.1 s and detector boxes are loose by ~5 %
    """

    hfov_prior_deg: float = DEFAULT_HFOV_DEG
    log_f_prior_std: float = 0.35
    height_prior_m: float = DEFAULT_HEIGHT_M
    log_h_prior_std: float = 0.2
    k1_prior_std: float = 0.25
    k2_prior_std: float = 0.05
    mount_prior_deg: float = 5.0
    roll_prior_deg: float = 2.0
    lane_width_prior_m: float = 3.4
    lane_width_prior_std_m: float = 0.35
    flow_noise_px: float = 0.5
    chain_noise_px: float = 0.45
    vp_floor_px: float = 2.0
    gps_speed_std_mps: float = 0.15
    gps_scale_std: float = 0.01
    gps_yaw_rate_std: float = 0.01
    body_pitch_std_deg: float = 0.4
    pitch_change_std_deg: float = 0.3
    slip_std: float = 0.05
    pair_interval_s: float = 0.1
    pair_every_s: float = 0.2
    max_pairs: int = 80
    max_points_per_pair: int = 100
    line_frames: int = 20
    chain_points: int = 40
    ground_range_h: tuple[float, float] = (2.0, 25.0)
    ground_half_width_h: float = 1.0
    outlier_sigmas: float = 3.0
    k1_systematic_std: float = 0.05
    k1_exclusion_sigmas: float = 2.0
    vehicle_mask_pad: float = 0.1

    #: the one-sigma the clip alone must give a parameter for it to count as observed (a
    #: focal length known to 8 % scales ranges by as much: beyond it, the prior's value
    #: is reported as the prior): ln f, k1, k2, pitch, yaw, roll [rad], ln h
    useful_log_f_std: float = 0.08
    useful_k1_std: float = 0.1
    useful_angle_std_deg: float = 1.0
    useful_log_h_std: float = 0.10

    def useful_std(self) -> np.ndarray:
        """The observability thresholds in the order of the fit's globals."""
        a = math.radians(self.useful_angle_std_deg)
        return np.array([self.useful_log_f_std, self.useful_k1_std, 0.5 * self.useful_k1_std,
                         a, a, a, self.useful_log_h_std])

    def check(self) -> None:
        """Raise :class:`ImpossibleValueError` for settings no calibration can use."""
        positive = {k: getattr(self, k) for k in (
            "hfov_prior_deg", "log_f_prior_std", "height_prior_m", "log_h_prior_std",
            "lane_width_prior_m", "lane_width_prior_std_m", "flow_noise_px", "chain_noise_px",
            "pair_interval_s", "pair_every_s")}
        for name, v in positive.items():
            if not (math.isfinite(v) and v > 0):
                raise ImpossibleValueError(None, f"calibration {name} must be positive, got {v}")
        if not (math.isfinite(self.vehicle_mask_pad) and self.vehicle_mask_pad >= 0):
            raise ImpossibleValueError(None, "calibration vehicle_mask_pad must be 0 or more, "
                                       f"got {self.vehicle_mask_pad}")
        if not 1.0 < self.hfov_prior_deg < 170.0:
            raise ImpossibleValueError(None, f"hfov_prior_deg {self.hfov_prior_deg} is not a "
                                       "lens's field of view")
