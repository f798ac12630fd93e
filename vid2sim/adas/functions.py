"""The built-in driving functions of ``vid2sim test-policy``: ACC, AEB, LKA and the recorded
driver, reading the camera observation of :mod:`vid2sim.adas.sensor`.

Each function maps a :class:`~vid2sim.adas.sensor.CameraFrame` to a command; a
:class:`DrivingFunction` combines one longitudinal controller (the recorded driver or ACC),
optionally AEB on top of it and optionally LKA for the steering, and turns the commands into
the environment's action (``accel_to_action``). Signs: accelerations positive forward,
steering and lateral offsets positive LEFT (ISO 8855); the environment's own steering sign is
mirrored and converted here.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from vid2sim.adas.sensor import CameraFrame, read_frame
from vid2sim.core.scenario import Trajectory

DEFAULT_ACCEL_RANGE_MPS2 = (-8.0, 8.0)
DEFAULT_STEERING_RANGE_RAD = (-math.pi / 4, math.pi / 4)
MIN_SET_SPEED_MPS = 30 / 3.6
"""Lowest ACC set speed [m/s]: 30 km/h, the bottom of the set-speed range car makers offer."""


def idm_acceleration(speed_mps: float, desired_speed_mps: float, gap_m: float | None,
                     closing_mps: float, *, time_gap_s: float, min_gap_m: float,
                     max_accel_mps2: float, comfort_decel_mps2: float) -> float:
    """The Intelligent Driver Model (Treiber, Hennecke and Helbing 2000) [m/s^2]:

    ``a = a_max [1 - (v / v0)^4 - (s* / s)^2]``,
    ``s* = s0 + max(0, v T + v dv / (2 sqrt(a_max b)))``, ``dv`` the closing speed, ``s`` the
    gap (no interaction term without a lead: ``gap_m`` None or infinite).
    """
    v = max(float(speed_mps), 0.0)
    a = max_accel_mps2 * (1.0 - (v / max(desired_speed_mps, 0.1)) ** 4)
    if gap_m is not None and math.isfinite(gap_m):
        s_star = min_gap_m + max(0.0, v * time_gap_s + v * closing_mps
                                 / (2.0 * math.sqrt(max_accel_mps2 * comfort_decel_mps2)))
        a -= max_accel_mps2 * (s_star / max(gap_m, 0.1)) ** 2
    return a


def accel_to_action(accel_mps2: float,
                    accel_range_mps2: tuple[float, float] = DEFAULT_ACCEL_RANGE_MPS2) -> np.ndarray:
    """Inverse of the environment's linear map from [-1, 1] to ``accel_range_mps2`` (clipped)."""
    lo, hi = accel_range_mps2
    a = 2.0 * (float(accel_mps2) - lo) / (hi - lo) - 1.0
    return np.array([np.clip(a, -1.0, 1.0)], dtype=np.float32)


def _to_unit(value: float, value_range: tuple[float, float]) -> float:
    lo, hi = value_range
    return float(np.clip(2.0 * (value - lo) / (hi - lo) - 1.0, -1.0, 1.0))


def iso_acc_limits(speed_mps: float) -> tuple[float, float]:
    """ACC's largest automatic deceleration [m/s^2] and negative jerk [m/s^3] at a speed.

    ISO 15622:2018 (ACC) with ISO 22179 (full-speed-range ACC): 5 m/s^2 and 5 m/s^3 below
    5 m/s, 3.5 m/s^2 and 2.5 m/s^3 above 20 m/s, linear in between. Stronger braking is the
    driver's (or AEB's) job.
    """
    w = float(np.clip((speed_mps - 5.0) / 15.0, 0.0, 1.0))
    return 5.0 - 1.5 * w, 5.0 - 2.5 * w


# --------------------------------------------------------------------------- longitudinal


@dataclass
class RecordedDriver:
    """The recorded driver's speed profile: the logged acceleration fed forward plus feedback
    on the speed and on the distance travelled (odometer against the log's path length).

    The feedback is bounded (at most ``max_extra_accel_mps2`` more and
    ``max_extra_decel_mps2`` less than the logged acceleration) so that a driver held up (by
    AEB, say) takes the log up again as a driver would, not by racing to where the log was.
    """

    log: Trajectory
    kp_speed_per_s: float = 1.0
    kp_position_per_s2: float = 0.5
    max_position_correction_mps2: float = 1.0
    max_extra_accel_mps2: float = 1.0
    max_extra_decel_mps2: float = 2.0

    def __post_init__(self) -> None:
        t = self.log.t
        self._accel = np.gradient(self.log.speed, t) if len(self.log) > 1 else np.zeros(1)
        self._s = np.r_[0.0, np.cumsum(np.hypot(np.diff(self.log.x), np.diff(self.log.y)))]

    def acceleration(self, frame: CameraFrame) -> float:
        t = frame.t_s
        along_err_m = float(np.interp(t, self.log.t, self._s)) - frame.odometer_m
        correction = float(np.clip(self.kp_position_per_s2 * along_err_m,
                                   -self.max_position_correction_mps2,
                                   self.max_position_correction_mps2))
        feedback = self.kp_speed_per_s * (float(np.interp(t, self.log.t, self.log.speed))
                                          - frame.speed_mps) + correction
        return float(np.interp(t, self.log.t, self._accel)) + float(np.clip(
            feedback, -self.max_extra_decel_mps2, self.max_extra_accel_mps2))


