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
    :param segment_gap_s: a gap longer than this splits the trace into segments smoothed
        apart, bridged by a straight line at constant speed: beyond ~10 s the
        constant-acceleration model's prediction spreads by tens of metres (sqrt(q dt^5 / 20))
        and end velocities in GPS noise, stretched over the gap by a cubic, invent motion
        (a 10 min gap while parked: 560 m of back-and-forth); such gaps are also warned about
    :param min_noise_m: floor of the position noise [m]
    :param max_noise_m: ceiling of the noise used to tell outliers from fixes [m]: a poor
        phone fix is within ~50 m (one sigma); a larger "noise" is fixes of different places
        (fixes alternating between two cities once gave 500 km and no outlier at all)
    :param jump_allowance_m: largest position error of a fix [m]: a step between fixes longer
        than ``v_max_mps * dt`` plus this cannot be driving plus GPS error (urban multipath
        stays below ~1 km; two such errors in opposite directions, 2 km)
    :param max_wild_share: share of the fixes that may lie impossibly far from the drive
        (a receiver's glitches, dropped as outliers); more is a trace that cannot be one
        drive, an input error (at least 3 such fixes)
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
    segment_gap_s: float = 10.0
    min_noise_m: float = 0.02
    max_noise_m: float = 50.0
    jump_allowance_m: float = 2000.0
    max_wild_share: float = 0.01
    noise_m: float | None = None
