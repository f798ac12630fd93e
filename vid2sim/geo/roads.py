"""The road the car drove: map-matched OSM route -> one centerline with lanes, in ENU.

Pipeline (:func:`build_road`): map (file, download, or none) -> :func:`vid2sim.geo.mapmatch.match`
-> centerline of the route (ways joined in travel order, resampled at <= 1 m) -> lanes and
lane width from OSM tags (defaults in :data:`LANE_DEFAULTS`) -> the ego's lane from its lateral
offset. Without a map, the road is the smoothed ego path itself (``source: "trajectory"``).

Lanes: ``Road.lanes`` counts every lane of the carriageway (OSM ``lanes``); the centerline
is the OSM way geometry, i.e. the middle of the carriageway; the ego's direction has
``lanes_forward`` lanes, on the right of the middle on a two-way road (right-hand traffic).
Lane indices follow :data:`LANE_NUMBERING`, the project's one convention.
"""

from __future__ import annotations

import logging
import math
import re
from collections import Counter
from pathlib import Path

import numpy as np

from vid2sim.base.defaults import LANE_WIDTH_M
from vid2sim.base.errors import InconsistentInputError
from vid2sim.base.fileio import atomic_open
from vid2sim.core.enu import EnuFrame
from vid2sim.core.lanelayout import (
    BACKWARD,
    DRIVING,
    FORWARD,
    PARKING,
    SHOULDER,
    CrossSection,
    LaneSpec,
)
from vid2sim.core.polyline import resample_polyline
from vid2sim.core.records import EgoTrack, GpsTrace, RoadResult
from vid2sim.core.scenario import MAX_LANES, Road
from vid2sim.geo.alongroute import signed_offsets
from vid2sim.geo.mapmatch import MatchConfig, MatchResult, match
from vid2sim.geo.osm import RoadNetwork, download_network, format_bbox, load_network
from vid2sim.geo.trace import video_t0_utc

log = logging.getLogger(__name__)

#: Defaults where OSM has no ``lanes`` / ``width`` tag, per ``highway`` value:
#: (lanes of a two-way road, lanes of a one-way road, lane width [m]). Lane counts follow the
#: OSM wiki's assumptions (Key:lanes: two-way roads 2, one-way roads 1, motorways and trunks
#: 2 per direction); widths are typical European design values (motorway 3.75 m, urban main
#: roads 3.25-3.5 m, residential 3.0 m, service and living streets 2.75-3.0 m).
LANE_DEFAULTS: dict[str, tuple[int, int, float]] = {
    "motorway": (4, 2, 3.75),
    "motorway_link": (2, 1, 3.5),
    "trunk": (4, 2, 3.5),
    "trunk_link": (2, 1, 3.5),
    "primary": (2, 1, 3.5),
    "primary_link": (2, 1, 3.5),
    "secondary": (2, 1, 3.25),
    "secondary_link": (2, 1, 3.25),
    "tertiary": (2, 1, 3.25),
    "tertiary_link": (2, 1, 3.25),
    "unclassified": (2, 1, 3.0),
    "residential": (2, 1, 3.0),
    "living_street": (1, 1, 2.75),
    "service": (1, 1, 3.0),
    "road": (2, 1, 3.0),
}
#: The project's lane numbering (stated here once; every lane index in vid2sim follows it):
#: lane 0 is the rightmost lane in the direction of travel, and indices count leftwards.
LANE_NUMBERING = "lane 0 = rightmost in the direction of travel, counting leftwards"
#: lane width of a road derived from the trajectory, and of unknown highway types [m]
DEFAULT_LANE_WIDTH_M = LANE_WIDTH_M  # the project's default (vid2sim.base.defaults)
#: lane widths outside this range in a ``width`` tag are taken as tagging errors [m]
LANE_WIDTH_RANGE_M = (2.5, 4.5)
#: centerline sample spacing, at most [m]
CENTERLINE_STEP_M = 1.0
#: margin around the trace's bounding box when cropping the map [m]
MAP_MARGIN_M = 300.0
#: a fix is heading-informative when the ego moves at least this fast [m/s]
_HEADING_MIN_SPEED_MPS = 2.0


# --------------------------------------------------------------------------- lanes


