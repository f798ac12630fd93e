"""Lane assignment of ranged vehicles and lead-vehicle selection with hysteresis.

The lead's geometry is :mod:`vid2sim.lead` (nearest ahead in the ego corridor); this module
adds what tracking needs on top: lane hysteresis and a delay before a rival takes over.

The ego corridor is the lane the camera sits in: +-lane_width/2 about the camera's optical
axis projected on the road (the camera's yaw is already removed by the camera model). Lanes
to the left are 1, 2, ... and to the right -1, -2, ..., named "ego", "left", "right",
"left2", "right2", ...
"""

from __future__ import annotations

from collections import defaultdict
from typing import Protocol

import numpy as np

from vid2sim.lead import nearest_ahead
from vid2sim.records import TrackedBox


class LaneSettings(Protocol):
    """What lane and lead assignment needs (``RangingConfig`` provides it)."""

    lane_width_m: float
    lane_hysteresis_m: float
    lead_switch_frames: int
    max_range_m: float

# A rival must be nearer than the current lead by this much to count as nearer at all
# [m]: two cars in one lane are a car length apart, so this only ignores range noise.
LEAD_SWITCH_MARGIN_M = 0.5
# Nearer than the lead by more than this (2 m + 10 %, beyond range noise at any distance)
# is a different situation, not noise: the lead changes without waiting.
CLEARLY_NEARER_M = 2.0
CLEARLY_NEARER_FRAC = 0.10


def lane_name(index: int) -> str:
    """0 -> "ego", 1 -> "left", -1 -> "right", 2 -> "left2", -3 -> "right3"."""
    if index == 0:
        return "ego"
    side = "left" if index > 0 else "right"
    return side if abs(index) == 1 else f"{side}{abs(index)}"


def lane_indices(lateral_m: np.ndarray, lane_width_m: float, hysteresis_m: float) -> np.ndarray:
    """Lane index over one track's time-ordered lateral offsets, with hysteresis.

    A vehicle keeps its lane until its centre is ``hysteresis_m`` past the lane boundary, so
    one drifting along a boundary does not flip between lanes every frame.
    """
    out = np.zeros(len(lateral_m), dtype=int)
    current: int | None = None
    for k, y in enumerate(lateral_m):
        if not np.isfinite(y):
            out[k] = current if current is not None else 0
            continue
        nearest = int(np.round(y / lane_width_m))
        if current is None or abs(y - current * lane_width_m) > lane_width_m / 2 + hysteresis_m:
            current = nearest
        out[k] = current
    return out


def assign_lanes_and_lead(boxes: list[TrackedBox], range_m: np.ndarray, lateral_m: np.ndarray,
                          config: LaneSettings, never_lead: np.ndarray | None = None
                          ) -> tuple[list[str], np.ndarray]:
    """Lane of every box and whether it is the lead vehicle in its frame.

    The lead is the nearest vehicle in the ego lane. Another ego-lane vehicle that is only a
    little nearer (within 2 m + 10 %) takes over after it has been nearer for
    ``config.lead_switch_frames`` consecutive frames, so the lead does not flicker between
    two similar candidates; one clearly nearer (a cut-in, once the lane hysteresis has put it
    in the ego lane) takes over at once, and so does the nearest when the lead leaves the
    lane (a cut-out) or is lost for longer than ``config.lead_switch_frames`` frames.

    Parameters
    ----------
    boxes : list of TrackedBox
        The boxes (any order).
    range_m, lateral_m : ndarray
        Range to the rear and lateral offset of each box [m] (smoothed).
    config : LaneSettings
        Lane width, hysteresis, switch delay, maximum range.
    never_lead : ndarray of bool, optional
        Boxes that may not be the lead whatever their lane (a tram on its own track bed,
        :mod:`vid2sim.detect.rail`).

    Returns
    -------
    (lane names, is_lead mask), both in the order of ``boxes``
    """
    n = len(boxes)
    lane_idx = np.zeros(n, dtype=int)
    by_track: dict[int, list[int]] = defaultdict(list)
    for i, b in enumerate(boxes):
        by_track[b.track_id].append(i)
    for members in by_track.values():
        members.sort(key=lambda i: (boxes[i].t_s, boxes[i].frame))
        idx = np.array(members)
        lane_idx[idx] = lane_indices(lateral_m[idx], config.lane_width_m,
                                     config.lane_hysteresis_m)
    lanes = [lane_name(int(k)) for k in lane_idx]

    is_lead = np.zeros(n, dtype=bool)
    may_lead = lane_idx == 0
    if never_lead is not None:
        may_lead &= ~np.asarray(never_lead, bool)
    by_frame: dict[int, list[int]] = defaultdict(list)
    for i, b in enumerate(boxes):
        by_frame[b.frame].append(i)
    lead_track: int | None = None
    lead_seen_frame = -(10 ** 9)
    challenger: int | None = None
    challenge_frames = 0
    for frame in sorted(by_frame):
        members = np.asarray(by_frame[frame])
        k = nearest_ahead(range_m[members], may_lead[members], config.max_range_m)
        if k < 0:
            continue
        nearest = int(members[k])
        cands = [int(i) for i in members if may_lead[i] and np.isfinite(range_m[i])
                 and 0 < range_m[i] <= config.max_range_m]
        current = next((i for i in cands if boxes[i].track_id == lead_track), None)
        if current is None:
            is_lead[nearest] = True
            # A lead missing for a frame or two (a missed detection) keeps its title: the
            # nearest stands in, and the lead takes over again as soon as it is back.
            if frame - lead_seen_frame > config.lead_switch_frames:
                lead_track, lead_seen_frame = boxes[nearest].track_id, frame
            challenger, challenge_frames = None, 0
            continue
        chosen = current
        gap_m = range_m[current] - range_m[nearest]
        if boxes[nearest].track_id != lead_track and gap_m > LEAD_SWITCH_MARGIN_M:
            if gap_m > CLEARLY_NEARER_M + CLEARLY_NEARER_FRAC * range_m[current]:
                # Clearly nearer (a cut-in: its lane change was already debounced by the
                # lane hysteresis): switch at once.
                chosen, challenger, challenge_frames = nearest, None, 0
            else:
                tid = boxes[nearest].track_id
                challenge_frames = challenge_frames + 1 if tid == challenger else 1
                challenger = tid
                if challenge_frames >= config.lead_switch_frames:
                    chosen, challenger, challenge_frames = nearest, None, 0
        else:
            challenger, challenge_frames = None, 0
        is_lead[chosen] = True
        lead_track, lead_seen_frame = boxes[chosen].track_id, frame
    return lanes, is_lead
