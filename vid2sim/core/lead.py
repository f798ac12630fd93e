"""The one definition of the lead vehicle and of lanes relative to the ego lane, shared by
tracking, the report and the environment.

The lead is the nearest vehicle AHEAD of the ego (its rear beyond the ego's reference point,
within a maximum range) whose centre lies in the ego's corridor: within half a lane width of
the ego's lane centre, measured across the lane. Tracking adds hysteresis on top (a car
drifting along a lane line keeps its lane; a rival must be clearly nearer to take over, see
:mod:`vid2sim.detect.assign`), but the geometry is this one.

Lanes relative to the ego lane are numbered 0 (the ego lane), +1, +2, ... to the left and
-1, -2, ... to the right, named "ego", "left", "right", "left2", "right2", ...
(:func:`lane_name`). Where the lane markings were measured, the ego lane's centre line ahead
is the lane model's (:func:`lane_centre_m`: offset, heading and curvature in the vehicle
frame); otherwise it is the camera's axis on the road.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from vid2sim.core.records import LaneTrack

#: The lane model's curvature is trusted this far ahead [m]; beyond, the centre line goes on
#: straight along its direction there. Lines are measured out to 35 m, but their curvature
#: is fitted mostly from the near rows: on KITTI raw 0001 the ego lane's left boundary,
#: against the same line fixed in the world with the OXTS poses, is off by 0.07 / 0.16 /
#: 0.32 / 0.64 m RMS at 10 / 20 / 30 / 40 m with 15 m and 0.07 / 0.17 / 0.42 / 0.77 m with
#: 25 m (0.44 / 0.62 / 1.00 / 1.58 m for the camera axis and a 3.5 m lane);
#: ``python benchmarks/bench_lanes.py --kitti``.
LANE_MODEL_REACH_M = 20.0

#: Beyond this distance ahead [m] the ego lane's centre line follows the road's course (where
#: the ego itself drove, :mod:`vid2sim.geo.course`) from the lane model's direction there,
#: instead of the lane model's curvature: against the world-fixed line on KITTI raw 0001,
#: 0.13 / 0.20 / 0.39 m RMS at 20 / 30 / 40 m (lane model: 0.16 / 0.35 / 0.64), on the demo
#: against its true lane 0.26 / 0.50 / 0.76 m (0.32 / 0.76 / 1.48) with the join at 10 m;
#: joined at 15 m, 0.15 / 0.26 / 0.46 and 0.30 / 0.60 / 0.94 m
#: (``python benchmarks/bench_lanes.py``). Re-measured at issue 19's merge with the boundary
#: beside the camera (lane track + OXTS) fixed in the world as the reference (``bench_lanes.py
#: --kitti``, last table): 0.08 / 0.15 / 0.22 / 0.42 m RMS at 10 / 20 / 30 / 40 m with the
#: course, 0.08 / 0.23 / 0.53 / 0.86 m with the lane model alone.
COURSE_JOIN_M = 10.0

#: Largest |lane| relative to the ego lane: a carriageway has at most 16 lanes
#: (vid2sim.core.scenario.MAX_LANES), so a vehicle further lanes away is not on the ego's road
#: (or its position is wrong) and its lane is unknown.
MAX_RELATIVE_LANE = 16


def lane_name(index: int) -> str:
    """0 -> "ego", 1 -> "left", -1 -> "right", 2 -> "left2", -3 -> "right3"."""
    if index == 0:
        return "ego"
    side = "left" if index > 0 else "right"
    return side if abs(index) == 1 else f"{side}{abs(index)}"


def lane_index(name: str) -> int | None:
    """Inverse of :func:`lane_name`: "ego" -> 0, "left2" -> 2, "right" -> -1; None for ""
    (unknown) or a name that is not a lane's."""
    if name == "ego":
        return 0
    for side, sign in (("left", 1), ("right", -1)):
        if name.startswith(side):
            rest = name[len(side):]
            if rest == "":
                return sign
            if rest.isdigit() and int(rest) >= 2 and rest == str(int(rest)):
                return sign * int(rest)
    return None