def _number(text: str | None) -> float | None:
    """First number in an OSM value ('7', '7.5 m', '3;2' -> 3), None if none."""
    if not text:
        return None
    m = re.search(r"\d+(?:\.\d+)?", str(text))
    return float(m.group()) if m else None


def lanes_from_tags(tags: dict[str, str], along_way: bool = True) -> tuple[int, int, float]:
    """Lanes of a carriageway from its OSM tags.

    Parameters
    ----------
    tags : OSM way tags (``highway``, ``lanes``, ``lanes:forward``, ``lanes:backward``,
        ``width``, ``oneway``)
    along_way : travel follows the way's node order (else ``lanes:backward`` applies)

    Returns
    -------
    (lanes_total, lanes_in_travel_direction, lane_width_m)
    """
    highway = tags.get("highway", "")
    two_way_default, one_way_default, width_default = LANE_DEFAULTS.get(
        highway, (2, 1, DEFAULT_LANE_WIDTH_M))
    oneway = tags.get("oneway", "") in ("yes", "true", "1", "-1", "reverse") or (
        tags.get("junction") in ("roundabout", "circular") and tags.get("oneway") != "no")
    # A lane count beyond any carriageway's (a tag typo, "lanes=99") is taken as no tag.
    lanes, fwd, bwd = (v if v is None or v <= MAX_LANES else None for v in (
        _number(tags.get("lanes")), _number(tags.get("lanes:forward")),
        _number(tags.get("lanes:backward"))))
    if oneway:
        total = int(lanes) if lanes and lanes >= 1 else one_way_default
        forward = total
    else:
        if lanes and lanes >= 1:
            total = int(lanes)
        elif fwd and bwd:
            total = int(fwd + bwd)
        else:
            total = two_way_default
        mine = fwd if along_way else bwd
        if mine and 1 <= mine <= total:
            forward = int(mine)
        else:
            # split evenly; an odd middle lane (turn lane, or one shared lane) counts for both
            forward = max(1, math.ceil(total / 2)) if total > 1 else 1
    width = _number(tags.get("width"))
    lane_width = width_default
    if width and total:
        per_lane = width / total
        if LANE_WIDTH_RANGE_M[0] <= per_lane <= LANE_WIDTH_RANGE_M[1]:
            lane_width = per_lane
    return total, forward, float(lane_width)


#: Width of a parking lane by how the cars stand [m] (RASt 06, the German street design
#: guideline, 6.1.5: parallel parking 2.00 m, at least 1.80 m, 2.50 m beside a bus route;
#: diagonal bays 4.15-4.50 m deep; perpendicular bays 5.00 m). ``parking:*:width`` wins.
PARKING_WIDTH_M = {"parallel": 2.3, "diagonal": 4.5, "perpendicular": 5.0}
#: Tag values (``parking:lane:<side>`` of the older scheme, ``parking:<side>`` of the 2022
#: one) that put standing cars beside the driving lanes; others (``no``, ``no_parking``,
#: ``no_stopping``, ``separate``, ``fire_lane``) do not.
PARKING_ON_ROAD = {"parallel", "diagonal", "perpendicular", "marked", "yes", "lane",
                   "street_side", "on_kerb", "half_on_kerb", "shoulder"}
#: Width of a shoulder without a ``shoulder:width`` tag [m]: the hard shoulder of German
#: motorways (RAA 2008: 2.50-3.00 m) and of rural roads (1.5 m) by road class.
SHOULDER_WIDTH_M = {"motorway": 2.5, "motorway_link": 2.5, "trunk": 2.5}
SHOULDER_WIDTH_OTHER_M = 1.5


def _side_value(tags: dict[str, str], prefix: str, side: str) -> str | None:
    """The tag ``<prefix>:<side>``, or ``<prefix>:both``."""
    for key in (f"{prefix}:{side}", f"{prefix}:both"):
        if tags.get(key):
            return str(tags[key]).strip().lower()
    return None


