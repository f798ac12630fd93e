"""The street of a built scenario: the road's reference line and lanes from the video, and
the actors stood on them.

:func:`lay_out_scene` takes the assembled scenario and the ego's lateral record
(:class:`~vid2sim.core.records.EgoLateral`: the lane track, the ego's lane, the path of its lane's
middle) and returns the scenario with

- **the main road's reference line**: on a road derived from the trajectory, the middle of
  the ego's first lane (the ego path with its wander and lane changes taken out), smoothed,
  and prolonged straight along its end tangents as far as actors were seen beyond the ego's
  path; a map road keeps the map's line;
- **its cross-section** (:mod:`vid2sim.export.crosssection`): lanes per direction and their
  widths, parking strips, track beds;
- **parked vehicles on their strip**: a static actor (held still by assembly) whose centre
  lies within ``snap_tolerance_m`` outside its strip is moved just inside it; every
  static actor faces along the road, the way of the lane it stands in. Moving actors keep
  their measured positions: how far they stand from their lane's middle is reported.

Pure functions: records in, records out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.ndimage import gaussian_filter1d

from vid2sim.core.lanelayout import (
    BACKWARD,
    DRIVING,
    PARKING,
    RAIL,
    ROAD_LANE_TYPES,
    SHOULDER,
    CrossSection,
)
from vid2sim.core.polyline import resample_polyline, signed_offsets
from vid2sim.core.records import RAIL_CATEGORIES, EgoLateral, Note
from vid2sim.core.scenario import LANE_WIDTH_RANGE_M, Actor, Road, Scenario, Trajectory
from vid2sim.export.assemble import is_static
from vid2sim.export.crosssection import (
    Inference,
    StandingVehicle,
    infer_cross_section,
    seen_lines,
)
from vid2sim.export.layout_config import LayoutConfig


@dataclass(slots=True)
class SceneLayout:
    """What :func:`lay_out_scene` did.

    :param moving_in_lane: share of moving road vehicles' trajectory points inside a lane
        of the road (driving, parking or shoulder)
    :param moving_from_centre_m: (median, p95) distance of those points from the middle of
        the lane they are in [m]
    """

    scenario: Scenario
    inference: Inference | None = None
    placed: int = 0
    static: int = 0
    moving_in_lane: float = float("nan")
    moving_from_centre_m: tuple[float, float] = (float("nan"), float("nan"))
    notes: list[str] = field(default_factory=list)
    #: ids of actors held standing by :func:`off_road_standing`
    held: list[str] = field(default_factory=list)


# --------------------------------------------------------------------------- geometry

#: Shortest prolongation of a line written [m] (shorter ones are left out).
MIN_EXTENSION_M = 1e-3


def line_frame(line_xy_m: np.ndarray, s_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points and unit left normals of a polyline at arc lengths ``s_m`` (clipped to it)."""
    line = np.asarray(line_xy_m, float)
    seg = np.diff(line, axis=0)
    length = np.hypot(seg[:, 0], seg[:, 1])
    cum = np.concatenate(([0.0], np.cumsum(length)))
    s = np.clip(np.asarray(s_m, float), 0.0, cum[-1])
    pts = np.column_stack((np.interp(s, cum, line[:, 0]), np.interp(s, cum, line[:, 1])))
    k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    tangent = seg[k] / np.maximum(length[k], 1e-12)[:, None]
    return pts, np.column_stack((-tangent[:, 1], tangent[:, 0]))


def extend_line(line_xy_m: np.ndarray, before_m: float, after_m: float,
                step_m: float = 1.0) -> np.ndarray:
    """Prolong a polyline straight along its end tangents [m]."""
    p = np.asarray(line_xy_m, float)
    out = [p]
    # under a millimetre adds no road, only a zero-length segment without a direction
    if before_m > MIN_EXTENSION_M:
        t0 = (p[1] - p[0]) / np.linalg.norm(p[1] - p[0])
        k = np.arange(math.ceil(before_m / step_m), 0, -1)[:, None] * (before_m / max(
            math.ceil(before_m / step_m), 1))
        out.insert(0, p[0] - k * t0)
    if after_m > MIN_EXTENSION_M:
        t1 = (p[-1] - p[-2]) / np.linalg.norm(p[-1] - p[-2])
        k = np.arange(1, math.ceil(after_m / step_m) + 1)[:, None] * (after_m / max(
            math.ceil(after_m / step_m), 1))
        out.append(p[-1] + k * t1)
    return np.vstack(out)