@dataclass
class AdaptiveCruise:
    """Adaptive cruise control: IDM car following towards a set speed and time gap, braking
    within ISO 15622's limits (:func:`iso_acc_limits`) and rate-limited by them.

    Oncoming objects (lead speed below ``-1 m/s``) are not followed: ACC is not required to
    react to them (ISO 15622 scope); AEB is.
    """

    set_speed_mps: float
    time_gap_s: float = 1.5
    """ISO 15622 asks for at least one selectable gap in 1.5-2.2 s; 1.5 s is the common
    default setting."""
    standstill_gap_m: float = 3.0
    """Gap kept when stopped behind a car [m] (full-speed-range ACC stops 2-5 m behind)."""
    max_accel_mps2: float = 1.5
    comfort_decel_mps2: float = 2.0
    """IDM's a and b [m/s^2]: the passenger-car values of Treiber and Kesting (2013)."""
    _last_mps2: float | None = field(default=None, repr=False)

    def acceleration(self, frame: CameraFrame) -> float:
        v = frame.speed_mps
        lead = frame.lead
        gap, closing = None, 0.0
        if lead is not None and v + lead.range_rate_mps > -1.0:
            gap, closing = lead.range_m, -lead.range_rate_mps
        a = idm_acceleration(v, self.set_speed_mps, gap, closing, time_gap_s=self.time_gap_s,
                             min_gap_m=self.standstill_gap_m, max_accel_mps2=self.max_accel_mps2,
                             comfort_decel_mps2=self.comfort_decel_mps2)
        max_decel, max_jerk = iso_acc_limits(v)
        a = float(np.clip(a, -max_decel, self.max_accel_mps2))
        if self._last_mps2 is not None:
            step = max_jerk * 0.1  # [m/s^2 per 0.1 s policy step]
            a = float(np.clip(a, self._last_mps2 - step, self._last_mps2 + step))
        self._last_mps2 = a
        return a


# --------------------------------------------------------------------------- AEB


def time_to_contact(gap_m: float, closing_mps: float, closing_accel_mps2: float) -> float:
    """Time until the gap closes [s] at constant closing acceleration (the enhanced TTC of
    GB/T 33577; the plain gap / closing speed when the acceleration is 0), ``inf`` if never."""
    if gap_m <= 0.0:
        return 0.0
    a, v = closing_accel_mps2, closing_mps
    disc = v * v + 2.0 * a * gap_m
    if disc < 0.0:
        return math.inf  # the closing stops first
    # the smaller positive root of gap = v t + a t^2 / 2, in the form that does not cancel
    root = math.sqrt(disc)
    if v >= 0.0:
        return 2.0 * gap_m / (v + root) if v + root > 0.0 else math.inf
    return (root - v) / a if a > 0.0 else math.inf  # opening now, closing later


