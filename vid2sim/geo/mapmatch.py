"""Map matching: a hidden-Markov-model / Viterbi matcher of GPS fixes onto a directed road graph.

Model (after Newson & Krumm, "Hidden Markov Map Matching Through Noise and Sparseness",
ACM SIGSPATIAL 2009), with additions for dash-cam traces:

- states: for each fix, candidate positions ``(edge, s_m)`` on directed edges within
  ``search_radius_m``; both twins of a two-way street are separate states, so the direction
  of travel is part of the state;
- emission: Gaussian in the fix-to-edge distance (sigma = the fix's accuracy or
  ``sigma_m``) plus, where the heading is known, a capped Gaussian in heading error;
- transition: ``-|route distance - straight-line distance| / beta_m``; routes run on the line
  graph, so they never turn back onto the twin edge; turning round in the street or at a dead
  end costs ``uturn_logp``; moving backwards on the same edge is GPS jitter: free while
  standing still, ``back / beta_m`` extra while driving;
- outliers: a fix may be skipped (the chain jumps up to ``max_skip`` fixes, each skipped fix
  costing ``skip_logp``); where no candidate can be reached the chain breaks and restarts
  (``break_logp``);
- after Viterbi the fixes' along-route positions are smoothed with a constant-velocity
  Rauch-Tung-Striebel smoother and made non-decreasing, so noise near a junction does not
  flip a fix onto the neighbouring way and stationary periods never run backwards.

Shortest-path distances are computed only from the end nodes of candidate edges (networkx
Dijkstra with a cutoff), cached per node for the whole trace.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import networkx as nx
import numpy as np
import shapely
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from vid2sim.geo.osm import RoadNetwork


@dataclass(frozen=True, slots=True)
class MatchConfig:
    """Tuning of the matcher (defaults suit consumer GPS at 1-10 Hz in cities).

    :param sigma_m: GPS position noise, one sigma [m], used when a fix has no accuracy
    :param search_radius_m: candidate edges are searched within this distance of a fix [m]
    :param max_geometries: nearest way pieces kept per fix (each gives 1-2 directed edges)
    :param beta_m: scale of the route-vs-straight distance difference [m]
    :param heading_sigma_rad: heading error scale of the emission [rad]
    :param heading_cap_logp: the heading term never costs more than this (a wrong heading
        estimate must not veto the right road)
    :param max_skip: consecutive fixes the chain may skip as outliers
    :param skip_logp: log-probability cost of one skipped fix
    :param break_logp: cost of restarting the chain (no connection found)
    :param uturn_logp: cost of turning onto the twin edge
    :param max_speed_mps: transitions faster than this are impossible [m/s]
    :param accel_sigma_mps2: process noise of the along-route smoother [m/s^2]
    :param stationary_mps: below this speed the car is taken as standing still, and a
        projection that moves backwards on the same edge costs no more than one forwards
    :param turn_m_per_rad: turning at a junction counts as this many extra metres of route
        per radian (prefers the straighter of two nearly equal routes) [m/rad]
    :param min_cover_m: a first/last edge the fixes cover less than this is dropped from the
        route (GPS noise at the start would otherwise add the way behind the start) [m]
    """

    sigma_m: float = 5.0
    search_radius_m: float = 40.0
    max_geometries: int = 6
    beta_m: float = 5.0
    heading_sigma_rad: float = 0.5
    heading_cap_logp: float = -4.0
    max_skip: int = 3
    skip_logp: float = -8.0
    break_logp: float = -60.0
    uturn_logp: float = -20.0
    max_speed_mps: float = 60.0
    accel_sigma_mps2: float = 1.5
    stationary_mps: float = 1.5
    min_cover_m: float = 3.5
    turn_m_per_rad: float = 10.0


@dataclass(slots=True)
class MatchResult:
    """Matcher output, one entry per input fix where arrays are per fix.

    :param route_edges: continuous pieces of the driven route as lists of directed edge
        indices in travel order (normally one piece; a break in the chain starts another)
    :param fix_piece: route piece of each fix (-1: not on the route: before/after the matched
        span or inside a break)
    :param fix_route_s_m: smoothed along-route position of each fix within its piece [m]
    :param fix_edge: directed edge of each fix (-1 when unmatched)
    :param fix_way_id: OSM way id of each fix (-1 when unmatched)
    :param fix_offset_m: signed lateral offset of the raw fix from the matched edge, positive
        to the left of travel [m] (NaN when unmatched)
    :param fix_outlier: fixes the Viterbi path skipped (not used for the route)
    """

    route_edges: list[list[int]]
    fix_piece: np.ndarray
    fix_route_s_m: np.ndarray
    fix_edge: np.ndarray
    fix_way_id: np.ndarray
    fix_offset_m: np.ndarray
    fix_outlier: np.ndarray
    n_breaks: int = 0
    warnings: list[str] = field(default_factory=list)

    @property
    def matched_share(self) -> float:
        """Share of fixes with a way [0..1]."""
        n = self.fix_edge.size
        return float((self.fix_edge >= 0).sum() / n) if n else 0.0

    def way_sequence(self) -> list[int]:
        """OSM way ids of the route in travel order, consecutive repeats merged."""
        ways: list[int] = []
        return _merge_ways(ways, self.route_edges, self._edge_way)

    _edge_way: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


def _merge_ways(out: list[int], pieces: list[list[int]], edge_way: np.ndarray) -> list[int]:
    for piece in pieces:
        for e in piece:
            w = int(edge_way[e])
            if not out or out[-1] != w:
                out.append(w)
    return out


# --------------------------------------------------------------------------- candidates


class _EdgeIndex:
    """STRtree over way-piece geometries (one per twin pair), mapped to directed edges."""

    def __init__(self, net: RoadNetwork):
        base = [i for i in range(net.n_edges) if net.edge_twin[i] < 0 or net.edge_twin[i] > i]
        self.base = np.array(base, dtype=np.int64)
        self.twin = net.edge_twin[self.base]
        self.lines = _lines([net.edge_xy[i] for i in base])
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


# --------------------------------------------------------------------------- matcher


def _lines(coords: list[np.ndarray]) -> np.ndarray:
    """Array of shapely LineStrings (vectorised creation needs equal lengths, so go through
    the flat-coordinates-with-indices form)."""
    if not coords:
        return np.empty(0, dtype=object)
    idx = np.repeat(np.arange(len(coords)), [len(c) for c in coords])
    return shapely.linestrings(np.vstack(coords), indices=idx)


def _end_heading(xy: np.ndarray, first: bool) -> float:
    """Heading [rad] of a polyline's first or last segment."""
    a, b = (xy[0], xy[1]) if first else (xy[-2], xy[-1])
    return math.atan2(b[1] - a[1], b[0] - a[0])


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


