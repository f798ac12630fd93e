"""The parsed-map cache: a map is parsed once per process and once per file content on disk;
a corrupt, truncated, tampered or stale entry is detected and rebuilt, never trusted."""

from __future__ import annotations

import json
import logging
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.geo.test_osm import NODES, ORIGIN, WAYS, helsinki_pbf, osm_xml
from vid2sim.base.errors import FormatError
from vid2sim.geo import mapcache, osm
from vid2sim.geo.mapcache import cached_map, clear_memory, read_entry
from vid2sim.geo.osm import load_network


@pytest.fixture
def town_file(tmp_path):
    path = tmp_path / "town.osm"
    path.write_text(osm_xml(NODES, WAYS), encoding="utf-8")
    return path


@pytest.fixture
def count_parses(monkeypatch):
    """Counts how often a map file is actually read."""
    calls = []
    real = osm.read_osm

    def counting(path):
        calls.append(path)
        return real(path)

    monkeypatch.setattr(osm, "read_osm", counting)
    clear_memory()
    yield calls
    clear_memory()


def _entry(cache_dir, path):
    (entry,) = (cache_dir / "maps").glob("*.npz")
    assert entry.stem == mapcache.map_sha256(path)
    return entry


def same_network(a, b):
    assert a.n_edges == b.n_edges
    for name in ("edge_u", "edge_v", "edge_way_id", "edge_twin", "edge_along_way"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    np.testing.assert_allclose(a.edge_length_m, b.edge_length_m, rtol=0, atol=1e-9)
    for xa, xb in zip(a.edge_xy, b.edge_xy, strict=True):
        np.testing.assert_allclose(xa, xb, rtol=0, atol=1e-9)
    assert a.edge_tags == b.edge_tags and a.bbox_lonlat == b.bbox_lonlat


def test_parsed_once_per_process_and_once_on_disk(town_file, tmp_path, count_parses):
    cache = tmp_path / "cache"
    first = load_network(town_file, ORIGIN, cache_dir=cache)
    again = load_network(town_file, ORIGIN, cache_dir=cache)
    assert len(count_parses) == 1  # the second load came from memory
    clear_memory()  # a new process: the disk entry is read, the file is not parsed
    from_disk = load_network(town_file, ORIGIN, cache_dir=cache)
    assert len(count_parses) == 1
    same_network(first, again)
    same_network(first, from_disk)
    same_network(first, load_network(town_file, ORIGIN, use_cache=False))


def test_cached_helsinki_equals_a_fresh_parse(tmp_path, count_parses):
    pbf = helsinki_pbf()
    cache = tmp_path / "cache"
    load_network(pbf, ORIGIN, cache_dir=cache)
    clear_memory()
    box = (24.935, 60.160, 24.950, 60.170)
    same_network(load_network(pbf, ORIGIN, cache_dir=cache, bbox_lonlat=box),
                 load_network(pbf, ORIGIN, use_cache=False, bbox_lonlat=box))
    assert len(count_parses) == 2  # the first load and the uncached one


@pytest.mark.parametrize("damage", ["garbage", "truncated", "empty", "tampered", "other_map",
                                    "other_filter", "old_format"])
def test_a_bad_entry_is_rebuilt(town_file, tmp_path, count_parses, caplog, damage):
    cache = tmp_path / "cache"
    good = load_network(town_file, ORIGIN, cache_dir=cache)
    entry = _entry(cache, town_file)
    data = entry.read_bytes()
    if damage == "garbage":
        entry.write_bytes(b"not a cache entry" * 50)
    elif damage == "truncated":
        entry.write_bytes(data[:len(data) // 2])
    elif damage == "empty":
        entry.write_bytes(b"")
    else:
        with np.load(entry) as z:
            files = {k: z[k] for k in z.files}
        meta = json.loads(bytes(files["meta"]).decode())
        if damage == "tampered":  # a node moved, header intact: the checksum catches it
            files["node_lonlat"] = files["node_lonlat"] + 1e-4
        elif damage == "other_map":
            meta["map_sha256"] = "0" * 64
        elif damage == "other_filter":
            meta["config"] = "another filter"
        else:
            meta["format"] = "vid2sim-drivable-map-0"
        files["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
        with open(entry, "wb") as fh:
            np.savez(fh, **files)
    clear_memory()
    with caplog.at_level(logging.WARNING, logger="vid2sim.geo.mapcache"):
        again = load_network(town_file, ORIGIN, cache_dir=cache)
    assert "unusable" in caplog.text and "rebuilding" in caplog.text
    assert len(count_parses) == 2  # parsed again
    same_network(good, again)
    # and the entry was rewritten whole
    assert read_entry(entry, mapcache.map_sha256(town_file), osm._FILTER_DIGEST) is not None


def test_a_changed_map_file_is_not_served_from_the_cache(town_file, tmp_path, count_parses):
    cache = tmp_path / "cache"
    before = load_network(town_file, ORIGIN, cache_dir=cache)
    ways = dict(WAYS)
    del ways[106]  # the Back street goes
    town_file.write_text(osm_xml(NODES, ways), encoding="utf-8")
    after = load_network(town_file, ORIGIN, cache_dir=cache)
    assert 106 in before.edge_way_id and 106 not in after.edge_way_id
    assert len(count_parses) == 2
    assert len(list((cache / "maps").glob("*.npz"))) == 2  # one entry per content


def test_an_unwritable_cache_is_skipped(town_file, tmp_path, count_parses, caplog):
    blocker = tmp_path / "cache"
    blocker.write_text("a file where the cache folder should be")
    with caplog.at_level(logging.WARNING, logger="vid2sim.geo.mapcache"):
        net = load_network(town_file, ORIGIN, cache_dir=blocker)
    assert net.n_edges > 0 and "not written" in caplog.text


def test_bad_maps_are_never_cached(tmp_path, count_parses):
    bad = tmp_path / "broken.osm"
    bad.write_text("<osm><node id='1' lat='60' lon=")
    for _ in range(2):
        with pytest.raises(FormatError):
            load_network(bad, ORIGIN, cache_dir=tmp_path / "cache")
    assert len(count_parses) == 2
    assert not list((tmp_path / "cache").glob("**/*.npz"))


def test_cache_dir_default_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("VID2SIM_CACHE_DIR", str(tmp_path / "v"))
    assert mapcache.default_cache_dir() == tmp_path / "v" / "osm"
    monkeypatch.delenv("VID2SIM_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "x"))
    assert mapcache.default_cache_dir() == tmp_path / "x" / "vid2sim" / "osm"


# --------------------------------------------------------------------------- property


@pytest.fixture(scope="module")
def stored_entry(tmp_path_factory):
    """A valid entry of the town map and what it must read back as."""
    folder = tmp_path_factory.mktemp("entry")
    path = folder / "town.osm"
    path.write_text(osm_xml(NODES, WAYS), encoding="utf-8")
    dmap = osm._parse_map(path)
    entry = folder / "e.npz"
    assert mapcache.write_entry(entry, dmap, "abc", "cfg")
    return entry.read_bytes(), dmap


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_a_damaged_entry_never_reads_as_a_different_map(stored_entry, tmp_path, data):
    raw, dmap = stored_entry
    damaged = bytearray(raw)
    for _ in range(data.draw(st.integers(1, 4))):
        k = data.draw(st.integers(0, len(raw) - 1))
        damaged[k] = data.draw(st.integers(0, 255))
    cut = data.draw(st.integers(1, len(raw)))
    entry = tmp_path / "d.npz"
    entry.write_bytes(bytes(damaged[:cut]))
    got = read_entry(entry, "abc", "cfg")
    if got is not None:  # only a change the zip container ignores may read back, and as is
        for name in mapcache._ARRAYS:
            np.testing.assert_array_equal(getattr(got, name), getattr(dmap, name))
        assert got.way_tags == dmap.way_tags


def test_the_entry_is_a_plain_npz_without_pickles(stored_entry, tmp_path):
    raw, _ = stored_entry
    entry = tmp_path / "e.npz"
    entry.write_bytes(raw)
    with zipfile.ZipFile(entry) as z:
        assert sorted(z.namelist()) == sorted(f"{n}.npy" for n in
                                              (*mapcache._ARRAYS, "tags", "meta"))
    with np.load(entry, allow_pickle=False) as z:
        assert all(z[n].dtype != object for n in z.files)


def test_cached_map_passes_build_errors_through(tmp_path):
    path = tmp_path / "x.osm"
    path.write_text("<osm/>")

    def fail():
        raise FormatError(path, "no ways in this map")

    with pytest.raises(FormatError, match="no ways"):  # the build's own error, class kept
        cached_map(path, fail, cache_dir=tmp_path / "c", config="t")
    assert not (tmp_path / "c").exists()
