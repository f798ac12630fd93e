"""How well a matched route agrees with the true one: the route mismatch fraction.

Newson & Krumm ("Hidden Markov Map Matching Through Noise and Sparseness", ACM SIGSPATIAL
2009, section 5) judge a matcher by

    RMF = (d_minus + d_plus) / d_true

where ``d_minus`` is the length of the true route that the matched route misses,
``d_plus`` the length of the matched route that is not on the true route and ``d_true`` the
length of the true route. 0 is a perfect match; a matched route that shares nothing with the
truth scores 1 + its own length / the true length (>= 1). Valhalla's Meili test rig and
LibCity use the same measure.

Two ways to say "on the route" are given:

- :func:`rmf_corridor`: geometry. A piece of one route lies on the other when it is within
  ``corridor_m`` of its polyline (shapely buffer + difference, segment by segment so that a
  street driven twice counts twice), so it needs no shared ids and works for any pair of
  polylines; it cannot see the direction of travel (the wrong twin of a two-way street lies
  in the corridor).
- :func:`rmf_pieces`: identity. Routes are sequences of directed road pieces (e.g. way id
  and the two junction nodes it runs between) with their lengths; a piece counts as shared
  as often as both routes drive it. It sees direction and repeated passes, but needs both
  routes on the same map.

What is compared (:func:`score_route`):

- corridor: the *driven stretch* of each route, from where the car was at its first fix to
  where it was at its last (the truth from the simulation; the matched route between the
  matched along-route positions of the first and last fix). A matcher cannot know where the
  car was before its first fix, and a drive need not start or end on a junction, so this
  judges only what the fixes can tell;
- pieces: every directed road piece of the route, whole, as in the paper (the true pieces
  from the one under the first fix to the one under the last; the matched route's pieces as
  the road stage turns them into the road's centerline). An extra or missing piece at a
  route end counts its whole length, however little of it was driven.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Hashable, Sequence
from dataclasses import dataclass

import numpy as np
import shapely
import shapely.ops

from vid2sim.geo.alongroute import join_xy
from vid2sim.geo.mapmatch import MatchResult
from vid2sim.geo.osm import RoadNetwork

#: half-width of the corridor within which a matched road counts as on the true route [m]
#: (the issue's 5 m: a lane and a half either side of a way's middle line, so the matched
#: way of the right carriageway lies in it, a parallel road 10+ m away does not)
CORRIDOR_M = 5.0


def _segments(parts: Sequence[np.ndarray]) -> np.ndarray:
    """Every segment of every polyline as its own LineString, zero-length ones dropped.

    Kept apart rather than merged into one geometry: shapely's overlay dissolves a line that
    runs over itself, and a route that drives a street twice must count it twice.
    """
    segs = []
    for part in parts:
        xy = np.asarray(part, float).reshape(-1, 2)
        if not np.isfinite(xy).all():
            raise ValueError("route coordinates must be finite")
        if len(xy) >= 2:
            a, b = xy[:-1], xy[1:]
            keep = np.hypot(*(b - a).T) > 0.0
            segs.append(np.stack([a[keep], b[keep]], axis=1))
    if not segs:
        return np.empty(0, dtype=object)
    pairs = np.concatenate(segs)
    return shapely.linestrings(pairs.reshape(-1, 2), indices=np.repeat(np.arange(len(pairs)), 2))


def _outside_m(segments: np.ndarray, other: np.ndarray, corridor_m: float) -> float:
    """Length of ``segments`` farther than ``corridor_m`` from every segment of ``other``."""
    if not segments.size:
        return 0.0
    if not other.size:
        return float(shapely.length(segments).sum())
    # quad_segs=16: round ends and bends of the corridor within 0.5 % of its half-width
    corridor = shapely.buffer(shapely.union_all(other), corridor_m, quad_segs=16)
    shapely.prepare(corridor)
    return float(shapely.length(shapely.difference(segments, corridor)).sum())


def rmf_corridor(true_xy_m: np.ndarray | Sequence[np.ndarray],
                 matched_xy_m: np.ndarray | Sequence[np.ndarray],
                 corridor_m: float = CORRIDOR_M) -> float:
    """Route mismatch fraction of polylines, "on the route" meaning within ``corridor_m``.

    Parameters
    ----------
    true_xy_m : the true route, an (N, 2) polyline [m] or a list of them (pieces)
    matched_xy_m : the matched route, an (M, 2) polyline [m] or a list of pieces (a matcher
        whose chain broke returns several); an empty list is a route that matched nothing
    corridor_m : half-width of the corridor [m], > 0

    Returns
    -------
    (missed length + extra length) / true length; inf when the true route has no length

    Raises
    ------
    ValueError
        non-finite coordinates or a corridor that is not positive.
    """
    if not corridor_m > 0:
        raise ValueError(f"corridor_m must be positive, got {corridor_m}")
    true = _segments(_as_parts(true_xy_m))
    matched = _segments(_as_parts(matched_xy_m))
    true_len = float(shapely.length(true).sum()) if true.size else 0.0
    if true_len <= 0.0:
        return float("inf")
    missed = _outside_m(true, matched, corridor_m)
    extra = _outside_m(matched, true, corridor_m)
    return (missed + extra) / true_len


def _as_parts(route: np.ndarray | Sequence[np.ndarray]) -> list[np.ndarray]:
    if isinstance(route, np.ndarray) and route.ndim == 2:
        return [route]
    return [np.asarray(p, float) for p in route]


def rmf_pieces(true_pieces: Sequence[Hashable], matched_pieces: Sequence[Hashable],
               length_m: dict[Hashable, float]) -> float:
    """Route mismatch fraction of routes given as sequences of directed road pieces.

    Parameters
    ----------
    true_pieces, matched_pieces : piece keys in travel order (a key may repeat: a loop)
    length_m : length of every key [m], >= 0

    Returns
    -------
    (missed length + extra length) / true length; inf when the true route has no length

    Raises
    ------
    KeyError
        a piece without a length.
    ValueError
        a negative or non-finite length.
    """
    need = Counter(true_pieces)
    got = Counter(matched_pieces)
    for key in need.keys() | got.keys():
        v = length_m[key]
        if not (np.isfinite(v) and v >= 0):
            raise ValueError(f"length of piece {key!r} must be finite and >= 0, got {v}")
    true_len = sum(length_m[k] * c for k, c in need.items())
    if true_len <= 0.0:
        return float("inf")
    missed = sum(length_m[k] * c for k, c in (need - got).items())
    extra = sum(length_m[k] * c for k, c in (got - need).items())
    return float((missed + extra) / true_len)


# --------------------------------------------------------------------------- matched routes


def piece_key(net: RoadNetwork, edge: int) -> tuple[int, int, int]:
    """Map-independent identity of a directed edge: (OSM way id, from node, to node).

    Edge indices differ between two loads of a map (a crop keeps fewer edges); OSM ids do not.
    """
    return int(net.edge_way_id[edge]), int(net.edge_u[edge]), int(net.edge_v[edge])


def stretch_xy(net: RoadNetwork, edges: Sequence[int], start_m: float, end_m: float
               ) -> np.ndarray:
    """The part of the route ``edges`` (joined in travel order) from ``start_m`` to ``end_m``
    along it [m]; (0, 2) when the part has no length."""
    if not len(edges) or not end_m > start_m:
        return np.zeros((0, 2))
    xy = join_xy(net, list(edges))
    xy = xy[np.concatenate([[True], np.hypot(*np.diff(xy, axis=0).T) > 0.0])]
    if len(xy) < 2:
        return np.zeros((0, 2))
    line = shapely.LineString(xy)
    part = shapely.ops.substring(line, max(start_m, 0.0), min(end_m, line.length))
    xy = shapely.get_coordinates(part)
    return xy if len(xy) >= 2 else np.zeros((0, 2))


def matched_stretches(net: RoadNetwork, result: MatchResult) -> list[np.ndarray]:
    """The driven part of each matched route piece: from the matched position of its first fix
    to that of its last fix [m]."""
    out = []
    for k, piece in enumerate(result.route_edges):
        s = result.fix_route_s_m[(result.fix_piece == k) & np.isfinite(result.fix_route_s_m)]
        if s.size:
            xy = stretch_xy(net, piece, float(s.min()), float(s.max()))
            if len(xy):
                out.append(xy)
    return out


@dataclass(frozen=True, slots=True)
class RouteScore:
    """Route mismatch fractions of one matched drive.

    :param rmf_corridor: driven stretches compared within the corridor (see module docs)
    :param rmf_pieces: whole directed road pieces compared by identity
    :param true_length_m: length of the true driven stretch [m]
    """

    rmf_corridor: float
    rmf_pieces: float
    true_length_m: float


def score_route(true_net: RoadNetwork, true_edges: Sequence[int], true_span_m: tuple[float, float],
                match_net: RoadNetwork, result: MatchResult,
                corridor_m: float = CORRIDOR_M) -> RouteScore:
    """Score a match against the truth.

    Parameters
    ----------
    true_net : network the true route is given on
    true_edges : directed edges the car drove, in order, from the one under the first fix to
        the one under the last fix
    true_span_m : along ``true_edges``, the true positions of the first and last fix [m]
    match_net : network the matcher ran on (may be a crop of ``true_net``: pieces are
        compared by OSM way and node ids)
    result : the matcher's output
    """
    true_xy = stretch_xy(true_net, true_edges, *true_span_m)
    corridor = rmf_corridor([true_xy] if len(true_xy) else [], matched_stretches(match_net, result),
                            corridor_m)
    lengths: dict[Hashable, float] = {}
    true_keys = []
    for e in true_edges:
        true_keys.append(piece_key(true_net, e))
        lengths[true_keys[-1]] = float(true_net.edge_length_m[e])
    got_keys = []
    for piece in result.route_edges:
        for e in piece:
            got_keys.append(piece_key(match_net, e))
            lengths[got_keys[-1]] = float(match_net.edge_length_m[e])
    pieces = rmf_pieces(true_keys, got_keys, lengths)
    span = float(np.hypot(*np.diff(true_xy, axis=0).T).sum()) if len(true_xy) else 0.0
    return RouteScore(corridor, pieces, span)
