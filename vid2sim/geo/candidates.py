"""Candidate road positions of GPS fixes: a shapely STRtree over the map's way pieces,
queried for all fixes at once; each hit gives the one or two directed edges (twins) of the
piece with the along-edge position, distance and edge heading at the projection."""

from __future__ import annotations

import math

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
                   ) -> list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]:
        """Per fix: directed edges, along-edge s [m], distance [m], edge heading [rad]."""
        pts = shapely.points(xy[:, 0], xy[:, 1])
        pi, gi = self.tree.query(pts, predicate="dwithin", distance=radius_m)
        lines = self.lines[gi]
        dist = shapely.distance(lines, pts[pi])
        s = shapely.line_locate_point(lines, pts[pi])
        length = self.length[gi]
        # edge tangent at the projection from points 0.5 m either side
        a = shapely.get_coordinates(shapely.line_interpolate_point(lines, np.maximum(s - 0.5, 0)))
        b = shapely.get_coordinates(
            shapely.line_interpolate_point(lines, np.minimum(s + 0.5, length)))
        heading = np.arctan2(b[:, 1] - a[:, 1], b[:, 0] - a[:, 0])
        out = []
        order = np.lexsort((dist, pi))
        bounds = np.searchsorted(pi[order], np.arange(len(xy) + 1))
        for k in range(len(xy)):
            sel = order[bounds[k]:bounds[k + 1]][:max_geometries]
            edges, ss, dd, hh = [self.base[gi[sel]]], [s[sel]], [dist[sel]], [heading[sel]]
            has_twin = self.twin[gi[sel]] >= 0
            if has_twin.any():
                t = sel[has_twin]
                edges.append(self.twin[gi[t]])
                ss.append(length[t] - s[t])
                dd.append(dist[t])
                hh.append(heading[t] + math.pi)
            out.append((np.concatenate(edges), np.concatenate(ss), np.concatenate(dd),
                        np.concatenate(hh)))
        return out
