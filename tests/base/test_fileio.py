"""Atomic writes: outputs appear whole, with the permissions of an ordinary new file."""

from __future__ import annotations

import errno
import os
import stat
from pathlib import Path

import pytest

from vid2sim.base.errors import FormatError, InputError, ScenarioError
from vid2sim.base.fileio import (
    STAGING_PREFIX,
    parse_json,
    read_input_text,
    staged_folder,
    write_text_atomic,
)


@pytest.mark.skipif(os.name != "posix", reason="POSIX permission bits")
def test_atomic_output_gets_umask_permissions_not_0600(tmp_path):
    old = os.umask(0o022)
    try:
        out = tmp_path / "scenario.json"
        write_text_atomic(out, "{}\n")
    finally:
        os.umask(old)
    assert stat.S_IMODE(out.stat().st_mode) == 0o644
    assert out.read_text() == "{}\n"
    assert [p.name for p in tmp_path.iterdir()] == ["scenario.json"]


# --------------------------------------------------------------------------- staged folders


def _tree(root):
    return {str(p.relative_to(root)): (None if p.is_dir() else p.read_text())
            for p in sorted(root.rglob("*"))}


def test_staged_folder_replaces_owned_outputs_and_keeps_the_rest(tmp_path):
    out = tmp_path / "out"
    (out / "keyframes").mkdir(parents=True)
    (out / "keyframes" / "0.png").write_text("old overlay")
    (out / "metrics.json").write_text("old metrics")
    (out / "scenario.json").write_text("old scenario")
    (out / "mine.txt").write_text("the user's")
    with staged_folder(out, owned=("scenario.json", "metrics.json", "keyframes")) as staging:
        assert staging.parent == out.resolve() and staging.name.startswith(STAGING_PREFIX)
        (staging / "scenario.json").write_text("new scenario")
        (staging / "figures").mkdir()
        (staging / "figures" / "a.png").write_text("new figure")
    assert _tree(out) == {"figures": None, "figures/a.png": "new figure",
                          "mine.txt": "the user's", "scenario.json": "new scenario"}


def test_staged_folder_new_output_appears_whole_and_failure_leaves_nothing(tmp_path):
    out = tmp_path / "a" / "b" / "out"
    with pytest.raises(RuntimeError), staged_folder(out) as staging:
        (staging / "scenario.json").write_text("half")
        raise RuntimeError("a stage failed")
    assert list(tmp_path.iterdir()) == []
    with staged_folder(out) as staging:
        assert staging.parent == tmp_path  # the nearest existing folder: out's filesystem
        (staging / "scenario.json").write_text("whole")
    assert _tree(tmp_path / "a") == {"b": None, "b/out": None,
                                     "b/out/scenario.json": "whole"}


def test_staged_folder_failure_keeps_the_old_outputs(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "scenario.json").write_text("old")
    before = _tree(tmp_path)
    with pytest.raises(KeyboardInterrupt), staged_folder(out, owned=("scenario.json",)) as st:
        (st / "scenario.json").write_text("new")
        raise KeyboardInterrupt
    assert _tree(tmp_path) == before


def test_staged_folder_copies_where_a_rename_crosses_filesystems(tmp_path, monkeypatch):
    # EXDEV from rename (another filesystem, overlayfs folders): copied beside, then renamed.
    out = tmp_path / "out"
    (out / "figures").mkdir(parents=True)
    (out / "figures" / "old.png").write_text("old")
    real_replace = os.replace

    def replace(src, dst):
        if Path(src).parent.name.startswith(STAGING_PREFIX):  # out of the staging folder
            raise OSError(errno.EXDEV, "Invalid cross-device link")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    monkeypatch.setattr(os, "rename", lambda s, d: (_ for _ in ()).throw(
        OSError(errno.EXDEV, "Invalid cross-device link")))
    with staged_folder(out, owned=("figures",)) as staging:
        (staging / "scenario.json").write_text("new")
        (staging / "figures").mkdir()
        (staging / "figures" / "new.png").write_text("new")
    assert _tree(out) == {"figures": None, "figures/new.png": "new", "scenario.json": "new"}


def test_errors_inside_staging_name_the_final_output(tmp_path):
    out = tmp_path / "out"
    with pytest.raises(ScenarioError) as e, staged_folder(out) as staging:
        raise ScenarioError(staging / "scenario.json", "roads[0].lanes", "must be 1-16")
    assert e.value.path == str(out / "scenario.json") and e.value.field == "roads[0].lanes"
    assert str(out / "scenario.json") in str(e.value)


def test_read_input_text_refuses_binary_and_parse_json_deep_nesting(tmp_path):
    f = tmp_path / "x.csv"
    f.write_bytes(b"frame,x\n0,\x001\n")
    with pytest.raises(FormatError, match="character 10"):  # where the NUL byte is
        read_input_text(f)
    f.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(FormatError, match="byte 0"):  # not UTF-8 from the first byte
        read_input_text(f)
    with pytest.raises(InputError, match="limit"):  # a size limit: no named class fits
        read_input_text(f, max_bytes=2)
    with pytest.raises(FormatError, match="deep.json"):  # nested too deeply to parse
        parse_json("[" * 100_000 + "]" * 100_000, "deep.json")