def _parking_side(tags: dict[str, str], side: str) -> float | None:
    """Width of the parking lane on one side of the way (``left``/``right`` of its node
    order) from ``parking:lane:*`` or ``parking:*`` tags [m], None without one."""
    old = _side_value(tags, "parking:lane", side)
    new = _side_value(tags, "parking", side)
    value = old or new
    if value is None or value not in PARKING_ON_ROAD:
        return None
    orientation = (value if value in PARKING_WIDTH_M else
                   _side_value(tags, "parking", f"{side}:orientation") or "parallel")
    width = (_number(tags.get(f"parking:{side}:width") or tags.get(f"parking:lane:{side}:width")
                     or tags.get("parking:both:width")))
    if width and 1.5 <= width <= 12.0:
        return float(width)
    return PARKING_WIDTH_M.get(orientation, PARKING_WIDTH_M["parallel"])


def _shoulder_sides(tags: dict[str, str]) -> set[str]:
    value = str(tags.get("shoulder", "")).strip().lower()
    sides = {"both": {"left", "right"}, "yes": {"right"}, "right": {"right"},
             "left": {"left"}}.get(value, set())
    sides |= {s for s in ("left", "right") if tags.get(f"shoulder:{s}") == "yes"}
    return sides


def cross_section_from_tags(tags: dict[str, str], along_way: bool = True) -> CrossSection:
    """A carriageway's lanes from its OSM tags, rightmost first in the travel direction.

    Driving lanes come from :func:`lanes_from_tags` (``lanes``, ``lanes:forward``,
    ``lanes:backward``, ``width``, ``oneway``): on a two-way road the travel direction's
    lanes lie right of the centerline (the way's geometry) and the others left of it, the
    rule by which :func:`vid2sim.geo.lateral.fuse_lateral` places the ego; a one-way road's
    lanes are centred on it. Parking lanes (``parking:lane:<side>``, ``parking:<side>`` with
    its ``:orientation`` and ``:width``) and shoulders (``shoulder``, ``shoulder:width``) go
    outside the driving lanes on their side; a way drawn against the travel direction has
    its sides swapped. Parked cars face the way of the driving lane beside them.
    """
    total, forward, width = lanes_from_tags(tags, along_way)
    backward = total - forward
    oneway = backward <= 0 or tags.get("oneway", "") in ("yes", "true", "1", "-1", "reverse")
    if oneway:
        forward, backward = total, 0
    right_edge = -forward * width if backward else -total * width / 2.0
    lanes = [LaneSpec(DRIVING, FORWARD, width) for _ in range(forward)]
    lanes += [LaneSpec(DRIVING, BACKWARD, width) for _ in range(backward)]
    # sides in the travel direction: a way drawn against it has its left on our right
    right, left = ("right", "left") if along_way else ("left", "right")
    shoulder_w = _number(tags.get("shoulder:width"))
    shoulder_w = (shoulder_w if shoulder_w and 0.5 <= shoulder_w <= 5.0 else
                  SHOULDER_WIDTH_M.get(tags.get("highway", ""), SHOULDER_WIDTH_OTHER_M))
    shoulders = _shoulder_sides(tags)
    left_dir = BACKWARD if backward else FORWARD
    park_right, park_left = _parking_side(tags, right), _parking_side(tags, left)
    outer_right: list[LaneSpec] = []
    if park_right:
        outer_right.append(LaneSpec(PARKING, FORWARD, park_right))
    if right in shoulders:
        outer_right.append(LaneSpec(SHOULDER, FORWARD, shoulder_w))
    outer_left: list[LaneSpec] = []
    if park_left:
        outer_left.append(LaneSpec(PARKING, left_dir, park_left))
    if left in shoulders:
        outer_left.append(LaneSpec(SHOULDER, left_dir, shoulder_w))
    right_edge -= sum(lane.width_m for lane in outer_right)
    return CrossSection(right_edge, tuple(outer_right[::-1] + lanes + outer_left))


# --------------------------------------------------------------------------- geometry


def join_route(net: RoadNetwork, edges: list[int]) -> np.ndarray:
    """Edge geometries joined in travel order (the shared node written once) [m]."""
    parts = [net.edge_xy[edges[0]]] + [net.edge_xy[e][1:] for e in edges[1:]]
    return np.vstack(parts)


