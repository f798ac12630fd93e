"""Candidate road positions of GPS fixes: a shapely STRtree over the map's way pieces,
queried for all fixes at once; each hit gives the one or two directed edges (twins) of the
piece with the along-edge position, distance and edge heading at the projection."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely

from vid2sim.geo.osm import RoadNetwork


def lines_array(coords: list[np.ndarray]) -> np.ndarray:
    """Array of shapely LineStrings (vectorised creation needs equal lengths, so go through
    the flat-coordinates-with-indices form)."""
    if not coords:
        return np.empty(0, dtype=object)
    idx = np.repeat(np.arange(len(coords)), [len(c) for c in coords])
    return shapely.linestrings(np.vstack(coords), indices=idx)


def end_heading(xy: np.ndarray, first: bool) -> float:
    """Heading [rad] of a polyline's first or last segment."""
    a, b = (xy[0], xy[1]) if first else (xy[-2], xy[-1])
    return math.atan2(b[1] - a[1], b[0] - a[0])


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped into [-pi, pi) [rad]."""
    return (a + np.pi) % (2 * np.pi) - np.pi



@dataclass(slots=True)
class Candidates:
    """Candidate road positions of one point.

    :param edges: directed edges
    :param s_m: position along each edge [m]
    :param dist_m: distance from the point [m]
    :param heading_rad: travel direction of the edge there, counter-clockwise from east [rad]
    """

    edges: np.ndarray
    s_m: np.ndarray
    dist_m: np.ndarray
    heading_rad: np.ndarray


class EdgeIndex:
    """STRtree over way-piece geometries (one per twin pair), mapped to directed edges."""

    def __init__(self, net: RoadNetwork):
        base = [i for i in range(net.n_edges) if net.edge_twin[i] < 0 or net.edge_twin[i] > i]
        self.base = np.array(base, dtype=np.int64)
        self.twin = net.edge_twin[self.base]
        self.lines = lines_array([net.edge_xy[i] for i in base])
        self.length = net.edge_length_m[self.base]
        self.tree = shapely.STRtree(self.lines)

    def candidates(self, xy: np.ndarray, radius_m: float, max_geometries: int
                   ) -> list[Candidates]:
        """Per point: the directed edges of the ``max_geometries`` nearest way pieces within
        ``radius_m`` (nearest first, then their twins), all points in one vectorised pass."""
        n = len(xy)
        pts = shapely.points(xy[:, 0], xy[:, 1])
        pi, gi = self.tree.query(pts, predicate="dwithin", distance=radius_m)
        lines = self.lines[gi]
        dist = shapely.distance(lines, pts[pi])
        order = np.lexsort((dist, pi))
        pi, gi, lines, dist = pi[order], gi[order], lines[order], dist[order]
        first = np.searchsorted(pi, np.arange(n + 1))
        keep = np.arange(pi.size) - first[pi] < max_geometries
        pi, gi, lines, dist = pi[keep], gi[keep], lines[keep], dist[keep]
        s = shapely.line_locate_point(lines, pts[pi])
        length = self.length[gi]
        # edge tangent at the projection from points 0.5 m either side
        a = shapely.get_coordinates(shapely.line_interpolate_point(lines, np.maximum(s - 0.5, 0)))
        b = shapely.get_coordinates(
            shapely.line_interpolate_point(lines, np.minimum(s + 0.5, length)))
        heading = np.arctan2(b[:, 1] - a[:, 1], b[:, 0] - a[:, 0])
        tw = np.flatnonzero(self.twin[gi] >= 0)
        owner = np.concatenate([pi, pi[tw]])
        is_twin = np.concatenate([np.zeros(pi.size, bool), np.ones(tw.size, bool)])
        edges = np.concatenate([self.base[gi], self.twin[gi[tw]]])
        along = np.concatenate([s, length[tw] - s[tw]])
        dd = np.concatenate([dist, dist[tw]])
        hh = np.concatenate([heading, heading[tw] + math.pi])
        # per point: its pieces nearest first, then their twins nearest first
        rank = np.lexsort((np.concatenate([dist, dist[tw]]), is_twin, owner))
        bounds = np.searchsorted(owner[rank], np.arange(1, n))
        return [Candidates(*parts) for parts in zip(
            *(np.split(v[rank], bounds) for v in (edges, along, dd, hh)), strict=True)]

    def nearest_distance(self, xy: np.ndarray, max_distance_m: float) -> np.ndarray:
        """Distance [m] of each point to its nearest way piece; NaN beyond
        ``max_distance_m``."""
        out = np.full(len(xy), np.nan)
        if not len(xy) or not len(self.lines):
            return out
        pts = shapely.points(xy[:, 0], xy[:, 1])
        (pi, _), d = self.tree.query_nearest(pts, max_distance=max_distance_m,
                                             return_distance=True, all_matches=False)
        out[pi] = d
        return out
