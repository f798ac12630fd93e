"""The code base passes ruff (the linter of the dev extra), so style problems fail CI."""

from __future__ import annotations

import shutil
import subprocess
import sys

from tests.conftest import REPO


def test_ruff_finds_nothing():
    if shutil.which("ruff") is None:
        cmd = [sys.executable, "-m", "ruff"]
    else:
        cmd = ["ruff"]
    proc = subprocess.run([*cmd, "check", "--no-cache", "vid2sim", "tests",
                           "benchmarks"], cwd=REPO, capture_output=True, text=True, check=False)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
