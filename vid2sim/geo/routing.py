"""Route lengths between directed road edges for the map matcher's transitions.

The matcher asks, for a candidate edge ``a`` of one fix and the candidate edges of the next
fixes, how far the car must drive from the end of ``a`` to the start of each. Routes run on
the *line graph* (edge -> edge arcs), so a route never turns back onto the twin of the edge
it arrives on (a U-turn in the street) except at a dead end.

One Dijkstra search per source edge, kept for the whole trace and grown only as far as a
question needs (FMM, Yang & Gidofalvi 2018, precomputes the same distances up to a bound for
the whole map; here they are computed per trace, up to the distance the car can drive in the
time between the fixes, and reused by every later question from the same edge). Consecutive
fixes share most of their candidate edges, so most questions are answered from a search
already made. The search stops at the bound the transition allows (``max speed x time``), so
its cost does not grow with the size of the map.

Pure Python on adjacency lists: the searches are a few dozen edges each, where scipy's
compiled Dijkstra would cost more to import (0.2 s) than every search of a drive together.
"""

from __future__ import annotations

import heapq
import math
from collections.abc import Sequence

import numpy as np

from vid2sim.geo.candidates import wrap_angle
from vid2sim.geo.osm import RoadNetwork


class LineGraph:
    """Arcs ``e -> f`` between directed edges: ``f`` leaves the node where ``e`` ends and is
    not ``e``'s twin (at a dead end the twin is allowed, at ``uturn_m`` extra).

    Crossing a junction costs ``turn_m_per_rad`` metres per radian of turning (a noisy fix
    beside a junction should not pull the route through a zig-zag of short ways when a
    straight way is as close). A route's cost is the length of the edges it drives through
    plus the costs of its junctions.

    :param succ: per edge, its arcs as ``(next edge, cost of the junction [m])`` pairs
    :param length: edge lengths [m] (at least a millimetre each)
    """

    def __init__(self, net: RoadNetwork, uturn_m: float, turn_m_per_rad: float = 0.0):
        n = net.n_edges
        u, v, twin = net.edge_u, net.edge_v, net.edge_twin
        order = np.argsort(u, kind="stable")
        lo = np.searchsorted(u[order], v, side="left")
        count = np.searchsorted(u[order], v, side="right") - lo
        rows = np.repeat(np.arange(n), count)
        # the k-th arc of row e is order[lo[e] + k]
        offset = np.arange(rows.size) - np.repeat(np.cumsum(count) - count, count)
        cols = order[np.repeat(lo, count) + offset].astype(np.int64)
        is_twin = cols == twin[rows]
        # an edge whose only way on is its twin is a dead end: turning round is allowed there
        onward = np.bincount(rows[~is_twin], minlength=n)
        keep = ~is_twin | (onward[rows] == 0)
        rows, cols, is_twin = rows[keep], cols[keep], is_twin[keep]
        # first and last segment of every edge, from its points laid end to end
        flat = np.concatenate(net.edge_xy) if n else np.zeros((0, 2))
        end = np.cumsum([len(xy) for xy in net.edge_xy]).astype(np.int64)
        start = end - np.diff(np.concatenate([[0], end]))
        first, last = flat[start + 1] - flat[start], flat[end - 1] - flat[end - 2]
        turn = np.abs(wrap_angle(np.arctan2(first[cols, 1], first[cols, 0])
                                 - np.arctan2(last[rows, 1], last[rows, 0])))
        cost = turn_m_per_rad * turn + np.where(is_twin, uturn_m, 0.0)
        self.length = np.maximum(net.edge_length_m, 1e-3).tolist()
        bounds = np.searchsorted(rows, np.arange(1, n))  # rows are sorted
        pairs = list(zip(cols.tolist(), cost.tolist(), strict=True))
        self.succ: list[list[tuple[int, float]]] = [
            pairs[a:b] for a, b in zip([0, *bounds.tolist()], [*bounds.tolist(), len(pairs)],
                                       strict=True)] if n else []


class _Search:
    """Dijkstra from one source edge, grown on demand. ``dist`` holds every edge settled so
    far with the route cost from the end of the source to the edge's start; ``heap`` is the
    frontier; every edge whose cost is at most ``heap[0][0]`` is settled."""

    __slots__ = ("best", "dist", "heap", "pred")

    def __init__(self, graph: LineGraph, source: int):
        self.dist: dict[int, float] = {source: -graph.length[source]}
        self.pred: dict[int, int] = {source: -1}
        self.heap = [(w, f, source) for f, w in graph.succ[source]]
        self.best: dict[int, float] = {f: w for w, f, _ in self.heap}
        heapq.heapify(self.heap)

    def grow(self, graph: LineGraph, limit: float) -> None:
        """Settle every edge whose cost is at most ``limit``."""
        heap, dist, pred, best, succ = self.heap, self.dist, self.pred, self.best, graph.succ
        length = graph.length
        while heap and heap[0][0] <= limit:
            d, f, p = heapq.heappop(heap)
            if f in dist:
                continue
            dist[f] = d
            pred[f] = p
            d_end = d + length[f]
            for g, w in succ[f]:
                dg = d_end + w
                if g not in dist and dg < best.get(g, math.inf):
                    best[g] = dg
                    heapq.heappush(heap, (dg, g, f))


class EdgeDistances:
    """Shortest route lengths between directed edges, searched lazily per source edge.

    ``gap(a, b)`` is the route cost [m] driven strictly between the end of edge ``a`` and the
    start of edge ``b`` (0 when ``b`` leaves the node where ``a`` ends; turn costs included,
    see :class:`LineGraph`), inf when farther than the bound asked for.
    """

    def __init__(self, net: RoadNetwork, uturn_m: float, turn_m_per_rad: float = 0.0):
        self.graph = LineGraph(net, uturn_m, turn_m_per_rad)
        self._searches: dict[int, _Search] = {}

    def _search(self, a: int) -> _Search:
        s = self._searches.get(a)
        if s is None:
            s = self._searches[a] = _Search(self.graph, a)
        return s

    def gaps(self, a: int, targets: Sequence[int], bound_m: float) -> list[float]:
        """Gap from ``a`` to each of ``targets`` [m]; inf where it exceeds ``bound_m``."""
        s = self._search(a)
        dist = s.dist
        if s.heap and s.heap[0][0] <= bound_m and any(f not in dist for f in targets):
            s.grow(self.graph, bound_m)
        inf = math.inf
        out = []
        for f in targets:
            g = dist.get(f, inf)
            out.append(g if g <= bound_m else inf)
        return out

    def gap(self, a: int, b: int, bound_m: float = math.inf) -> float:
        return self.gaps(a, [b], bound_m)[0]

    def path(self, a: int, b: int) -> list[int]:
        """Edges strictly between ``a`` and ``b`` on the shortest route (empty when ``b``
        follows ``a`` directly or is not reachable)."""
        s = self._search(a)
        if b not in s.dist:
            s.grow(self.graph, math.inf)
        if b not in s.dist:
            return []
        edges = []
        cur = s.pred[b]
        while cur != a and cur >= 0:
            edges.append(cur)
            cur = s.pred[cur]
        return edges[::-1]

    @property
    def n_searched(self) -> int:
        """Source edges searched so far (for benchmarks)."""
        return len(self._searches)
