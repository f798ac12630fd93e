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
from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

import numpy as np

from vid2sim.base.errors import InconsistentInputError
from vid2sim.base.fileio import atomic_open
from vid2sim.core.enu import EnuFrame
from vid2sim.core.polyline import resample_polyline
from vid2sim.core.records import EgoTrack, GpsTrace, RoadResult
from vid2sim.core.scenario import Road
from vid2sim.geo.alongroute import signed_offsets, sub_polyline
from vid2sim.geo.mapmatch import MatchConfig, MatchResult, match, merge_ways
from vid2sim.geo.osm import RoadNetwork, download_network, format_bbox, load_network
from vid2sim.geo.osmlanes import (  # noqa: F401 - the lanes of a road, read here too
    DEFAULT_LANE_WIDTH_M,
    LANE_DEFAULTS,
    LANE_WIDTH_RANGE_M,
    cross_section_from_tags,
    lanes_from_tags,
    with_driving_width,
)
from vid2sim.geo.trace import video_t0_utc

log = logging.getLogger(__name__)

#: The project's lane numbering (stated here once; every lane index in vid2sim follows it):
#: lane 0 is the rightmost lane in the direction of travel, and indices count leftwards.
LANE_NUMBERING = "lane 0 = rightmost in the direction of travel, counting leftwards"
#: centerline sample spacing, at most [m]
CENTERLINE_STEP_M = 1.0
#: margin around the trace's bounding box when cropping the map [m]
MAP_MARGIN_M = 300.0
#: a fix is heading-informative when the ego moves at least this fast [m/s]
_HEADING_MIN_SPEED_MPS = 2.0


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


def driven_span(res: MatchResult, piece: int, length_m: float, margin_m: float
                ) -> tuple[float, float]:
    """Along route piece ``piece`` [m]: from ``margin_m`` before the projection of its first
    matched fix to ``margin_m`` beyond that of its last, within the piece (at least
    ``2 margin_m`` long where the piece is)."""
    s = res.fix_route_s_m[(res.fix_piece == piece) & np.isfinite(res.fix_route_s_m)]
    if not s.size:
        return 0.0, length_m
    start, end = max(float(s.min()) - margin_m, 0.0), min(float(s.max()) + margin_m, length_m)
    if end - start < 2.0 * margin_m:  # one fix, or the car stood still: a car length each way
        mid = float(np.clip((start + end) / 2.0, margin_m, max(length_m - margin_m, margin_m)))
        start, end = max(mid - margin_m, 0.0), min(mid + margin_m, length_m)
    return start, end


def cover_points(result: RoadResult, roads: list[Road], xy_m: np.ndarray, reach_m: float,
                 near_m: float = 15.0) -> list[Road]:
    """The roads of a map-matched ``result`` run on along their matched route
    (``result.route_lines``: each road's whole route polyline [m] and the span of it the road
    covers [m]) until every
    point within ``near_m`` of it (vehicles the camera saw ahead of the first or beyond the
    last fix) lies ``reach_m`` inside them; roads without a route, or already covering the
    points, are returned as they are. Only the centerline changes."""
    pts = np.asarray(xy_m, float).reshape(-1, 2)
    out = list(roads)
    if not pts.size or result.source != "osm":
        return out
    for k, (line, (start, end)) in enumerate(result.route_lines):
        if k >= len(out):
            break
        s, off = signed_offsets(line, pts)
        on = np.abs(off) <= near_m
        if not on.any():
            continue
        length = float(np.hypot(*np.diff(line, axis=0).T).sum())
        lo = max(min(start, float(s[on].min()) - reach_m), 0.0)
        hi = min(max(end, float(s[on].max()) + reach_m), length)
        if lo < start - 1e-6 or hi > end + 1e-6:
            out[k] = replace(out[k], centerline=resample_polyline(sub_polyline(line, lo, hi),
                                                                  CENTERLINE_STEP_M))
    return out


