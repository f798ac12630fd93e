"""Atomic writes: outputs appear whole, with the permissions of an ordinary new file."""

from __future__ import annotations

import os
import stat

import pytest

from vid2sim.fileio import write_text_atomic


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
