"""Rail vehicles: which tracks are trams, and which of them run on their own bed.

A tram reaches the tracker in three ways:

1. **The detector says so**: COCO's ``train`` class is the ``tram`` category
   (:data:`vid2sim.detect.vehicles.detector.COCO_VEHICLES`); the tracker's score-weighted vote makes
   the track a tram.
2. **A tall vehicle beyond the kerb.** A small detector seeing a tram from behind at 40-90 m
   mostly calls it a car or a bus (KITTI raw 0001: car scores 0.3-0.5, train at most 0.26).
   What gives it away is geometry that needs no class: the box stands on the ground beyond
   the road edge the lane markings measured (a kerb: no road vehicle drives there) and is
   taller, at the range its bottom edge gives, than any car or van (``min_height_m``).
   A bus or lorry is as tall but stays on the carriageway.
3. **A fragment of a tram.** A tracker that loses the tram's whole box often picks up a
   part of it (its lower front) as a new track a frame later; a track that starts within
   ``continue_s`` of a tram track's end with its first box mostly inside that track's last
   box is the same tram.

A tram whose centre lies beyond the road edge runs on its own track bed and is never the
ego's lead; a tram in the street (in the ego lane) can be.

Pure functions on records: boxes and the lane track in, track ids out.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field, replace

import numpy as np

from vid2sim.core.camera import Camera
from vid2sim.core.records import (
    LaneTrack,
    MarkingKind,
    Note,
    RangingResult,
    TrackedBox,
    VehicleCategory,
)

TRAM = VehicleCategory.TRAM


@dataclass(frozen=True)
class RailConfig:
    """Tuning of the rail-vehicle tests (sources in the comments)."""

    #: a vehicle taller than this stands out of the road fleet [m]: cars 1.4-1.7 m, vans
    #: and SUVs up to 2.1 m; buses, lorries and trams 3.0-3.6 m (ranging.config priors)
    min_height_m: float = 2.6
    #: its centre beyond the road edge by at least this [m]: a bus in a lay-by or a car
    #: half on the kerb stays within about a metre of it
    beyond_edge_m: float = 1.0
    #: frames of a track the geometric test needs (a few noisy frames decide nothing)
    min_frames: int = 5
    #: the box's bottom must lie this far below the horizon [px] for its ground range to
    #: count (1 px at 2 px below the horizon is half the range)
    min_rows_below_horizon_px: float = 4.0
    #: ground ranges beyond this are not used [m]
    max_range_m: float = 120.0
    #: a road edge is read this far ahead at most [m] (the lane model's clothoid beyond it
    #: is an extrapolation; its straight part still holds within a metre)
    max_edge_reach_m: float = 90.0
    #: a fragment track starts within this of a tram track's end [s]
    continue_s: float = 0.5
    #: share of the fragment's first box inside the tram's last box
    continue_inside: float = 0.7


@dataclass(slots=True)
class RailTracks:
    """Which tracks are trams.

    :param trams: every tram track id
    :param relabelled: trams the detector had called something else (their boxes need the
        tram's size for ranging)
    :param own_bed: trams standing beyond the road edge (never the lead)
    :param reasons: track id -> why it is a tram (for the notes)
    """

    trams: set[int] = field(default_factory=set)
    relabelled: set[int] = field(default_factory=set)
    own_bed: set[int] = field(default_factory=set)
    reasons: dict[int, str] = field(default_factory=dict)


def _by_track(boxes: list[TrackedBox]) -> dict[int, list[TrackedBox]]:
    out: dict[int, list[TrackedBox]] = defaultdict(list)
    for b in boxes:
        out[int(b.track_id)].append(b)
    for rows in out.values():
        rows.sort(key=lambda b: (b.t_s, b.frame))
    return out


def road_edges(lanes: LaneTrack | None, max_gap_frames: int = 10
               ) -> dict[int, tuple[object | None, object | None]]:
    """Per frame: the (right, left) ego-lane boundary where the lane track calls it a road
    edge (a :class:`~vid2sim.core.records.LaneBoundary`), else None; frames without a measured
    boundary take the nearest frame's within ``max_gap_frames``."""
    if lanes is None or not len(lanes.observations):
        return {}
    seen: dict[int, list] = {}
    for k, obs in enumerate(lanes.observations):
        right = (obs.right if obs.right is not None and k < len(lanes.right_kind)
                 and lanes.right_kind[k] == MarkingKind.ROAD_EDGE.value else None)
        left = (obs.left if obs.left is not None and k < len(lanes.left_kind)
                and lanes.left_kind[k] == MarkingKind.ROAD_EDGE.value else None)
        seen[int(obs.frame)] = [right, left]
    frames = np.array(sorted(seen))
    out: dict[int, tuple] = {}
    for side in (0, 1):
        have = np.array([f for f in frames if seen[f][side] is not None])
        for f in frames:
            if not len(have):
                continue
            j = int(have[np.argmin(np.abs(have - f))])
            if abs(j - f) <= max_gap_frames:
                pair = list(out.get(int(f), (None, None)))
                pair[side] = seen[j][side]
                out[int(f)] = tuple(pair)
    return out


def ground_geometry(camera: Camera, boxes: list[TrackedBox], config: RailConfig
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per box, from its bottom-centre pixel on the flat road (no class needed): ground
    range ``x`` [m], lateral ``y`` [m, positive left] and the box's height at that range
    [m]; NaN where the bottom is too near the horizon or too far."""
    if not boxes:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    px = np.array([[(b.x1 + b.x2) / 2.0, b.y2] for b in boxes], float)
    pts, below = camera.pixel_to_ground(px)
    horizon = np.array([camera.horizon_y_px(u) for u in px[:, 0]])
    ok = below & (px[:, 1] - horizon >= config.min_rows_below_horizon_px) \
        & (pts[:, 0] <= config.max_range_m)
    x = np.where(ok, pts[:, 0], np.nan)
    y = np.where(ok, pts[:, 1], np.nan)
    height = np.array([b.y2 - b.y1 for b in boxes], float) * x / camera.fy
    return x, y, height


def beyond_edge(x_m: float, y_m: float, edges: tuple, config: RailConfig) -> int:
    """+1 when a ground point lies beyond the left road edge, -1 beyond the right one (by
    ``beyond_edge_m``), 0 otherwise or where no edge is known."""
    right, left = edges if edges else (None, None)
    reach = min(x_m, config.max_edge_reach_m)
    if right is not None and y_m < float(right.y_at(reach)) - config.beyond_edge_m:
        return -1
    if left is not None and y_m > float(left.y_at(reach)) + config.beyond_edge_m:
        return 1
    return 0


def _inside_share(inner: TrackedBox, outer: TrackedBox) -> float:
    w = max(0.0, min(inner.x2, outer.x2) - max(inner.x1, outer.x1))
    h = max(0.0, min(inner.y2, outer.y2) - max(inner.y1, outer.y1))
    area = max((inner.x2 - inner.x1) * (inner.y2 - inner.y1), 1e-9)
    return w * h / area


def find_rail_tracks(boxes: list[TrackedBox], lanes: LaneTrack | None, camera: Camera,
                     config: RailConfig | None = None) -> RailTracks:
    """Which tracks are trams, and which of them run beyond the road edge (see the module
    docstring). ``camera``: the camera with the pitch the ranging estimated."""
    cfg = config or RailConfig()
    tracks = _by_track(boxes)
    edges = road_edges(lanes)
    out = RailTracks()
    x, y, height = ground_geometry(camera, boxes, cfg)
    index = {id(b): i for i, b in enumerate(boxes)}
    side_of: dict[int, float] = {}
    for tid, rows in tracks.items():
        idx = np.array([index[id(b)] for b in rows])
        sides = np.array([beyond_edge(x[i], y[i], edges.get(int(b.frame), (None, None)), cfg)
                          if np.isfinite(x[i]) else 0 for i, b in zip(idx, rows, strict=True)])
        side_of[tid] = float(np.mean(sides != 0)) if len(sides) else 0.0
        if rows[0].category == TRAM:
            out.trams.add(tid)
            out.reasons[tid] = "the detector's class (train)"
            continue
        usable = np.isfinite(height[idx])
        if usable.sum() < cfg.min_frames:
            continue
        tall = float(np.median(height[idx][usable])) >= cfg.min_height_m
        beyond = float(np.mean(sides[usable] != 0)) > 0.5
        if tall and beyond:
            out.trams.add(tid)
            out.relabelled.add(tid)
            out.reasons[tid] = (f"{np.median(height[idx][usable]):.1f} m tall beyond the "
                                "road edge")
    # fragments: a track starting where a tram track ended, inside its last box
    for tid in sorted(tracks, key=lambda k: tracks[k][0].t_s):
        if tid in out.trams:
            continue
        first = tracks[tid][0]
        for tram in list(out.trams):
            last = tracks[tram][-1]
            if 0.0 < first.t_s - last.t_s <= cfg.continue_s + 1e-9 \
                    and _inside_share(first, last) >= cfg.continue_inside:
                out.trams.add(tid)
                out.relabelled.add(tid)
                out.reasons[tid] = f"a part of tram track {tram} after it was lost"
                side_of[tid] = max(side_of.get(tid, 0.0), side_of.get(tram, 0.0))
                break
    out.own_bed = {t for t in out.trams if side_of.get(t, 0.0) > 0.5}
    return out


def relabel(boxes: list[TrackedBox], tracks: set[int]) -> list[TrackedBox]:
    """The boxes with the given tracks' category set to ``tram``."""
    return [replace(b, category=TRAM) if int(b.track_id) in tracks and b.category != TRAM
            else b for b in boxes]


def keep_trams_from_lead(result: RangingResult, rail: RailTracks
                         ) -> tuple[RangingResult, list[Note]]:
    """The ranging result with the trams of ``rail`` (:func:`find_rail_tracks`) named in
    notes, and those on their own track bed marked never to be the lead
    (``result.never_lead_tracks``, which the lane assignment honours).

    ``result`` is the ranging of the boxes with the trams relabelled (:func:`relabel`), so
    that a tram the detector called a truck was ranged with the tram's size prior: find the
    trams before ranging (with the pitch :func:`vid2sim.detect.ranging.choose_horizon`
    gives, which is the one the ranging estimates) and range once.
    """
    if not rail.trams:
        return result, []
    notes = [Note.estimate(f"track {t}: a tram ({rail.reasons[t]})"
                           + (", on its own track bed: never the lead" if t in rail.own_bed
                              else "")) for t in sorted(rail.trams)]
    if rail.own_bed:
        result.never_lead_tracks = frozenset(rail.own_bed)
    return result, notes