@dataclass
class EmergencyBraking:
    """Forward collision warning, then staged autonomous braking, as a Euro NCAP car-to-car AEB
    function (test scenarios CCRs, CCRm, CCRb of the Euro NCAP AEB C2C test protocol; the
    tests in ``tests/adas/test_functions.py`` run them).

    Stages are entered on time-to-collision thresholds that grow with the closing speed
    ``dv``: the time a stage's deceleration needs to cancel ``dv`` (``dv / (2 a)``) plus a
    delay. The time to collision is the enhanced TTC of GB/T 33577 (ETTC: constant relative
    acceleration, so a braking target counts; its deceleration is estimated from the range
    rate's slope). The deceleration ``a_req`` required to stop short of the target (which may
    brake to a stop) escalates:

    - FCW (warning only): ``ETTC < reaction_time_s + dv / (2 driver_decel_mps2)`` or
      ``a_req > driver_decel_mps2`` (a warned driver must brake harder than comfortable);
    - partial braking at ``partial_decel_mps2``: ``ETTC < system_delay_s + dv / (2 partial)``;
    - full braking at ``full_decel_mps2``: ``ETTC < system_delay_s + dv / (2 full)`` or
      ``a_req > partial_decel_mps2`` (partial braking would not do).

    A stage holds until the threat is over (no longer closing and ``a_req`` below 1 m/s^2) or
    the lead is gone. Braked to a standstill behind a lead that stays (slower than 1 m/s,
    within ``hold_range_m``), the brake is held until it drives off (a standstill hold as
    production systems have: the recorded driver would otherwise creep into it). ``events``
    records ``(t_s, "fcw" | "partial" | "full" | "hold")`` on each entry.
    """

    reaction_time_s: float = 1.2
    """Driver brake reaction time to a warning [s] (Green 2000, "How long does it take to
    stop?": about 1.25 s for an unexpected but common event)."""
    driver_decel_mps2: float = 3.4
    """Braking of a warned driver [m/s^2]: AASHTO's comfortable deceleration for most drivers
    (Green Book, 2011)."""
    partial_decel_mps2: float = 4.0
    """First braking stage [m/s^2], about 0.4 g as production systems' partial braking."""
    full_decel_mps2: float = 8.0
    """Full braking [m/s^2]: the environment's deceleration limit (dry asphalt gives 8-10)."""
    system_delay_s: float = 0.6
    """Sensor latency (0.1 s), policy period (0.1 s), brake build-up (0.3 s) and 0.1 s margin."""
    margin_m: float = 1.0
    """Gap left when computing the required deceleration [m]."""
    braking_target_mps2: float = -1.0
    """A lead decelerating harder than this is a braking target [m/s^2] (below, range-rate
    noise would fake one)."""
    lead_accel_window_s: float = 1.0
    hold_range_m: float = 10.0
    stage: int = 0
    holding: bool = False
    events: list = field(default_factory=list)
    _rates: deque = field(default_factory=lambda: deque(maxlen=16), repr=False)

    def _lead_accel(self, frame: CameraFrame) -> float:
        """The lead's acceleration [m/s^2]: own acceleration plus the slope of the range rate
        over the last ``lead_accel_window_s`` (least squares)."""
        lead = frame.lead
        self._rates.append((frame.t_s, lead.range_rate_mps))
        pts = [(t, r) for t, r in self._rates if t >= frame.t_s - self.lead_accel_window_s - 1e-9]
        if len(pts) < 3:
            return frame.accel_mps2
        t, r = np.array(pts).T
        slope = float(np.polyfit(t - t[-1], r, 1)[0])
        return frame.accel_mps2 + slope

    def required_decel(self, frame: CameraFrame, lead_accel_mps2: float) -> float:
        """Constant deceleration [m/s^2] that just avoids reaching the lead (minus
        ``margin_m``), given its own deceleration when it brakes (below -1 m/s^2)."""
        lead = frame.lead
        v_e = max(frame.speed_mps, 0.0)
        v_l = max(v_e + lead.range_rate_mps, 0.0)
        closing = v_e - v_l
        g = max(lead.range_m - self.margin_m, 0.05)
        if v_l < 0.5:  # a stopped (or stopping) lead: stop behind it
            return v_e * v_e / (2.0 * g)
        if lead_accel_mps2 < self.braking_target_mps2:
            b = -lead_accel_mps2
            stop_ego = v_e * v_e / (2.0 * (g + v_l * v_l / (2.0 * b)))
            if stop_ego > 0 and v_e / stop_ego >= v_l / b:  # the lead stops first
                return stop_ego
            return b + max(closing, 0.0) ** 2 / (2.0 * g)
        return max(closing, 0.0) ** 2 / (2.0 * g)

    def command(self, frame: CameraFrame, requested_mps2: float) -> float:
        """The acceleration to apply [m/s^2]: the request, or the braking stage's."""
        lead = frame.lead
        if lead is None:
            self.stage, self.holding = 0, False
            self._rates.clear()
            return requested_mps2
        if self.holding:
            if frame.speed_mps + lead.range_rate_mps > 1.0 or lead.range_m > self.hold_range_m:
                self.stage, self.holding = 0, False  # the lead drives off: the driver's turn
            else:
                return min(requested_mps2, -self.partial_decel_mps2)
        closing = -lead.range_rate_mps
        lead_accel = self._lead_accel(frame)
        a_lead = lead_accel if lead_accel < self.braking_target_mps2 else 0.0
        ettc = time_to_contact(lead.range_m, closing, frame.accel_mps2 - a_lead)
        a_req = self.required_decel(frame, lead_accel)
        dv = max(closing, 0.0)
        stage = 0
        if ettc < self.reaction_time_s + dv / (2 * self.driver_decel_mps2) or (
                a_req > self.driver_decel_mps2):
            stage = 1
        if ettc < self.system_delay_s + dv / (2 * self.partial_decel_mps2):
            stage = 2
        if ettc < self.system_delay_s + dv / (2 * self.full_decel_mps2) or (
                a_req > self.partial_decel_mps2):
            stage = 3
        if self.stage >= 2 and frame.speed_mps < 0.3:  # braked to a stop: hold it there
            self.holding = True
            self.events.append((frame.t_s, "hold"))
            return min(requested_mps2, -self.partial_decel_mps2)
        if stage > self.stage:
            self.events.append((frame.t_s, ("fcw", "partial", "full")[stage - 1]))
            self.stage = stage
        elif closing <= 0.0 and a_req < 1.0:
            self.stage = 0  # the threat is over
        if self.stage == 3:
            return min(requested_mps2, -self.full_decel_mps2)
        if self.stage == 2:
            return min(requested_mps2, -self.partial_decel_mps2)
        return requested_mps2