def lane_centre_m(x_m: np.ndarray | float, offset_m: np.ndarray | float,
                  heading_rad: np.ndarray | float, curvature_inv_m: np.ndarray | float,
                  reach_m: float = LANE_MODEL_REACH_M) -> np.ndarray:
    """Lateral position [m, positive left] of the ego lane's centre line at ``x_m`` ahead of
    the camera's ground point, in the vehicle frame.

    The centre line is ``offset + heading x + curvature x^2 / 2`` up to ``reach_m`` and
    straight along its direction there beyond (see :data:`LANE_MODEL_REACH_M`).

    Parameters
    ----------
    x_m : distance ahead [m] (negative: behind, where the line is taken straight)
    offset_m : the centre line beside the camera (x = 0) [m]; minus the camera's offset
        from the lane's middle
    heading_rad : the lane's direction relative to the vehicle's x axis [rad, positive left]
    curvature_inv_m : the lane's curvature [1/m, positive bending left]
    """
    x = np.asarray(x_m, dtype=float)
    xr = np.clip(x, 0.0, reach_m)
    return (np.asarray(offset_m, dtype=float) + np.asarray(heading_rad, dtype=float) * x
            + np.asarray(curvature_inv_m, dtype=float) * xr * (x - 0.5 * xr))


def in_ego_corridor(lateral_m: np.ndarray | float, lane_width_m: float) -> np.ndarray:
    """True where a centre ``lateral_m`` across the ego lane's centre line [m] lies in the ego
    lane (boundary included)."""
    return np.abs(np.asarray(lateral_m, dtype=float)) <= lane_width_m / 2.0


def nearest_ahead(ahead_m: np.ndarray, candidate: np.ndarray,
                  max_range_m: float = math.inf, nearness_m: np.ndarray | None = None
                  ) -> np.ndarray | int:
    """Index of the nearest candidate with ``0 < ahead_m <= max_range_m``, or -1.

    Parameters
    ----------
    ahead_m : ndarray, (A,) or (A, T)
        Distance from the ego's reference point along the lane to each vehicle [m] (NaN for
        unknown): a vehicle is ahead where it is positive. With a second axis, one answer per
        instant (vehicles along the first axis).
    candidate : ndarray of bool, shaped as ``ahead_m``
        Vehicles that may be the lead (in the ego corridor).
    max_range_m : float
        Farther vehicles are not the lead [m].
    nearness_m : ndarray, optional
        What "nearest" compares (default ``ahead_m``): e.g. the bumper-to-bumper gap where
        ``ahead_m`` is measured between the vehicles' centres.

    Returns
    -------
    int for (A,) input, (T,) int array for (A, T) input; -1 where there is no candidate. Of
    equally near candidates the first wins.
    """
    ahead = np.asarray(ahead_m, dtype=float)
    ok = np.asarray(candidate, dtype=bool) & np.isfinite(ahead) & (ahead > 0) & (
        ahead <= max_range_m)
    near = ahead if nearness_m is None else np.asarray(nearness_m, dtype=float)
    ok &= ~np.isnan(near)
    keyed = np.where(ok, near, np.inf)
    if keyed.size == 0:
        return -1 if ahead.ndim <= 1 else np.full(ahead.shape[1:], -1, dtype=int)
    best = np.argmin(keyed, axis=0)
    found = np.take_along_axis(ok, best[None], axis=0)[0] if ahead.ndim > 1 else ok[best]
    out = np.where(found, best, -1)
    return int(out) if ahead.ndim <= 1 else out.astype(int)


