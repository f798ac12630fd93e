"""Benchmark of whole builds: wall time per stage and peak memory (not a test: prints figures).

Cases:
1. ``demo-imported``: the demo sample (24 s, 240 frames 960x540) generated and built with its
   imported noisy detections (the README's main command);
2. ``demo-detector``: the same with the real default detector on the rendered frames;
3. ``kitti-raw``: ../shared/data/kitti_raw_0001 (108 frames 1242x374, OXTS GPS, no map, so
   a trajectory road) with the default detector.

Peak memory is the child process's maximum resident set: frames are streamed, so it should
not grow with the video's length (compare the 108- and 240-frame cases).

Each case runs in a fresh child process so that its peak resident memory (ru_maxrss) is its
own. Usage:

    python benchmarks/bench_build.py [--shared ../shared] [--cases demo,kitti-raw]

Figures depend on the machine and its load; say so when quoting them.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import tempfile
import time
from pathlib import Path

from peakrss import own_peak_mib

REPO = Path(__file__).resolve().parents[1]


def _run_case(case: str, shared: Path, model_dir: Path | None, queue) -> None:
    from vid2sim.app.build import build
    from vid2sim.app.demo import run_demo
    from vid2sim.app.inputs import Inputs
    from vid2sim.app.settings import DetectorSettings, Settings

    settings = Settings(detector=DetectorSettings(model_dir=model_dir), allow_download=False,
                        progress=False)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix=f"bench-{case}-") as tmp:
        tmp = Path(tmp)
        if case == "demo-imported":
            result = run_demo(tmp, force_detections=True, settings=settings)
        elif case == "demo-detector":
            result = run_demo(tmp, settings=settings)
        elif case == "kitti-raw":
            raw = shared / "data" / "kitti_raw_0001"
            result = build(Inputs(video=raw / "video.mp4", gps=raw, camera=raw / "camera.yaml"),
                           tmp / "out", settings)
        else:
            raise SystemExit(f"unknown case {case}")
    wall = time.perf_counter() - t0
    peak_mib = own_peak_mib()
    queue.put({"case": case, "wall_s": wall, "peak_rss_mib": peak_mib,
               "stages_s": result.stage_seconds,
               "f1": (result.metrics or {}).get("f1"),
               "mean_iou": (result.metrics or {}).get("mean_iou")})


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=REPO.parent / "shared")
    parser.add_argument("--cases", default="demo-imported,demo-detector,kitti-raw")
    args = parser.parse_args()
    model_dir = Path(os.environ.get("VID2SIM_MODEL_DIR", args.shared / "models"))
    if not model_dir.exists():
        model_dir = None
    ctx = mp.get_context("spawn")
    for case in args.cases.split(","):
        if case != "demo-imported" and model_dir is None:
            print(f"{case}: skipped (no detector weights)")
            continue
        if case == "kitti-raw" and not (args.shared / "data" / "kitti_raw_0001").exists():
            print(f"{case}: skipped (no KITTI data)")
            continue
        queue = ctx.Queue()
        proc = ctx.Process(target=_run_case, args=(case, args.shared, model_dir, queue))
        proc.start()
        proc.join()
        if proc.exitcode != 0:
            print(f"{case}: failed with exit code {proc.exitcode}")
            continue
        row = queue.get()
        stages = ", ".join(f"{k} {v:.1f}" for k, v in row["stages_s"].items())
        print(f"{row['case']}: {row['wall_s']:.1f} s wall, peak RSS {row['peak_rss_mib']:.0f} MiB"
              + (f", F1 {row['f1']:.3f}, mean IoU {row['mean_iou']:.3f}" if row["f1"] is not None
                 else ""))
        print(f"    stages [s]: {stages}")
        print("    " + json.dumps({k: v for k, v in row.items() if k != "stages_s"}))


if __name__ == "__main__":
    main()
