"""The scenario at successive instants, for drawing it frame after frame.

:class:`SceneClock` answers "where is everyone at t" for times that only grow (a video's
frames): actors enter the active set when their trajectory starts and leave it when it
ends, so a frame costs the active actors only, whatever the clip's length and however many
actors the scenario holds; headings are unwrapped once per trajectory, not per query
(:meth:`vid2sim.core.scenario.Trajectory.state_at` unwraps on every call). Poses are the
trajectories linearly interpolated, as the replay environment's logged vehicles move
(:class:`vid2sim.export.highway.ReplayVehicle`). The lead is THE lead rule
(:func:`vid2sim.core.lead.lead_of`) on the ego's longitudinal axis, as the report's lead
plot (:func:`vid2sim.evaluate.report.lead_series`).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass

import numpy as np

from vid2sim.base.defaults import LANE_WIDTH_M
from vid2sim.core.lead import lead_of
from vid2sim.core.scenario import Actor, Scenario, Trajectory

#: Slack at the ends of a trajectory [s] (as the replay's TIME_TOLERANCE_S).
_SLACK_S = 1e-3


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
        ids = list(actors)
        c, s = math.cos(ego.heading_rad), math.sin(ego.heading_rad)
        dx = np.array([actors[i].x_m - ego.x_m for i in ids])
        dy = np.array([actors[i].y_m - ego.y_m for i in ids])
        length = np.array([self.actors[i].length_m for i in ids])
        ahead = c * dx + s * dy - length / 2.0
        k = lead_of(ahead, -s * dx + c * dy, self.lane_width_m)
        if k < 0:
            return None
        p = actors[ids[k]]
        along = p.speed_mps * math.cos(p.heading_rad - ego.heading_rad)
        return Lead(ids[k], float(ahead[k]), float(p.speed_mps), float(ego.speed_mps - along))