def lane_index(offset_m: np.ndarray, lanes_total: int, lanes_forward: int,
               lane_width_m: float) -> np.ndarray:
    """Lane index (:data:`LANE_NUMBERING`) from the signed offset to the carriageway's middle
    line (positive left).

    The carriageway spans ``-lanes_total * w / 2 .. +lanes_total * w / 2``; the travel
    direction owns the ``lanes_forward`` lanes from its right edge. Offsets beyond the road
    are clipped to the outermost lane of the travel direction.
    """
    right_edge = -lanes_total * lane_width_m / 2.0
    lane = np.floor((np.asarray(offset_m, float) - right_edge) / lane_width_m)
    lane = np.where(np.isfinite(lane), lane, 0)
    return np.clip(lane, 0, max(lanes_forward - 1, 0)).astype(int)


# --------------------------------------------------------------------------- building


def fix_times_s(trace: GpsTrace, gps_offset_s: float | None = None) -> np.ndarray:
    """Fix times on the video clock [s], in file order, by the rule the ego smoother uses
    (:func:`vid2sim.geo.trace.video_t0_utc`): ``gps_offset_s`` is the video time of the
    earliest fix; else the file's own clock (``video_start_utc_s``); else the earliest fix is
    t = 0."""
    t_utc = np.array([f.t_utc_s for f in trace.fixes], float)
    if not t_utc.size:
        return t_utc
    return t_utc - video_t0_utc(trace, gps_offset_s)[0]


def _trace_bbox(lat: np.ndarray, lon: np.ndarray, margin_m: float
                ) -> tuple[float, float, float, float]:
    dlat = margin_m / 111_320.0
    dlon = margin_m / (111_320.0 * max(math.cos(math.radians(float(np.mean(lat)))), 0.01))
    return (float(lon.min() - dlon), float(lat.min() - dlat),
            float(lon.max() + dlon), float(lat.max() + dlat))


def _weighted_mode(values: list, weights: np.ndarray):
    acc: Counter = Counter()
    for v, w in zip(values, weights, strict=True):
        acc[v] += float(w)
    return acc.most_common(1)[0][0]


def _ego_headings(ego: EgoTrack, t_s: np.ndarray) -> np.ndarray:
    """Ego heading at the fix times where the ego moves, else NaN [rad]."""
    if len(ego.t_s) < 2:
        return np.full(len(t_s), np.nan)
    heading = np.interp(t_s, ego.t_s, np.unwrap(ego.heading_rad))
    speed = np.interp(t_s, ego.t_s, ego.speed_mps)
    inside = (t_s >= ego.t_s[0]) & (t_s <= ego.t_s[-1])
    return np.where(inside & (speed >= _HEADING_MIN_SPEED_MPS), heading, np.nan)


def _osm_road(net: RoadNetwork, res: MatchResult, piece: int) -> tuple[Road, int, list[str]]:
    edges = res.route_edges[piece]
    warnings: list[str] = []
    centerline = resample_polyline(join_route(net, edges))
    lengths = net.edge_length_m[edges]
    per_edge = [lanes_from_tags(net.edge_tags[e], bool(net.edge_along_way[e])) for e in edges]
    lanes = int(_weighted_mode([p[0] for p in per_edge], lengths))
    forward = int(_weighted_mode([p[1] for p in per_edge if p[0] == lanes],
                                 lengths[[p[0] == lanes for p in per_edge]]))
    width = float(np.median(np.repeat([p[2] for p in per_edge],
                                      np.maximum(1, np.round(lengths).astype(int)))))
    if len({p[0] for p in per_edge}) > 1:
        counts = sorted({p[0] for p in per_edge})
        warnings.append(f"lane count varies along the route ({counts}); the road uses {lanes}, "
                        "the most common by length")
    # the cross-section of the longest stretch with the chosen lane count (a road has one)
    same = [i for i, p in enumerate(per_edge) if p[0] == lanes and p[1] == forward]
    main_edge = edges[max(same, key=lambda i: lengths[i])]
    section = cross_section_from_tags(net.edge_tags[main_edge], bool(net.edge_along_way[main_edge]))
    section = with_driving_width(section, round(width, 3))
    names = [net.edge_tags[e].get("name", "") for e in edges]
    highways = [net.edge_tags[e].get("highway", "") for e in edges]
    ways: list[int] = []
    for e in edges:
        if not ways or ways[-1] != int(net.edge_way_id[e]):
            ways.append(int(net.edge_way_id[e]))
    road = Road(id=f"road{piece}", name=_weighted_mode(names, lengths),
                highway=_weighted_mode(highways, lengths), source="osm", osm_way_ids=ways,
                lanes=lanes, lane_width_m=round(width, 3), centerline=centerline,
                cross_section=section)
    return road, forward, warnings


