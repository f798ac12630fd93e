"""Where the replayed vehicles stand on the simulated street: for each actor and each step
of a log replay in ``vid2sim/Replay-v0``, is its centre inside a lane of the gym network,
and of which type?

A scenario whose street is right puts its moving cars in driving lanes, its parked cars in
parking strips and its trams on their track beds; one whose road is a single default lane
leaves most vehicles floating beside it (KITTI raw 0001 before issue 19: 5 % of actor-steps
on a lane).

The measure (:func:`lane_occupancy`) steps the environment with the ego on its log, as
``vid2sim eval`` does, and tests every vehicle but the ego against every lane of the network
(highway-env's straight extensions of the road's ends included): inside when its arc length
lies on the lane and its lateral offset within half the lane's width.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from vid2sim.core.lanelayout import ROAD_LANE_TYPES
from vid2sim.core.records import RAIL_CATEGORIES
from vid2sim.core.scenario import Scenario
from vid2sim.export.highway.env import ReplayEnv


@dataclass(slots=True)
class LaneOccupancy:
    """Actor-steps of a log replay and where they stood.

    :param steps: actor-steps (one per actor present at a replay step)
    :param by_type: actor-steps inside a lane, per lane type (``driving``, ``parking``, ...)
    :param by_group: ``(steps, inside any lane)`` per group: ``moving``, ``static`` (parked,
        held still) and ``rail`` (trams)
    :param by_actor: ``(steps, inside any lane)`` per actor id
    :param road_steps: actor-steps of road vehicles (all but rail vehicles)
    :param road_on_road_lane: of those, inside a driving, parking or shoulder lane
    """

    steps: int = 0
    by_type: Counter = field(default_factory=Counter)
    by_group: dict[str, list[int]] = field(default_factory=dict)
    by_actor: dict[str, list[int]] = field(default_factory=dict)
    road_steps: int = 0
    road_on_road_lane: int = 0

    @property
    def on_lane(self) -> int:
        """Actor-steps inside any lane of the network."""
        return int(sum(self.by_type.values()))

    @property
    def share(self) -> float:
        """Share of actor-steps inside a lane of the network (any type)."""
        return self.on_lane / self.steps if self.steps else float("nan")

    @property
    def road_share(self) -> float:
        """Share of road vehicles' actor-steps inside a driving, parking or shoulder lane."""
        return self.road_on_road_lane / self.road_steps if self.road_steps else float("nan")

    def summary(self) -> str:
        groups = ", ".join(f"{g} {on}/{n}" for g, (n, on) in sorted(self.by_group.items()))
        types = ", ".join(f"{t} {n}" for t, n in sorted(self.by_type.items()))
        return (f"{self.share:.1%} of {self.steps} actor-steps on a lane ({types}); road "
                f"vehicles on a driving/parking/shoulder lane {self.road_share:.1%}; by group: "
                f"{groups}")


def lane_of(lanes: list, position: np.ndarray) -> object | None:
    """The lane of ``lanes`` whose area holds ``position`` (highway-env frame), the nearest
    to its middle where two overlap; None outside all."""
    best, best_lat = None, np.inf
    for lane in lanes:
        s, lat = lane.local_coordinates(position)
        if 0.0 <= s <= lane.length and abs(lat) <= lane.width_at(s) / 2.0 \
                and abs(lat) < best_lat:
            best, best_lat = lane, abs(lat)
    return best


def lane_occupancy(scenario: Scenario | str) -> LaneOccupancy:
    """Replay ``scenario`` with the ego on its log and count where the actors stand (see
    the module docstring)."""
    env = ReplayEnv(scenario, ego_mode="log")
    env.reset(seed=0)
    actors = {a.id: a for a in env.scenario.actors}
    lanes = env.road.network.lanes_list()
    out = LaneOccupancy()
    action = np.zeros(env.action_space.shape, dtype=np.float32)
    for step in range(env.n_steps + 1):
        if step:
            env.step(action)
        for v in env.road.vehicles:
            if v is env.vehicle:
                continue
            actor = actors.get(str(getattr(v, "vehicle_id", "")))
            if actor is None:
                continue
            lane = lane_of(lanes, np.asarray(v.position, float))
            lane_type = getattr(lane, "lane_type", "driving") if lane is not None else None
            group = ("rail" if actor.category in RAIL_CATEGORIES else
                     "static" if actor.static else "moving")
            out.steps += 1
            if lane_type is not None:
                out.by_type[lane_type] += 1
            for table, key in ((out.by_group, group), (out.by_actor, actor.id)):
                row = table.setdefault(key, [0, 0])
                row[0] += 1
                row[1] += lane_type is not None
            if group != "rail":
                out.road_steps += 1
                out.road_on_road_lane += lane_type in ROAD_LANE_TYPES
    env.close()
    return out