class _EdgeDistances:
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
        head_out = np.array([_end_heading(xy, first=False) for xy in net.edge_xy])
        head_in = np.array([_end_heading(xy, first=True) for xy in net.edge_xy])
        turn = np.abs(_wrap(head_in[cols_a] - head_out[rows_a])) if rows else np.zeros(0)
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


def match(net: RoadNetwork, x_m: np.ndarray, y_m: np.ndarray, t_s: np.ndarray, *,
          heading_rad: np.ndarray | None = None, accuracy_m: np.ndarray | None = None,
          speed_mps: np.ndarray | None = None, config: MatchConfig | None = None
          ) -> MatchResult:
    """Match fixes (ENU, time order) to the network.

    Parameters
    ----------
    net : the drivable network in the same ENU frame as the fixes
    x_m, y_m : fix positions [m]
    t_s : fix times [s] (any clock; only differences are used)
    heading_rad : direction of travel per fix, counter-clockwise from east [rad]; NaN where
        unknown (stationary, no course); None if unknown everywhere
    accuracy_m : one-sigma horizontal accuracy per fix [m]; NaN/None -> ``config.sigma_m``
    speed_mps : ground speed per fix [m/s] (e.g. from the smoothed ego track), used to tell
        standing still from driving; None -> estimated from the fixes (:func:`_chord_speed`)
    config : tuning

    Returns
    -------
    MatchResult
    """
    cfg = config or MatchConfig()
    xy = np.column_stack([np.asarray(x_m, float), np.asarray(y_m, float)])
    t_s = np.asarray(t_s, float)
    n = len(xy)
    heading = (np.full(n, np.nan) if heading_rad is None
               else np.asarray(heading_rad, float).reshape(n))
    sigma = np.full(n, cfg.sigma_m)
    if accuracy_m is not None:
        acc = np.asarray(accuracy_m, float).reshape(n)
        sigma = np.where(np.isfinite(acc) & (acc > 0), np.maximum(acc, 1.0), cfg.sigma_m)
    radius = max(cfg.search_radius_m, 4.0 * float(np.median(sigma)) if n else 0.0)

    index = _EdgeIndex(net)
    cands = index.candidates(xy, radius, cfg.max_geometries)
    emis = []
    for k, (edges_k, s_k, d, h) in enumerate(cands):
        e = -0.5 * (d / sigma[k]) ** 2
        # a projection clamped to an edge's end means the fix lies beyond it: the next or
        # previous edge holds the fix, and must win the tie at the shared node (this decides
        # the first and last way of the route)
        clamped = (s_k <= 1e-6) | (s_k >= net.edge_length_m[edges_k] - 1e-6)
        e = e - CLAMP_LOGP * clamped
        if np.isfinite(heading[k]):
            e = e + np.maximum(-0.5 * (_wrap(h - heading[k]) / cfg.heading_sigma_rad) ** 2,
                               cfg.heading_cap_logp)
        emis.append(e)

    if speed_mps is None:
        speed_mps = _chord_speed(xy, t_s)
    stationary = np.asarray(speed_mps, float).reshape(n) < cfg.stationary_mps

    step = np.hypot(*np.diff(xy, axis=0).T) if n > 1 else np.zeros(0)
    window_gc = max(float(step.max()) if step.size else 0.0, 1.0) * (cfg.max_skip + 1)
    dist = _EdgeDistances(net, cutoff_m=min(2 * window_gc + 2 * radius + 50.0, 5000.0),
                          uturn_m=-cfg.uturn_logp * cfg.beta_m,
                          turn_m_per_rad=cfg.turn_m_per_rad)
    dist.prefetch(np.concatenate([c[0] for c in cands]) if n else np.zeros(0, np.int64))
    length = net.edge_length_m
    twin = net.edge_twin

    score: list[np.ndarray] = []
    back: list[list[tuple[int, int, bool]]] = []  # (t_prev, i_prev, is_break)
    for t in range(n):
        edges_t, s_t, _, _ = cands[t]
        m = len(edges_t)
        best = np.full(m, -np.inf)
        ptr: list[tuple[int, int, bool]] = [(-1, -1, False)] * m
        if t < cfg.max_skip + 1:  # start of the chain, earlier fixes skipped as outliers
            best = emis[t] + cfg.skip_logp * t
        for k in range(1, cfg.max_skip + 2):
            tp = t - k
            if tp < 0:
                break
            edges_p, s_p, _, _ = cands[tp]
            if not len(edges_p) or not m:
                continue
            valid = np.isfinite(score[tp])
            if not valid.any():
                continue
            d_gc = float(np.hypot(*(xy[t] - xy[tp])))
            dt = max(float(t_s[t] - t_s[tp]), 1e-3)
            max_route = cfg.max_speed_mps * dt + 2 * radius
            skip = cfg.skip_logp * (k - 1)
            still = bool(stationary[t] and stationary[tp])
            for i in np.flatnonzero(valid):
                ea, sa, sc = int(edges_p[i]), float(s_p[i]), float(score[tp][i])
                reach = dist.rows[ea]
                rest = float(length[ea]) - sa
                for j in range(m):
                    eb, sb = int(edges_t[j]), float(s_t[j])
                    penalty = 0.0
                    if eb == ea and sb >= sa - 1e-9:
                        d_route = sb - sa
                    elif eb == ea and still:
                        # standing still: a projection behind the last one is GPS jitter
                        d_route = sa - sb
                    elif eb == ea:
                        d_route, penalty = 0.0, (sa - sb) / cfg.beta_m
                    else:
                        via = reach.get(eb)
                        if eb == twin[ea]:
                            # turning round in the street (not through the line graph)
                            via, penalty = 0.0, -cfg.uturn_logp
                        if via is None:
                            continue
                        d_route = rest + via + sb
                    if d_route > max_route:
                        continue
                    v = sc + skip - abs(d_route - d_gc) / cfg.beta_m - penalty + emis[t][j]
                    if v > best[j]:
                        best[j] = v
                        ptr[j] = (tp, int(i), False)
        if m and not np.isfinite(best).any() and t > 0:
            # nothing reachable: restart the chain after the best recent state
            src = _best_recent(score, t, cfg)
            if src is not None:
                tp, i, base = src
                best = emis[t] + base + cfg.break_logp
                ptr = [(tp, i, True)] * m
        score.append(best)
        back.append(ptr)

    return _finish(net, xy, t_s, sigma, cands, score, back, dist, cfg)


