"""Tuning of the ego-trajectory smoother (:func:`vid2sim.geo.trace.smooth_ego`)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class TraceParams:
    """Tuning of :func:`smooth_ego`; the defaults suit road vehicles.

    :param v_max_mps: fastest plausible speed; faster steps between fixes are outliers [m/s]
    :param jerk_psd: white-jerk power spectral density of the constant-acceleration model
        [m^2/s^5]; larger follows manoeuvres faster but passes more noise into speed
    :param gate_sigma: a fix farther than this many sigmas from the smoothed track is dropped
    :param gate_floor_m: ...but never one closer than this [m] (protects very precise traces
        from rejecting model mismatch)
    :param speed_sigma_mps: one-sigma error of a reported speed [m/s]
    :param course_sigma_deg: one-sigma error of a reported course [deg]
    :param stop_doppler_mps: reported speeds below this mean the vehicle is stopped [m/s]
    :param stop_min_s: shortest stop that is detected [s]
    :param stop_max_mps: a run of fixes moving faster than this is never called a stop [m/s]
    :param heading_min_speed_mps: below this speed the heading is held, not taken from noise
    :param gap_s: a time between accepted fixes longer than this is reported as a gap [s]
    :param min_noise_m: floor of the position noise [m]
    :param noise_m: white position noise [m] if known; default estimated from the fixes
    """

    v_max_mps: float = 70.0
    jerk_psd: float = 0.1
    gate_sigma: float = 4.5
    gate_floor_m: float = 0.5
    speed_sigma_mps: float = 0.3
    course_sigma_deg: float = 5.0
    stop_doppler_mps: float = 0.25
    stop_min_s: float = 1.5
    stop_max_mps: float = 1.0
    heading_min_speed_mps: float = 0.5
    gap_s: float = 2.0
    min_noise_m: float = 0.02
    noise_m: float | None = None
