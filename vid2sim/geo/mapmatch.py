"""Map matching: a hidden-Markov-model / Viterbi matcher of GPS fixes onto a directed road graph.

Model (after Newson & Krumm, "Hidden Markov Map Matching Through Noise and Sparseness",
ACM SIGSPATIAL 2009), with additions for dash-cam traces:

- noise: each fix's reported accuracy, else ``sigma_m``, else estimated from the trace as
  the paper does (1.4826 x the median distance of the fixes to their nearest road), checked
  against the matched route's own offsets and matched again when those say it is larger;
- observations: fixes less than ``obs_window_s`` apart (a 10 Hz receiver) are merged into
  their median, and the HMM reasons about observations at least ``thin_sigmas`` sigma apart
  (the paper's thinning; sparse fixes are all kept); every fix is placed on the matched
  route afterwards;
- states: for each observation, candidate positions ``(edge, s_m)`` on directed edges
  within the search radius; both twins of a two-way street are separate states, so the
  direction of travel is part of the state;
- emission: Gaussian in the distance to the edge, plus, where the heading is known, a capped
  Gaussian in heading error;
- transition (:mod:`vid2sim.geo.hmm`): ``-|route length - distance driven| / beta_m``, the
  distance driven from the trace's speed where it is known, else the straight line between
  the fixes; routes run on the line graph, so they never turn back onto the twin edge;
  turning round costs ``uturn_logp``; moving backwards on the same edge is GPS jitter;
- outliers: an observation may be skipped (up to ``max_skip`` in a row, each costing
  ``skip_logp``); where nothing can be reached the chain breaks and restarts
  (``break_logp``);
- after Viterbi every fix's along-route position is smoothed with a constant-velocity
  Rauch-Tung-Striebel smoother (4-sigma gate) and made non-decreasing, so noise near a
  junction does not flip a fix onto the neighbouring way and stationary periods never run
  backwards.

Route lengths between candidate edges come from one Dijkstra search per candidate edge on the
line graph, grown only as far as the car can drive in the time between the fixes and reused
by every later transition from that edge (:mod:`vid2sim.geo.routing`).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field

import numpy as np
import shapely

from vid2sim.geo.alongroute import join_xy, rts_along, signed_offsets, trim_route
from vid2sim.geo.candidates import EdgeIndex, lines_array, wrap_angle
from vid2sim.geo.hmm import ChainParams, Lattice, viterbi
from vid2sim.geo.match_config import MatchConfig
from vid2sim.geo.osm import RoadNetwork
from vid2sim.geo.routing import EdgeDistances


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
        return merge_ways(ways, self.route_edges, self._edge_way)

    _edge_way: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


def merge_ways(out: list[int], pieces: list[list[int]], edge_way: np.ndarray) -> list[int]:
    """Append the way ids of ``pieces`` (lists of directed edges) to ``out``, consecutive
    repeats merged."""
    for piece in pieces:
        for e in piece:
            w = int(edge_way[e])
            if not out or out[-1] != w:
                out.append(w)
    return out


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
        or, when that is None, the noise estimated from the trace
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
    acc = (np.full(n, np.nan) if accuracy_m is None
           else np.asarray(accuracy_m, float).reshape(n))
    index = EdgeIndex(net)
    obs = observations(xy, t_s, cfg.obs_window_s)
    noise = _noise(index, xy, acc, obs, cfg)
    obs_still, obs_travel = _motion(obs, speed_mps, n, cfg)
    use, off_map = on_map(index, obs, noise.obs_sigma, cfg)
    # one set of route searches for both passes: they depend on the map, not on the noise
    dist = EdgeDistances(net, uturn_m=-cfg.uturn_logp * cfg.beta_m,
                         turn_m_per_rad=cfg.turn_m_per_rad)

    def once(sigma: np.ndarray, obs_sigma: np.ndarray) -> MatchResult:
        return _match_once(net, index, dist, xy, t_s, sigma, obs, heading[obs.fix], obs_sigma,
                           obs_still, obs_travel, use, cfg)

    result = once(noise.sigma, noise.obs_sigma)
    if noise.estimated and cfg.refine_sigma:
        # the nearest-road estimate reads low where noise carries fixes towards other roads;
        # the matched route's offsets are the noise across the road (Newson & Krumm's
        # estimator on the route itself): match again if they say the noise is larger
        used = ~result.fix_outlier & np.isfinite(result.fix_offset_m) & ~noise.known
        if used.sum() >= MIN_FIXES_FOR_SIGMA:
            again = float(np.clip(MAD_TO_SIGMA * np.median(np.abs(result.fix_offset_m[used])),
                                  cfg.min_sigma_m, cfg.max_sigma_m))
            if again > SIGMA_RETRY_RATIO * noise.sigma_fix:
                # the offsets are those of single fixes: they say nothing about how steady
                # the median of several fixes is, so a merged observation keeps its estimate
                result = once(np.where(noise.known, noise.sigma, again),
                              np.where(noise.known[obs.fix] | (obs.size > 1), noise.obs_sigma,
                                       again))
    result.warnings[:0] = off_map
    return result


@dataclass(slots=True)
class _Noise:
    """GPS noise per fix and per observation [m], the estimate for fixes without an
    accuracy, whether it was estimated, and which fixes report their own accuracy."""

    sigma: np.ndarray
    obs_sigma: np.ndarray
    sigma_fix: float
    estimated: bool
    known: np.ndarray


def _noise(index: EdgeIndex, xy: np.ndarray, acc: np.ndarray, obs: Observations,
           cfg: MatchConfig) -> _Noise:
    known = np.isfinite(acc) & (acc > 0)
    estimate = cfg.sigma_m is None and not known.all()
    if cfg.sigma_m is not None:
        sigma_fix = sigma_obs = float(cfg.sigma_m)
    elif estimate:
        sigma_fix = estimate_sigma(index, xy[~known], cfg)
        # the median of several fixes is steadier than one fix if their errors are
        # independent, and as bad if they move together: measured, not assumed
        sigma_obs = min(estimate_sigma(index, obs.xy, cfg), sigma_fix)
    else:
        sigma_fix = sigma_obs = cfg.min_sigma_m  # every fix has its accuracy
    sigma = np.where(known, np.maximum(acc, 1.0), sigma_fix)
    obs_sigma = np.where(known[obs.fix], sigma[obs.fix], sigma_obs)
    return _Noise(sigma, obs_sigma, sigma_fix, estimate, known)


def _motion(obs: Observations, speed_mps: np.ndarray | None, n: int, cfg: MatchConfig
            ) -> tuple[np.ndarray, np.ndarray]:
    """Per observation: whether the car stands still, and the distance driven since the
    previous observation [m] (inf where the speed is unknown)."""
    if speed_mps is None:
        obs_speed = _chord_speed(obs.xy, obs.t_s)
    else:
        obs_speed = np.asarray(speed_mps, float).reshape(n)[obs.fix]
    obs_travel = np.zeros(len(obs.t_s))
    if len(obs.t_s) > 1:
        v = np.where(np.isfinite(obs_speed[1:]), np.minimum(obs_speed[1:], cfg.max_speed_mps),
                     np.inf)
        obs_travel[1:] = np.diff(obs.t_s) * v
    return obs_speed < cfg.stationary_mps, obs_travel


def on_map(index: EdgeIndex, obs: Observations, obs_sigma: np.ndarray, cfg: MatchConfig
           ) -> tuple[np.ndarray, list[str]]:
    """Which observations the HMM reasons about: all but a run at the start or the end of
    the trace that lies off the map, farther than ``off_map_sigmas`` sigma from every
    drivable road for at least ``off_map_fixes`` observations (a car park, private
    ground, a ferry): the route begins where the car joins the road network. Returns the
    mask and a warning per run left out."""
    k = len(obs.t_s)
    use = np.ones(k, bool)
    if k == 0:
        return use, []
    near = index.nearest_distance(obs.xy, float(cfg.off_map_sigmas * obs_sigma.max() * 4.0))
    off = ~(near <= cfg.off_map_sigmas * obs_sigma)  # NaN: nothing within reach
    run = cfg.off_map_fixes
    on_runs = np.flatnonzero(np.convolve(~off, np.ones(run), "valid") == run)
    if not on_runs.size:
        return use, []  # nothing stays on the map: that is the map's error, not a car park
    first, last = int(on_runs[0]), int(on_runs[-1]) + run - 1
    notes = []
    for lo, hi, where in ((0, first, "starts"), (last + 1, k, "ends")):
        if hi - lo >= run and off[lo:hi].sum() >= run:
            use[lo:hi] = False
            fixes = int(obs.size[lo:hi].sum())
            notes.append(f"the drive {where} off the map: {fixes} fix(es) over "
                         f"{obs.t_s[hi - 1] - obs.t_s[lo]:.0f} s lie more than "
                         f"{cfg.off_map_sigmas:g} sigma from every drivable road (a car park?); "
                         "they are not matched and the road " + ("begins where the car joins "
                         "the streets" if where == "starts" else "ends where it leaves them"))
    return use, notes


@dataclass(slots=True)
class Observations:
    """What the HMM sees: fixes less than ``obs_window_s`` apart merged into one.

    :param xy: component-wise median position of each group [m] (K, 2)
    :param t_s: median time of each group [s]
    :param fix: the group's middle fix (index into the input), which stands for it
    :param size: fixes in the group
    """

    xy: np.ndarray
    t_s: np.ndarray
    fix: np.ndarray
    size: np.ndarray


def observations(xy: np.ndarray, t_s: np.ndarray, window_s: float) -> Observations:
    """Group consecutive fixes within ``window_s`` of the group's first fix; each group
    becomes its median (an outlier among several fixes does not move it). Fixes further
    apart stay single, so a 1 Hz trace is used as it is."""
    n = len(xy)
    if n == 0 or window_s <= 0:
        return Observations(xy.copy(), t_s.copy(), np.arange(n), np.ones(n, dtype=np.int64))
    starts = [0]
    for k in range(1, n):
        if t_s[k] - t_s[starts[-1]] >= window_s:
            starts.append(k)
    bounds = [*starts, n]
    if len(starts) == n:
        return Observations(xy.copy(), t_s.copy(), np.arange(n), np.ones(n, dtype=np.int64))
    mid = np.array([(a + b - 1) // 2 for a, b in itertools.pairwise(bounds)])
    med_xy = np.array([np.median(xy[a:b], axis=0) for a, b in itertools.pairwise(bounds)])
    med_t = np.array([np.median(t_s[a:b]) for a, b in itertools.pairwise(bounds)])
    return Observations(med_xy, med_t, mid, np.diff(bounds))


def estimate_sigma(index: EdgeIndex, xy: np.ndarray, cfg: MatchConfig) -> float:
    """GPS noise [m] from the fixes' distances to their nearest road: 1.4826 x their median
    (Newson & Krumm 2009, section 4.1: the median absolute deviation of a Gaussian), within
    ``[min_sigma_m, max_sigma_m]``; ``min_sigma_m`` when too few fixes lie near a road."""
    near = index.nearest_distance(xy, cfg.max_sigma_m * 3.0)
    near = near[np.isfinite(near)]
    if near.size < MIN_FIXES_FOR_SIGMA:
        return cfg.min_sigma_m
    return float(np.clip(MAD_TO_SIGMA * np.median(near), cfg.min_sigma_m, cfg.max_sigma_m))


def hmm_steps(xy: np.ndarray, sigma: np.ndarray, thin_sigmas: float,
              travel_m: np.ndarray) -> np.ndarray:
    """Indices of the observations the HMM reasons about: the first, every one at least
    ``thin_sigmas`` sigma from the previous step, and the last (Newson & Krumm 2009, section
    4.1: closer fixes say little about the route and their noise dominates the route-length
    comparison). Observations whose travel from the previous one is unknown (``travel_m``
    inf: too few fixes around them to tell the speed, i.e. sparse sampling) are all kept.
    The other fixes are placed on the matched route afterwards."""
    n = len(xy)
    if n <= 2 or thin_sigmas <= 0:
        return np.arange(n)
    keep = [0]
    last = xy[0]
    for k in range(1, n - 1):
        far = (xy[k, 0] - last[0]) ** 2 + (xy[k, 1] - last[1]) ** 2 >= \
            (thin_sigmas * sigma[k]) ** 2
        if far or not math.isfinite(travel_m[k]):
            keep.append(k)
            last = xy[k]
    keep.append(n - 1)
    return np.asarray(keep)


def _match_once(net: RoadNetwork, index: EdgeIndex, dist: EdgeDistances, xy: np.ndarray,
                t_s: np.ndarray,
                sigma: np.ndarray, obs: Observations, obs_heading: np.ndarray,
                obs_sigma: np.ndarray, obs_still: np.ndarray, obs_travel: np.ndarray,
                use: np.ndarray, cfg: MatchConfig) -> MatchResult:
    n = len(xy)
    radius = max(cfg.search_radius_m,
                 cfg.search_sigmas * float(np.median(obs_sigma)) if n else 0.0)
    inside = np.flatnonzero(use)
    k_steps = inside[hmm_steps(obs.xy[inside], obs_sigma[inside], cfg.thin_sigmas,
                               obs_travel[inside])]
    sxy = obs.xy[k_steps]
    beta = cfg.beta_m
    cands = index.candidates(sxy, radius, cfg.max_geometries)
    service = np.array([t.get("highway") == "service" for t in net.edge_tags], bool)
    emis = []
    for k, c in enumerate(cands):
        edges_k, s_k, h = c.edges, c.s_m, c.heading_rad
        e = -0.5 * (c.dist_m / obs_sigma[k_steps[k]]) ** 2
        # a projection clamped to an edge's end means the fix lies beyond it: the next or
        # previous edge holds the fix, and must win the tie at the shared node (this decides
        # the first and last way of the route)
        clamped = (s_k <= 1e-6) | (s_k >= net.edge_length_m[edges_k] - 1e-6)
        e = e - CLAMP_LOGP * clamped + cfg.service_logp * service[edges_k]
        hd = obs_heading[k_steps[k]]
        if np.isfinite(hd):
            e = e + np.maximum(-0.5 * (wrap_angle(h - hd) / cfg.heading_sigma_rad) ** 2,
                               cfg.heading_cap_logp)
        emis.append(e)

    prm = ChainParams(beta_m=beta, uturn_cost=-cfg.uturn_logp, max_skip=cfg.max_skip,
                      skip_logp=cfg.skip_logp, break_logp=cfg.break_logp,
                      max_speed_mps=cfg.max_speed_mps, slack_m=2 * radius,
                      prune_m=cfg.prune_beta * beta)
    lattice = Lattice([c.edges for c in cands], [c.s_m for c in cands], emis)
    chains = viterbi(lattice, sxy, obs.t_s[k_steps], obs_still[k_steps], dist,
                     net.edge_length_m, net.edge_twin, prm, np.cumsum(obs_travel)[k_steps])
    steps = obs.fix[k_steps]  # each step stands for its middle fix
    chains = [[(int(steps[k]), e, s) for k, e, s in chain] for chain in chains]
    return _finish(net, xy, t_s, sigma, chains, steps, dist, cfg)


def _chord_speed(xy: np.ndarray, t_s: np.ndarray, half_window_s: float = 4.0) -> np.ndarray:
    """Speed [m/s] from the median positions of the fixes in the ``half_window_s`` before and
    after each fix (inf where fewer than 3 fixes lie in the window).

    Medians ignore outliers; the chord over several seconds keeps GPS noise small against
    the distance driven (5 m noise over 4 s reads as ~1 m/s).
    """
    n = len(xy)
    speed = np.full(n, np.inf)
    if n < 3:
        return speed
    lo = np.searchsorted(t_s, t_s - half_window_s, side="left")
    hi = np.searchsorted(t_s, t_s + half_window_s, side="right")
    k = np.arange(n)
    # every fix's window before (lo..k) and after (k..hi-1) as NaN-padded rows
    width = int(max((k - lo).max(), (hi - 1 - k).max())) + 1
    offs = np.arange(width)
    idx_b = k[:, None] - offs[None, :]
    idx_a = k[:, None] + offs[None, :]
    in_b = idx_b >= lo[:, None]
    in_a = idx_a <= (hi - 1)[:, None]
    idx_b, idx_a = np.clip(idx_b, 0, n - 1), np.clip(idx_a, 0, n - 1)

    def med(values: np.ndarray, idx: np.ndarray, inside: np.ndarray) -> np.ndarray:
        return np.nanmedian(np.where(inside, values[idx], np.nan), axis=1)

    before = np.column_stack([med(xy[:, 0], idx_b, in_b), med(xy[:, 1], idx_b, in_b)])
    after = np.column_stack([med(xy[:, 0], idx_a, in_a), med(xy[:, 1], idx_a, in_a)])
    dt = med(t_s, idx_a, in_a) - med(t_s, idx_b, in_b)
    ok = (hi - lo >= 3) & (dt > 0)
    speed[ok] = np.hypot(*(after - before)[ok].T) / dt[ok]
    return speed


def _finish(net: RoadNetwork, xy: np.ndarray, t_s: np.ndarray, sigma: np.ndarray,
            chains: list[list[tuple[int, int, float]]], steps: np.ndarray,
            dist: EdgeDistances, cfg: MatchConfig) -> MatchResult:
    n = len(xy)
    if not chains:
        empty = MatchResult([], np.full(n, -1), np.full(n, np.nan), np.full(n, -1),
                            np.full(n, -1, dtype=np.int64), np.full(n, np.nan),
                            np.ones(n, bool), _edge_way=net.edge_way_id)
        empty.warnings.append("no fix lies within reach of a drivable road")
        return empty

    route_edges: list[list[int]] = []
    fix_piece = np.full(n, -1)
    fix_s = np.full(n, np.nan)
    outlier = np.ones(n, bool)
    is_step = np.zeros(n, bool)
    is_step[steps] = True
    for chain in chains:
        piece, s_raw = _route_of_chain(net, chain, dist)
        t0, t1 = chain[0][0], chain[-1][0]
        sel = np.arange(t0, t1 + 1)
        meas = np.array([s_raw.get(int(t), np.nan) for t in sel])
        # fixes between the steps (thinned out, not skipped as outliers): their place on
        # the route near where the steps around them put the car
        between = ~is_step[sel]
        if between.any():
            known_t = np.array(sorted(s_raw))
            expect = np.interp(t_s[sel[between]], t_s[known_t], [s_raw[t] for t in known_t])
            window = PROJECT_WINDOW_SIGMAS * float(np.max(sigma[sel])) + PROJECT_WINDOW_M
            meas[between], _ = signed_offsets(join_xy(net, piece), xy[sel[between]], expect,
                                              window)
        smooth, accepted = rts_along(t_s[sel], meas, sigma[sel], cfg.accel_sigma_mps2,
                                     return_accepted=True)
        outlier[sel] = ~accepted
        piece, smooth = trim_route(net, piece, np.maximum.accumulate(smooth), cfg.min_cover_m)
        route_edges.append(piece)
        fix_s[sel] = np.clip(smooth, 0.0, float(net.edge_length_m[piece].sum()))
        fix_piece[sel] = len(route_edges) - 1

    result = MatchResult(route_edges, fix_piece, fix_s, np.full(n, -1),
                         np.full(n, -1, dtype=np.int64), np.full(n, np.nan), outlier,
                         n_breaks=len(chains) - 1, _edge_way=net.edge_way_id)
    _assign_edges(net, xy, result)
    if result.n_breaks:
        result.warnings.append(f"the matched route has {result.n_breaks} break(s): no drivable "
                               "connection between parts of the trace")
    return result


def _route_of_chain(net: RoadNetwork, chain: list[tuple[int, int, float]],
                    dist: EdgeDistances) -> tuple[list[int], dict[int, float]]:
    """The route edges of a Viterbi chain (consecutive states joined by their shortest
    route) and each chain fix's position along them [m]."""
    piece = [chain[0][1]]
    cum = 0.0  # route length before the current (last) edge of the piece
    s_raw: dict[int, float] = {}
    for t, e, s in chain:
        if e != piece[-1]:
            between = [] if e == net.edge_twin[piece[-1]] else dist.path(piece[-1], e)
            for f in [*between, e]:
                cum += float(net.edge_length_m[piece[-1]])
                piece.append(f)
        s_raw[t] = cum + s
    return piece, s_raw


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
        # one geometry per edge of the piece, shared by its fixes
        uniq, inv = np.unique(edges, return_inverse=True)
        lines = lines_array([net.edge_xy[e] for e in uniq.tolist()])[inv]
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


#: emission cost of a projection clamped to an edge end (a tie-breaker, see match())
CLAMP_LOGP = 0.2
#: median absolute deviation -> standard deviation of a Gaussian (1 / 0.6745)
MAD_TO_SIGMA = 1.4826
#: fewest fixes a noise estimate is made from (fewer: ``min_sigma_m``)
MIN_FIXES_FOR_SIGMA = 5
#: re-match when the route's own offsets say the noise is this much above the first estimate
SIGMA_RETRY_RATIO = 1.25
#: a fix between steps is placed on the route within this many sigma + metres of where the
#: steps around it put the car
PROJECT_WINDOW_SIGMAS = 3.0
PROJECT_WINDOW_M = 20.0