def _chord_speed(xy: np.ndarray, t_s: np.ndarray, half_window: int = 4) -> np.ndarray:
    """Speed [m/s] from the median positions of the fixes before and after each fix.

    Medians over ``half_window`` fixes ignore outliers; the chord over several seconds keeps
    GPS noise small against the distance driven (5 m noise over 4 s reads as ~1 m/s).
    """
    n = len(xy)
    speed = np.full(n, np.inf)
    for k in range(n):
        a, b = max(0, k - half_window), min(n, k + half_window + 1)
        if b - a < 3:
            continue
        before = np.median(xy[a:k + 1], axis=0)
        after = np.median(xy[k:b], axis=0)
        dt = (np.median(t_s[k:b]) - np.median(t_s[a:k + 1]))
        if dt > 0:
            speed[k] = float(np.hypot(*(after - before))) / dt
    return speed


def _best_recent(score: list[np.ndarray], t: int, cfg: MatchConfig
                 ) -> tuple[int, int, float] | None:
    for tp in range(t - 1, -1, -1):
        if score[tp].size and np.isfinite(score[tp]).any():
            i = int(np.argmax(score[tp]))
            return tp, i, float(score[tp][i]) + cfg.skip_logp * min(t - tp - 1, cfg.max_skip)
    return None


