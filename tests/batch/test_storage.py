"""Shared storage through fsspec: memory:// as an object store without rename, file:// URLs."""

from __future__ import annotations

import dataclasses
import os
import uuid
from pathlib import Path

import fsspec
import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.batch.conftest import MANIFEST, offline
from vid2sim.app.batch import RowTask, read_manifest, run_row, storage
from vid2sim.app.batch.driver import plan_row
from vid2sim.app.batch.hashing import HashCache, HashEntry, hash_inputs
from vid2sim.app.batch.index import RowOutcome, index_record, read_index, write_index
from vid2sim.app.batch.manifest import BatchRow
from vid2sim.base.errors import InputError
from vid2sim.base.fileio import sha256_path

SAMPLE_FILES = ("demo.mp4", "demo.gpx", "camera.yaml", "detections.txt", "keyframes.json",
                "broken.mp4", "nofix.gpx")


@pytest.fixture()
def bucket(clip) -> str:
    """A fresh memory:// "bucket" holding the clip's files and the acceptance manifest."""
    root = f"memory://bucket-{uuid.uuid4().hex[:8]}"
    fs = fsspec.filesystem("memory")
    for name in SAMPLE_FILES:
        fs.pipe_file(f"{root}/in/{name}", (clip / name).read_bytes())
    fs.pipe_file(f"{root}/in/manifest.csv", MANIFEST.encode())
    yield root
    fs.rm(root, recursive=True)


def test_a_url_manifest_resolves_its_rows_against_its_own_url(bucket):
    rows = read_manifest(f"{bucket}/in/manifest.csv")
    assert [r.name for r in rows] == ["full", "plain", "bad", "nogps"]
    assert rows[0].video == f"{bucket}/in/demo.mp4"
    assert rows[0].gps == f"{bucket}/in/demo.gpx" and rows[1].gps is None


def test_a_url_manifest_checks_its_files_exist(bucket):
    fs = fsspec.filesystem("memory")
    fs.pipe_file(f"{bucket}/in/m2.csv", b"video,name\ndemo.mp4,a\nmissing.mp4,b\n")
    with pytest.raises(InputError, match="line 3: no such video file missing.mp4"):
        read_manifest(f"{bucket}/in/m2.csv")


def test_a_row_from_and_to_memory_urls_equals_the_local_build(bucket, clip, tmp_path):
    """The worker downloads URL inputs, builds locally, uploads: the same scenario.json."""
    url_row = read_manifest(f"{bucket}/in/manifest.csv")[0]
    local_row = read_manifest(clip / "manifest.csv")[0]
    out_url = f"{bucket}/out"
    remote = run_row(RowTask(url_row, offline(), out_url))
    local = run_row(RowTask(local_row, offline(), tmp_path))
    assert remote.status == local.status == "ok", (remote.error, local.error)
    fs = fsspec.filesystem("memory")
    for file in ("scenario.json", "tracks.csv", "scenario.xosc"):
        assert fs.cat_file(f"{out_url}/full/{file}") == (tmp_path / "full" / file).read_bytes()
    assert fs.exists(f"{out_url}/full/report.html") and fs.exists(f"{out_url}/full/metrics.json")
    assert remote.sha256 == local.sha256
    assert remote.sha256["video"] == sha256_path(clip / "demo.mp4")
    # The cache entries name the URLs and carry the object store's stamp.
    assert set(remote.hash_entries) == {str(w) for w in url_row.sources().values()}


def test_upload_puts_scenario_json_last_and_replaces_the_old_objects(tmp_path):
    local = tmp_path / "row"
    (local / "figures").mkdir(parents=True)
    for name in ("scenario.json", "report.html", "tracks.csv", "figures/a.png"):
        (local / name).write_text(name, encoding="utf-8")
    root = f"memory://up-{uuid.uuid4().hex[:8]}"
    fs = fsspec.filesystem("memory")
    fs.pipe_file(f"{root}/row/stale.json", b"old")
    order: list[str] = []
    put = fs.put_file
    fs.put_file = lambda lpath, rpath, **kw: (order.append(Path(rpath).name), put(lpath, rpath,
                                                                                  **kw))
    try:
        storage.upload_folder(local, f"{root}/row")
    finally:
        del fs.put_file
    assert order[-2:] == ["report.html", "scenario.json"]
    assert not fs.exists(f"{root}/row/stale.json")
    assert fs.cat_file(f"{root}/row/figures/a.png") == b"figures/a.png"
    fs.rm(root, recursive=True)


def test_index_round_trip_through_a_url(bucket, clip):
    rows = read_manifest(clip / "manifest.csv")
    outcomes = [RowOutcome(name=r.name, status="ok", line=r.line, f1=0.5, attempts=1,
                           sha256={"video": "ab"}, stage_s={"stage_x_s": 1.5}) for r in rows]
    write_index(f"{bucket}/idx", [index_record(r, o) for r, o in zip(rows, outcomes,
                                                                     strict=True)])
    back = read_index(f"{bucket}/idx")
    assert list(back) == [r.name for r in rows]
    assert back["full"].f1 == 0.5 and back["full"].stage_s == {"stage_x_s": 1.5}
    assert back["full"].sha256 == {"video": "ab"}


def test_sha256_of_a_url_folder_equals_the_local_folder_hash(tmp_path):
    (tmp_path / "seq" / "sub").mkdir(parents=True)
    (tmp_path / "seq" / "000001.png").write_bytes(b"one")
    (tmp_path / "seq" / "sub" / "x.txt").write_bytes(b"two")
    root = f"memory://h-{uuid.uuid4().hex[:8]}"
    fs = fsspec.filesystem("memory")
    fs.put(str(tmp_path / "seq") + "/", f"{root}/seq", recursive=True)
    assert storage.sha256_of(f"{root}/seq") == sha256_path(tmp_path / "seq")
    assert storage.sha256_of(f"{root}/seq/000001.png") == sha256_path(tmp_path / "seq/000001.png")
    fs.rm(root, recursive=True)


