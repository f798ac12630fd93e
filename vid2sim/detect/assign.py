"""Lane assignment of ranged vehicles and lead-vehicle selection with hysteresis.

The lead's and the lanes' geometry is :mod:`vid2sim.core.lead` (nearest ahead in the ego lane;
lanes relative to the ego lane); this module adds what tracking needs on top: lane
hysteresis and a delay before a rival takes over.

The ego lane is the one the lane markings bound (:class:`~vid2sim.core.records.LaneTrack`): at
a vehicle's range its centre line is the lane model's (the camera's offset in the lane, the
lane's heading and curvature; :func:`vid2sim.core.lead.lane_centre_m`) and its width the measured
one. Where the markings were not measured, the ego lane is +-lane_width/2 about the camera's
optical axis projected on the road (the camera's yaw is already removed by the camera
model). Lanes to the left are 1, 2, ... and to the right -1, -2, ..., named "ego", "left",
"right", "left2", "right2", ... A vehicle's lane is counted on the road (it does not change
when the ego changes lanes under it) and reported relative to the ego lane of each frame.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, replace
from typing import Protocol

import numpy as np

from vid2sim.core.lead import (
    COURSE_JOIN_M,
    MAX_RELATIVE_LANE,
    ego_lane_at,
    lane_centre_ahead_m,
    nearest_ahead,
)
from vid2sim.core.records import LaneTrack, RangedBox, TrackedBox

__all__ = [
    "Course",
    "LaneSettings",
    "assign_lanes_and_lead",
    "lane_indices",
    "lane_offsets",
    "relane",
]


class Course(Protocol):
    """The road's course ahead (:class:`vid2sim.geo.course.RoadCourse`)."""

    def bend_m(self, t_s: np.ndarray, ahead_m: np.ndarray, join_m: float) -> np.ndarray:
        ...


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


def lane_indices(offset_m: np.ndarray, lane_width_m: np.ndarray | float, hysteresis_m: float,
                 ego_lane: np.ndarray | None = None) -> np.ndarray:
    """Lane index relative to the ego lane over one track's time-ordered samples, with
    hysteresis.

    A vehicle keeps its lane until its centre is ``hysteresis_m`` past the lane boundary, so
    one drifting along a boundary does not flip between lanes every frame. Its lane is kept
    on the road: when the ego changes lanes (``ego_lane`` steps by one), the vehicle's index
    relative to the ego lane steps the other way, with no hysteresis to overcome.

    Parameters
    ----------
    offset_m : (N,) the vehicle centre's offset from the ego lane's centre line at its
        range [m, positive left]; NaN where unknown (the lane is held)
    lane_width_m : (N,) or scalar, the lane width [m]
    hysteresis_m : distance past a boundary before the lane changes [m]
    ego_lane : (N,) int, the ego's lane on the road (e.g. :attr:`LaneTrack.lane`); default 0

    Returns
    -------
    (N,) int: 0 the ego lane, +1 the next to the left, -1 the next to the right, ...
    """
    y = np.asarray(offset_m, dtype=float)
    n = len(y)
    w = np.broadcast_to(np.asarray(lane_width_m, dtype=float), (n,))
    e = np.zeros(n, dtype=int) if ego_lane is None else np.asarray(ego_lane, dtype=int)
    out = np.zeros(n, dtype=int)
    on_road: int | None = None  # the vehicle's lane counted like ego_lane
    for k in range(n):
        if not (np.isfinite(y[k]) and np.isfinite(w[k]) and w[k] > 0):
            out[k] = on_road - e[k] if on_road is not None else 0
            continue
        if on_road is None or abs(y[k] - (on_road - e[k]) * w[k]) > w[k] / 2 + hysteresis_m:
            on_road = int(np.round(y[k] / w[k])) + int(e[k])
        out[k] = on_road - e[k]
    return out


