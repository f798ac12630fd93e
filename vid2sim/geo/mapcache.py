"""The parsed form of a map file, kept in memory and on disk so a map is parsed once.

Reading an OSM extract (pyrosm or osmnx, then the drivable filter and the split at
junctions) costs far more than matching a drive on it: about 0.7 s for pyrosm's 0.7 MB
Helsinki extract before pyrosm's own imports, against about 0.05 s per km of matching. The
result, a :class:`DrivableMap` (lon/lat pieces, independent of the scenario's origin), is

- kept in memory for the life of the process (the last :data:`MEMO_MAPS` maps), and
- written to ``<cache dir>/maps/<sha256 of the map file>.npz`` (numpy arrays only, never
  pickles), with a header naming the cache format, the map's sha256, the drivable filter it
  was built with, and a sha256 of the arrays. An entry whose header or checksum does not
  match, that does not load, or whose arrays are not a consistent set of pieces is logged
  and rebuilt; a cache that cannot be written is logged and skipped. The run never fails
  because of the cache.

The cache folder is ``cache_dir`` when given, else ``$VID2SIM_CACHE_DIR/osm``, else
``$XDG_CACHE_HOME/vid2sim/osm``, else ``~/.cache/vid2sim/osm`` (the same folder osmnx keeps
its downloads in; the parsed maps live in its ``maps`` sub-folder).
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from vid2sim.base.fileio import atomic_open, sha256_file

log = logging.getLogger(__name__)

#: version of the file layout below; bump it when the arrays or their meaning change
CACHE_FORMAT = "vid2sim-drivable-map-1"
#: maps kept in memory per process (a batch run matches many drives on one or two maps)
MEMO_MAPS = 4

_ARRAYS = ("node_id", "node_lonlat", "piece_way", "piece_ptr", "piece_node")


@dataclass(slots=True)
class DrivableMap:
    """The drivable way pieces of a map in lon/lat: what does not depend on the scenario's
    origin, so it is built once per map file and cached (:mod:`vid2sim.geo.mapcache`).

    Piece ``k`` is part of way ``piece_way[k]`` between two junctions (or way ends), running
    in way node order through nodes ``node_id[piece_node[piece_ptr[k]:piece_ptr[k + 1]]]``.

    :param node_id: OSM node ids, sorted (N,)
    :param node_lonlat: their (lon, lat) [deg] (N, 2)
    :param piece_way: OSM way id of each piece (P,)
    :param piece_ptr: offsets of each piece's nodes in ``piece_node`` (P + 1,)
    :param piece_node: indices into ``node_id``
    :param way_tags: the kept tags (:data:`KEPT_TAGS`) of every way with a piece
    """

    node_id: np.ndarray
    node_lonlat: np.ndarray
    piece_way: np.ndarray
    piece_ptr: np.ndarray
    piece_node: np.ndarray
    way_tags: dict[int, dict[str, str]]

    @property
    def n_pieces(self) -> int:
        return int(self.piece_way.size)

    def bbox_lonlat(self) -> tuple[float, float, float, float]:
        """(west, south, east, north) of all pieces [deg]."""
        used = self.node_lonlat[np.unique(self.piece_node)]
        return (float(used[:, 0].min()), float(used[:, 1].min()),
                float(used[:, 0].max()), float(used[:, 1].max()))




# --------------------------------------------------------------------------- folder


def default_cache_dir() -> Path:
    """The map cache folder when none is given (see the module docs)."""
    root = os.environ.get("VID2SIM_CACHE_DIR")
    if root:
        return Path(root) / "osm"
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / "vid2sim" / "osm"


# --------------------------------------------------------------------------- entry points

_memo: OrderedDict[tuple[str, str], DrivableMap] = OrderedDict()
_sha_memo: dict[tuple[str, int, int, int], str] = {}


def map_sha256(path: Path) -> str:
    """sha256 of a map file, remembered per (path, size, mtime, inode): a file rewritten in
    place is hashed again."""
    st = path.stat()
    key = (str(path.resolve()), st.st_size, st.st_mtime_ns, st.st_ino)
    if key not in _sha_memo:
        _sha_memo[key] = sha256_file(path)
    return _sha_memo[key]


def cached_map(path: Path, build: Callable[[], DrivableMap], *,
               cache_dir: str | Path | None = None, config: str = "") -> DrivableMap:
    """The drivable map of ``path``: from memory, else from the disk cache, else ``build()``
    (then stored in both).

    Parameters
    ----------
    path : the map file (its sha256 is the key)
    build : parses the file; its errors (InputError) pass through and nothing is cached
    cache_dir : cache folder (default :func:`default_cache_dir`)
    config : everything besides the file that ``build`` depends on (the drivable filter);
        an entry built with another ``config`` is stale
    """
    sha = map_sha256(path)
    key = (sha, config)
    if key in _memo:
        _memo.move_to_end(key)
        return _memo[key]
    folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    entry = folder / "maps" / f"{sha}.npz"
    dmap = read_entry(entry, sha, config) if entry.exists() else None
    if dmap is None:
        dmap = build()
        write_entry(entry, dmap, sha, config)
    _memo[key] = dmap
    while len(_memo) > MEMO_MAPS:
        _memo.popitem(last=False)
    return dmap


def clear_memory() -> None:
    """Forget the maps kept in memory (the next load reads the disk cache): for tests and
    for benchmarks that time a fresh process's first load."""
    _memo.clear()
    _sha_memo.clear()


