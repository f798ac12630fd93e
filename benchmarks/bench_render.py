"""Benchmark of ``vid2sim render``: cost against the clip's own time at the video's
resolution, and peak memory against the clip's length (not a test: prints figures).

Cases (each render runs in a fresh child process, so its CPU time and peak resident memory
are its own; the builds it renders are made first, in other children):

1. ``kitti``: a build of ../shared/data/kitti_raw_0001 (10.8 s, 108 frames 1242x374, OXTS,
   the default detector), rendered at the video's resolution (a 1868x494 replay);
2. ``demo``: the generated demo clip (960x540) at 6, 12 and 24 s, each built with its
   imported boxes and rendered: real builds of growing length;
3. ``long``: the KITTI clip looped 1x, 4x and 10x (10.8 / 43 / 108 s) under a scenario made
   in code that lasts as long (straight road, four vehicles): the pipeline's memory over ten
   times the frames.

"Cost" is the render's CPU time (user + sys, all threads: decoding, drawing, encoding) over
the clip's duration; on the 2-core machine the wall time is the number to compare with real
time (printed with the load average, the machine is shared). Peak RSS should not grow with
the clip (frames are streamed). Usage:

    python benchmarks/bench_render.py [--shared ../shared] [--cases kitti,demo,long]
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

from peakrss import own_peak_mib

REPO = Path(__file__).resolve().parents[1]


def _rss_mib() -> float:
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20


def _render_child(build_dir: str, video: str, out: str, queue) -> None:
    from vid2sim.app.rendering import RenderRequest, run_render
    from vid2sim.evaluate import replayvideo

    # the resident memory every 100 output frames: flat after the encoder's warm-up
    samples: list[float] = []
    draw = replayvideo.BuildReplay.draw

    def sampled(self, k, frame, boxes):
        if k % 100 == 0:
            samples.append(_rss_mib())
        return draw(self, k, frame, boxes)

    replayvideo.BuildReplay.draw = sampled
    t0 = time.perf_counter()
    summary = run_render(RenderRequest(Path(build_dir), Path(out), video=Path(video)))
    wall = time.perf_counter() - t0
    ru = resource.getrusage(resource.RUSAGE_SELF)
    queue.put({"wall_s": wall, "cpu_s": ru.ru_utime + ru.ru_stime,
               "peak_rss_mib": own_peak_mib(), "summary": summary,
               "rss_samples": samples})


def _build_child(kind: str, arg: str, out: str, queue) -> None:
    from vid2sim.app.build import build
    from vid2sim.app.inputs import Inputs
    from vid2sim.app.settings import DetectorSettings, Settings

    settings = Settings(detector=DetectorSettings(model_dir=Path(arg) if kind == "kitti"
                                                  else None),
                        allow_download=False, progress=False)
    if kind == "kitti":
        raw = Path(os.environ["BENCH_KITTI"])
        build(Inputs(video=raw / "video.mp4", gps=raw / "oxts", camera=raw / "camera.yaml"),
              Path(out), settings)
        queue.put(str(raw / "video.mp4"))
        return
    from vid2sim.samples.demo_sample import generate_demo_sample
    from vid2sim.samples.drives import helsinki_pbf

    sample = generate_demo_sample(Path(out) / "clip", duration_s=float(arg))
    build(Inputs(video=sample.video, gps=sample.gps, map=helsinki_pbf(), camera=sample.camera,
                 detections=sample.detections), Path(out) / "B", settings)
    queue.put(str(sample.video))


def _long_build(raw: Path, loops: int, out: Path) -> Path:
    """The KITTI clip looped ``loops`` times and a scenario in code of the same length."""
    import cv2

    from vid2sim.core.camera import fit_camera_to_frames, load_camera
    from vid2sim.core.scenario import save
    from vid2sim.core.tables import write_tracks_csv
    from vid2sim.samples.scenarios import parallel_traffic_scenario

    out.mkdir(parents=True)
    cap = cv2.VideoCapture(str(raw / "video.mp4"))
    frames = []
    while True:
        ok, img = cap.read()
        if not ok:
            break
        frames.append(img)
    h, w = frames[0].shape[:2]
    video = out / "video.mp4"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (w, h))
    for _ in range(loops):
        for img in frames:
            writer.write(img)
    writer.release()
    n = loops * len(frames)
    duration = (n - 1) / 10.0
    cam, _ = fit_camera_to_frames(load_camera(raw / "camera.yaml"), w, h)
    sc = parallel_traffic_scenario(duration_s=duration, camera=cam,
                                   actors=[("1", 20.0, 0.0, 9.0, 0.0, duration),
                                           ("2", 10.0, 3.5, 11.0, 0.0, duration),
                                           ("3", 35.0, -3.5, 10.0, 0.0, duration),
                                           ("4", 60.0, 0.0, 10.0, 0.0, duration)])
    sc.source.options.update({"fps": 10.0, "n_frames": n})
    save(sc, out / "scenario.json")
    write_tracks_csv([], out / "tracks.csv")
    return video


def _run(ctx, target, *args):
    queue = ctx.Queue()
    proc = ctx.Process(target=target, args=(*args, queue))
    proc.start()
    row = queue.get()
    proc.join()
    if proc.exitcode != 0:
        raise SystemExit(f"child failed with exit code {proc.exitcode}")
    return row


def _report(name: str, clip_s: float, row: dict) -> None:
    load = os.getloadavg()[0]
    print(f"{name}: clip {clip_s:.1f} s, render {row['cpu_s']:.1f} s CPU "
          f"({row['cpu_s'] / clip_s:.2f}x the clip), {row['wall_s']:.1f} s wall "
          f"({row['wall_s'] / clip_s:.2f}x, load average {load:.1f}), peak RSS "
          f"{row['peak_rss_mib']:.0f} MiB")
    rss = row["rss_samples"]
    print("    RSS every 100 frames [MiB]: " + " ".join(f"{v:.0f}" for v in rss))
    print("    " + row["summary"].splitlines()[0])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=REPO.parent / "shared")
    parser.add_argument("--cases", default="kitti,demo,long")
    args = parser.parse_args()
    raw = args.shared / "data" / "kitti_raw_0001"
    models = Path(os.environ.get("VID2SIM_MODEL_DIR", args.shared / "models"))
    cases = args.cases.split(",")
    if ("kitti" in cases or "long" in cases) and not raw.exists():
        print(f"error: {raw}: not found (pass --shared, or --cases demo)", file=sys.stderr)
        raise SystemExit(2)
    os.environ["BENCH_KITTI"] = str(raw)
    ctx = mp.get_context("spawn")
    with tempfile.TemporaryDirectory(prefix="bench-render-") as tmp:
        tmp = Path(tmp)
        if "kitti" in cases:
            video = _run(ctx, _build_child, "kitti", str(models), str(tmp / "kitti"))
            _report("kitti", 10.8, _run(ctx, _render_child, str(tmp / "kitti"), video,
                                        str(tmp / "kitti" / "replay.mp4")))
        if "demo" in cases:
            for seconds in (6.0, 12.0, 24.0):
                out = tmp / f"demo{seconds:g}"
                video = _run(ctx, _build_child, "demo", str(seconds), str(out))
                _report(f"demo {seconds:g} s 960x540", seconds - 0.1,
                        _run(ctx, _render_child, str(out / "B"), video,
                             str(out / "B" / "replay.mp4")))
        if "long" in cases:
            for loops in (1, 4, 10):
                out = tmp / f"long{loops}"
                video = _long_build(raw, loops, out)
                _report(f"long {loops}x KITTI", loops * 10.8 - 0.1,
                        _run(ctx, _render_child, str(out), str(video), str(out / "replay.mp4")))


if __name__ == "__main__":
    main()
