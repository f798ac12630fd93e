"""The Viterbi pass of the map matcher: the most likely sequence of candidate road positions.

The lattice has one column per HMM step (a fix the matcher reasons about) and one state per
candidate ``(directed edge, along-edge s)`` of that fix. A transition from step ``tp`` to step
``t`` scores ``-|route length - distance driven| / beta`` with the route taken on the edge
graph (:class:`~vid2sim.geo.routing.EdgeDistances`, searched only as far as the car can drive in
the time). Newson & Krumm (2009, eq. 2) compare the
route with the straight line between the two fixes; where the trace tells the speed (densely
sampled stretches), the distance driven is the speed times the time instead: the straight
line between two noisy fixes carries their noise twice, and an outlier that lies on the road
ahead looks like a plausible hop to it but not like plausible driving. Further:

- on the same edge, a projection behind the previous one is GPS jitter: free while standing
  still, ``back / beta`` while driving;
- turning onto the twin edge (a U-turn in the street) costs ``uturn_cost``;
- a route longer than the car could drive in the time (``max_speed_mps``) is impossible;
- a step may be skipped as an outlier: the chain jumps up to ``max_skip`` steps, each skipped
  step costing ``skip_logp``; where nothing is reachable the chain breaks and restarts after
  the best recent state (``break_logp``).

The transitions into a step, from the states of all the earlier steps it may follow, are one
(sources x candidates) numpy array.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vid2sim.geo.routing import EdgeDistances


@dataclass(frozen=True, slots=True)
class ChainParams:
    """What the Viterbi pass needs of the matcher's tuning (see :class:`MatchConfig`).

    :param beta_m: scale of |route - straight| [m]
    :param uturn_cost: cost of turning onto the twin edge [nats, > 0]
    :param max_skip: steps the chain may skip
    :param skip_logp: log-probability of one skipped step
    :param break_logp: log-probability of a chain restart
    :param max_speed_mps: fastest plausible driving [m/s]
    :param slack_m: route length allowed on top of ``max_speed_mps * dt`` (two search radii:
        both ends of a transition may lie that far from their fixes) [m]
    :param prune_m: where the distance driven is known (from the speed), a route longer than
        it by more than this is impossible [m] (inf: only ``max_speed_mps`` bounds routes)
    """

    beta_m: float
    uturn_cost: float
    max_skip: int
    skip_logp: float
    break_logp: float
    max_speed_mps: float
    slack_m: float
    prune_m: float = float("inf")


@dataclass(slots=True)
class Lattice:
    """Candidates of each step: directed edges, along-edge positions [m], emission log-prob."""

    edges: list[np.ndarray]
    s_m: list[np.ndarray]
    emission: list[np.ndarray]


@dataclass(slots=True)
class Sources:
    """The states a step's transitions start from: the valid states of the previous
    ``max_skip + 1`` steps, one row each.

    :param edges, s_m: the state's directed edge and along-edge position [m]
    :param score: its Viterbi score with the cost of the steps skipped to get here
    :param step, index: the step and the state's index in it (back pointers)
    :param d_gc_m: distance driven from the state's step to this one [m]
    :param max_route_m: longest route the transition allows [m]
    :param dt_s: time from the state's step to this one [s]
    :param still: the car stands still at both steps
    """

    edges: np.ndarray
    s_m: np.ndarray
    score: np.ndarray
    step: np.ndarray
    index: np.ndarray
    d_gc_m: np.ndarray
    max_route_m: np.ndarray
    dt_s: np.ndarray
    still: np.ndarray


def route_gaps(dist: EdgeDistances, edges_p: np.ndarray, remaining_m: np.ndarray,
               edges_t: np.ndarray, max_route_m: np.ndarray) -> np.ndarray:
    """Gaps [m] of the routes from each source edge to each target edge, (P, M); inf where
    longer than the row's ``max_route_m`` allows after the ``remaining_m`` of its own edge.

    One search per distinct source edge (:class:`~vid2sim.geo.routing.EdgeDistances`),
    asked for the distinct target edges only."""
    ua, inv_a = np.unique(edges_p, return_inverse=True)
    uf, inv_f = np.unique(edges_t, return_inverse=True)
    bound = np.full(ua.size, -np.inf)
    np.maximum.at(bound, inv_a, max_route_m - remaining_m)
    targets = uf.tolist()
    table = np.array([dist.gaps(a, targets, b) for a, b in zip(ua.tolist(), bound.tolist(),
                                                               strict=True)])
    return table.reshape(ua.size, uf.size)[inv_a][:, inv_f]


def transition_logp(dist: EdgeDistances, length_m: np.ndarray, twin: np.ndarray,
                    src: Sources, edges_t: np.ndarray, s_t: np.ndarray, prm: ChainParams
                    ) -> np.ndarray:
    """Log-probability of moving from each source state to each current candidate,
    (len(src.edges), len(edges_t)); -inf where impossible. All rows at once: the sources
    of several earlier steps, each with its own distance driven and time."""
    edges_p, s_p = src.edges, src.s_m
    max_route = src.max_route_m[:, None]
    remaining = length_m[edges_p] - s_p
    gaps = route_gaps(dist, edges_p, remaining, edges_t, max_route[:, 0])
    is_twin = twin[edges_p][:, None] == edges_t[None, :]
    gaps = np.where(is_twin, 0.0, gaps)  # turning round in the street, not via the graph
    d_route = remaining[:, None] + gaps + s_t[None, :]
    penalty = np.where(is_twin, prm.uturn_cost, 0.0)
    same = edges_p[:, None] == edges_t[None, :]
    fwd = s_t[None, :] - s_p[:, None]
    behind = fwd < -1e-9
    still = src.still[:, None]
    d_same = np.where(behind, np.where(still, -fwd, 0.0), fwd)
    pen_same = np.where(behind & ~still, -fwd / prm.beta_m, 0.0)
    d_route = np.where(same, d_same, d_route)
    penalty = np.where(same, pen_same, penalty)
    logp = -np.abs(d_route - src.d_gc_m[:, None]) / prm.beta_m - penalty
    return np.where(np.isfinite(d_route) & (d_route <= max_route), logp, -np.inf)


def _sources(lat: Lattice, score: list[np.ndarray], t: int, xy_m: np.ndarray, t_s: np.ndarray,
             still: np.ndarray, travel_m: np.ndarray | None, prm: ChainParams
             ) -> Sources | None:
    """The valid states of steps ``t - 1 .. t - 1 - max_skip`` as transition sources."""
    parts = []
    for k in range(1, prm.max_skip + 2):
        tp = t - k
        if tp < 0:
            break
        valid = np.flatnonzero(np.isfinite(score[tp]))
        if not valid.size:
            continue
        dt = float(t_s[t] - t_s[tp])
        max_route = prm.max_speed_mps * max(dt, 1e-3) + prm.slack_m
        d_gc = float(np.hypot(*(xy_m[t] - xy_m[tp])))
        if travel_m is not None and np.isfinite(travel_m[t]):  # cumulative: so is tp's
            d_gc = float(travel_m[t] - travel_m[tp])
            max_route = min(max_route, d_gc + prm.prune_m)
        parts.append((tp, valid, score[tp][valid] + prm.skip_logp * (k - 1), d_gc, dt,
                      bool(still[t] and still[tp]), max_route))
    if not parts:
        return None
    sizes = [p[1].size for p in parts]

    def each(value_of) -> np.ndarray:
        return np.repeat([value_of(p) for p in parts], sizes)

    return Sources(
        edges=np.concatenate([lat.edges[p[0]][p[1]] for p in parts]),
        s_m=np.concatenate([lat.s_m[p[0]][p[1]] for p in parts]),
        score=np.concatenate([p[2] for p in parts]), step=each(lambda p: p[0]),
        index=np.concatenate([p[1] for p in parts]), d_gc_m=each(lambda p: p[3]),
        max_route_m=each(lambda p: p[6]), dt_s=each(lambda p: p[4]),
        still=each(lambda p: p[5]).astype(bool))


def viterbi(lat: Lattice, xy_m: np.ndarray, t_s: np.ndarray, still: np.ndarray,
            dist: EdgeDistances, length_m: np.ndarray, twin: np.ndarray, prm: ChainParams,
            travel_m: np.ndarray | None = None) -> list[list[tuple[int, int, float]]]:
    """Best chains through the lattice.

    Parameters
    ----------
    lat : candidates per step
    xy_m, t_s : the steps' fix positions [m] and times [s]
    still : per step, whether the car stands still there
    travel_m : per step, distance driven since the first step [m] (cumulative; inf from
        where the speed is unknown): the transitions compare routes with it, else with the
        straight line between the fixes

    Returns
    -------
    chains in time order (more than one where the chain broke), each a list of
    ``(step, directed edge, along-edge s [m])``; empty when no step has a candidate
    """
    n = len(lat.edges)
    score: list[np.ndarray] = []
    ptr_t: list[np.ndarray] = []
    ptr_i: list[np.ndarray] = []
    brk: list[bool] = []
    started = False  # some earlier step has a state: before that, every step may start
    for t in range(n):
        m = len(lat.edges[t])
        best = np.full(m, -np.inf)
        from_t = np.full(m, -1)
        from_i = np.full(m, -1)
        if t < prm.max_skip + 1 or not started:
            # start of the chain, earlier steps skipped as outliers (or without candidates)
            best = lat.emission[t] + prm.skip_logp * min(t, prm.max_skip)
        src = _sources(lat, score, t, xy_m, t_s, still, travel_m, prm) if m else None
        if src is not None:
            total = src.score[:, None] + transition_logp(dist, length_m, twin, src,
                                                         lat.edges[t], lat.s_m[t], prm)
            arg = np.argmax(total, axis=0)  # the first of equals: the fewest skips
            v = total[arg, np.arange(m)] + lat.emission[t]
            better = v > best
            best = np.where(better, v, best)
            from_t = np.where(better, src.step[arg], from_t)
            from_i = np.where(better, src.index[arg], from_i)
        is_break = False
        if m and not np.isfinite(best).any() and t > 0:
            restart = _best_recent(score, t, prm)
            if restart is not None:  # nothing reachable: restart after the best recent state
                tp, i, base = restart
                best = lat.emission[t] + base + prm.break_logp
                from_t, from_i, is_break = np.full(m, tp), np.full(m, i), True
        started = started or bool(np.isfinite(best).any())
        score.append(best)
        ptr_t.append(from_t)
        ptr_i.append(from_i)
        brk.append(is_break)
    return _backtrack(lat, score, ptr_t, ptr_i, brk, prm)


def _backtrack(lat: Lattice, score: list[np.ndarray], ptr_t: list[np.ndarray],
               ptr_i: list[np.ndarray], brk: list[bool], prm: ChainParams
               ) -> list[list[tuple[int, int, float]]]:
    end = _end_state(score, prm)
    if end is None:
        return []
    chains: list[list[tuple[int, int, float]]] = [[]]
    t, i = end
    while t >= 0:
        chains[-1].append((t, int(lat.edges[t][i]), float(lat.s_m[t][i])))
        tp, ip = int(ptr_t[t][i]), int(ptr_i[t][i])
        if brk[t]:
            chains.append([])
        t, i = tp, ip
    return [c[::-1] for c in chains[::-1] if c]


def _best_recent(score: list[np.ndarray], t: int, prm: ChainParams
                 ) -> tuple[int, int, float] | None:
    for tp in range(t - 1, -1, -1):
        if score[tp].size and np.isfinite(score[tp]).any():
            i = int(np.argmax(score[tp]))
            return tp, i, float(score[tp][i]) + prm.skip_logp * min(t - tp - 1, prm.max_skip)
    return None


def _end_state(score: list[np.ndarray], prm: ChainParams) -> tuple[int, int] | None:
    """Best final state: over the last steps, trailing ones skipped as outliers; failing
    that, the best state of the last step that has one."""
    n = len(score)
    end, end_v = None, -np.inf
    for t in range(n - 1, max(-1, n - 2 - prm.max_skip), -1):
        if score[t].size and np.isfinite(score[t]).any():
            v = float(score[t].max()) + prm.skip_logp * (n - 1 - t)
            if v > end_v:
                end, end_v = (t, int(np.argmax(score[t]))), v
    if end is None:
        for t in range(n - 1, -1, -1):
            if score[t].size and np.isfinite(score[t]).any():
                return t, int(np.argmax(score[t]))
    return end
