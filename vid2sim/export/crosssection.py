"""The road's cross-section from what the video shows (and the map, where there is one).

Evidence, all as lateral offsets from the road's reference line (positive left):

- **Lines** (:func:`seen_lines`): every line the lane markings measured (the ego lane's
  boundaries and the further lines on each side), placed across the road with the ego's
  filtered position in its lane, gathered over the clip. A line seen in at least
  ``min_line_support`` of the measured frames is a line of the road; its kind is the
  majority of its frames' kinds. A road edge ends the carriageway on its side: lines beyond
  it (rails, shadows, a kerb's far side) are not lanes.
- **Vehicles** (:class:`StandingVehicle`): where each actor stands across the road (the
  median of its offsets), whether it stood still, which way it moved, whether it is a rail
  vehicle.

:func:`infer_cross_section` turns them into lanes, rightmost first:

1. The ego lane, of the measured width, centred at ``anchor_m`` (the ego's first lane's middle
   from the reference line).
2. Lanes between consecutive lines on each side, out to the outermost supported line or a
   road edge; a gap of several lane widths is split into lanes of the ego lane's width. The
   ego's lane number (lanes of its direction to its right) adds lanes the lines missed.
3. Directions: the ego's lane and those right of it run forward; left of the first solid
   line (a centre line) they run backward; moving vehicles standing in a lane outvote that
   rule (an oncoming car in a lane makes it backward).
4. Moving vehicles beyond the outermost lane add lanes of the ego lane's width, one per lane
   they fill, in their direction.
5. Static vehicles lining a side beyond the driving lanes make a parking strip (a shoulder on
   motorways and trunk roads) wide enough for them, facing the way of the lane beside it;
   more static vehicles beyond that strip (a car park behind the kerb) make a parking area
   there, with a ``border`` (the kerb and pavement) between.
6. Rail vehicles beyond a road edge (a tram on its own bed) make a track bed (``rail``) at
   their offset, with a ``border`` between the kerb and the bed.

With a map (``prior``: the cross-section of the OSM tags, :func:`vid2sim.geo.roads.
cross_section_from_tags`) the driving lanes per direction and the tagged parking strips are
the map's, at the video's lane width; the video adds forward lanes the map lacks, parking
strips where parked cars line an untagged side, and track beds.

Pure functions: records in, records out.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from vid2sim.core.lanelayout import (
    BACKWARD,
    BORDER,
    DRIVING,
    FORWARD,
    PARKING,
    RAIL,
    SHOULDER,
    CrossSection,
    LaneSpec,
)
from vid2sim.core.records import LaneTrack, MarkingKind

#: Road classes whose strip beside the lanes is a hard shoulder, not a parking strip.
SHOULDER_HIGHWAYS = ("motorway", "motorway_link", "trunk", "trunk_link")


@dataclass(frozen=True)
class CrossSectionConfig:
    """Tuning of the cross-section inference (sources in the comments)."""

    #: a further line counts when seen in at least this share of the measured frames: the
    #: KITTI raw 0001 centre line is found in ~90 % of its frames, rails and shadows beyond
    #: the kerb in under 15 %
    min_line_support: float = 0.25
    #: lines closer than this across the road are one line [m] (a 0.12-0.15 m wide line,
    #: measured to +-0.1 m at 8-15 m ahead, bench_lanes.py)
    line_merge_m: float = 0.4
    #: plausible widths of a driving lane between line centres [m]
    #: (lane_track.LaneTrackConfig.lane_width_range_m)
    lane_width_range_m: tuple[float, float] = (2.2, 4.5)
    #: narrowest parking strip [m]: parallel parking, RASt 06 6.1.5 (2.0 m, 2.3 m taken)
    parking_width_m: float = 2.3
    #: widest strip made for parallel-parked cars [m] (RASt 06: at most 2.5 m, plus the
    #: scatter of monocular lateral offsets at 20-40 m, about +-0.5 m); static vehicles
    #: beyond it stand elsewhere (a car park behind the kerb)
    parking_max_width_m: float = 3.5
    #: a parked car's half width plus the room to its strip's outer edge [m]
    parking_margin_m: float = 1.2
    #: static vehicles on a side needed to make a parking strip there
    min_parked: int = 2
    #: width of one tram track's bed [m]: a tram 2.65 m wide (BOStrab section 34 limit) with
    #: its swept envelope; double-track lines lay their track centres about 3 m apart
    rail_bed_width_m: float = 3.0
    #: rail vehicles closer than this across the road run on one track [m] (the track
    #: centres of a double-track line lie about 3 m apart)
    rail_merge_m: float = 2.5
    #: a moving vehicle adds a lane when its median offset lies beyond the outermost lane by
    #: at least this share of a lane width
    beyond_lane_share: float = 0.25
    #: at most this many lanes are added on a side from vehicles alone
    max_added_lanes: int = 2
    #: a border strip narrower than this is not written (the bed or strip moves in) [m]
    min_border_m: float = 0.2
    #: widest parking area beyond a kerb strip [m]: a row of perpendicular bays (5.0 m,
    #: RASt 06 6.1.5) with its 6-7 m aisle (EAR 05, the German car-park guideline) is
    #: under 12 m, the widest non-driving lane (lanelayout.OTHER_LANE_WIDTH_RANGE_M)
    car_park_max_width_m: float = 12.0


@dataclass(frozen=True, slots=True)
class SeenLine:
    """A line of the road: offset from the reference line [m, positive left], its majority
    :class:`~vid2sim.core.records.MarkingKind` value and the share of measured frames it was
    seen in."""

    offset_m: float
    kind: str
    support: float


@dataclass(frozen=True, slots=True)
class StandingVehicle:
    """Where one actor stands across the road.

    :param offset_m: median offset of its centre from the reference line [m, positive left]
    :param static: it stood still (held by assembly, or moving at under the static share of
        the ego's speed)
    :param direction: +1 moving along the road, -1 against it, 0 standing
    :param rail: a rail vehicle (tram)
    :param width_m: its width [m]
    :param samples: trajectory points it was seen at (its weight)
    """

    actor_id: str
    offset_m: float
    static: bool
    direction: int
    rail: bool = False
    width_m: float = 1.8
    samples: int = 1


@dataclass(slots=True)
class _Lane:
    lo: float
    hi: float
    type: str = DRIVING
    direction: str = FORWARD
    left_kind: str = MarkingKind.UNKNOWN.value

    def spec(self) -> LaneSpec:
        return LaneSpec(self.type, self.direction, float(self.hi - self.lo))


@dataclass(slots=True)
class Inference:
    """The cross-section with how it came about (for notes and tests).

    :param ego_lane: the ego's first lane number (forward driving lanes from the right)
    :param parked_sides: sides ("left"/"right") where parked cars made a strip
    """

    section: CrossSection
    ego_lane: int
    lines_used: list[SeenLine] = field(default_factory=list)
    parked_sides: list[str] = field(default_factory=list)
    rail_beds: int = 0
    added_lanes: int = 0
    car_parks: list[str] = field(default_factory=list)


# --------------------------------------------------------------------------- lines


def seen_lines(track: LaneTrack, anchor_m: float = 0.0,
               config: CrossSectionConfig | None = None) -> list[SeenLine]:
    """The lines of the road over a clip, as offsets from the reference line [m].

    Each measured frame's lines (its ego-lane boundaries and further lines) are placed at
    ``anchor_m + lateral_m + y``: the camera sits ``lateral_m`` left of the middle of the
    clip's first lane (:attr:`LaneTrack.lateral_m`), which is ``anchor_m`` left of the
    reference line. Lines closer than ``line_merge_m`` are clustered; a cluster seen in at
    least ``min_line_support`` of the measured frames is kept, sorted right to left.
    """
    cfg = config or CrossSectionConfig()
    offsets, kinds, frames = [], [], []
    measured = 0
    for k, obs in enumerate(track.observations):
        if k >= len(track.lateral_m) or not np.isfinite(track.lateral_m[k]):
            continue
        measured += 1
        base = anchor_m + float(track.lateral_m[k])
        for line in (obs.right, obs.left, *obs.lines_right, *obs.lines_left):
            if line is not None and np.isfinite(line.offset_m):
                offsets.append(base + line.offset_m)
                kinds.append(line.kind)
                frames.append(k)
    if not measured or not offsets:
        return []
    y = np.asarray(offsets)
    order = np.argsort(y)
    clusters: list[list[int]] = [[int(order[0])]]
    for i in order[1:]:
        if y[i] - np.median(y[clusters[-1]]) <= cfg.line_merge_m:
            clusters[-1].append(int(i))
        else:
            clusters.append([int(i)])
    out = []
    for members in clusters:
        support = len({frames[i] for i in members}) / measured
        if support >= cfg.min_line_support:
            kind = Counter(kinds[i] for i in members).most_common(1)[0][0]
            out.append(SeenLine(float(np.median(y[members])), kind, float(support)))
    return out


# --------------------------------------------------------------------------- inference


def _walk(start: float, lines: list[SeenLine], sign: float, width_m: float,
          cfg: CrossSectionConfig) -> tuple[list[_Lane], bool]:
    """Lanes between consecutive lines outward from ``start`` (sign +1 left, -1 right);
    True when a road edge ended the walk."""
    lo_w, hi_w = cfg.lane_width_range_m
    lanes: list[_Lane] = []
    prev = start
    for line in sorted(lines, key=lambda ln: sign * ln.offset_m):
        gap = sign * (line.offset_m - prev)
        if gap < lo_w:
            if line.kind == MarkingKind.ROAD_EDGE.value:
                return lanes, True  # a gutter or kerb just past the last line
            continue  # a second line beside one (a double line), or noise
        n = max(1, round(gap / width_m))
        step = gap / n
        if not lo_w <= step <= hi_w:
            break  # a gap no whole number of lanes explains: the lines beyond are not lanes
        for j in range(n):
            a, b = prev + sign * j * step, prev + sign * (j + 1) * step
            lane = _Lane(min(a, b), max(a, b))
            if j == n - 1 and sign > 0:
                lane.left_kind = line.kind
            lanes.append(lane)
        prev = line.offset_m
        if line.kind == MarkingKind.ROAD_EDGE.value:
            return lanes, True
    return lanes, False


def _vote_directions(lanes: list[_Lane], vehicles: list[StandingVehicle], ego: _Lane) -> None:
    """Backward beyond the first solid line left of the ego; moving vehicles outvote."""
    left = [ln for ln in lanes if ln.lo >= ego.hi - 1e-6]
    backward = False
    prev_kind = ego.left_kind
    for lane in sorted(left, key=lambda ln: ln.lo):
        if prev_kind == MarkingKind.SOLID.value:
            backward = True
        lane.direction = BACKWARD if backward else FORWARD
        prev_kind = lane.left_kind
    for lane in left:
        votes = [v.direction for v in vehicles if not v.static and not v.rail and v.direction
                 and lane.lo <= v.offset_m < lane.hi]
        if votes:
            lane.direction = FORWARD if sum(votes) > 0 else BACKWARD


def _add_for_moving(lanes: list[_Lane], vehicles: list[StandingVehicle], width_m: float,
                    cfg: CrossSectionConfig, closed: dict[str, bool]) -> int:
    """Lanes added beyond the outermost ones for moving vehicles standing there."""
    added = 0
    for side, sign in (("left", 1.0), ("right", -1.0)):
        if closed[side]:
            continue
        for _ in range(cfg.max_added_lanes):
            edge = max(ln.hi for ln in lanes) if sign > 0 else min(ln.lo for ln in lanes)
            lo, hi = sorted((edge, edge + sign * width_m))
            inside = [v for v in vehicles if not v.static and not v.rail and v.direction
                      and lo <= v.offset_m < hi
                      and sign * (v.offset_m - edge) >= cfg.beyond_lane_share * width_m]
            if not inside:
                break
            direction = FORWARD if sum(v.direction for v in inside) > 0 else BACKWARD
            lanes.append(_Lane(lo, hi, DRIVING, direction))
            added += 1
    return added


def _outer_strip(lanes: list[_Lane], vehicles: list[StandingVehicle], side: str,
                 lane_type: str, cfg: CrossSectionConfig) -> _Lane | None:
    """A parking strip (or shoulder) beyond the outermost lane on one side, wide enough for
    the static vehicles lining it; None when fewer than ``min_parked`` stand there."""
    sign = 1.0 if side == "left" else -1.0
    outer = max(lanes, key=lambda ln: ln.hi) if sign > 0 else min(lanes, key=lambda ln: ln.lo)
    edge = outer.hi if sign > 0 else outer.lo
    beyond = [v for v in vehicles if v.static and not v.rail
              and sign * (v.offset_m - edge) > -0.25 * (outer.hi - outer.lo)]
    near = [v for v in beyond
            if sign * (v.offset_m - edge) <= cfg.parking_max_width_m - 0.5 * v.width_m]
    if len(near) < cfg.min_parked:
        return None
    reach = float(np.quantile([sign * (v.offset_m - edge) for v in near], 0.9))
    width = float(np.clip(reach + cfg.parking_margin_m, cfg.parking_width_m,
                          cfg.parking_max_width_m))
    lo, hi = sorted((edge, edge + sign * width))
    return _Lane(lo, hi, lane_type, outer.direction)


def _car_park(lanes: list[_Lane], vehicles: list[StandingVehicle], side: str,
              cfg: CrossSectionConfig) -> list[_Lane]:
    """A parking area (a car park or a row of bays behind the kerb) beyond the outermost lane
    on one side, with a ``border`` (kerb, pavement, hedge) between, for the static vehicles
    standing there; empty when fewer than ``min_parked`` do. The area reaches from the
    nearest of them to the farthest (each widened by ``parking_margin_m``), at most
    ``car_park_max_width_m`` wide; vehicles beyond that stay off the lanes."""
    sign = 1.0 if side == "left" else -1.0
    edge = max(ln.hi for ln in lanes) if sign > 0 else min(ln.lo for ln in lanes)
    beyond = sorted(sign * (v.offset_m - edge) for v in vehicles
                    if v.static and not v.rail and sign * (v.offset_m - edge) > 0.0)
    if len(beyond) < cfg.min_parked:
        return []
    inner = max(beyond[0] - cfg.parking_margin_m, 0.0)
    if inner < cfg.min_border_m:
        inner = 0.0
    outer = min(max(beyond[-1] + cfg.parking_margin_m, inner + cfg.parking_width_m),
                inner + cfg.car_park_max_width_m)
    direction = (max(lanes, key=lambda ln: ln.hi) if sign > 0
                 else min(lanes, key=lambda ln: ln.lo)).direction
    out = []
    if inner > 0.0:
        a, b = sorted((edge, edge + sign * inner))
        out.append(_Lane(a, b, BORDER, direction))
    a, b = sorted((edge + sign * inner, edge + sign * outer))
    out.append(_Lane(a, b, PARKING, direction))
    return out


def _rail_beds(lanes: list[_Lane], vehicles: list[StandingVehicle], closed: dict[str, bool],
               cfg: CrossSectionConfig) -> list[_Lane]:
    """Track beds for rail vehicles standing beyond a road edge, with a border before."""
    added: list[_Lane] = []
    for side, sign in (("left", 1.0), ("right", -1.0)):
        edge = max(ln.hi for ln in lanes) if sign > 0 else min(ln.lo for ln in lanes)
        rails = sorted((v for v in vehicles if v.rail and sign * (v.offset_m - edge) > 0.0),
                       key=lambda v: sign * v.offset_m)
        if not rails or not closed[side]:
            continue
        groups: list[list[StandingVehicle]] = [[rails[0]]]
        for v in rails[1:]:
            if abs(v.offset_m - _weighted_offset(groups[-1])) <= cfg.rail_merge_m:
                groups[-1].append(v)
            else:
                groups.append([v])
        for g in groups:
            centre = _weighted_offset(g)
            near = sign * (centre - edge) - cfg.rail_bed_width_m / 2.0
            if near >= cfg.min_border_m:
                a, b = sorted((edge, edge + sign * near))
                added.append(_Lane(a, b, BORDER, FORWARD if sign < 0 else BACKWARD))
                edge = edge + sign * near
            elif near < 0 and added and added[-1].type == RAIL:
                continue  # the same bed as the previous group
            a, b = sorted((edge, edge + sign * cfg.rail_bed_width_m))
            directions = [v.direction for v in vehicles if v.rail and a <= v.offset_m <= b]
            added.append(_Lane(a, b, RAIL, BACKWARD if sum(directions) < 0 else FORWARD))
            edge = edge + sign * cfg.rail_bed_width_m
    return added


def _weighted_offset(vehicles: list[StandingVehicle]) -> float:
    """Mean offset weighted by the points each vehicle was seen at [m]."""
    w = np.array([max(v.samples, 1) for v in vehicles], float)
    return float(np.sum(w * [v.offset_m for v in vehicles]) / np.sum(w))


def infer_cross_section(lines: list[SeenLine], vehicles: list[StandingVehicle],
                        lane_width_m: float, ego_lane: int = 0, anchor_m: float = 0.0,
                        prior: CrossSection | None = None, highway: str = "",
                        config: CrossSectionConfig | None = None) -> Inference:
    """The road's lanes from the evidence (see the module docstring).

    Parameters
    ----------
    lines : the lines of the road (:func:`seen_lines`), offsets from the reference line [m]
    vehicles : where the actors stand, offsets from the reference line
    lane_width_m : the ego lane's measured width [m]
    ego_lane : the ego's first lane, counted from the right (lane markings)
    anchor_m : offset of the middle of the ego's first lane from the reference line [m]
    prior : the map's cross-section (None without a map)
    highway : the road's OSM class (a shoulder rather than a parking strip on motorways)
    """
    cfg = config or CrossSectionConfig()
    w = float(lane_width_m)
    ego = _Lane(anchor_m - w / 2.0, anchor_m + w / 2.0)
    near_left = [ln for ln in lines if abs(ln.offset_m - ego.hi) <= cfg.line_merge_m]
    if near_left:
        ego.left_kind = near_left[0].kind
    others = [ln for ln in lines if abs(ln.offset_m - ego.hi) > cfg.line_merge_m
              and abs(ln.offset_m - ego.lo) > cfg.line_merge_m]
    right_edge_line = [ln for ln in lines if abs(ln.offset_m - ego.lo) <= cfg.line_merge_m]
    left_lanes, left_closed = _walk(ego.hi, [ln for ln in others if ln.offset_m > ego.hi],
                                    1.0, w, cfg)
    if right_edge_line and right_edge_line[0].kind == MarkingKind.ROAD_EDGE.value:
        right_lanes, right_closed = [], True
    else:
        right_lanes, right_closed = _walk(ego.lo, [ln for ln in others if ln.offset_m < ego.lo],
                                          -1.0, w, cfg)
    # lanes of the ego's direction the lines missed on its right
    while len(right_lanes) < ego_lane:
        edge = min([ego.lo] + [ln.lo for ln in right_lanes])
        right_lanes.append(_Lane(edge - w, edge))
        right_closed = False
    lanes = [ego, *right_lanes, *left_lanes]
    _vote_directions(lanes, vehicles, ego)
    ego_number = len(right_lanes)
    used = [ln for ln in lines if ln in others or ln in near_left or ln in right_edge_line]
    inference = Inference(CrossSection(0.0, ()), ego_number, used)
    if prior is not None and prior.n_driving:
        lanes = _from_prior(prior, w, lanes)
        # the map's carriageway ends at its outermost lanes
        closed = {"left": True, "right": True}
    else:
        closed = {"left": left_closed, "right": right_closed}
        inference.added_lanes = _add_for_moving(lanes, vehicles, w, cfg, closed)
    strip_type = SHOULDER if highway in SHOULDER_HIGHWAYS else PARKING
    for side in ("right", "left"):
        driving = [ln for ln in lanes if ln.type == DRIVING]
        has_strip = any(ln.type in (PARKING, SHOULDER) and
                        (ln.lo >= max(d.hi for d in driving) - 1e-6 if side == "left"
                         else ln.hi <= min(d.lo for d in driving) + 1e-6) for ln in lanes)
        strip = _outer_strip(lanes, vehicles, side, strip_type, cfg)
        if strip is not None and not has_strip:
            lanes.append(strip)
            inference.parked_sides.append(side)
            closed[side] = True
        elif has_strip:
            closed[side] = closed[side] or strip is not None
        if closed[side] and (strip is not None or has_strip):
            # beyond a kerb strip: a car park where more static vehicles stand
            park = _car_park(lanes, vehicles, side, cfg)
            lanes.extend(park)
            if park:
                inference.car_parks.append(side)
    rails = _rail_beds(lanes, vehicles, closed, cfg)
    inference.rail_beds = sum(r.type == RAIL for r in rails)
    lanes = sorted(lanes + rails, key=lambda ln: ln.lo)
    inference.section = CrossSection(float(lanes[0].lo), tuple(ln.spec() for ln in lanes))
    return inference


def _from_prior(prior: CrossSection, width_m: float, seen: list[_Lane]) -> list[_Lane]:
    """The map's lanes at the video's width, with the forward lanes the video saw and the
    map lacks; laid out by the map's rule (two-way: forward lanes right of the centerline)."""
    forward = max(len(prior.indices(DRIVING, FORWARD)),
                  sum(ln.type == DRIVING and ln.direction == FORWARD for ln in seen))
    backward = len(prior.indices(DRIVING, BACKWARD))
    right_edge = -forward * width_m if backward else -(forward + backward) * width_m / 2.0
    lanes = [_Lane(right_edge + k * width_m, right_edge + (k + 1) * width_m)
             for k in range(forward)]
    lanes += [_Lane(right_edge + k * width_m, right_edge + (k + 1) * width_m, DRIVING, BACKWARD)
              for k in range(forward, forward + backward)]
    first = prior.indices(DRIVING)[0]
    last = prior.indices(DRIVING)[-1]
    edge = lanes[0].lo
    for spec in reversed(prior.lanes[:first]):
        lanes.append(_Lane(edge - spec.width_m, edge, spec.type, spec.direction))
        edge -= spec.width_m
    edge = lanes[forward + backward - 1].hi
    for spec in prior.lanes[last + 1:]:
        lanes.append(_Lane(edge, edge + spec.width_m, spec.type, spec.direction))
        edge += spec.width_m
    return lanes
