"""Cost of a whole build against video length: time and peak memory per stage (not a test).

The real KITTI raw drive 0001 (108 frames, 10 fps, OXTS GPS) looped to 1,500 / 3,000 / 6,000
frames, built with imported detections (so the figures measure the pipeline, not the
detector):

- video: the 108 frames written again and again into one mp4 (OpenCV, mp4v);
- detections: one ``vid2sim detect`` run on the 108 frames (or ``--detections FILE``),
  repeated with the frame numbers shifted by 108 per loop;
- GPS: the OXTS fixes of the drive, each loop's copy moved (in the local ENU frame) to start
  where the previous one ended, so the trace is one continuous drive at the real speed;
- camera: ``camera.yaml`` of the drive; no map (a road derived from the trajectory).

Each build runs in a fresh process. Per stage: CPU time (all threads; the figure a shared
machine's load disturbs least), wall time and the stage's own peak resident
memory (``VmHWM`` reset through ``/proc/self/clear_refs`` when the stage starts; output
writing between stages counts to the stage before); per build: total wall time and the
process's peak resident memory (the largest stage peak). A linear pipeline costs 4x the time
at 4x the frames and the same peak memory.

    python benchmarks/bench_scale.py [--frames 1500,3000,6000] [--repeat 1]
        [--shared ../shared] [--work /tmp/vid2sim-bench-scale] [--detections FILE]

Figures depend on the machine and its load; compare ratios within one run.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import time
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
RAW_FRAMES = 108


# --------------------------------------------------------------------------- inputs


def raw_detections(raw: Path, work: Path, model_dir: Path | None) -> Path:
    """detections.csv of one `vid2sim detect` run on the 108 raw frames (cached in ``work``)."""
    out = work / "kitti_raw_0001_detections.csv"
    if out.exists():
        return out
    from vid2sim.app.inputs import Inputs
    from vid2sim.app.settings import DetectorSettings, Settings
    from vid2sim.app.tracking import run_detect_command

    if model_dir is None:
        raise SystemExit("no detector weights: pass --detections FILE or set VID2SIM_MODEL_DIR")
    settings = Settings(detector=DetectorSettings(model_dir=model_dir), progress=False)
    print(run_detect_command(Inputs(video=raw / "video.mp4"), out, settings), flush=True)
    return out


def looped_inputs(raw: Path, detections: Path, n_frames: int, work: Path) -> dict[str, Path]:
    """Video, detections and GPS of the raw drive looped to ``n_frames`` (cached)."""
    import cv2

    from vid2sim.core.enu import EnuFrame
    from vid2sim.core.records import Origin
    from vid2sim.geo.readers import read_gps

    folder = work / f"loop_{n_frames}"
    video, dets, gps = folder / "video.mp4", folder / "detections.csv", folder / "gps.csv"
    if video.exists() and dets.exists() and gps.exists():
        return {"video": video, "detections": dets, "gps": gps}
    folder.mkdir(parents=True, exist_ok=True)
    loops = -(-n_frames // RAW_FRAMES)

    cap = cv2.VideoCapture(str(raw / "video.mp4"))
    frames = []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        frames.append(img)
    cap.release()
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (w, h))
    for i in range(n_frames):
        writer.write(frames[i % len(frames)])
    writer.release()

    lines = detections.read_text().splitlines()
    out = [lines[0]]
    for k in range(loops):
        for line in lines[1:]:
            cells = line.split(",")
            frame = int(cells[0]) + k * RAW_FRAMES
            if frame < n_frames:
                cells[0], cells[1] = str(frame), f"{frame / 10.0:.6f}"
                out.append(",".join(cells))
    dets.write_text("\n".join(out) + "\n")

    trace = read_gps(raw)
    lat = np.array([f.lat_deg for f in trace.fixes])
    lon = np.array([f.lon_deg for f in trace.fixes])
    origin = Origin(float(lat[0]), float(lon[0]), 0.0)
    frame = EnuFrame(origin)
    enu = frame.to_enu(lat, lon, np.zeros(len(lat)))[:, :2]
    step = enu[-1] - enu[-2]  # one more fix interval between the loops
    shift = enu[-1] - enu[0] + step
    t0 = datetime(2011, 9, 26, 13, 2, 25, tzinfo=UTC).timestamp()
    rows = ["t,lat,lon"]
    n_fix = len(enu)
    for k in range(loops):
        xy = enu + k * shift
        la, lo, _ = frame.to_geodetic(np.column_stack((xy, np.zeros(n_fix))))
        for i in range(n_fix):
            j = k * n_fix + i
            if j > n_frames + 10:
                break
            rows.append(f"{t0 + 0.1 * j:.3f},{la[i]:.9f},{lo[i]:.9f}")
    gps.write_text("\n".join(rows) + "\n")
    return {"video": video, "detections": dets, "gps": gps}


# --------------------------------------------------------------------------- one build


def _vm_hwm_mib() -> float:
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def _reset_hwm() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def _run_build(paths: dict[str, str], camera: str, queue) -> None:
    from vid2sim.app.build import build
    from vid2sim.app.inputs import Inputs
    from vid2sim.app.settings import Settings

    stage_peak: dict[str, float] = {}
    stage_cpu: dict[str, float] = {}
    current: list[str] = ["checks and loading"]
    cpu0 = [time.process_time()]

    def report(line: str) -> None:
        # "[k] stage name ..." at each stage start: close the previous stage's peak and CPU.
        stage_peak[current[-1]] = _vm_hwm_mib()
        stage_cpu[current[-1]] = time.process_time() - cpu0[0]
        current.append(line.split("] ", 1)[1].rstrip(". "))
        cpu0[0] = time.process_time()
        _reset_hwm()

    inputs = Inputs(video=Path(paths["video"]), gps=Path(paths["gps"]), camera=Path(camera),
                    detections=Path(paths["detections"]))
    out = Path(paths["video"]).parent / "build"
    t0, c0 = time.perf_counter(), time.process_time()
    result = build(inputs, out, Settings(allow_download=False, progress=False), report=report)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    stage_peak[current[-1]] = _vm_hwm_mib()
    stage_cpu[current[-1]] = time.process_time() - cpu0[0]
    # The process's peak is the largest stage peak (resetting VmHWM also resets ru_maxrss).
    # CPU time (all threads) is what a shared machine's load disturbs least.
    queue.put({"wall_s": wall, "cpu_s": cpu, "stages_s": result.stage_seconds,
               "stage_cpu_s": stage_cpu, "stage_peak_mib": stage_peak,
               "peak_rss_mib": max(stage_peak.values()),
               "actors": result.n_actors, "duration_s": result.duration_s})


def measure(paths: dict[str, Path], camera: Path) -> dict:
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_run_build,
                       args=({k: str(v) for k, v in paths.items()}, str(camera), queue))
    proc.start()
    row = queue.get()
    proc.join()
    if proc.exitcode != 0:
        raise SystemExit(f"build failed with exit code {proc.exitcode}")
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", default="1500,3000,6000")
    parser.add_argument("--repeat", type=int, default=1,
                        help="builds per length (the least CPU time kept)")
    parser.add_argument("--shared", type=Path, default=REPO.parent / "shared")
    parser.add_argument("--work", type=Path, default=Path("/tmp/vid2sim-bench-scale"))
    parser.add_argument("--detections", type=Path, default=None,
                        help="detections.csv of the 108 raw frames (default: run the detector)")
    args = parser.parse_args()
    raw = args.shared / "data" / "kitti_raw_0001"
    if not raw.exists():
        raise SystemExit(f"no KITTI raw drive at {raw}")
    model_dir = Path(os.environ.get("VID2SIM_MODEL_DIR", args.shared / "models"))
    args.work.mkdir(parents=True, exist_ok=True)
    dets = args.detections or raw_detections(raw, args.work,
                                             model_dir if model_dir.exists() else None)
    rows = {}
    for n in (int(v) for v in args.frames.split(",")):
        paths = looped_inputs(raw, dets, n, args.work)
        best = None
        for _ in range(args.repeat):
            row = measure(paths, raw / "camera.yaml")
            if best is None or row["cpu_s"] < best["cpu_s"]:
                best = row
        rows[n] = best
        stages = ", ".join(f"{k} {v:.1f} s CPU / {best['stage_peak_mib'].get(k, float('nan')):.0f}"
                           " MiB" for k, v in best["stage_cpu_s"].items())
        print(f"{n} frames ({best['duration_s']:.0f} s, {best['actors']} actors): "
              f"{best['cpu_s']:.1f} s CPU, {best['wall_s']:.1f} s wall, peak RSS "
              f"{best['peak_rss_mib']:.0f} MiB", flush=True)
        print(f"    stages: {stages}", flush=True)
        print("    " + json.dumps(best), flush=True)
    ns = sorted(rows)
    if len(ns) > 1:
        a, b = rows[ns[0]], rows[ns[-1]]
        hours = 3600.0 * 10.0 / ns[-1]  # 10 frames/s
        print(f"{ns[-1]} vs {ns[0]} frames ({ns[-1] / ns[0]:.0f}x): CPU time x"
              f"{b['cpu_s'] / a['cpu_s']:.2f} (wall x{b['wall_s'] / a['wall_s']:.2f}), peak "
              f"memory x{b['peak_rss_mib'] / a['peak_rss_mib']:.2f}; per stage CPU x "
              + ", ".join(f"{k} {b['stage_cpu_s'][k] / max(a['stage_cpu_s'][k], 1e-9):.1f}"
                          for k in b["stage_cpu_s"] if k in a["stage_cpu_s"]), flush=True)
        print(f"an hour of 10 fps video at this rate: {b['cpu_s'] * hours / 60:.1f} CPU min "
              f"({b['wall_s'] * hours / 60:.1f} min wall here), peak {b['peak_rss_mib']:.0f} "
              "MiB", flush=True)


if __name__ == "__main__":
    main()
