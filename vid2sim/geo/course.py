"""The road's course ahead of the ego, from where the ego itself drove.

The lane markings give the ego lane near the car well (7 cm at 10 m on KITTI raw 0001), but
their curvature is fitted from a few metres of paint, and a bend that starts 30 m ahead is
not in it at all. The ego's own trajectory says how the road goes on: it drove there a few
seconds later. With its wander in the lane and its lane changes taken out (the lane track
says where in its lane it was), the trajectory is the course of the lane it started in, a
line parallel to every lane of the road.

:class:`RoadCourse` holds that line (ENU, smoothed over :data:`COURSE_SMOOTHING_M` of arc)
and answers, for an instant and distances ahead, how far the road bends away from the
straight line it follows at a join point (:meth:`RoadCourse.bend_m`): what a lane model
continued from the join along the road needs (:func:`vid2sim.core.lead.lane_centre_ahead_m`).

Pure: records in, arrays out.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d

from vid2sim.core.records import EgoLateral

#: The course is smoothed over this arc length [m] (Gaussian one-sigma): GPS/INS positions
#: 10 cm apart with centimetre noise give headings that scatter by a few 1e-3 rad per
#: sample; a car's path has continuous curvature, so 3 m rounds nothing a road does
#: (a 50 m radius moves inwards by sigma^2 / (2 R) = 9 cm).
COURSE_SMOOTHING_M = 3.0
#: Resampling step of the course [m].
COURSE_STEP_M = 0.5


class RoadCourse:
    """The course of the road along the ego's drive (see the module docstring).

    Parameters
    ----------
    t_s : (N,) the ego's sample times [s]
    x_m, y_m : (N,) ENU positions of the course line at those times [m] (the ego's positions
        moved across by its offset from the line)
    """

    def __init__(self, t_s: np.ndarray, x_m: np.ndarray, y_m: np.ndarray):
        t = np.asarray(t_s, dtype=float)
        xy = np.column_stack((np.asarray(x_m, dtype=float), np.asarray(y_m, dtype=float)))
        ok = np.isfinite(xy).all(axis=1) & np.isfinite(t)
        t, xy = t[ok], xy[ok]
        step = np.hypot(*np.diff(xy, axis=0).T) if len(xy) > 1 else np.zeros(0)
        s = np.concatenate(([0.0], np.cumsum(step)))
        self.t_s = t
        self.s_at_t = s
        if len(xy) < 2 or s[-1] < 2 * COURSE_STEP_M:
            self.s_m = np.zeros(0)
            return
        self.s_m = np.arange(0.0, s[-1] + 1e-9, COURSE_STEP_M)
        # s(t) is flat while the ego stands: keep one point per distance for the resampling
        moved = np.concatenate(([True], np.diff(s) > 1e-6))
        sigma = COURSE_SMOOTHING_M / COURSE_STEP_M
        self.x_m = gaussian_filter1d(np.interp(self.s_m, s[moved], xy[moved, 0]), sigma,
                                     mode="nearest")
        self.y_m = gaussian_filter1d(np.interp(self.s_m, s[moved], xy[moved, 1]), sigma,
                                     mode="nearest")
        self.heading_rad = np.unwrap(np.arctan2(np.gradient(self.y_m), np.gradient(self.x_m)))

    def __len__(self) -> int:
        return len(self.s_m)

    def bend_m(self, t_s: np.ndarray, ahead_m: np.ndarray, join_m: float) -> np.ndarray:
        """How far left [m] the course ``ahead_m`` ahead of the ego at ``t_s`` lies from the
        straight line it follows at ``join_m`` ahead (its tangent there), measured across
        that tangent; 0 up to the join, NaN where the course does not reach (beyond the end
        of the drive).

        Parameters
        ----------
        t_s : (K,) instants [s]
        ahead_m : (K,) distances ahead along the course [m]
        join_m : where the straight line touches the course [m]
        """
        t = np.asarray(t_s, dtype=float)
        ahead = np.asarray(ahead_m, dtype=float)
        out = np.full(t.shape, np.nan)
        if len(self) == 0:
            return out
        s0 = np.interp(t, self.t_s, self.s_at_t)
        s_join = s0 + join_m
        s_far = s0 + np.maximum(ahead, join_m)
        reach = s_far <= self.s_m[-1]
        h = np.interp(s_join, self.s_m, self.heading_rad)
        dx = np.interp(s_far, self.s_m, self.x_m) - np.interp(s_join, self.s_m, self.x_m)
        dy = np.interp(s_far, self.s_m, self.y_m) - np.interp(s_join, self.s_m, self.y_m)
        out[reach] = (-dx * np.sin(h) + dy * np.cos(h))[reach]
        return out


def road_course(lateral: EgoLateral) -> RoadCourse:
    """The course of the lane the ego started in: the ego's path moved across by its offset
    in its lane and by its lane changes (where the markings were not measured, by the
    nearest measured offset; without any, the path itself)."""
    ego = lateral.ego
    t = np.asarray(ego.t_s, dtype=float)
    offset = np.asarray(lateral.offset_in_lane_m, dtype=float)
    width = np.asarray(lateral.lane_width_m, dtype=float)
    lane = np.asarray(lateral.lane, dtype=float)
    shift = offset + (lane - (lane[0] if len(lane) else 0.0)) * width
    ok = np.isfinite(shift)
    shift = np.interp(t, t[ok], shift[ok]) if ok.any() else np.zeros(len(t))
    c, s = np.cos(ego.heading_rad), np.sin(ego.heading_rad)
    # the line is right of the ego by its shift (positive left): move the ego right by it
    return RoadCourse(t, ego.x_m + s * shift, ego.y_m - c * shift)
