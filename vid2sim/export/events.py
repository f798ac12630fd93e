"""Lane-change events of a scenario: cut-ins, cut-outs and other lane changes.

Every tracked vehicle has a lane per frame relative to the ego lane, with hysteresis
(``RangedBox.lane``, :func:`vid2sim.detect.assign.lane_indices`), and its centre's offset from
the ego lane's centre line (``RangedBox.lane_offset_m``). A vehicle's lane is counted on the
road (the ego's own lane changes, :attr:`~vid2sim.core.records.LaneTrack.lane`, are added back),
so only the vehicle's own moves are events:

1. **Runs.** A track's frames are cut into runs of one lane; only runs that last at least
   :attr:`EventConfig.min_dwell_s` count (a vehicle must be seen in a lane for a while
   before it counts as coming from or going to it; readings that flip for a few frames
   along a boundary are noise, and a lane crossed in passing is no stay).
2. **Crossings.** Between two consecutive counted runs of different lanes the vehicle
   crossed one boundary per lane step. The moment is when its centre crossed the boundary, interpolated linearly
   between the two frames on either side (the hysteresis only confirms the change later).
3. **Kinds.** Lanes at that moment relative to the ego lane: into lane 0 from another lane
   ahead of the ego is a ``cut_in``, out of lane 0 ahead a ``cut_out``, anything else a
   ``lane_change``. Lanes read farther ahead than :attr:`EventConfig.max_range_m` (where the
   lane at the vehicle's range is not known well enough) are left out before step 1; actors the scenario holds still or that move
   slower than :attr:`EventConfig.min_speed_mps` along the ego's direction at the moment (a
   parked car does not change lanes: its lateral offset drifts with the range error) and
   oncoming ones (they pass in a second or two, seen mostly far ahead) give no events,
   nor crossings between lanes more than :attr:`EventConfig.max_lane` from the ego lane.

The ego's own lane changes (:attr:`~vid2sim.core.records.EgoLateral.lane_changes`) are events of
the actor ``"ego"`` from lane 0 to +1 (left) or -1 (right).
"""

from __future__ import annotations

import itertools
import math
from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from vid2sim.core.lead import ego_lane_at
from vid2sim.core.records import EGO_ID, LaneChange, LaneTrack, RangedBox
from vid2sim.core.scenario import Actor, Event, Trajectory


@dataclass(frozen=True, slots=True)
class EventConfig:
    """Tuning of the event detection (sources in the comments)."""

    #: a lane held for less than this [s] between two runs of one lane is noise: a lane
    #: change takes 3-6 s from start to end (Toledo and Zohar 2007, NGSIM), the centre stays
    #: in the new lane for its second half, and lane readings flip for a few frames when a
    #: vehicle drives along a boundary
    min_dwell_s: float = 0.5
    #: lanes read farther ahead than this [m] are no evidence of a lane change: the ego
    #: lane's boundary at a vehicle's range is off by 0.22 / 0.42 m RMS at 30 / 40 m on
    #: KITTI raw 0001 with the road's course (0.53 / 0.86 m from the lane model alone;
    #: ``python benchmarks/bench_lanes.py --kitti``) and by 0.50 / 0.76 m on the demo's bend
    #: (vid2sim.core.lead): within a tenth of a lane at 30 m, a sixth or worse beyond (a parked
    #: car 40 m ahead in the demo's bend read as in the ego lane)
    max_range_m: float = 30.0
    #: actors slower than this along the ego's direction at the crossing give no events
    #: [m/s] (AssembleConfig's stationary speed: below it monocular range noise moves a
    #: parked car)
    min_speed_mps: float = 1.0
    #: crossings between lanes farther than this from the ego lane give no events: they do
    #: not concern the ego (no cut-in follows within seconds), and a vehicle 7 m or more to
    #: the side is where the ranging fails most (on the KITTI raw 0001 cut-in clips, parked
    #: cars read at a constant range while the ego passes them "moved" from lane +2 to +3
    #: and +5 to +6 in 2 of 8 clips, ``python benchmarks/bench_cutin.py``)
    max_lane: int = 2


@dataclass(frozen=True, slots=True)
class Crossing:
    """One vehicle's centre crossing one lane boundary.

    ``t_s`` [s]; ``from_lane``, ``to_lane`` relative to the ego lane at that moment;
    ``range_m`` the vehicle's range then [m].
    """

    t_s: float
    from_lane: int
    to_lane: int
    range_m: float