def _smooth(line: np.ndarray, sigma_m: float) -> np.ndarray:
    """Resample at 1 m and Gaussian-smooth the coordinates over arc length (ends kept)."""
    res = resample_polyline(line, 1.0)
    if len(res) < 5 or sigma_m <= 0:
        return res
    sm = np.column_stack([gaussian_filter1d(res[:, k], sigma_m, mode="nearest") for k in (0, 1)])
    sm[0], sm[-1] = res[0], res[-1]
    return sm


def lane_middle_path(lateral: EgoLateral, sigma_m: float) -> np.ndarray | None:
    """The path of the middle of the ego's first lane (ENU [m]), gaps filled by holding
    the ego's last measured shift from it, smoothed; None where never measured."""
    centre = lateral.lane_center_xy_m
    if centre is None:
        return None
    ego = lateral.ego
    ok = np.isfinite(centre).all(axis=1)
    if ok.sum() < 2:
        return None
    # the shift of the lane's middle from the ego, positive left, where measured
    normal = np.column_stack((-np.sin(ego.heading_rad), np.cos(ego.heading_rad)))
    shift = np.einsum("ij,ij->i", centre - np.column_stack((ego.x_m, ego.y_m)), normal)
    shift = np.interp(ego.t_s, ego.t_s[ok], shift[ok])
    path = np.column_stack((ego.x_m, ego.y_m)) + normal * shift[:, None]
    path = resample_polyline(path, 1.0)
    if len(path) < 2 or float(np.hypot(*(path[-1] - path[0]))) < 2.0:
        return None
    return _smooth(path, sigma_m)


# --------------------------------------------------------------------------- evidence


def project_actors(line: np.ndarray, actors: list[Actor]
                   ) -> list[tuple[np.ndarray, np.ndarray]]:
    """Arc length and offset (positive left) of every trajectory point of each actor on
    ``line`` [m]."""
    # one call for all the points: a long drive's points then go through the spatial index
    # (one call per actor kept every call under its threshold: quadratic in the drive)
    xy = [np.column_stack((a.trajectory.x, a.trajectory.y)).reshape(-1, 2) for a in actors]
    if not xy:
        return []
    s_m, d_m = signed_offsets(line, np.concatenate(xy))
    cuts = np.cumsum([len(p) for p in xy])[:-1]
    return list(zip(np.split(s_m, cuts), np.split(d_m, cuts), strict=True))


def standing_vehicles(actors: list[Actor], offsets: list[tuple[np.ndarray, np.ndarray]],
                      ego_speed_at, config: LayoutConfig) -> list[StandingVehicle]:
    """Where each actor stands across the road (see :class:`StandingVehicle`).

    ``ego_speed_at``: function of time [s] -> the ego's speed [m/s] (the static test).
    """
    out = []
    for a, (s, d) in zip(actors, offsets, strict=True):
        if not np.isfinite(d).any():
            continue
        t = a.trajectory.t
        static = a.static or is_static(a.trajectory.speed, ego_speed_at(t), config.assemble)
        direction = 0
        if not static and len(t) > 1 and t[-1] > t[0]:
            v = (s[-1] - s[0]) / (t[-1] - t[0])
            direction = 1 if v > 0.5 else (-1 if v < -0.5 else 0)
        out.append(StandingVehicle(a.id, float(np.nanmedian(d)), bool(static), direction,
                                   a.category in RAIL_CATEGORIES, float(a.width_m),
                                   int(np.isfinite(d).sum())))
    return out


