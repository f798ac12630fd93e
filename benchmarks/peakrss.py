"""A process's own peak resident memory, as the benchmarks report it.

``ru_maxrss`` (``getrusage``, ``wait4``) is not that figure on Linux: at ``exec`` the kernel
keeps the larger of the new program's peak and the peak of the memory it replaced
(``setmax_mm_hiwater_rss`` in ``exec_mmap``), and a child started by ``subprocess`` or by a
spawning ``multiprocessing`` context replaces a copy of its parent. A benchmark that has held
500 MiB of frames therefore reads 500 MiB for every command it starts afterwards. ``VmHWM``
in ``/proc/<pid>/status`` is the high-water mark of the process's own address space, so it
starts afresh at ``exec``.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

PEAK_FILE_ENV = "VID2SIM_BENCH_PEAK_FILE"

#: Runs ``python -m vid2sim ARGS`` and, at exit (also on SystemExit), writes its VmHWM [KiB].
_CHILD = (
    "import atexit, os, runpy, sys\n"
    "def _peak():\n"
    "    with open('/proc/self/status') as f:\n"
    "        kib = next(int(l.split()[1]) for l in f if l.startswith('VmHWM:'))\n"
    f"    with open(os.environ['{PEAK_FILE_ENV}'], 'w') as out:\n"
    "        out.write(str(kib))\n"
    "atexit.register(_peak)\n"
    "sys.argv = ['vid2sim', *sys.argv[1:]]\n"
    "runpy.run_module('vid2sim', run_name='__main__', alter_sys=True)\n"
)


def own_peak_mib() -> float:
    """This process's own peak resident memory [MiB] (``VmHWM``)."""
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmHWM in /proc/self/status (not Linux?)")


class VidCommand:
    """``argv`` and ``env`` for a ``vid2sim`` command whose own peak RSS is read after it
    exits (:meth:`peak_mib`)."""

    def __init__(self, args: list[str], env: dict | None = None):
        fd, name = tempfile.mkstemp(prefix="vid2sim-peak-", suffix=".txt")
        os.close(fd)
        self.peak_file = Path(name)
        self.argv = [sys.executable, "-c", _CHILD, *args]
        self.env = {**(env if env is not None else os.environ), PEAK_FILE_ENV: name}

    def peak_mib(self) -> float:
        """The command's own peak RSS [MiB]; NaN if it did not write it (killed)."""
        try:
            text = self.peak_file.read_text().strip()
        finally:
            self.peak_file.unlink(missing_ok=True)
        return int(text) / 1024.0 if text else float("nan")