def _finish(net: RoadNetwork, xy: np.ndarray, t_s: np.ndarray, sigma: np.ndarray, cands,
            score, back, dist: _EdgeDistances, cfg: MatchConfig) -> MatchResult:
    n = len(xy)
    empty = MatchResult([], np.full(n, -1), np.full(n, np.nan), np.full(n, -1),
                        np.full(n, -1, dtype=np.int64), np.full(n, np.nan), np.ones(n, bool),
                        _edge_way=net.edge_way_id)
    # end state: best over the last fixes, trailing ones skipped as outliers
    end, end_v = None, -np.inf
    for t in range(n - 1, max(-1, n - 2 - cfg.max_skip), -1):
        if score[t].size and np.isfinite(score[t]).any():
            v = float(score[t].max()) + cfg.skip_logp * (n - 1 - t)
            if v > end_v:
                end, end_v = (t, int(np.argmax(score[t]))), v
    if end is None:
        for t in range(n - 1, -1, -1):
            if score[t].size and np.isfinite(score[t]).any():
                end = (t, int(np.argmax(score[t])))
                break
    if end is None:
        empty.warnings.append("no fix lies within reach of a drivable road")
        return empty

    # backtrack: chosen (t, edge, s) in time order, split at chain breaks
    chains: list[list[tuple[int, int, float]]] = [[]]
    t, i = end
    while t >= 0:
        edges_t, s_t, _, _ = cands[t]
        chains[-1].append((t, int(edges_t[i]), float(s_t[i])))
        tp, ip, is_break = back[t][i]
        if is_break:
            chains.append([])
        t, i = tp, ip
    chains = [c[::-1] for c in chains[::-1] if c]

    route_edges: list[list[int]] = []
    fix_piece = np.full(n, -1)
    fix_s = np.full(n, np.nan)
    outlier = np.ones(n, bool)
    for chain in chains:
        piece: list[int] = [chain[0][1]]
        cum = 0.0  # route length before the current (last) edge of the piece
        s_raw = {}
        prev_e = chain[0][1]
        for t, e, s in chain:
            if e != prev_e:
                between = [] if e == net.edge_twin[prev_e] else dist.path(prev_e, e)
                for f in between:
                    cum += float(net.edge_length_m[piece[-1]])
                    piece.append(f)
                cum += float(net.edge_length_m[piece[-1]])
                piece.append(e)
                prev_e = e
            s_raw[t] = cum + s
            outlier[t] = False
        route_edges.append(piece)
        k = len(route_edges) - 1
        t0, t1 = chain[0][0], chain[-1][0]
        sel = np.arange(t0, t1 + 1)
        meas = np.array([s_raw.get(int(t), np.nan) for t in sel])
        smooth = _rts_along(t_s[sel], meas, sigma[sel], cfg.accel_sigma_mps2)
        piece, smooth = _trim(net, piece, np.maximum.accumulate(smooth), cfg.min_cover_m)
        route_edges[k] = piece
        fix_s[sel] = np.clip(smooth, 0.0, float(net.edge_length_m[piece].sum()))
        fix_piece[sel] = k

    result = MatchResult(route_edges, fix_piece, fix_s, np.full(n, -1),
                         np.full(n, -1, dtype=np.int64), np.full(n, np.nan), outlier,
                         n_breaks=len(chains) - 1, _edge_way=net.edge_way_id)
    _assign_edges(net, xy, result)
    if result.n_breaks:
        result.warnings.append(f"the matched route has {result.n_breaks} break(s): no drivable "
                               "connection between parts of the trace")
    return result