# --------------------------------------------------------------------------- placing


def off_road_standing(actors: list[Actor], offsets: list[tuple[np.ndarray, np.ndarray]],
                      section: CrossSection, ego_speed_at, config: LayoutConfig) -> set[str]:
    """Ids of moving actors that are standing ones seen through a wrong monocular range:
    outside every lane of ``section`` a road vehicle may use (driving, parking, shoulder:
    beyond the kerb, in a car park) and moving along the road at a share of the
    ego's speed a range scale error explains (``off_road_max_forward_share`` forward,
    ``off_road_max_back_share`` backward) while the ego moves (see :class:`LayoutConfig`).
    ``ego_speed_at``: time [s] -> the ego's speed [m/s]."""
    held = set()
    for a, (s, d) in zip(actors, offsets, strict=True):
        t = a.trajectory.t
        ok = np.isfinite(s) & np.isfinite(d)
        if a.static or a.category in RAIL_CATEGORIES or ok.sum() < 2 or t[ok][-1] <= t[ok][0]:
            continue
        k = int(section.lane_at(float(np.median(d[ok]))))
        if k >= 0 and section.lanes[k].type in ROAD_LANE_TYPES:
            continue
        u = float(np.median(ego_speed_at(t[ok])))
        if u < config.assemble.static_min_ego_speed_mps:
            continue
        v = float(np.polyfit(t[ok], s[ok], 1)[0])  # along-road speed [m/s]
        if -config.off_road_max_back_share < v / u < config.off_road_max_forward_share:
            held.add(a.id)
    return held


def place_static(actor: Actor, line: np.ndarray, section: CrossSection, s_m: float,
                 offset_m: float, tolerance_m: float) -> tuple[Actor, bool]:
    """A static actor on the road: where it was seen, moved into its parking strip (or car
    park, or shoulder) when its centre lies within ``tolerance_m`` outside it, facing along
    the road the way of the lane it stands in. Returns the actor and whether it was moved
    across the road."""
    centres, edges = section.centres_m, section.edges_m
    moved = False
    d = offset_m
    best = None
    for k, lane in enumerate(section.lanes):
        if lane.type not in (PARKING, SHOULDER):
            continue
        if edges[k] - tolerance_m <= offset_m <= edges[k + 1] + tolerance_m and (
                best is None or abs(centres[k] - offset_m) < abs(centres[best] - offset_m)):
            best = k
    if best is not None:
        # inside the strip where it was seen: the row keeps the scatter of the monocular
        # lateral offsets, but each car stays where the keyframes saw it
        half = min(actor.width_m / 2.0, section.lanes[best].width_m / 2.0)
        d = float(np.clip(offset_m, edges[best] + half, edges[best + 1] - half))
        moved = d != offset_m
    k = int(section.lane_at(d))
    pts, normal = line_frame(line, np.array([s_m]))
    tangent = np.array([normal[0, 1], -normal[0, 0]])
    heading = math.atan2(tangent[1], tangent[0])
    if k >= 0 and section.lanes[k].direction == BACKWARD:
        heading += math.pi
    heading = math.atan2(math.sin(heading), math.cos(heading))
    x, y = pts[0] + normal[0] * d
    n = len(actor.trajectory)
    traj = Trajectory(actor.trajectory.t, np.full(n, x), np.full(n, y), np.full(n, heading),
                      np.zeros(n))
    return replace(actor, trajectory=traj), moved


# --------------------------------------------------------------------------- the scene