def with_driving_width(section: CrossSection, width_m: float) -> CrossSection:
    """The cross-section with every driving lane ``width_m`` wide, laid out by the rule of
    :func:`cross_section_from_tags` (two-way: the travel direction's lanes right of the
    centerline; one-way: centred on it)."""
    lanes = tuple(LaneSpec(lane.type, lane.direction, width_m) if lane.type == DRIVING
                  else lane for lane in section.lanes)
    forward = len(section.indices(DRIVING, FORWARD))
    backward = len(section.indices(DRIVING, BACKWARD))
    first = next(i for i, lane in enumerate(lanes) if lane.type == DRIVING)
    edge = -forward * width_m if backward else -(forward + backward) * width_m / 2.0
    return CrossSection(edge - sum(lane.width_m for lane in lanes[:first]), lanes)


def trajectory_road(ego: EgoTrack) -> Road:
    """A one-lane road along the smoothed ego path (used where no map is available).

    Standing-still samples are dropped; a path shorter than 2 m becomes a 20 m straight road
    along the median heading, so the scenario still has a road.
    """
    xy = np.column_stack([ego.x_m, ego.y_m])
    line = resample_polyline(xy)
    if len(line) < 3:
        h = float(np.median(ego.heading_rad)) if len(ego.heading_rad) else 0.0
        c = xy.mean(axis=0) if len(xy) else np.zeros(2)
        direction = np.array([math.cos(h), math.sin(h)])
        line = resample_polyline(np.vstack([c - 10 * direction, c + 10 * direction]))
    return Road(id="road0", name="", highway="unknown", source="trajectory", osm_way_ids=[],
                lanes=1, lane_width_m=DEFAULT_LANE_WIDTH_M, centerline=line)


