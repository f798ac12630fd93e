"""Benchmark of ``vid2sim batch``: throughput of the local and Ray engines on the same cores,
and the time a resume takes (not a test: prints figures).

The manifest is N copies of the demo sample (24 s, 240 frames 960x540; GPS, the Helsinki
OpenStreetMap extract, camera, keyframes) in N folders, built with the sample's imported noisy
detections (no weights needed) or, with ``--detector``, the default detector on the rendered
frames. Each engine gets the same cores: ``--engine local --jobs C --cpus-per-job 1`` against
a local Ray runtime started with ``num_cpus=C`` (one task per row, one CPU each). A serial
in-process build of one copy gives the engines' ideal: N x that / C.

Then the same manifest is run again (every row built): the resume's wall time, in process
(what ``run_batch`` costs) and as a fresh ``vid2sim batch`` command (Python start-up and
imports included).

Usage:

    python benchmarks/bench_batch.py [--copies 8] [--cores 2] [--repeats 1] [--detector]

Figures depend on the machine and its load; on a shared machine compare the engines within
one run (they alternate, best of ``--repeats``).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
FILES = ("demo.mp4", "demo.gpx", "camera.yaml", "detections.txt", "keyframes.json")


def make_manifest(work: Path, copies: int, use_detections: bool) -> Path:
    """Generate the demo sample once and copy it into ``copies`` folders; the manifest."""
    from vid2sim.samples.demo_sample import generate_demo_sample, helsinki_pbf_path

    sample = work / "sample"
    t0 = time.perf_counter()
    generate_demo_sample(sample, seed=7)
    print(f"demo sample generated in {time.perf_counter() - t0:.1f} s")
    lines = ["video,name,gps,map,camera,detections,keyframes"]
    for k in range(copies):
        folder = work / f"drive_{k:02d}"
        folder.mkdir()
        for name in FILES:
            shutil.copy(sample / name, folder / name)
        detections = f"{folder.name}/detections.txt" if use_detections else ""
        lines.append(f"{folder.name}/demo.mp4,drive_{k:02d},{folder.name}/demo.gpx,"
                     f"{helsinki_pbf_path()},{folder.name}/camera.yaml,{detections},"
                     f"{folder.name}/keyframes.json")
    manifest = work / "manifest.csv"
    manifest.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return manifest


def settings_for(model_dir: Path | None):
    from vid2sim.app.settings import DetectorSettings, Settings

    return Settings(detector=DetectorSettings(model_dir=model_dir), allow_download=False,
                    progress=False)


def serial_build_s(manifest: Path, settings, out: Path) -> float:
    """Wall time of one row built in this process (warm imports): the per-video cost."""
    from vid2sim.app.batch import RowTask, read_manifest, run_row

    row = read_manifest(manifest)[0]
    t0 = time.perf_counter()
    outcome = run_row(RowTask(row, settings, out))
    assert outcome.status == "ok", outcome.error
    return time.perf_counter() - t0


def run_engine(engine: str, manifest: Path, out: Path, cores: int, settings) -> dict:
    from vid2sim.app.batch import run_batch

    if out.exists():
        shutil.rmtree(out)
    t0 = time.perf_counter()
    summary = run_batch(manifest, out, settings, engine=engine, jobs=cores, cpus_per_job=1)
    wall = time.perf_counter() - t0
    rows = [o for o in summary.outcomes if o.status == "ok"]
    assert len(rows) == len(summary.outcomes), [o.error for o in summary.outcomes]
    return {"engine": engine, "wall_s": wall, "n": len(rows),
            "row_s": statistics.median(o.seconds for o in rows),
            "rss_mb": max(o.peak_rss_mb for o in rows),
            "f1": statistics.median(o.f1 for o in rows if o.f1 is not None)}


def resume_s(manifest: Path, out: Path, settings, engine: str) -> tuple[float, float]:
    """Wall time of a rerun with every row built: in process, and as a fresh command."""
    from vid2sim.app.batch import run_batch

    t0 = time.perf_counter()
    summary = run_batch(manifest, out, settings, engine=engine)
    in_process = time.perf_counter() - t0
    assert summary.count("skipped") == len(summary.outcomes)
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "vid2sim", "-q", "batch", str(manifest), "--out",
                    str(out), "--engine", engine, "--offline"], check=True, env=env)
    return in_process, time.perf_counter() - t0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--copies", type=int, default=8)
    parser.add_argument("--cores", type=int, default=2, help="cores given to each engine")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--detector", action="store_true",
                        help="run the default detector (needs weights) instead of importing "
                             "the sample's detections")
    parser.add_argument("--shared", type=Path, default=REPO.parent / "shared")
    args = parser.parse_args()
    model_dir = None
    if args.detector:
        model_dir = Path(os.environ.get("VID2SIM_MODEL_DIR", args.shared / "models"))
        if not model_dir.exists():
            raise SystemExit(f"no detector weights in {model_dir}")
    import ray

    settings = settings_for(model_dir)
    with tempfile.TemporaryDirectory(prefix="bench-batch-") as tmp:
        work = Path(tmp)
        manifest = make_manifest(work, args.copies, use_detections=not args.detector)
        one = serial_build_s(manifest, settings, work / "serial")
        print(f"one row in process (warm): {one:.1f} s -> ideal {args.copies} rows on "
              f"{args.cores} cores: {args.copies * one / args.cores:.1f} s")
        t0 = time.perf_counter()
        ray.init(num_cpus=args.cores, include_dashboard=False, log_to_driver=False)
        print(f"local Ray runtime ({args.cores} CPUs) started in {time.perf_counter() - t0:.1f} s")
        results: dict[str, list[dict]] = {"local": [], "ray": []}
        for _ in range(args.repeats):
            for engine in ("local", "ray"):
                r = run_engine(engine, manifest, work / f"out_{engine}", args.cores, settings)
                results[engine].append(r)
                print(f"  {engine}: {r['wall_s']:.1f} s wall, median row {r['row_s']:.1f} s, "
                      f"peak {r['rss_mb']:.0f} MiB, F1 {r['f1']:.3f}")
        print(f"\n{'engine':8} {'best wall [s]':>14} {'videos/h':>9} {'videos/core-h':>14} "
              f"{'vs ideal':>9}")
        for engine, runs in results.items():
            best = min(r["wall_s"] for r in runs)
            per_hour = 3600.0 * args.copies / best
            print(f"{engine:8} {best:14.1f} {per_hour:9.0f} {per_hour / args.cores:14.0f} "
                  f"{args.copies * one / args.cores / best:9.2f}")
        for engine in ("local", "ray"):
            inside, command = resume_s(manifest, work / f"out_{engine}", settings, engine)
            print(f"resume, {engine}: {inside:.2f} s in process, {command:.1f} s as a command")
        ray.shutdown()


if __name__ == "__main__":
    main()