def event_type(from_lane: int, to_lane: int, ahead: bool) -> str:
    """``cut_in`` (into the ego lane ahead), ``cut_out`` (out of it ahead) or
    ``lane_change``."""
    if ahead and to_lane == 0 and from_lane != 0:
        return "cut_in"
    if ahead and from_lane == 0 and to_lane != 0:
        return "cut_out"
    return "lane_change"


def _runs(lane: np.ndarray) -> list[list[int]]:
    """[value, first index, last index] of the runs of equal values."""
    runs: list[list[int]] = []
    for i, v in enumerate(lane.tolist()):
        if runs and runs[-1][0] == v:
            runs[-1][2] = i
        else:
            runs.append([v, i, i])
    return runs


def _debounced_runs(t_s: np.ndarray, lane: np.ndarray, min_dwell_s: float
                    ) -> list[list[int]]:
    """The runs of one lane held for at least ``min_dwell_s`` (module docstring), each as
    [lane, first index, last index]; consecutive ones may share a lane (a shorter run of
    another lane lay between: noise, or a lane passed through)."""
    step = float(np.median(np.diff(t_s))) if len(t_s) > 1 else 0.0
    return [r for r in _runs(lane)
            if float(t_s[r[2]] - t_s[r[1]]) + step >= min_dwell_s - 1e-9]


def lane_crossings(t_s: np.ndarray, lane: np.ndarray, offset_m: np.ndarray,
                   lane_width_m: np.ndarray, ego_lane: np.ndarray, range_m: np.ndarray,
                   min_dwell_s: float = 0.5) -> list[Crossing]:
    """The lane boundaries one vehicle's centre crossed.

    Parameters
    ----------
    t_s : (N,) increasing frame times [s] (frames with a known lane only)
    lane : (N,) int, its lane relative to the ego lane, with hysteresis
    offset_m : (N,) its centre's offset from the ego lane's centre line [m, positive left]
    lane_width_m : (N,) the lane width [m]
    ego_lane : (N,) int, the ego's lane on the road (+1 per lane to the left)
    range_m : (N,) its range [m]
    min_dwell_s : a lane held for less is noise [s] (:attr:`EventConfig.min_dwell_s`)

    Returns
    -------
    list of Crossing, in time order
    """
    t = np.asarray(t_s, dtype=float)
    e = np.asarray(ego_lane, dtype=int)
    w = np.asarray(lane_width_m, dtype=float)
    on_road = np.asarray(lane, dtype=int) + e
    # Its place across the road in lane widths from the ego's first lane's centre.
    place = np.asarray(offset_m, dtype=float) / w + e
    rng = np.asarray(range_m, dtype=float)
    runs = _debounced_runs(t, on_road, min_dwell_s)
    out: list[Crossing] = []
    for prev, nxt in itertools.pairwise(runs):
        a, b = prev[0], nxt[0]
        if a == b:
            continue  # a short excursion in between: noise
        step = 1 if b > a else -1
        for lane_from in range(a, b, step):
            boundary = lane_from + 0.5 * step
            # The last frame of the old run (or later, up to the new run's first) still on
            # the old side; the crossing lies between it and the next frame.
            k = nxt[1]
            while k > prev[1] and not (np.isfinite(place[k - 1])
                                       and (place[k - 1] - boundary) * step < 0):
                k -= 1
            if k > prev[1] and np.isfinite(place[k]):
                i0, frac = k - 1, (boundary - place[k - 1]) / (place[k] - place[k - 1])
            else:  # never seen on the old side of this boundary: when the lane switched
                k = nxt[1]
                i0, frac = k, 0.0
            t_cross = float(t[i0] + frac * (t[k] - t[i0]))
            r_cross = float(rng[i0] + frac * (rng[k] - rng[i0]))
            ego = int(e[k])
            out.append(Crossing(t_cross, lane_from - ego, lane_from + step - ego, r_cross))
    return out