def lay_out_scene(scenario: Scenario, lateral: EgoLateral | None,
                  config: LayoutConfig | None = None) -> SceneLayout:
    """The scenario with its main road's reference line and cross-section from the video,
    and its parked cars on their strips (see the module docstring)."""
    cfg = config or LayoutConfig()
    out = SceneLayout(scenario)
    if not scenario.roads or lateral is None or lateral.lanes is None \
            or lateral.source == "gps":
        out.notes.append(Note.warning("no lane markings measured: the road keeps its lanes"))
        return out
    main = max(range(len(scenario.roads)), key=lambda i: len(scenario.roads[i].centerline))
    road = scenario.roads[main]
    ego = lateral.ego
    width = float(np.nanmedian(lateral.lane_width_m)) if np.isfinite(
        lateral.lane_width_m).any() else float(road.lane_width_m)
    width = float(np.clip(width, *cfg.cross_section.lane_width_range_m))
    ego_lane = int(lateral.lane[0]) if len(lateral.lane) else 0

    line = lane_middle_path(lateral, cfg.reference_smoothing_m) \
        if road.source == "trajectory" else None
    if line is not None:
        anchor = 0.0
    else:
        line = np.asarray(road.centerline, float)
        anchor = _anchor(lateral, line)
    extendable = road.source != "osm"
    if extendable:
        line = _cover_actors(line, scenario.actors, cfg)
    offsets = project_actors(line, scenario.actors)
    def ego_speed_at(t_s: np.ndarray) -> np.ndarray:
        return np.interp(t_s, ego.t_s, ego.speed_mps)

    vehicles = standing_vehicles(scenario.actors, offsets, ego_speed_at, cfg)
    lines = seen_lines(lateral.lanes, anchor, cfg.cross_section)
    prior = road.cross_section if road.source == "osm" else None
    inference = infer_cross_section(lines, vehicles, width, ego_lane, anchor, prior,
                                    road.highway, cfg.cross_section)
    # vehicles off the driving lanes whose motion is a range error: standing, and the
    # cross-section again with them (they may line a strip or fill a car park)
    held = off_road_standing(scenario.actors, offsets, inference.section, ego_speed_at, cfg)
    if held:
        scenario = replace(scenario, actors=[
            replace(a, static=True, static_by="road layout") if a.id in held else a
            for a in scenario.actors])
        vehicles = standing_vehicles(scenario.actors, offsets, ego_speed_at, cfg)
        inference = infer_cross_section(lines, vehicles, width, ego_lane, anchor, prior,
                                        road.highway, cfg.cross_section)
    section = inference.section
    lane_width = float(np.clip(round(width, 3), *LANE_WIDTH_RANGE_M))
    new_road = replace(road, centerline=line, lanes=section.n_driving,
                       lane_width_m=lane_width, cross_section=section)
    roads = list(scenario.roads)
    roads[main] = new_road

    actors = []
    placed = static = 0
    for a, (s, d) in zip(scenario.actors, offsets, strict=True):
        if a.static and np.isfinite(d).any():
            a, moved = place_static(a, line, section, float(np.nanmedian(s)),
                                    float(np.nanmedian(d)), cfg.snap_tolerance_m)
            placed += moved
            static += 1
        actors.append(a)
    out.scenario = replace(scenario, roads=roads, actors=actors)
    out.inference, out.placed, out.static = inference, placed, static
    in_lane, from_centre = _moving_report(scenario.actors, offsets, section)
    out.moving_in_lane, out.moving_from_centre_m = in_lane, from_centre
    out.notes.extend(_notes(new_road, inference, ego_lane, placed, static, in_lane,
                            from_centre, extendable and len(line) != len(road.centerline)))
    if held:
        out.notes.append(Note.estimate(
            f"{len(held)} vehicle(s) off the driving lanes ({', '.join(sorted(held))}) seemed "
            "to move along the road slower than the ego: standing, their monocular range off "
            "by a scale factor; replayed standing"))
    out.held = sorted(held)
    return out


def _anchor(lateral: EgoLateral, line: np.ndarray) -> float:
    """Offset of the middle of the ego's first lane from ``line`` [m] (median over the
    samples where the markings measured the ego's place in its lane)."""
    ego = lateral.ego
    _, d = signed_offsets(line, np.column_stack((ego.x_m, ego.y_m)))
    lane0 = lateral.lane[0] if len(lateral.lane) else 0
    w = np.where(np.isfinite(lateral.lane_width_m), lateral.lane_width_m,
                 np.nanmedian(lateral.lane_width_m) if np.isfinite(lateral.lane_width_m).any()
                 else 0.0)
    mid = d - lateral.offset_in_lane_m - (lateral.lane - lane0) * w
    return float(np.nanmedian(mid)) if np.isfinite(mid).any() else 0.0