# --------------------------------------------------------------------------- the hash cache


def test_the_cache_answers_while_size_and_mtime_hold_and_rehashes_after(tmp_path, monkeypatch):
    video = tmp_path / "v.mp4"
    video.write_bytes(b"x" * 1000)
    calls: list = []
    real = storage.sha256_of
    monkeypatch.setattr(storage, "sha256_of", lambda w: (calls.append(w), real(w))[1])
    hashes, entries = hash_inputs({"video": video}, {})
    assert len(calls) == 1 and hashes["video"] == sha256_path(video)
    again, _ = hash_inputs({"video": video}, entries)
    assert len(calls) == 1 and again == hashes, "cached"
    st_ = video.stat()
    video.write_bytes(b"y" * 1000)  # same size, new content ...
    os.utime(video, ns=(st_.st_atime_ns, st_.st_mtime_ns + 10**9))  # ... and a later mtime
    changed, _ = hash_inputs({"video": video}, entries)
    assert len(calls) == 2 and changed["video"] == sha256_path(video) != hashes["video"]


def test_a_folder_stamp_changes_when_a_file_inside_is_rewritten(tmp_path):
    (tmp_path / "seq").mkdir()
    frame = tmp_path / "seq" / "000000.png"
    frame.write_bytes(b"a")
    before = storage.stat_key(tmp_path / "seq")
    os.utime(frame, ns=(0, frame.stat().st_mtime_ns + 10**9))
    assert storage.stat_key(tmp_path / "seq") != before


def test_done_rows_need_no_hash_when_the_cache_knows_them(clip, tmp_path, monkeypatch):
    row = BatchRow(line=2, name="p", video=clip / "demo.mp4", detections=clip / "detections.txt")
    first = run_row(RowTask(row, offline(), tmp_path))
    cache = HashCache(first.hash_entries)
    monkeypatch.setattr(storage, "sha256_of", lambda w: pytest.fail(f"hashed {w}"))
    monkeypatch.setattr("vid2sim.base.fileio.sha256_file", lambda p: pytest.fail(f"hashed {p}"))
    first.status = "ok"
    planned = plan_row(row, tmp_path, first, cache, retry_failed=False, settings=offline())
    assert planned is not None and planned.status == "skipped"
    # Without an index record the row folder's scenario.json decides, still without hashing.
    planned = plan_row(row, tmp_path, None, cache, retry_failed=False, settings=offline())
    assert planned is not None and planned.status == "skipped"
    # Without cache entries the driver cannot tell: a worker must look (None).
    assert plan_row(row, tmp_path, first, HashCache(), retry_failed=False,
                    settings=offline()) is None
    # Other settings (any number of the tree): the row is built again, with or without record.
    other = dataclasses.replace(offline(), tracker=dataclasses.replace(
        offline().tracker, min_hits=offline().tracker.min_hits + 1))
    assert plan_row(row, tmp_path, first, cache, retry_failed=False, settings=other) is None
    assert plan_row(row, tmp_path, None, cache, retry_failed=False, settings=other) is None


_paths = st.text(st.characters(codec="utf-8", exclude_characters="\r\n\x00"), min_size=1,
                 max_size=40)
_entries = st.builds(HashEntry, st.integers(0, 2**62),
                     st.text(st.characters(codec="utf-8", exclude_characters="\r\n\x00"),
                             max_size=30),
                     st.text("0123456789abcdef", min_size=64, max_size=64))


@given(st.dictionaries(_paths, _entries, max_size=8))
def test_the_hash_cache_file_round_trips(entries):
    where = f"memory://cache-{uuid.uuid4().hex}/hashes.csv"
    cache = HashCache()
    for path, entry in entries.items():
        cache.add(path, entry)
    cache.save(where)
    assert HashCache.load(where).entries == entries
    storage.remove(storage.parent(where))


def test_an_unreadable_cache_is_an_empty_cache(tmp_path):
    (tmp_path / "hashes.csv").write_text("path,size_bytes\nx,notanumber\n", encoding="utf-8")
    assert HashCache.load(tmp_path / "hashes.csv").entries == {}
    assert HashCache.load(tmp_path / "absent.csv").entries == {}


# --------------------------------------------------------------------------- locations


@given(st.lists(st.text("abcdefghijklmnopqrstuvwxyz0123456789_-.", min_size=1, max_size=12)
                .filter(lambda s: s not in (".", "..")), min_size=1, max_size=4),
       st.sampled_from(["s3", "gs", "memory"]))
def test_url_locations_join_and_split(parts, protocol):
    base = f"{protocol}://bucket"
    where = storage.join(base, *parts)
    assert storage.location(where + "/") == where
    assert storage.name(where) == parts[-1]
    assert storage.parent(where) == storage.join(base, *parts[:-1])
    assert storage.is_url(where) and not storage.is_url(Path(where))


def test_file_urls_are_local_paths():
    assert storage.location("file:///data/drives") == Path("/data/drives")
    assert storage.location("/data/x") == Path("/data/x")
    assert storage.location("s3://b/k/") == "s3://b/k"
    assert not storage.is_url("file:///x") and storage.is_url("gs://b/x")


def test_an_unknown_protocol_is_an_input_error():
    with pytest.raises(InputError, match="cannot open this URL"):
        storage.exists("nosuchprotocol://bucket/x")