def build_road(trace: GpsTrace, ego: EgoTrack, map_path: Path | None, *,
               gps_offset_s: float | None = None, allow_download: bool = True,
               cache_dir: Path | None = None, config: MatchConfig | None = None) -> RoadResult:
    """Match the trace to OSM and build the driven road in the ego's ENU frame.

    Parameters
    ----------
    trace : GPS fixes (as read); every fix gets one entry in ``matches``
    ego : smoothed ego track (:func:`vid2sim.geo.trace.smooth_ego` with the same
        ``gps_offset_s``); its ``origin`` is the frame of the output
    map_path : ``.osm`` or ``.osm.pbf``; None -> download the trace's box with osmnx if
        ``allow_download`` and the network is reachable, else the trajectory road
    cache_dir : map cache: parsed map files and osmnx downloads (default
        :func:`vid2sim.geo.mapcache.default_cache_dir`)
    gps_offset_s : video time of the earliest fix [s] (``--gps-offset``); None: the file's
        clock (:func:`fix_times_s`, the rule of the ego smoother)
    config : matcher tuning

    Raises
    ------
    InputError
        unreadable/empty map, no drivable roads, or the trace outside the map (both boxes).
    """
    fixes = trace.fixes
    if not fixes:
        raise InconsistentInputError(trace.path, "no GPS fixes")
    lat = np.array([f.lat_deg for f in fixes])
    lon = np.array([f.lon_deg for f in fixes])
    t_fix = fix_times_s(trace, gps_offset_s)
    xy = EnuFrame(ego.origin).to_enu(lat, lon)[:, :2]
    bbox = _trace_bbox(lat, lon, MAP_MARGIN_M)
    warnings: list[str] = []

    net: RoadNetwork | None = None
    if map_path is not None:
        net = load_network(map_path, ego.origin, bbox_lonlat=bbox, cache_dir=cache_dir)
    elif allow_download:
        net = download_network(bbox, ego.origin, cache_dir=cache_dir)
        if net is None:
            warnings.append("no map given and OpenStreetMap could not be reached: the road "
                            "follows the smoothed trajectory (default lane width)")
    else:
        warnings.append("no map given (downloads disabled): the road follows the smoothed "
                        "trajectory (default lane width)")

    if net is None:
        return _trajectory_result(trace, ego, xy, t_fix, warnings)

    accuracy = np.array([np.nan if f.accuracy_m is None else f.accuracy_m for f in fixes])
    speed = np.interp(t_fix, ego.t_s, ego.speed_mps) if len(ego.t_s) else None
    res = match(net, xy[:, 0], xy[:, 1], t_fix, heading_rad=_ego_headings(ego, t_fix),
                accuracy_m=accuracy, speed_mps=speed, config=config)
    if not res.route_edges or res.matched_share == 0.0:
        raise InconsistentInputError(map_path, f"no fix lies near a drivable road of this map: the trace "
                         f"({format_bbox(_trace_bbox(lat, lon, 0.0))}) and the map's roads "
                         f"({format_bbox(net.bbox_lonlat)}) do not overlap",
                         "pass a map that covers the drive")
    warnings.extend(res.warnings)
    if res.matched_share < 0.5:
        warnings.append(f"only {res.matched_share:.0%} of the fixes matched a road")

    roads, forwards = [], []
    for k in range(len(res.route_edges)):
        road, forward, w = _osm_road(net, res, k)
        roads.append(road)
        forwards.append(forward)
        warnings.extend(w)
    # ego lane: offsets to the road of the matched piece, searched near the expected place
    main = int(np.argmax([r.centerline.shape[0] for r in roads]))
    ego_xy = np.column_stack([ego.x_m, ego.y_m])
    on_main = res.fix_piece == main
    expected = (np.interp(ego.t_s, t_fix[on_main], res.fix_route_s_m[on_main])
                if on_main.sum() >= 2 else None)
    _, ego_off = signed_offsets(roads[main].centerline, ego_xy, expected)
    ego_lane = lane_index(ego_off, roads[main].lanes, forwards[main], roads[main].lane_width_m)

    matches = [
        {"t": float(t), "osm_way_id": int(w) if w >= 0 else None,
         "offset_m": float(o) if np.isfinite(o) else None}
        for t, w, o in zip(t_fix, res.fix_way_id, res.fix_offset_m, strict=True)
    ]
    ways = res.way_sequence()
    route_length = float(sum(net.edge_length_m[p].sum() for p in res.route_edges))
    stats = {
        "fixes": len(fixes), "matched_share": res.matched_share,
        "outlier_fixes": int(res.fix_outlier.sum()), "route_length_m": route_length,
        "ways": len(ways), "lanes": roads[main].lanes, "lanes_forward": forwards[main],
        "lane_width_m": roads[main].lane_width_m, "source": "osm", "map": net.source,
        "breaks": res.n_breaks,
    }
    return RoadResult(origin=ego.origin, roads=roads, route_osm_way_ids=ways, matches=matches,
                      ego_lane=ego_lane, ego_offset_m=ego_off, source="osm",
                      lanes_forward=forwards[main], stats=stats, warnings=warnings,
                      map_polylines=[net.edge_xy[i] for i in range(net.n_edges)
                                     if net.edge_twin[i] < i])


def _trajectory_result(trace: GpsTrace, ego: EgoTrack, fix_xy: np.ndarray, t_fix: np.ndarray,
                       warnings: list[str]) -> RoadResult:
    road = trajectory_road(ego)
    ego_xy = np.column_stack([ego.x_m, ego.y_m])
    # the road was resampled from the ego path, so each sample's place on it is known: the
    # distance driven (keeps the projection local and linear in the trace length)
    driven = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(ego_xy, axis=0).T))])
    expected_fix = np.interp(t_fix, ego.t_s, driven) if len(ego.t_s) else None
    _, fix_off = signed_offsets(road.centerline, fix_xy, expected_fix)
    _, ego_off = signed_offsets(road.centerline, ego_xy, driven if len(ego.t_s) else None)
    matches = [{"t": float(t), "osm_way_id": None, "offset_m": float(o)}
               for t, o in zip(t_fix, fix_off, strict=True)]
    length = float(np.hypot(*np.diff(road.centerline, axis=0).T).sum())
    stats = {"fixes": len(trace.fixes), "matched_share": 0.0, "outlier_fixes": 0,
             "route_length_m": length, "ways": 0, "lanes": 1, "lanes_forward": 1,
             "lane_width_m": road.lane_width_m, "source": "trajectory", "map": None,
             "breaks": 0}
    return RoadResult(origin=ego.origin, roads=[road], route_osm_way_ids=[], matches=matches,
                      ego_lane=np.zeros(len(ego.t_s), dtype=int), ego_offset_m=ego_off,
                      source="trajectory", lanes_forward=1, stats=stats, warnings=warnings)