# --------------------------------------------------------------------------- files


def _payload_sha256(arrays: dict[str, np.ndarray], tags_json: bytes) -> str:
    digest = hashlib.sha256()
    for name in _ARRAYS:
        a = np.ascontiguousarray(arrays[name])
        digest.update(f"{name}:{a.dtype.str}:{a.shape}".encode())
        digest.update(a.tobytes())
    digest.update(tags_json)
    return digest.hexdigest()


def write_entry(entry: Path, dmap: DrivableMap, sha: str, config: str) -> bool:
    """Store ``dmap`` atomically at ``entry``; False (and a log line) when it cannot be."""
    arrays = {name: getattr(dmap, name) for name in _ARRAYS}
    tags_json = json.dumps({str(k): v for k, v in dmap.way_tags.items()},
                           sort_keys=True).encode()
    meta = {"format": CACHE_FORMAT, "map_sha256": sha, "config": config,
            "payload_sha256": _payload_sha256(arrays, tags_json)}
    try:
        with atomic_open(entry, "wb") as fh:
            np.savez(fh, **arrays, tags=np.frombuffer(tags_json, dtype=np.uint8),
                     meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))
    except OSError as exc:
        log.warning("map cache %s not written (%s); the map will be parsed again next time",
                    entry, exc)
        return False
    return True


def read_entry(entry: Path, sha: str, config: str) -> DrivableMap | None:
    """The map stored at ``entry`` if it is whole and was built from the file with sha256
    ``sha`` under ``config``; else None (and a log line saying why)."""
    try:
        with np.load(entry, allow_pickle=False) as z:
            files = {name: z[name] for name in z.files}
        meta = json.loads(bytes(files["meta"]).decode())
        tags_json = bytes(files["tags"])
        arrays = {name: files[name] for name in _ARRAYS}
        problem = _check_meta(meta, sha, config)
        if problem is None and meta["payload_sha256"] != _payload_sha256(arrays, tags_json):
            problem = "checksum mismatch"
        if problem is None:
            tags = {int(k): {str(a): str(b) for a, b in v.items()}
                    for k, v in json.loads(tags_json.decode()).items()}
            dmap = DrivableMap(**arrays, way_tags=tags)
            problem = _check_arrays(dmap)
    except Exception as exc:  # noqa: BLE001 - any unreadable entry is rebuilt, never trusted
        problem = f"unreadable: {type(exc).__name__}: {exc}"
    if problem is not None:
        log.warning("map cache entry %s is unusable (%s); rebuilding it", entry, problem)
        return None
    return dmap


def _check_meta(meta: object, sha: str, config: str) -> str | None:
    if not isinstance(meta, dict):
        return "no header"
    if meta.get("format") != CACHE_FORMAT:
        return f"format {meta.get('format')!r}, expected {CACHE_FORMAT!r}"
    if meta.get("map_sha256") != sha:
        return "built from another map file"
    if meta.get("config") != config:
        return "built with another drivable-road filter"
    return None


def _check_arrays(d: DrivableMap) -> str | None:
    """Why the arrays are not a consistent set of pieces, or None."""
    n, p = d.node_id.size, d.piece_way.size
    if d.node_id.dtype != np.int64 or d.node_id.ndim != 1 or n == 0:
        return "bad node ids"
    if np.any(np.diff(d.node_id) <= 0):
        return "node ids not sorted"
    ll = d.node_lonlat
    if ll.dtype != np.float64 or ll.shape != (n, 2) or not np.isfinite(ll).all() \
            or np.abs(ll[:, 0]).max() > 180 or np.abs(ll[:, 1]).max() > 90:
        return "bad node coordinates"
    ptr = d.piece_ptr
    if ptr.dtype != np.int64 or ptr.shape != (p + 1,) or p == 0 or ptr[0] != 0 \
            or ptr[-1] != d.piece_node.size or np.any(np.diff(ptr) < 2):
        return "bad piece offsets"
    if d.piece_node.dtype != np.int64 or d.piece_node.min() < 0 or d.piece_node.max() >= n:
        return "piece node index out of range"
    if not set(d.piece_way.tolist()) <= set(d.way_tags):
        return "way tags missing"
    return None