# --------------------------------------------------------------------------- LKA


@dataclass
class LaneKeeping:
    """Lane keeping: steer the ego's centre to its lane's centre from the lane model.

    A cascade as highway-env's lane follower, on measurements: the lateral offset gives a
    lateral-speed command (``-k_lateral y``) hence a course reference, less the steady-turn
    sideslip; the heading error gives a yaw-rate command on top of the lane curvature's
    ``v kappa``; the kinematic bicycle model
    (highway-env's: yaw rate ``v sin(beta) / (L/2)``, ``tan(beta) = tan(delta) / 2``) turns it
    into a front-wheel angle. Without a lane model the last angle is held.
    """

    length_m: float
    k_lateral_per_s: float = 0.5
    """Lateral offset to lateral speed [1/s]: a 2 s time constant, slow enough to average the
    lane model's noise."""
    k_heading_per_s: float = 2.5
    """Heading error to yaw rate [1/s]: 0.4 s, four policy periods and sensor latencies."""
    _last_rad: float = field(default=0.0, repr=False)

    def steering(self, frame: CameraFrame) -> float:
        """Front-wheel angle [rad], positive left."""
        lane = frame.lane
        if lane is None:
            return self._last_rad
        v = max(frame.speed_mps, 1.0)
        course_ref = math.asin(float(np.clip(-self.k_lateral_per_s * lane.lateral_offset_m / v,
                                             -0.5, 0.5)))
        # in a steady turn the bicycle model's velocity points sin(beta) = kappa L / 2 inside
        # its heading, so the heading that keeps the course lies that much outside
        slip = math.asin(float(np.clip(lane.curvature_per_m * self.length_m / 2.0, -1.0, 1.0)))
        yaw_rate = v * lane.curvature_per_m + self.k_heading_per_s * (
            course_ref - slip - lane.heading_error_rad)
        beta = math.asin(float(np.clip(yaw_rate * self.length_m / 2.0 / v, -1.0, 1.0)))
        self._last_rad = math.atan(2.0 * math.tan(beta))
        return self._last_rad


# --------------------------------------------------------------------------- composition


@dataclass
class DrivingFunction:
    """A policy ``(observation, info) -> action`` from a longitudinal controller, optional AEB
    and optional LKA, reading the camera observation (``info`` is not used: it holds the
    simulator's exact values, which a driving function does not have)."""

    longitudinal: RecordedDriver | AdaptiveCruise
    aeb: EmergencyBraking | None = None
    lka: LaneKeeping | None = None
    accel_range_mps2: tuple[float, float] = DEFAULT_ACCEL_RANGE_MPS2
    steering_range_rad: tuple[float, float] = DEFAULT_STEERING_RANGE_RAD

    @property
    def lateral(self) -> bool:
        """Needs the environment's lateral control."""
        return self.lka is not None

    @property
    def events(self) -> list:
        return self.aeb.events if self.aeb is not None else []

    def __call__(self, obs: np.ndarray, info: dict | None = None) -> np.ndarray:
        frame = read_frame(obs)
        accel = self.longitudinal.acceleration(frame)
        if self.aeb is not None:
            accel = self.aeb.command(frame, accel)
        action = accel_to_action(accel, self.accel_range_mps2)
        if self.lka is None:
            return action
        # the environment's steering is positive to the right (mirrored frame)
        steer = _to_unit(-self.lka.steering(frame), self.steering_range_rad)
        return np.array([action[0], steer], dtype=np.float32)