def signed_offsets(line_xy_m: np.ndarray, xy_m: np.ndarray,
                   expected_s_m: np.ndarray | None = None, window_m: float = 40.0
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Arc length along ``line_xy_m`` and signed lateral offset (positive left) of points.

    With ``expected_s_m`` each point is projected only onto the part of the line within
    ``window_m`` of where it should be, so a route that passes a place twice (a loop round a
    block) does not project onto the wrong pass.

    Returns
    -------
    (s_m, offset_m) per point [m]
    """
    line = np.asarray(line_xy_m, float)
    pts = np.asarray(xy_m, float).reshape(-1, 2)
    a, d = line[:-1], np.diff(line, axis=0)
    seg_len = np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-9)
    seg_s = np.concatenate([[0.0], np.cumsum(seg_len)])
    n_seg = len(a)
    if expected_s_m is None or not len(pts):
        first = np.zeros(len(pts), dtype=np.int64)
        width = n_seg
    else:
        exp = np.asarray(expected_s_m, float).reshape(-1)
        known = np.isfinite(exp)
        lo = np.where(known, np.searchsorted(seg_s, exp - window_m, side="right") - 1, 0)
        hi = np.where(known, np.searchsorted(seg_s, exp + window_m, side="left"), n_seg)
        first = np.clip(lo, 0, n_seg - 1)
        width = int(max(1, (np.clip(hi, 1, n_seg) - first).max()))
    s_out = np.full(len(pts), np.nan)
    off_out = np.full(len(pts), np.nan)
    chunk = max(1, 200_000 // max(width, 1))  # bounds the (points x segments) work arrays
    for k0 in range(0, len(pts), chunk):
        p = pts[k0:k0 + chunk]
        # candidate segments of each point: a window of ``width`` from ``first``
        j = np.minimum(first[k0:k0 + chunk, None] + np.arange(width)[None], n_seg - 1)
        rel0 = p[:, None, :] - a[j]
        u = np.clip((rel0 * d[j]).sum(-1) / seg_len[j] ** 2, 0.0, 1.0)
        foot = a[j] + u[..., None] * d[j]
        dist2 = ((p[:, None, :] - foot) ** 2).sum(-1)
        if expected_s_m is not None:
            exp_k = np.asarray(expected_s_m, float)[k0:k0 + chunk]
            far = np.abs(seg_s[j] + u * seg_len[j] - exp_k[:, None]) > window_m
            dist2 = np.where(far & np.isfinite(exp_k)[:, None] & (dist2 < np.inf), np.inf,
                             dist2)
            # no segment inside the window (an expectation off the line): take the nearest
            none = ~np.isfinite(dist2).any(axis=1)
            dist2[none] = ((p[none, None, :] - foot[none]) ** 2).sum(-1)
        best = np.argmin(dist2, axis=1)
        rows = np.arange(len(p))
        jj = j[rows, best]
        rel = p - foot[rows, best]
        cross = d[jj, 0] * rel[:, 1] - d[jj, 1] * rel[:, 0]
        s_out[k0:k0 + chunk] = seg_s[jj] + u[rows, best] * seg_len[jj]
        off_out[k0:k0 + chunk] = np.sign(cross) * np.sqrt(dist2[rows, best])
    return s_out, off_out


def _trim(net: RoadNetwork, piece: list[int], s_m: np.ndarray, min_cover_m: float
          ) -> tuple[list[int], np.ndarray]:
    """Drop route edges before the first / after the last fix position, and a first or last
    edge covered by less than ``min_cover_m``; shift positions to the trimmed start."""
    lengths = net.edge_length_m[piece]
    ends = np.cumsum(lengths)
    starts = ends - lengths
    lo, hi = float(np.nanmin(s_m)), float(np.nanmax(s_m))
    first = int(np.searchsorted(ends, lo, side="right"))
    last = int(np.searchsorted(starts, hi, side="left")) - 1
    first, last = min(first, len(piece) - 1), max(last, 0)
    if last > first and ends[first] - lo < min_cover_m:
        first += 1
    if last > first and hi - starts[last] < min_cover_m:
        last -= 1
    last = max(last, first)
    return piece[first:last + 1], s_m - starts[first]


def _assign_edges(net: RoadNetwork, xy: np.ndarray, res: MatchResult) -> None:
    """Edge, way and signed lateral offset of each fix from its along-route position."""
    for k, piece in enumerate(res.route_edges):
        sel = np.flatnonzero(res.fix_piece == k)
        if not sel.size:
            continue
        lengths = net.edge_length_m[piece]
        starts = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
        pos = np.clip(np.searchsorted(starts, res.fix_route_s_m[sel], side="right") - 1, 0,
                      len(piece) - 1)
        edges = np.asarray(piece)[pos]
        res.fix_edge[sel] = edges
        res.fix_way_id[sel] = net.edge_way_id[edges]
        lines = _lines([net.edge_xy[e] for e in edges])
        pts = shapely.points(xy[sel, 0], xy[sel, 1])
        s = shapely.line_locate_point(lines, pts)
        foot = shapely.get_coordinates(shapely.line_interpolate_point(lines, s))
        ahead = shapely.get_coordinates(
            shapely.line_interpolate_point(lines, np.minimum(s + 0.5, net.edge_length_m[edges])))
        behind = shapely.get_coordinates(
            shapely.line_interpolate_point(lines, np.maximum(s - 0.5, 0.0)))
        tangent = ahead - behind
        rel = xy[sel] - foot
        cross = tangent[:, 0] * rel[:, 1] - tangent[:, 1] * rel[:, 0]
        res.fix_offset_m[sel] = np.sign(cross) * np.hypot(rel[:, 0], rel[:, 1])


def join_xy(net: RoadNetwork, edges: list[int]) -> np.ndarray:
    """Edge geometries joined in travel order (the shared node written once) [m]."""
    return np.vstack([net.edge_xy[edges[0]]] + [net.edge_xy[e][1:] for e in edges[1:]])


#: emission cost of a projection clamped to an edge end (a tie-breaker, see match())
CLAMP_LOGP = 0.2

#: innovations beyond 4 sigma (16 = 4^2 in variance) are rejected by the along-route filter
GATE = 16.0


def _rts_along(t_s: np.ndarray, s_meas_m: np.ndarray, sigma_m: np.ndarray,
               accel_sigma_mps2: float) -> np.ndarray:
    """Constant-velocity Kalman filter + Rauch-Tung-Striebel smoother of along-route position.

    NaN measurements (skipped outliers) are predicted through; innovations beyond 4 sigma are
    rejected. Returns the smoothed positions [m].
    """
    n = len(t_s)
    first = int(np.flatnonzero(np.isfinite(s_meas_m))[0])
    x = np.array([s_meas_m[first], 0.0])
    p = np.diag([sigma_m[first] ** 2, 15.0 ** 2])
    xs_f = np.zeros((n, 2))
    ps_f = np.zeros((n, 2, 2))
    xs_p = np.zeros((n, 2))
    ps_p = np.zeros((n, 2, 2))
    fs = np.zeros((n, 2, 2))
    q = accel_sigma_mps2 ** 2
    for k in range(n):
        dt = float(t_s[k] - t_s[k - 1]) if k else 0.0
        f = np.array([[1.0, dt], [0.0, 1.0]])
        # white-acceleration process noise (Bar-Shalom, discretised continuous model)
        qm = q * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
        x = f @ x
        p = f @ p @ f.T + qm
        xs_p[k], ps_p[k], fs[k] = x, p, f
        z = s_meas_m[k]
        if np.isfinite(z):
            r = sigma_m[k] ** 2
            innov_var = p[0, 0] + r
            innov = z - x[0]
            if innov ** 2 <= GATE * innov_var:
                gain = p[:, 0] / innov_var
                x = x + gain * innov
                p = p - np.outer(gain, p[0, :])
        xs_f[k], ps_f[k] = x, p
    xs = xs_f.copy()
    for k in range(n - 2, -1, -1):
        c = ps_f[k] @ fs[k + 1].T @ np.linalg.inv(ps_p[k + 1])
        xs[k] = xs_f[k] + c @ (xs[k + 1] - xs_p[k + 1])
    return xs[:, 0]


# --------------------------------------------------------------------------- evaluation


@dataclass(slots=True)
class SimulatedDrive:
    """A drive simulated along a shortest path, with its ground truth.

    :param route_edges: true directed edges in travel order, from the first to the last fix
    :param true_ways: their way ids, consecutive repeats merged
    :param t_s, x_m, y_m: noisy 1 Hz fixes [s, m]
    :param true_way_id: way under the true position of each fix
    :param is_outlier: fixes displaced by 30-80 m
    :param true_s_m: true position of each fix along ``route_edges`` [m]
    """

    route_edges: list[int]
    true_ways: list[int]
    t_s: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray
    true_way_id: np.ndarray
    is_outlier: np.ndarray
    length_m: float
    true_s_m: np.ndarray


def simulate_drive(net: RoadNetwork, rng: np.random.Generator, *, min_length_m: float = 1000.0,
                   max_length_m: float = 3000.0, noise_m: float = 5.0,
                   outlier_share: float = 0.02, stop_s: float = 0.0,
                   rate_hz: float = 1.0, random_phase: bool = True) -> SimulatedDrive:
    """Drive the shortest path between two random junctions of ``net`` and record noisy fixes.

    Speed: a cruise speed drawn from 7-13 m/s (25-47 km/h, urban), 4 m/s through turns
    sharper than 45 degrees, accelerating and braking at most 1.5 m/s^2; with ``stop_s`` > 0
    the car stops halfway and stands still that long. The first fix falls at a random point
    of the first second of driving (``random_phase``), not exactly on the start junction.
    Noise: Gaussian, ``noise_m`` per axis; ``outlier_share`` of the fixes are
    instead displaced 30-80 m in a random direction.
    """
    graph = net.graph()
    nodes = np.unique(np.concatenate([net.edge_u, net.edge_v]))
    for _ in range(10000):
        a, b = (int(v) for v in rng.choice(nodes, 2, replace=False))
        try:
            path = nx.dijkstra_path(graph, a, b, weight="length")
        except nx.NetworkXNoPath:
            continue
        edges = [int(graph[p][q]["edge"]) for p, q in itertools.pairwise(path)]
        total = float(net.edge_length_m[edges].sum())
        if min_length_m <= total <= max_length_m:
            break
    else:  # pragma: no cover - the map is too small for the requested lengths
        raise ValueError("no route of the requested length in this network")
    pts = np.vstack([net.edge_xy[edges[0]]] + [net.edge_xy[e][1:] for e in edges[1:]])
    seg = np.hypot(*np.diff(pts, axis=0).T)
    keep = np.concatenate([[True], seg > 1e-6])
    pts = pts[keep]
    s_pts = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    # speed limit profile along a 1 m grid: slow down around sharp turns
    grid = np.arange(0.0, total, 1.0)
    gx, gy = np.interp(grid, s_pts, pts[:, 0]), np.interp(grid, s_pts, pts[:, 1])
    head = np.unwrap(np.arctan2(np.gradient(gy), np.gradient(gx)))
    turn = np.abs(np.interp(grid + 10, grid, head) - np.interp(grid - 10, grid, head))
    cruise = float(rng.uniform(7.0, 13.0))
    v_grid = np.where(turn > math.radians(45), 4.0, cruise)
    if stop_s > 0:
        v_grid[int(total / 2)] = 0.3  # creep to the stop line, then stand
    # comfortable acceleration / braking limit (1.5 m/s^2): v^2 <= v0^2 + 2 a ds
    for order in (slice(None), slice(None, None, -1)):
        v = v_grid[order]
        for k in range(1, v.size):
            v[k] = min(v[k], math.sqrt(v[k - 1] ** 2 + 2 * 1.5 * 1.0))
    dt = 1.0 / rate_hz
    # the receiver's 1 Hz clock does not know where the route begins: the first fix falls
    # anywhere within the first second of driving
    s = float(rng.uniform(0.0, v_grid[0] * dt)) if random_phase else 0.0
    t, s_list, t_list = 0.0, [], []
    stopped = stop_s <= 0
    while s < total:
        s_list.append(s)
        t_list.append(t)
        if not stopped and s >= total / 2:
            stopped = True
            for _ in range(int(stop_s * rate_hz)):
                t += dt
                s_list.append(s)
                t_list.append(t)
        s += float(np.interp(s, grid, v_grid)) * dt
        t += dt
    s_true = np.array(s_list)
    x = np.interp(s_true, s_pts, pts[:, 0])
    y = np.interp(s_true, s_pts, pts[:, 1])
    ends = np.cumsum(net.edge_length_m[edges])
    pos = np.minimum(np.searchsorted(ends, s_true, side="right"), len(edges) - 1)
    true_way = net.edge_way_id[np.asarray(edges)[pos]]
    n = len(s_true)
    x = x + rng.normal(0.0, noise_m, n)
    y = y + rng.normal(0.0, noise_m, n)
    out = rng.random(n) < outlier_share
    r, ang = rng.uniform(30.0, 80.0, n), rng.uniform(-math.pi, math.pi, n)
    x = np.where(out, np.interp(s_true, s_pts, pts[:, 0]) + r * np.cos(ang), x)
    y = np.where(out, np.interp(s_true, s_pts, pts[:, 1]) + r * np.sin(ang), y)
    # the driven sequence is what lies between the first and the last fix: a way the car
    # entered after its last fix was recorded cannot be known
    driven = edges[int(pos[0]):int(pos[-1]) + 1]
    ways = _merge_ways([], [driven], net.edge_way_id)
    driven_start = float(ends[int(pos[0])] - net.edge_length_m[edges[int(pos[0])]])
    return SimulatedDrive(driven, ways, np.array(t_list), x, y, true_way, out, total,
                          s_true - driven_start)