def _osm_road(net: RoadNetwork, res: MatchResult, piece: int, margin_m: float
              ) -> tuple[Road, int, float, list[str]]:
    """The road of one matched route piece, cut to the driven span (:func:`driven_span`):
    the road, its lanes in the travel direction, where the span starts along the piece [m]
    and warnings. Lanes, width, name and highway class are those of the ways the span runs
    on, weighed by the length driven on each."""
    edges = res.route_edges[piece]
    whole = net.edge_length_m[edges]
    ends = np.cumsum(whole)
    start, end = driven_span(res, piece, float(ends[-1]), margin_m)
    centerline = resample_polyline(sub_polyline(join_route(net, edges), start, end),
                                   CENTERLINE_STEP_M)
    driven = np.minimum(ends, end) - np.maximum(ends - whole, start)
    inside = driven > 0.0
    if not inside.any():  # a route of zero-length pieces
        inside[:] = True
    edges = [e for e, k in zip(edges, inside, strict=True) if k]
    lengths = np.maximum(driven[inside], 1e-3)
    warnings: list[str] = []
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
    road = Road(id=f"road{piece}", name=_weighted_mode(names, lengths),
                highway=_weighted_mode(highways, lengths), source="osm",
                osm_way_ids=merge_ways([], [edges], net.edge_way_id), lanes=lanes,
                lane_width_m=round(width, 3), centerline=centerline, cross_section=section)
    return road, forward, start, warnings


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


#: length of the straight extensions of a road's ends that ego offsets are measured on [m]
_END_TANGENT_M = 50.0
#: an ego sample is projected onto the road within this of where its fixes put it [m] (the
#: smoothed ego and the matched positions agree within a few metres; the window only keeps a
#: road that passes a place twice from taking the other pass)
_EGO_WINDOW_M = 20.0


def _with_end_tangents(line: np.ndarray) -> np.ndarray:
    """The polyline with a straight ``_END_TANGENT_M`` added before its start and after its
    end, along its first and last segments."""
    a, b = line[1] - line[0], line[-1] - line[-2]
    a, b = a / max(float(np.hypot(*a)), 1e-9), b / max(float(np.hypot(*b)), 1e-9)
    return np.vstack([line[0] - _END_TANGENT_M * a, line, line[-1] + _END_TANGENT_M * b])