def lane_offsets(boxes: list[TrackedBox], range_m: np.ndarray, lateral_m: np.ndarray,
                 config: LaneSettings, lanes: LaneTrack | None = None,
                 course: Course | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each box's centre relative to the ego lane, the lane width and the ego's lane.

    Parameters
    ----------
    boxes : the boxes (any order)
    range_m, lateral_m : range to the rear and lateral offset of each box's centre [m]
    config : lane width (where the markings give none)
    lanes : the ego lane from the lane markings; None: the camera axis is the lane's centre
    course : the road's course ahead (where the ego drove): beyond
        :data:`vid2sim.core.lead.COURSE_JOIN_M` the lane's centre line follows it

    Returns
    -------
    offset_m : the box centre's offset from the ego lane's centre line at its rear's range
        [m, positive left] (NaN where the range or lateral offset is unknown)
    width_m : the ego lane's width at the box's time [m]
    ego_lane : the ego's lane on the road at the box's time (:attr:`LaneTrack.lane`; 0
        without lanes)
    """
    n = len(boxes)
    lateral = np.asarray(lateral_m, dtype=float)
    width = np.full(n, float(config.lane_width_m))
    ego_lane = np.zeros(n, dtype=int)
    if lanes is None or len(lanes) == 0 or n == 0:
        return lateral.copy(), width, ego_lane
    at = ego_lane_at(lanes, np.array([b.t_s for b in boxes], dtype=float))
    # The lateral offset is the visible box's centre, on the vehicle's rear face: it is
    # compared with the lane's centre line at the rear's range. Half a car length further,
    # where a bend has already moved the line, a car in the ego lane read a lane to the right
    # in the demo's left bend (29 m ahead, 0.8 m).
    x_c = np.asarray(range_m, dtype=float)
    known = np.isfinite(at.offset_m) & np.isfinite(at.lane_width_m)
    t = np.array([b.t_s for b in boxes], dtype=float)
    bend = (np.full(n, np.nan) if course is None
            else course.bend_m(t, x_c, COURSE_JOIN_M))
    centre = lane_centre_ahead_m(x_c, at.centre_m, at.heading_rad, at.curvature_inv_m, bend)
    offset = np.where(known, lateral - centre, lateral)
    width = np.where(known, at.lane_width_m, width)
    return offset, width, at.lane.astype(int)


def assign_lanes_and_lead(boxes: list[TrackedBox], range_m: np.ndarray, lateral_m: np.ndarray,
                          config: LaneSettings, lanes: LaneTrack | None = None,
                          course: Course | None = None, never_lead: np.ndarray | None = None
                          ) -> tuple[list[int | None], np.ndarray, np.ndarray]:
    """Lane of every box and whether it is the lead vehicle in its frame.

    Lanes are relative to the ego lane of the box's frame (:func:`lane_offsets`, with
    hysteresis per track: :func:`lane_indices`); a box whose range or lateral offset is
    unknown, or beyond ``config.max_range_m``, has no lane (None).

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
    lanes : LaneTrack, optional
        The ego lane from the lane markings (default: the camera axis).
    course : Course, optional
        The road's course ahead (with a GPS trajectory), see :func:`lane_offsets`.
    never_lead : ndarray of bool, optional
        Boxes that may not be the lead whatever their lane (a tram on its own track bed,
        :mod:`vid2sim.detect.rail`).

    Returns
    -------
    (lanes relative to the ego lane or None, is_lead mask, lane offsets [m] as
    :func:`lane_offsets`), in the order of ``boxes``
    """
    range_m = np.asarray(range_m, dtype=float)
    offset, width, ego_lane = lane_offsets(boxes, range_m, lateral_m, config, lanes, course)
    known = (np.isfinite(offset) & np.isfinite(range_m)
             & (range_m <= config.max_range_m))
    lane_idx = _track_lanes(boxes, offset, width, ego_lane, known, config.lane_hysteresis_m)
    known &= np.abs(lane_idx) <= MAX_RELATIVE_LANE
    lanes_of = [int(k) if known[i] else None for i, k in enumerate(lane_idx)]
    may_lead = known & (lane_idx == 0)
    if never_lead is not None:
        may_lead &= ~np.asarray(never_lead, bool)
    return lanes_of, _leads_with_hysteresis(boxes, range_m, may_lead, config), offset


def _track_lanes(boxes: list[TrackedBox], offset: np.ndarray, width: np.ndarray,
                 ego_lane: np.ndarray, known: np.ndarray, hysteresis_m: float) -> np.ndarray:
    """Each box's lane relative to the ego lane, with hysteresis along its own track
    (:func:`lane_indices`); unknown offsets hold the track's lane."""
    lane_idx = np.zeros(len(boxes), dtype=int)
    by_track: dict[int, list[int]] = defaultdict(list)
    for i, b in enumerate(boxes):
        by_track[b.track_id].append(i)
    for members in by_track.values():
        members.sort(key=lambda i: (boxes[i].t_s, boxes[i].frame))
        idx = np.array(members)
        lane_idx[idx] = lane_indices(np.where(known[idx], offset[idx], np.nan), width[idx],
                                     hysteresis_m, ego_lane[idx])
    return lane_idx


