"""The scenario at successive instants, for drawing it frame after frame.

:class:`SceneClock` answers "where is everyone at t" for times that only grow (a video's
frames): actors enter the active set when their trajectory starts and leave it when it
ends, so a frame costs the active actors only, whatever the clip's length and however many
actors the scenario holds; headings are unwrapped once per trajectory, not per query
(:meth:`vid2sim.core.scenario.Trajectory.state_at` unwraps on every call). Poses are the
trajectories linearly interpolated, as the replay environment's logged vehicles move
(:class:`vid2sim.export.highway.ReplayVehicle`).

The lead is THE lead rule (:func:`vid2sim.core.lead.lead_of`) measured along the ego's
path, as the replay environment measures it for the policies (``info["lead_id"]``): the
nearest vehicle ahead whose centre lies within half a lane width of the path the ego drove
(its logged positions, prolonged straight beyond the end), the range counted along that
path from the ego's reference point to the vehicle's rear (what ``tracks.csv``'s
``range_m`` measures). The report's lead plot (:func:`vid2sim.evaluate.report.lead_series`)
uses it too: along the ego's straight axis, a bend takes the lead out of the corridor within a
few tens of metres; along the path it does not.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from vid2sim.base.defaults import LANE_WIDTH_M
from vid2sim.core.lead import lead_of
from vid2sim.core.polyline import resample_polyline
from vid2sim.core.scenario import Actor, Scenario, Trajectory

#: Slack at the ends of a trajectory [s] (as the replay's TIME_TOLERANCE_S).
_SLACK_S = 1e-3
#: The ego's path is resampled at this spacing [m] to measure along it (a 0.5 m step puts a
#: point within 0.25 m of any vehicle's foot on it; arc lengths are exact from there).
PATH_SAMPLE_M = 0.5
#: The path goes on straight this far beyond the log's end [m], as the environment's
#: logged path does, so a lead ahead of the last pose is still found.
PATH_AHEAD_M = 300.0
PATH_BEHIND_M = 50.0


@dataclass(frozen=True, slots=True)
class Pose:
    """ENU position [m], heading [rad, CCW from east] and speed [m/s]."""

    x_m: float
    y_m: float
    heading_rad: float
    speed_mps: float

    @property
    def xyh(self) -> tuple[float, float, float]:
        return (self.x_m, self.y_m, self.heading_rad)


@dataclass(frozen=True, slots=True)
class Lead:
    """The lead at an instant: its id, range from the ego origin to its rear [m], its speed
    [m/s] and the closing speed (ego minus lead along the ego's heading) [m/s]."""

    id: str
    range_m: float
    speed_mps: float
    closing_mps: float


class _Track:
    """A trajectory's arrays, heading unwrapped once."""

    __slots__ = ("h", "t", "v", "x", "y")

    def __init__(self, tr: Trajectory):
        self.t, self.x, self.y, self.v = tr.t, tr.x, tr.y, tr.speed
        self.h = np.unwrap(tr.heading)

    def at(self, t_s: float) -> Pose:
        t = self.t
        if len(t) == 1 or t_s <= t[0]:
            i, w = 0, 0.0
        elif t_s >= t[-1]:
            i, w = len(t) - 2, 1.0
        else:
            i = int(np.searchsorted(t, t_s, side="right")) - 1
            w = (t_s - t[i]) / (t[i + 1] - t[i])
        j = min(i + 1, len(t) - 1)

        def lerp(a: np.ndarray) -> float:
            return float(a[i] + w * (a[j] - a[i]))

        return Pose(lerp(self.x), lerp(self.y), lerp(self.h), lerp(self.v))


class EgoPath:
    """The ego's logged path as a polyline with arc lengths, prolonged straight by
    :data:`PATH_AHEAD_M` beyond its end (and :data:`PATH_BEHIND_M` before its start), and
    the arc length and signed offset (positive left) of points near it."""

    def __init__(self, trajectory: Trajectory, sample_m: float = PATH_SAMPLE_M):
        xy = resample_polyline(np.column_stack((trajectory.x, trajectory.y)), sample_m)
        if len(xy) < 2:  # a standing ego: the road ahead along its heading
            h = float(trajectory.heading[0])
            xy = np.vstack((xy[:1], xy[:1] + sample_m * np.array([[math.cos(h), math.sin(h)]])))
        d0 = xy[1] - xy[0]
        d1 = xy[-1] - xy[-2]
        d0, d1 = d0 / np.hypot(*d0), d1 / np.hypot(*d1)
        before = xy[0] - np.arange(PATH_BEHIND_M, 0.0, -sample_m)[:, None] * d0
        after = xy[-1] + np.arange(sample_m, PATH_AHEAD_M + sample_m, sample_m)[:, None] * d1
        self.xy = np.vstack((before, xy, after))
        seg = np.diff(self.xy, axis=0)
        self.s = np.concatenate(([0.0], np.cumsum(np.hypot(seg[:, 0], seg[:, 1]))))
        tangent = np.vstack((seg, seg[-1:]))
        self.tangent = tangent / np.hypot(tangent[:, 0], tangent[:, 1])[:, None]
        self.heading = np.arctan2(self.tangent[:, 1], self.tangent[:, 0])

    def locate(self, xy_m: np.ndarray, near_s_m: float | None = None,
               window_m: tuple[float, float] = (-30.0, 250.0)) -> tuple[np.ndarray, np.ndarray,
                                                                      np.ndarray]:
        """(arc length [m], offset left [m], path point index) of each point (N, 2), each
        on its nearest path point, searched within ``window_m`` of ``near_s_m`` (the whole
        path without it)."""
        pts = np.asarray(xy_m, float).reshape(-1, 2)
        lo, hi = 0, len(self.s)
        if near_s_m is not None:
            lo = int(np.searchsorted(self.s, near_s_m + window_m[0]))
            hi = max(int(np.searchsorted(self.s, near_s_m + window_m[1])), lo + 1)
        seg = self.xy[lo:hi]
        d2 = ((pts[:, None, :] - seg[None, :, :]) ** 2).sum(axis=2)
        i = lo + np.argmin(d2, axis=1)
        rel = pts - self.xy[i]
        along = (rel * self.tangent[i]).sum(axis=1)
        left = rel[:, 0] * -self.tangent[i, 1] + rel[:, 1] * self.tangent[i, 0]
        return self.s[i] + along, left, i


class SceneClock:
    """Poses of the ego and the active actors at non-decreasing times (module docstring)."""

    def __init__(self, scenario: Scenario):
        self.scenario = scenario
        self.ego = _Track(scenario.ego.trajectory)
        self.actors = {a.id: a for a in scenario.actors}
        self._tracks = {a.id: _Track(a.trajectory) for a in scenario.actors}
        self._pending = [(float(a.trajectory.t[0]), k, a.id)
                         for k, a in enumerate(scenario.actors)]
        heapq.heapify(self._pending)
        self._active: dict[str, float] = {}  # id -> end time
        self._order = {a.id: k for k, a in enumerate(scenario.actors)}
        self._last_t = -math.inf
        self._path: EgoPath | None = None
        self._s_ego: float | None = None
        self.lane_width_m = (scenario.roads[0].lane_width_m if scenario.roads
                             else LANE_WIDTH_M)

    def at(self, t_s: float) -> tuple[Pose, dict[str, Pose]]:
        """The ego's pose and the active actors' (in scenario order) at ``t_s`` [s]; ``t_s``
        must not be earlier than the last time asked."""
        if t_s < self._last_t - 1e-9:
            raise ValueError(f"SceneClock goes forward only ({t_s} < {self._last_t})")
        self._last_t = t_s
        while self._pending and self._pending[0][0] - _SLACK_S <= t_s:
            _, _, actor_id = heapq.heappop(self._pending)
            self._active[actor_id] = float(self.actors[actor_id].trajectory.t[-1])
        for actor_id in [i for i, end in self._active.items() if end + _SLACK_S < t_s]:
            del self._active[actor_id]
        ids = sorted(self._active, key=self._order.__getitem__)
        return self.ego.at(t_s), {i: self._tracks[i].at(t_s) for i in ids}

    def actor(self, actor_id: str) -> Actor:
        return self.actors[actor_id]

    def lead(self, ego: Pose, actors: dict[str, Pose]) -> Lead | None:
        """The lead among ``actors`` seen from ``ego`` (module docstring), or None."""
        if not actors:
            return None
        if self._path is None:
            self._path = EgoPath(self.scenario.ego.trajectory)
        path = self._path
        s_ego, lat_ego, _ = path.locate(np.array([[ego.x_m, ego.y_m]]), self._s_ego)
        self._s_ego = float(s_ego[0])
        ids = list(actors)
        pts = np.array([[actors[i].x_m, actors[i].y_m] for i in ids])
        s_a, lat_a, k = path.locate(pts, self._s_ego)
        length = np.array([self.actors[i].length_m for i in ids])
        ahead = s_a - self._s_ego - length / 2.0
        j = lead_of(ahead, lat_a - lat_ego[0], self.lane_width_m)
        if j < 0:
            return None
        p = actors[ids[j]]
        along = p.speed_mps * math.cos(p.heading_rad - float(path.heading[k[j]]))
        return Lead(ids[j], float(ahead[j]), float(p.speed_mps), float(ego.speed_mps - along))
