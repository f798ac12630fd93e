"""Before/after speed of two versions of vid2sim on KITTI raw 0001, run in turn (issue 15).

    python benchmarks/bench_compare.py BASE [NEW] [--rounds 3] [--shared ../shared]

BASE and NEW are git commits of this repository (NEW defaults to the working tree). Each is
exported with ``git archive`` into a temporary folder and run from there (``PYTHONPATH``), in
turn, ``--rounds`` times: on a shared machine the load drifts over minutes, so only runs made
side by side compare. Per version and round:

* ``detect_and_range`` in a fresh interpreter (detector loaded and warmed up first, then two
  runs on the clip): wall, CPU of all threads, and wall over the decode time of the same
  moment;
* ``vid2sim track`` and ``vid2sim build`` (GPS, camera, no map) as commands: wall, CPU (user
  + system), peak RSS.

Printed: every run, then the best of each figure per version and the ratios new / base.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from peakrss import VidCommand

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"

# Runs in the version's own interpreter: only names that have been in vid2sim.detect since the
# keyframe schedule (detect_and_range, load_detector_for, load_camera, iter_frames).
IN_PROCESS = r"""
import os, sys, time
from pathlib import Path
import vid2sim
assert vid2sim.__file__.startswith(os.getcwd()), vid2sim.__file__  # the exported tree
from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.app.loaders import load_detector_for
from vid2sim.core.camera import load_camera
from vid2sim.detect.pipeline import detect_and_range
from vid2sim.detect.video import iter_frames
raw, models = Path(sys.argv[1]), Path(sys.argv[2])
s = Settings(detector=DetectorSettings(model_dir=models), progress=False, allow_download=False)
det = load_detector_for(s)
cam = load_camera(raw / "camera.yaml")
run = lambda: detect_and_range(raw / "video.mp4", cam, detector=det, progress=False,
                               schedule=s.detector.schedule())
run()
for _ in range(2):
    t0 = time.perf_counter()
    for _f in iter_frames(raw / "video.mp4"):
        pass
    dec = time.perf_counter() - t0
    w0, c0 = time.perf_counter(), time.process_time()
    run()
    w, c = time.perf_counter() - w0, time.process_time() - c0
    print(f"{w:.3f} {c:.3f} {w / dec:.2f}")
"""


def export(commit: str | None, into: Path) -> Path:
    """The tree of ``commit`` (None: the working tree as it is) in ``into``."""
    into.mkdir(parents=True)
    if commit is None:
        files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "vid2sim"],
                               cwd=REPO, check=True, capture_output=True, text=True).stdout
        subprocess.run(["tar", "cf", str(into / "t.tar"), *files.split()], cwd=REPO,
                       check=True)
    else:
        subprocess.run(["git", "archive", "-o", str(into / "t.tar"), commit, "vid2sim"],
                       cwd=REPO, check=True, stderr=subprocess.DEVNULL)
    subprocess.run(["tar", "xf", "t.tar"], cwd=into, check=True)
    return into


def run_cli(tree: Path, args: list[str], env: dict) -> tuple[float, float, float]:
    t0 = time.perf_counter()
    cmd = VidCommand(["-q", *args], {**env, "PYTHONPATH": str(tree)})
    proc = subprocess.Popen(cmd.argv, cwd=tree, env=cmd.env, stdout=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    peak = cmd.peak_mib()
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{tree}: vid2sim {args[0]} failed")
    return (time.perf_counter() - t0, usage.ru_utime + usage.ru_stime,
            peak)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("base")
    parser.add_argument("new", nargs="?", default=None,
                        help="commit to compare (default: the working tree)")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--shared", type=Path, default=SHARED)
    args = parser.parse_args(argv)
    raw, models = args.shared / "data" / "kitti_raw_0001", args.shared / "models"
    if not raw.is_dir() or not models.is_dir():
        print(f"error: {raw if not raw.is_dir() else models}: not found "
              "(the real data and the detector weights are in ../shared beside the repository; give --shared DIR)", file=sys.stderr)
        return 2
    env = {**os.environ, "VID2SIM_MODEL_DIR": str(models)}
    best: dict[tuple[str, str], list[float]] = {}
    names = {"base": args.base, "new": args.new or "working tree"}
    with tempfile.TemporaryDirectory() as tmp:
        try:
            trees = {"base": export(args.base, Path(tmp) / "base"),
                     "new": export(args.new, Path(tmp) / "new")}
        except subprocess.CalledProcessError:
            print(f"error: {args.base} / {names['new']}: not a commit of {REPO} "
                  "(see `git log --oneline`)", file=sys.stderr)
            return 2
        for r in range(args.rounds):
            for key, tree in trees.items():
                out = subprocess.run([sys.executable, "-c", IN_PROCESS, str(raw), str(models)],
                                     cwd=tree, env={**env, "PYTHONPATH": str(tree)},
                                     check=True, capture_output=True, text=True).stdout
                figures = {"detect_and_range": [list(map(float, line.split()))
                                                for line in out.split("\n") if line.strip()]}
                with tempfile.TemporaryDirectory() as work:
                    figures["vid2sim track"] = [list(run_cli(tree, [
                        "track", str(raw / "video.mp4"), "--camera", str(raw / "camera.yaml"),
                        "--out", f"{work}/tracks.csv"], env))]
                    figures["vid2sim build"] = [list(run_cli(tree, [
                        "build", str(raw / "video.mp4"), "--gps", str(raw), "--camera",
                        str(raw / "camera.yaml"), "--offline", "--out", f"{work}/build"], env))]
                for what, rows in figures.items():
                    for row in rows:
                        label = "x decode" if what == "detect_and_range" else "MiB"
                        print(f"round {r + 1} {key:4s} {what:16s} wall {row[0]:6.2f} s, CPU "
                              f"{row[1]:6.2f} s, {label} {row[2]:.1f}")
                        old = best.get((key, what))
                        best[(key, what)] = row if old is None else [min(a, b) for a, b in
                                                                      zip(old, row)]
    print(f"\nbest of each figure; base = {names['base']}, new = {names['new']}")
    for what in ("detect_and_range", "vid2sim track", "vid2sim build"):
        b, n = best[("base", what)], best[("new", what)]
        print(f"  {what:16s} wall {b[0]:.2f} -> {n[0]:.2f} s ({n[0] / b[0]:.2f}x), CPU "
              f"{b[1]:.2f} -> {n[1]:.2f} s ({n[1] / b[1]:.2f}x)")
    for key in ("base", "new"):
        ratio = best[(key, "vid2sim build")][0] / best[(key, "vid2sim track")][0]
        print(f"  build / track wall, {key}: {ratio:.2f} (bar <= 1.5)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