def track_crossings(boxes: list[RangedBox], lanes: LaneTrack | None, lane_width_m: float,
                    config: EventConfig | None = None) -> dict[int, list[Crossing]]:
    """:func:`lane_crossings` of every track of ranged boxes.

    Parameters
    ----------
    boxes : ranged boxes with lanes and lane offsets (boxes without a lane, or ahead
        farther than ``config.max_range_m`` or not ahead at all, are left out)
    lanes : the ego lane track the boxes' lanes were counted from (None: the camera axis)
    lane_width_m : the lane width used where ``lanes`` gives none [m]
    config : EventConfig, optional
    """
    cfg = config or EventConfig()
    by_track: dict[int, list[RangedBox]] = defaultdict(list)
    for b in boxes:
        if (b.lane is not None and math.isfinite(b.lane_offset_m)
                and 0.0 < b.range_m <= cfg.max_range_m):
            by_track[b.track_id].append(b)
    tracks = []
    for tid, rows in sorted(by_track.items()):
        rows.sort(key=lambda b: (b.t_s, b.frame))
        t = np.array([b.t_s for b in rows], dtype=float)
        keep = np.r_[True, np.diff(t) > 0]  # one row per time
        tracks.append((tid, [b for b, k in zip(rows, keep, strict=True) if k], t[keep]))
    # The ego lane at every track's times in one call: it smooths the whole lane track's
    # heading and curvature each time (per track, that was 3.7 s on a 60 s 720p clip).
    at = (ego_lane_at(lanes, np.concatenate([t for _, _, t in tracks]))
          if lanes is not None and len(lanes) and tracks else None)
    out: dict[int, list[Crossing]] = {}
    start = 0
    for tid, rows, t in tracks:
        width = np.full(len(rows), float(lane_width_m))
        ego_lane = np.zeros(len(rows), dtype=int)
        if at is not None:
            part = slice(start, start + len(t))
            width = np.where(np.isfinite(at.lane_width_m[part]), at.lane_width_m[part], width)
            ego_lane = at.lane[part].astype(int)
        start += len(t)
        found = lane_crossings(t, np.array([b.lane for b in rows]),
                               np.array([b.lane_offset_m for b in rows]), width, ego_lane,
                               np.array([b.range_m for b in rows]), cfg.min_dwell_s)
        if found:
            out[tid] = found
    return out


def _actor_at(actors_of_track: list[Actor], t_s: float) -> Actor | None:
    """The piece of a track (actor ``ID`` or ``ID-k``) whose trajectory spans ``t_s``."""
    for a in actors_of_track:
        if a.trajectory.t[0] - 1e-6 <= t_s <= a.trajectory.t[-1] + 1e-6:
            return a
    return None


def _is_track_piece(actor_id: str, track_id: int) -> bool:
    """Whether an actor id is a piece of a track: ``"ID"`` or ``"ID-k"`` (the names
    :func:`vid2sim.export.assemble.actors_from_tracks` gives)."""
    head, _, tail = actor_id.partition("-")
    return head == str(track_id) and (tail == "" or tail.isdigit())


def _speed_along_ego(actor: Actor, ego: Trajectory, t_s: float) -> float:
    """The actor's speed along the ego's direction of travel at ``t_s`` [m/s] (negative:
    oncoming); 0 for an actor the scenario holds still."""
    if not np.any(actor.trajectory.speed > 0):
        return 0.0
    a, e = actor.trajectory.state_at(t_s), ego.state_at(t_s)
    return float(a["speed"] * math.cos(float(a["heading"]) - float(e["heading"])))


def scenario_events(boxes: list[RangedBox], lanes: LaneTrack | None, actors: list[Actor],
                    ego_changes: list[LaneChange], lane_width_m: float, ego: Trajectory,
                    config: EventConfig | None = None) -> list[Event]:
    """The scenario's events: the actors' lane changes and the ego's own.

    Parameters
    ----------
    boxes : the ranged boxes the actors were made from
    lanes : the ego lane track their lanes were counted from (None: the camera axis)
    actors : the scenario's actors (pieces of tracks, ``ID`` or ``ID-k``)
    ego_changes : the ego's lane changes (any lane numbering: only the direction counts)
    lane_width_m : the lane width used where ``lanes`` gives none [m]
    ego : the scenario's ego trajectory (the direction of travel)
    config : EventConfig, optional

    Returns
    -------
    list of Event, sorted by time then actor
    """
    cfg = config or EventConfig()
    events = [Event("lane_change", EGO_ID, float(c.t_s), 0, int(np.sign(c.to_lane - c.from_lane)))
              for c in ego_changes if c.to_lane != c.from_lane]
    crossings = track_crossings(boxes, lanes, lane_width_m, cfg)
    for tid, found in crossings.items():
        pieces = [a for a in actors if _is_track_piece(a.id, tid)]
        for c in found:
            actor = _actor_at(pieces, c.t_s)
            if actor is None:
                continue
            if _speed_along_ego(actor, ego, c.t_s) < cfg.min_speed_mps:
                continue  # held still (parked), too slow to be changing lanes, or oncoming
            if max(abs(c.from_lane), abs(c.to_lane)) > cfg.max_lane:
                continue  # far from the ego lane (EventConfig.max_lane)
            events.append(Event(event_type(c.from_lane, c.to_lane, c.range_m > 0), actor.id,
                                c.t_s, c.from_lane, c.to_lane))
    events.sort(key=lambda ev: (ev.t_s, ev.actor))
    return events