@dataclass(slots=True)
class _LeadState:
    """Who leads, frame by frame: the lead's track and when it was last seen, and a rival
    that has been a little nearer for ``challenge_frames`` frames."""

    track: int | None = None
    seen_frame: int = -(10 ** 9)
    challenger: int | None = None
    challenge_frames: int = 0


def _leads_with_hysteresis(boxes: list[TrackedBox], range_m: np.ndarray, may_lead: np.ndarray,
                           config: LaneSettings) -> np.ndarray:
    """The lead's mask: in each frame the nearest ego-lane vehicle ahead
    (:func:`vid2sim.core.lead.nearest_ahead`), with the switch delay of
    :func:`assign_lanes_and_lead`."""
    is_lead = np.zeros(len(boxes), dtype=bool)
    by_frame: dict[int, list[int]] = defaultdict(list)
    for i, b in enumerate(boxes):
        by_frame[b.frame].append(i)
    state = _LeadState()
    for frame in sorted(by_frame):
        members = np.asarray(by_frame[frame])
        k = nearest_ahead(range_m[members], may_lead[members], config.max_range_m)
        if k < 0:
            continue
        nearest = int(members[k])
        cands = [int(i) for i in members if may_lead[i] and np.isfinite(range_m[i])
                 and 0 < range_m[i] <= config.max_range_m]
        current = next((i for i in cands if boxes[i].track_id == state.track), None)
        if current is None:
            is_lead[nearest] = True
            # A lead missing for a frame or two (a missed detection) keeps its title: the
            # nearest stands in, and the lead takes over again as soon as it is back.
            if frame - state.seen_frame > config.lead_switch_frames:
                state.track, state.seen_frame = boxes[nearest].track_id, frame
            state.challenger, state.challenge_frames = None, 0
            continue
        chosen = _chosen_lead(boxes, range_m, current, nearest, state, config)
        is_lead[chosen] = True
        state.track, state.seen_frame = boxes[chosen].track_id, frame
    return is_lead


def _chosen_lead(boxes: list[TrackedBox], range_m: np.ndarray, current: int, nearest: int,
                 state: _LeadState, config: LaneSettings) -> int:
    """The current lead, or the nearest rival once it is clearly nearer (a cut-in: its lane
    change was already debounced by the lane hysteresis) or has been nearer for
    ``lead_switch_frames`` frames."""
    gap_m = range_m[current] - range_m[nearest]
    if boxes[nearest].track_id == state.track or gap_m <= LEAD_SWITCH_MARGIN_M:
        state.challenger, state.challenge_frames = None, 0
        return current
    if gap_m > CLEARLY_NEARER_M + CLEARLY_NEARER_FRAC * range_m[current]:
        state.challenger, state.challenge_frames = None, 0
        return nearest
    tid = boxes[nearest].track_id
    state.challenge_frames = state.challenge_frames + 1 if tid == state.challenger else 1
    state.challenger = tid
    if state.challenge_frames >= config.lead_switch_frames:
        state.challenger, state.challenge_frames = None, 0
        return nearest
    return current


def relane(boxes: list[RangedBox], config: LaneSettings, lanes: LaneTrack | None,
           course: Course | None = None, never_lead_tracks: frozenset[int] = frozenset()
           ) -> list[RangedBox]:
    """The ranged boxes with their lanes, lane offsets and lead assigned again (e.g. once the
    road's course is known from the ego's trajectory, or trams on their own bed are known:
    ``never_lead_tracks``), in the same order."""
    if not boxes:
        return []
    range_m = np.array([b.range_m for b in boxes], dtype=float)
    lateral_m = np.array([b.lateral_m for b in boxes], dtype=float)
    never = (np.array([int(b.track_id) in never_lead_tracks for b in boxes], bool)
             if never_lead_tracks else None)
    lanes_of, is_lead, offset = assign_lanes_and_lead(boxes, range_m, lateral_m, config, lanes,
                                                      course, never)
    return [replace(b, lane=lanes_of[i], is_lead=bool(is_lead[i]),
                    lane_offset_m=float(offset[i])) for i, b in enumerate(boxes)]