def lead_of(ahead_m: np.ndarray, lateral_m: np.ndarray, lane_width_m: float,
            max_range_m: float = math.inf, nearness_m: np.ndarray | None = None
            ) -> np.ndarray | int:
    """THE lead rule: index of the lead among vehicles at ``ahead_m`` along and ``lateral_m``
    (of their centre) across the ego lane [m], or -1 when there is none: the nearest one
    ahead whose centre lies in the ego's corridor. Shapes and ``nearness_m`` as
    :func:`nearest_ahead` ((A, T) arrays give one lead per instant)."""
    return nearest_ahead(ahead_m, in_ego_corridor(lateral_m, lane_width_m), max_range_m,
                         nearness_m)


def lane_centre_ahead_m(x_m: np.ndarray | float, offset_m: np.ndarray | float,
                        heading_rad: np.ndarray | float, curvature_inv_m: np.ndarray | float,
                        bend_m: np.ndarray | float, join_m: float = COURSE_JOIN_M,
                        reach_m: float = LANE_MODEL_REACH_M) -> np.ndarray:
    """:func:`lane_centre_m` continued along the road's course beyond ``join_m``.

    Up to ``join_m`` the centre line is the lane model's; beyond, it leaves the model's
    point and direction at ``join_m`` and bends as the road's course does: ``bend_m`` is how
    far left of the course's tangent at the join the course lies at ``x_m``
    (:meth:`vid2sim.geo.course.RoadCourse.bend_m`). Where ``bend_m`` is NaN (the course
    does not reach), the lane model alone.
    """
    x = np.asarray(x_m, dtype=float)
    model = lane_centre_m(x, offset_m, heading_rad, curvature_inv_m, reach_m)
    y_join = lane_centre_m(join_m, offset_m, heading_rad, curvature_inv_m, reach_m)
    dir_join = (np.asarray(heading_rad, dtype=float)
                + np.asarray(curvature_inv_m, dtype=float) * min(join_m, reach_m))
    bend = np.asarray(bend_m, dtype=float)
    along = y_join + dir_join * (x - join_m) + bend
    return np.where((x > join_m) & np.isfinite(bend), along, model)


# --------------------------------------------------------------------------- the ego lane at any instant
# Shared by ranging (vehicles' lanes) and the export (events), so both count lanes from the
# same line: a LaneTrack holds the lane model per processed frame, boxes and events come at
# their own times.


def gap_to(t: np.ndarray, t_acc: np.ndarray) -> np.ndarray:
    """Distance [s] from each time to the nearest accepted time (both sorted)."""
    if len(t_acc) == 1:
        return np.abs(t - t_acc[0])
    j = np.clip(np.searchsorted(t_acc, t), 1, len(t_acc) - 1)
    return np.minimum(np.abs(t - t_acc[j - 1]), np.abs(t_acc[j] - t))


#: The lane's curvature for use far ahead is the median over this window [s]: one frame's
#: curvature comes from a few metres of paint and scatters by several 1e-3 1/m; the median
#: over 1 s halves the boundary's error at 20-30 m on KITTI raw 0001 (0.29 -> 0.16 m RMS at
#: 20 m, ``python benchmarks/bench_lanes.py --kitti``), while a real bend's curvature
#: changes over several seconds.
CURVATURE_WINDOW_S = 1.0
#: The lane's heading for use far ahead is the median over this window [s]: the lane track's
#: heading can jump for a frame or two on clutter (0.02 -> 0.125 rad on the generated road
#: of tests/detect/test_ranging_cli.py: 3 m at 25 m, a car ahead read a lane to the left),
#: while the ego's yaw in its lane changes over seconds (a lane change takes 3-6 s).
HEADING_WINDOW_S = 0.5
#: Farther than this [s] from a measured frame, the lane model is unknown at a time.
LANE_AT_MAX_GAP_S = 0.5