# --------------------------------------------------------------------------- output


def road_json(result: RoadResult) -> dict:
    """The ``road.json`` content: ``origin`` and ``roads`` exactly as in scenario.json, the
    route's way ids and the per-fix matches."""
    o = result.origin
    return {
        "origin": {"lat": o.lat, "lon": o.lon, "alt": o.alt},
        "roads": [r.to_json() for r in result.roads],
        "route_osm_way_ids": [int(w) for w in result.route_osm_way_ids],
        "matches": result.matches,
    }


def format_summary(result: RoadResult, out_path: Path | None = None) -> str:
    """Human summary: fixes, matched share, route length, ways, lanes."""
    s = result.stats
    lines = [
        f"road source:    {result.source}" + (f" ({s['map']})" if s.get("map") else ""),
        f"fixes:          {s['fixes']}, matched {s['matched_share']:.1%}"
        + (f", {s['outlier_fixes']} skipped as outliers" if s.get("outlier_fixes") else ""),
        f"route length:   {s['route_length_m']:.0f} m over {s['ways']} OSM way(s)",
        (f"lanes:          {s['lanes']} ({s['lanes_forward']} in the travel direction), "
        f"{s['lane_width_m']:.2f} m wide"),
    ]
    if len(result.ego_lane):
        counts = np.bincount(result.ego_lane)
        share = ", ".join(f"lane {k}: {c / counts.sum():.0%}" for k, c in enumerate(counts) if c)
        lines.append(f"ego lane:       {share} ({LANE_NUMBERING})")
    lines.extend(f"warning:        {w}" for w in result.warnings)
    if out_path is not None:
        lines.append(f"written:        {out_path}")
    return "\n".join(lines)


def plot_road(result: RoadResult, trace: GpsTrace, ego: EgoTrack, path_png: str | Path) -> None:
    """PNG picture: OSM roads (grey), raw fixes (dots), matched route (blue), smoothed ego
    path (orange), in ENU metres, written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frame = EnuFrame(result.origin)
    fixes_xy = (frame.to_enu([f.lat_deg for f in trace.fixes], [f.lon_deg for f in trace.fixes])
                [:, :2] if trace.fixes else np.zeros((0, 2)))
    fig, ax = plt.subplots(figsize=(8, 8), dpi=110)
    for k, line in enumerate(result.map_polylines):
        ax.plot(line[:, 0], line[:, 1], color="0.75", lw=1.0, zorder=1,
                label="OSM drivable roads" if k == 0 else None)
    ax.scatter(fixes_xy[:, 0], fixes_xy[:, 1], s=8, color="k", zorder=3, label="GPS fixes")
    for k, road in enumerate(result.roads):
        c = road.centerline
        ax.plot(c[:, 0], c[:, 1], color="tab:blue", lw=3, alpha=0.7, zorder=2,
                label=f"matched route ({road.source})" if k == 0 else None)
    ax.plot(ego.x_m, ego.y_m, color="tab:orange", lw=1.5, zorder=4, label="smoothed ego path")
    pts = np.vstack([fixes_xy, np.column_stack([ego.x_m, ego.y_m])] +
                    [r.centerline for r in result.roads])
    lo, hi = pts.min(axis=0) - 30, pts.max(axis=0) + 30
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    s = result.stats
    ax.set_title(f"road: {result.source}, {s['route_length_m']:.0f} m, {s['ways']} ways, "
                 f"{s['lanes']} lanes, matched {s['matched_share']:.0%}")
    ax.legend(loc="best", fontsize=8)
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    with atomic_open(path_png, "wb") as fh:
        fig.savefig(fh, format="png")
    plt.close(fig)
