"""Start-up cost of the commands (issue 15): what a command imports before its first frame.

    python benchmarks/bench_startup.py [--shared ../shared] [--repeat 5] [--no-track]

1. Each command module in a fresh interpreter: ``vid2sim`` (registers the gym environment),
   ``vid2sim.cli`` (every command parses its options with it), ``vid2sim.app.tracking``
   (``detect``, ``track``), ``vid2sim.app.commands`` (``trace``, ``road``, ``export``,
   ``eval``) and ``vid2sim.app.build``: seconds of the import measured inside the child
   (best of ``--repeat``), modules loaded, and which heavy packages came with it.
2. ``vid2sim track`` on KITTI raw 0001 in a fresh interpreter (the CLI run in-process by the
   child), stopped when the tracker's third update returns: by then the camera and the
   detector are loaded, three frames are decoded and detected and the first assignment has
   loaded scipy.optimize (:func:`vid2sim.core.boxes.match`). Seconds from the interpreter's start
   (read from /proc), best of ``--repeat``, and the heavy packages loaded by then.

Timing on a shared machine is noisy: read the best of several runs, and compare modules in
the same run.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
#: Packages worth naming when a command loads them (0.05-0.5 s each to import after numpy).
HEAVY = ("scipy.optimize", "matplotlib", "networkx", "shapely", "pyproj", "gymnasium",
         "highway_env", "pygame", "pandas", "osmnx", "geopandas", "pyrosm", "sklearn",
         "scenariogeneration", "pyarrow", "ray", "onnxruntime")
MODULES = ("vid2sim", "vid2sim.cli", "vid2sim.app.tracking", "vid2sim.app.commands",
           "vid2sim.app.build")

_IMPORT_CHILD = """
import importlib, json, sys, time
t = time.perf_counter()
importlib.import_module({module!r})
dt = time.perf_counter() - t
print(json.dumps({{"s": dt, "n": len(sys.modules),
                  "heavy": [h for h in {heavy!r} if h in sys.modules]}}))
"""

_TRACK_CHILD = """
import json, os, sys, time

def started_s_ago():
    # the process start in clock ticks since boot (field 22 of /proc/PID/stat)
    ticks = os.sysconf("SC_CLK_TCK")
    start = int(open(f"/proc/{{os.getpid()}}/stat").read().rsplit(")", 1)[1].split()[19])
    return float(open("/proc/uptime").read().split()[0]) - start / ticks

T0 = time.time() - started_s_ago()
import vid2sim.cli as cli
t_cli = time.time() - T0
from vid2sim.detect.tracking.tracker import Tracker  # imported by the track command anyway

class Stop(Exception):
    pass

update, calls = Tracker.update, []
def counted(self, *a, **k):
    out = update(self, *a, **k)
    calls.append(1)
    if len(calls) >= 3:
        raise Stop(time.time() - T0)
    return out
Tracker.update = counted
try:
    cli.cli.main(args={args!r}, prog_name="vid2sim", standalone_mode=False)
    raise SystemExit("the track command finished before three tracker updates")
except Stop as stop:
    print(json.dumps({{"cli_s": t_cli, "s": stop.args[0], "n": len(sys.modules),
                      "heavy": [h for h in {heavy!r} if h in sys.modules]}}))
"""


def _child(code: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=env, cwd="/", timeout=600, check=False)
    if proc.returncode != 0:
        raise SystemExit(proc.stderr[-2000:])
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _best(runs: list[dict]) -> dict:
    return min(runs, key=lambda r: r["s"])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--shared", type=Path, default=SHARED)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--no-track", action="store_true", help="Only the import figures.")
    args = ap.parse_args()

    print(f"{'module':24s} {'import s':>8s} {'modules':>7s}  heavy packages loaded")
    for module in MODULES:
        best = _best([_child(_IMPORT_CHILD.format(module=module, heavy=HEAVY))
                      for _ in range(args.repeat)])
        print(f"{module:24s} {best['s']:8.2f} {best['n']:7d}  {' '.join(best['heavy']) or '-'}")
    if args.no_track:
        return
    raw = args.shared / "data" / "kitti_raw_0001"
    if not (raw / "video.mp4").exists():
        raise SystemExit(f"KITTI raw 0001 not found under {raw} (--shared)")
    out = Path("/tmp") / f"bench_startup_{os.getpid()}.csv"
    cli_args = ["-q", "track", str(raw / "video.mp4"), "--camera", str(raw / "camera.yaml"),
                "--out", str(out)]
    best = _best([_child(_TRACK_CHILD.format(args=cli_args, heavy=HEAVY))
                  for _ in range(args.repeat)])
    out.unlink(missing_ok=True)
    print(f"\nvid2sim track, KITTI raw 0001, best of {args.repeat}: CLI imported "
          f"{best['cli_s']:.2f} s, third tracker update done {best['s']:.2f} s after the "
          f"interpreter started; {best['n']} modules; heavy: {' '.join(best['heavy']) or '-'}")


if __name__ == "__main__":
    main()