class _Fixes(NamedTuple):
    """The trace's fixes in file order: lat/lon [deg], video-clock times [s], ENU [m] in the
    ego's frame, and the box the map is cropped to [deg]."""

    lat: np.ndarray
    lon: np.ndarray
    t_s: np.ndarray
    xy: np.ndarray
    bbox: tuple[float, float, float, float]


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
    config : matcher tuning (and how far the road runs beyond the first and last fix)

    Raises
    ------
    InputError
        unreadable/empty map, no drivable roads, or the trace outside the map (both boxes).
    """
    cfg = config or MatchConfig()
    fixes = _fixes_in_frame(trace, ego, gps_offset_s)
    net, warnings = _network_for(map_path, fixes.bbox, ego, allow_download, cache_dir)
    if net is None:
        return _trajectory_result(trace, ego, fixes.xy, fixes.t_s, warnings)
    res = _match_fixes(net, trace, ego, fixes, map_path, cfg)
    warnings.extend(res.warnings)
    if res.matched_share < 0.5:
        warnings.append(f"only {res.matched_share:.0%} of the fixes matched a road")
    return _osm_result(net, res, ego, fixes, cfg.route_margin_m, warnings)


def _fixes_in_frame(trace: GpsTrace, ego: EgoTrack, gps_offset_s: float | None) -> _Fixes:
    fixes = trace.fixes
    if not fixes:
        raise InconsistentInputError(trace.path, "no GPS fixes")
    lat = np.array([f.lat_deg for f in fixes])
    lon = np.array([f.lon_deg for f in fixes])
    xy = EnuFrame(ego.origin).to_enu(lat, lon)[:, :2]
    return _Fixes(lat, lon, fix_times_s(trace, gps_offset_s), xy,
                  _trace_bbox(lat, lon, MAP_MARGIN_M))


def _network_for(map_path: Path | None, bbox: tuple[float, float, float, float], ego: EgoTrack,
                 allow_download: bool, cache_dir: Path | None
                 ) -> tuple[RoadNetwork | None, list[str]]:
    """The drivable network around the trace: from the map file, else downloaded, else None
    (with a warning saying why the road follows the trajectory)."""
    if map_path is not None:
        return load_network(map_path, ego.origin, bbox_lonlat=bbox, cache_dir=cache_dir), []
    if not allow_download:
        return None, [("no map given (downloads disabled): the road follows the smoothed "
                       "trajectory (default lane width)")]
    net = download_network(bbox, ego.origin, cache_dir=cache_dir)
    if net is None:
        return None, [("no map given and OpenStreetMap could not be reached: the road follows "
                       "the smoothed trajectory (default lane width)")]
    return net, []


def _match_fixes(net: RoadNetwork, trace: GpsTrace, ego: EgoTrack, fixes: _Fixes,
                 map_path: Path | None, cfg: MatchConfig) -> MatchResult:
    """The fixes matched with the ego's heading and speed; an error when none is near a
    road of the map."""
    accuracy = np.array([np.nan if f.accuracy_m is None else f.accuracy_m
                         for f in trace.fixes])
    t_fix = fixes.t_s
    speed = np.interp(t_fix, ego.t_s, ego.speed_mps) if len(ego.t_s) else None
    res = match(net, fixes.xy[:, 0], fixes.xy[:, 1], t_fix,
                heading_rad=_ego_headings(ego, t_fix), accuracy_m=accuracy, speed_mps=speed,
                config=cfg)
    if not res.route_edges or res.matched_share == 0.0:
        raise InconsistentInputError(
            map_path, f"no fix lies near a drivable road of this map: the trace "
            f"({format_bbox(_trace_bbox(fixes.lat, fixes.lon, 0.0))}) and the map's roads "
            f"({format_bbox(net.bbox_lonlat)}) do not overlap", "pass a map that covers the drive")
    return res


def _osm_result(net: RoadNetwork, res: MatchResult, ego: EgoTrack, fixes: _Fixes,
                margin_m: float, warnings: list[str]) -> RoadResult:
    """Roads of the matched route pieces, the ego's lane on the main one, each fix's match."""
    roads, forwards, starts, lines, spans = [], [], [], [], []
    for k in range(len(res.route_edges)):
        road, forward, start, w = _osm_road(net, res, k, margin_m)
        roads.append(road)
        forwards.append(forward)
        starts.append(start)
        lines.append(join_route(net, res.route_edges[k]))
        spans.append((start, start + float(np.hypot(*np.diff(road.centerline, axis=0).T).sum())))
        warnings.extend(w)
    # ego lane: offsets to the road of the matched piece, searched near the expected place
    main = int(np.argmax([r.centerline.shape[0] for r in roads]))
    ego_xy = np.column_stack([ego.x_m, ego.y_m])
    on_main = res.fix_piece == main
    expected = (np.interp(ego.t_s, fixes.t_s[on_main], res.fix_route_s_m[on_main] - starts[main])
                + _END_TANGENT_M if on_main.sum() >= 2 else None)
    # the road ends a car length beyond the first and last fix: ego samples past an end
    # (GPS noise) take their offset from the end's tangent, not from the end point
    _, ego_off = signed_offsets(_with_end_tangents(roads[main].centerline), ego_xy, expected,
                                _EGO_WINDOW_M)
    ego_lane = lane_index(ego_off, roads[main].lanes, forwards[main], roads[main].lane_width_m)
    matches = [
        {"t": float(t), "osm_way_id": int(w) if w >= 0 else None,
         "offset_m": float(o) if np.isfinite(o) else None}
        for t, w, o in zip(fixes.t_s, res.fix_way_id, res.fix_offset_m, strict=True)
    ]
    ways = res.way_sequence()
    route_length = float(sum(np.hypot(*np.diff(r.centerline, axis=0).T).sum() for r in roads))
    stats = {
        "fixes": len(fixes.t_s), "matched_share": res.matched_share,
        "outlier_fixes": int(res.fix_outlier.sum()), "route_length_m": route_length,
        "ways": len(ways), "lanes": roads[main].lanes, "lanes_forward": forwards[main],
        "lane_width_m": roads[main].lane_width_m, "source": "osm", "map": net.source,
        "breaks": res.n_breaks,
    }
    return RoadResult(origin=ego.origin, roads=roads, route_osm_way_ids=ways, matches=matches,
                      ego_lane=ego_lane, ego_offset_m=ego_off, source="osm",
                      lanes_forward=forwards[main], stats=stats, warnings=warnings,
                      map_polylines=[net.edge_xy[i] for i in range(net.n_edges)
                                     if net.edge_twin[i] < i],
                      route_lines=list(zip(lines, spans, strict=True)))


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
