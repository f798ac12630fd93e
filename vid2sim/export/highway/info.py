"""What ``vid2sim/Replay-v0`` reports after every reset and step: a typed record.

gymnasium's API hands ``info`` around as a dict (:meth:`StepInfo.to_dict`); whoever reads it
turns it back with :meth:`StepInfo.of` and reads attributes, so that a renamed or missing key
is an error at once instead of a silent default (a ``.get("gap_m", inf)`` that no longer
finds its key disables AEB without a word).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from typing import Any


@dataclass(frozen=True, slots=True)
class StepInfo:
    """The replay's state as a driving function sees it, at one instant.

    Speeds along the ego's path: a crossing car's speed counts only along it.

    :param t_s: scenario time [s]
    :param ego_mode: how the ego moves (``log``, ``policy``, ...)
    :param ego_speed_mps: ego speed [m/s]
    :param ego_accel_mps2: ego longitudinal acceleration [m/s^2]
    :param ego_lane: the ego's lane on its road (0 the rightmost driving lane)
    :param lane_offset_m: ego centre from its lane's centre line, positive left [m]
    :param lane_width_m: the ego lane's width [m]
    :param crashed: the ego touched another vehicle (highway-env's box test)
    :param collision_with: id of the vehicle it first touched ("" none)
    :param offroad: the ego left the road (see the environment's ``offroad``)
    :param has_lead: a lead vehicle exists (:mod:`vid2sim.core.lead`)
    :param lead_id: the lead's actor id ("" without one)
    :param gap_m: bumper-to-bumper gap to the lead [m] (inf without one)
    :param lead_speed_mps: the lead's speed along the path [m/s] (0 without one)
    :param closing_speed_mps: ego speed minus lead speed along the path [m/s]
    :param ttc_s: time to collision, gap / closing speed [s] (inf when not closing)
    :param time_headway_s: gap / ego speed [s] (inf when standing)
    :param handovers: how many recorded actors have been handed to a reactive driver model
    """

    t_s: float
    ego_mode: str
    ego_speed_mps: float
    ego_accel_mps2: float
    ego_lane: int
    lane_offset_m: float
    lane_width_m: float
    crashed: bool
    collision_with: str
    offroad: bool
    has_lead: bool = False
    lead_id: str = ""
    gap_m: float = math.inf
    lead_speed_mps: float = 0.0
    closing_speed_mps: float = 0.0
    ttc_s: float = math.inf
    time_headway_s: float = math.inf
    handovers: int = 0

    def to_dict(self) -> dict[str, Any]:
        """The record as gymnasium's ``info`` dict."""
        return asdict(self)

    @classmethod
    def of(cls, info: StepInfo | Mapping[str, Any]) -> StepInfo:
        """The record of an ``info`` dict (keys added by wrappers are ignored).

        Raises
        ------
        KeyError
            If a field of the record is missing from ``info``: the dict does not come from
            this environment (or from a version with other keys).
        """
        if isinstance(info, StepInfo):
            return info
        missing = [f.name for f in fields(cls) if f.name not in info]
        if missing:
            raise KeyError(f"info lacks {', '.join(missing)}: not a vid2sim/Replay-v0 info")
        return cls(**{f.name: info[f.name] for f in fields(cls)})
