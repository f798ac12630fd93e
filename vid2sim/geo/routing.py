"""Route lengths between directed road edges for the map matcher's transitions."""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from vid2sim.geo.candidates import end_heading, wrap_angle
from vid2sim.geo.osm import RoadNetwork


class EdgeDistances:
    """Shortest route lengths between directed edges on the *line graph* (edge -> edge arcs),
    so a route can never turn back onto the twin of the edge it arrives on (a U-turn) except
    at a dead end. Computed with scipy's C Dijkstra in batches of sources, with a cutoff;
    only the reached entries are kept (as dicts), so memory stays small on long traces.

    ``gap(a, b)`` is the length [m] driven strictly between the end of edge ``a`` and the start
    of edge ``b`` (0 when ``b`` leaves the node where ``a`` ends), None when farther than the
    cutoff or unreachable.
    """

    def __init__(self, net: RoadNetwork, cutoff_m: float, uturn_m: float,
                 turn_m_per_rad: float = 0.0):
        n = net.n_edges
        extra: list[float] = []
        out_by_node: dict[int, list[int]] = {}
        for e in range(n):
            out_by_node.setdefault(int(net.edge_u[e]), []).append(e)
        rows, cols = [], []
        for e in range(n):
            nxt = out_by_node.get(int(net.edge_v[e]), [])
            allowed = [f for f in nxt if f != net.edge_twin[e]]
            rows.extend([e] * len(allowed))
            cols.extend(allowed)
            extra.extend([0.0] * len(allowed))
            if not allowed and nxt:
                # dead end: turning round is the only way on, but it is not free, or every
                # short spur beside the route would attract noisy fixes
                rows.extend([e] * len(nxt))
                cols.extend(nxt)
                extra.extend([uturn_m] * len(nxt))
        # arc weight = length of the edge entered + a cost per radian of turning at the
        # junction (a noisy fix beside a junction should not pull the route through a
        # zig-zag of short ways when a straight way is as close); zero-length edges would
        # vanish from a sparse matrix, so they get a millimetre
        rows_a, cols_a = np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)
        head_out = np.array([end_heading(xy, first=False) for xy in net.edge_xy])
        head_in = np.array([end_heading(xy, first=True) for xy in net.edge_xy])
        turn = np.abs(wrap_angle(head_in[cols_a] - head_out[rows_a])) if rows else np.zeros(0)
        weight = np.maximum(net.edge_length_m[cols_a], 1e-3) + np.asarray(extra)
        weight = weight + turn_m_per_rad * turn
        self.graph = csr_matrix((weight, (rows_a, cols_a)), shape=(n, n))
        self.length = net.edge_length_m
        self.limit = cutoff_m + float(net.edge_length_m.max(initial=0.0))
        self.rows: dict[int, dict[int, float]] = {}

    def prefetch(self, sources: np.ndarray, batch: int = 256) -> None:
        todo = np.array(sorted({int(s) for s in sources} - set(self.rows)), dtype=np.int64)
        for k in range(0, todo.size, batch):
            src = todo[k:k + batch]
            dist = dijkstra(self.graph, directed=True, indices=src, limit=self.limit)
            for e, row in zip(src.tolist(), dist, strict=True):
                idx = np.flatnonzero(np.isfinite(row))
                gaps = row[idx] - self.length[idx]  # the target edge itself is not between
                self.rows[e] = dict(zip(idx.tolist(), gaps.tolist(), strict=True))

    def gap(self, a: int, b: int) -> float | None:
        if a not in self.rows:
            self.prefetch(np.array([a]))
        return self.rows[a].get(b)

    def path(self, a: int, b: int) -> list[int]:
        """Edges strictly between ``a`` and ``b`` on the shortest route."""
        _, pred = dijkstra(self.graph, directed=True, indices=a, return_predecessors=True,
                           limit=self.limit)
        edges = []
        cur = int(pred[b])
        while cur != a and cur >= 0:
            edges.append(cur)
            cur = int(pred[cur])
        return edges[::-1]
