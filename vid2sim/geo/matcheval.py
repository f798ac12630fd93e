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
  ``corridor_m`` of its polyline (shapely buffer + difference), so it needs no shared ids
  and works for any pair of polylines; it cannot see the direction of travel (the wrong twin
  of a two-way street lies in the corridor).
- :func:`rmf_pieces`: identity. Routes are sequences of directed road pieces (e.g. way id
  and the two junction nodes it runs between) with their lengths; a piece counts as shared
  as often as both routes drive it. It sees direction and repeated passes, but needs both
  routes on the same map.

Routes are compared as whole road pieces, as in the paper: the true route is every road
piece the car drove on between its first and last fix, the matched route every piece the
matcher put in its route (the road stage's centerline), so a perfect match scores 0 and an
extra or missing piece at a route end counts its whole length.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Hashable, Sequence

import numpy as np
import shapely

#: half-width of the corridor within which a matched road counts as on the true route [m]
#: (the issue's 5 m: a lane and a half either side of a way's middle line, so the matched
#: way of the right carriageway lies in it, a parallel road 10+ m away does not)
CORRIDOR_M = 5.0


def _line(xy_m: np.ndarray) -> shapely.LineString | None:
    """A LineString of the distinct consecutive points, None when shorter than 2 points."""
    xy = np.asarray(xy_m, float).reshape(-1, 2)
    if not np.isfinite(xy).all():
        raise ValueError("route coordinates must be finite")
    if len(xy) >= 2:
        keep = np.concatenate([[True], np.hypot(*np.diff(xy, axis=0).T) > 0.0])
        xy = xy[keep]
    return shapely.LineString(xy) if len(xy) >= 2 else None


def _multi(parts: Sequence[np.ndarray]) -> shapely.Geometry | None:
    lines = [g for g in (_line(p) for p in parts) if g is not None]
    if not lines:
        return None
    return lines[0] if len(lines) == 1 else shapely.MultiLineString(lines)


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
    true = _multi(_as_parts(true_xy_m))
    matched = _multi(_as_parts(matched_xy_m))
    true_len = 0.0 if true is None else float(true.length)
    if true_len <= 0.0:
        return float("inf")
    if matched is None:
        return 1.0
    # quad_segs=16: the round ends and bends of the buffer are within 0.5 % of the radius
    missed = shapely.difference(true, shapely.buffer(matched, corridor_m, quad_segs=16))
    extra = shapely.difference(matched, shapely.buffer(true, corridor_m, quad_segs=16))
    return (float(missed.length) + float(extra.length)) / true_len


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