class EgoLaneAt(NamedTuple):
    """The ego lane at given times (:func:`ego_lane_at`), arrays of the times' length.

    ``centre_m``: the lane's centre line beside the camera (x = 0) [m, positive left], i.e.
    minus ``offset_m``, the camera's offset from the lane's middle; ``heading_rad`` and
    ``curvature_inv_m``: the lane model (curvature over :data:`CURVATURE_WINDOW_S`);
    ``lane_width_m``; ``lane``: the ego's lane counted as :attr:`LaneTrack.lane`. NaN where
    unknown (``lane`` is always known: held from the nearest earlier frame).
    """

    centre_m: np.ndarray
    offset_m: np.ndarray
    heading_rad: np.ndarray
    curvature_inv_m: np.ndarray
    lane_width_m: np.ndarray
    lane: np.ndarray


def _interp_known(t_q: np.ndarray, t: np.ndarray, v: np.ndarray, max_gap_s: float
                  ) -> np.ndarray:
    """Linear interpolation of the finite samples of ``v``; NaN farther than ``max_gap_s``
    from any of them."""
    ok = np.isfinite(v)
    if not ok.any():
        return np.full(len(t_q), np.nan)
    tk = t[ok]
    out = np.interp(t_q, tk, v[ok])
    out[gap_to(t_q, tk) > max_gap_s] = np.nan
    return out


def windowed_median(t_s: np.ndarray, values: np.ndarray, window_s: float) -> np.ndarray:
    """The median of the finite ``values`` within ``window_s`` about each time (NaN where
    there are none); ``t_s`` increasing."""
    t = np.asarray(t_s, dtype=float)
    v = np.asarray(values, dtype=float)
    out = np.full(len(t), np.nan)
    ok = np.isfinite(v)
    tk, vk = t[ok], v[ok]
    lo = np.searchsorted(tk, t - window_s / 2.0, side="left")
    hi = np.searchsorted(tk, t + window_s / 2.0, side="right")
    for i in np.flatnonzero(hi > lo):
        out[i] = float(np.median(vk[lo[i]:hi[i]]))
    return out


def smoothed_curvature(track: LaneTrack, window_s: float = CURVATURE_WINDOW_S) -> np.ndarray:
    """The track's curvature [1/m] as the median of the finite values within ``window_s``
    about each frame (NaN where there are none)."""
    return windowed_median(track.t_s, track.curvature_inv_m, window_s)


def ego_lane_at(track: LaneTrack, t_s: np.ndarray, max_gap_s: float = LANE_AT_MAX_GAP_S
                ) -> EgoLaneAt:
    """The ego lane of a lane track at times ``t_s`` [s] (e.g. of tracked boxes).

    The continuous lateral position, the heading, the curvature (:func:`smoothed_curvature`)
    and the width are interpolated between the measured frames; the lane index is the one
    of the latest frame at or before each time; the camera's offset in the lane follows
    from them, so a time between two frames of a lane change is placed in the right lane.
    """
    t_q = np.asarray(t_s, dtype=float)
    t = np.asarray(track.t_s, dtype=float)
    if len(t) == 0:
        nan = np.full(len(t_q), np.nan)
        return EgoLaneAt(nan, nan.copy(), nan.copy(), nan.copy(), nan.copy(),
                         np.zeros(len(t_q), dtype=int))
    lateral = _interp_known(t_q, t, track.lateral_m, max_gap_s)
    width = _interp_known(t_q, t, track.lane_width_m, max_gap_s)
    heading = _interp_known(t_q, t, windowed_median(t, track.heading_rad, HEADING_WINDOW_S),
                            max_gap_s)
    curvature = _interp_known(t_q, t, smoothed_curvature(track), max_gap_s)
    # The lane model is known where the position and heading are; an unknown curvature
    # (lines too short to bend) counts as straight.
    curvature = np.where(np.isfinite(lateral) & ~np.isfinite(curvature), 0.0, curvature)
    j = np.clip(np.searchsorted(t, t_q, side="right") - 1, 0, len(t) - 1)
    lane = np.asarray(track.lane, dtype=int)[j]
    offset = lateral - lane * width
    offset = np.where(np.isfinite(heading), offset, np.nan)
    return EgoLaneAt(-offset, offset, heading, curvature, width, lane)