def _cover_actors(line: np.ndarray, actors: list[Actor], cfg: LayoutConfig) -> np.ndarray:
    """The line prolonged straight so that every actor's position projects onto it."""
    if not actors or len(line) < 2:
        return line
    xy = np.vstack([np.column_stack((a.trajectory.x, a.trajectory.y)) for a in actors])
    reach = max(a.length_m for a in actors) / 2.0 + cfg.end_margin_m
    t0 = (line[1] - line[0]) / np.linalg.norm(line[1] - line[0])
    t1 = (line[-1] - line[-2]) / np.linalg.norm(line[-1] - line[-2])
    before = float(np.max((line[0] - xy) @ t0)) + reach
    after = float(np.max((xy - line[-1]) @ t1)) + reach
    before = min(max(before, 0.0), cfg.max_extension_m)
    after = min(max(after, 0.0), cfg.max_extension_m)
    return extend_line(line, before, after)


def _moving_report(actors: list[Actor], offsets, section: CrossSection
                   ) -> tuple[float, tuple[float, float]]:
    """Share of moving road vehicles' points inside a road lane, and the (median, p95)
    distance of those points from their lane's middle [m]."""
    centres = section.centres_m
    inside, dist = 0, []
    total = 0
    for a, (_, d) in zip(actors, offsets, strict=True):
        if a.static or a.category in RAIL_CATEGORIES:
            continue
        k = section.lane_at(d)
        ok = k >= 0
        road = np.array([ok_ and section.lanes[kk].type in (DRIVING, PARKING, SHOULDER)
                         for kk, ok_ in zip(k, ok, strict=True)], bool)
        total += len(d)
        inside += int(road.sum())
        dist.extend(np.abs(d[road] - centres[k[road]]).tolist())
    if not total:
        return float("nan"), (float("nan"), float("nan"))
    med = float(np.median(dist)) if dist else float("nan")
    p95 = float(np.percentile(dist, 95)) if dist else float("nan")
    return inside / total, (med, p95)


def _notes(road: Road, inference: Inference, ego_lane: int, placed: int, static: int,
           in_lane: float, from_centre: tuple[float, float], extended: bool) -> list[str]:
    section = road.cross_section
    forward = len(section.indices(DRIVING, "forward"))
    backward = len(section.indices(DRIVING, BACKWARD))
    kinds = ", ".join(f"{lane.type} {lane.direction} {lane.width_m:.2f} m"
                      for lane in section.lanes)
    notes = [Note.estimate(
        f"road cross-section (right to left): {kinds}; {forward} lane(s) in the ego's "
        f"direction with the ego in lane {inference.ego_lane} (0 = rightmost), {backward} "
        f"oncoming" + (f"; parked cars make a strip on the {' and '.join(inference.parked_sides)}"
                       if inference.parked_sides else "")
        + (f"; a car park on the {' and '.join(inference.car_parks)}" if inference.car_parks
           else "")
        + (f"; {inference.rail_beds} track bed(s) beside the road" if inference.rail_beds
           else ""))]
    if static:
        notes.append(Note.estimate(f"{static} parked vehicle(s) stand along the road, "
                                   f"{placed} of them moved into their strip"))
    if np.isfinite(in_lane):
        notes.append(Note.estimate(
            f"moving vehicles: {in_lane:.0%} of their positions in a lane of the road, "
            f"{from_centre[0]:.2f} m from its middle (median; p95 {from_centre[1]:.2f} m)"))
    if extended:
        notes.append(Note.assumption("the road runs straight beyond the ego's path as far "
                                     "as vehicles were seen"))
    if any(lane.type == RAIL for lane in section.lanes):
        notes.append(Note.estimate("rail vehicles run on a track bed outside the road's lanes"))
    return notes
