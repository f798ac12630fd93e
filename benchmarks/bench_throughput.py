"""Throughput and memory of ``vid2sim track`` and ``vid2sim build`` as a user runs them.

    python benchmarks/bench_throughput.py [--shared ../shared] [--work DIR] [--repeat 2]
        [--parts speed,memory] [--lengths 1,4] [--compare COMMIT]

Every figure is a command in a fresh process (interpreter start, imports and model load
included), timed with its CPU (user + system of all its threads, from ``wait4``) and peak
resident memory (the command's own ``VmHWM``, see ``peakrss.py``: ``ru_maxrss`` of a child
includes the peak of the parent it replaced); the machine's load average is printed beside each run, since
wall time on a shared machine says as much about the others as about us.

speed:
  1. ``vid2sim track`` on KITTI raw 0001 played forward and back to 43 s (430 frames, 10 fps,
     1242x374; built from ``../shared/data/kitti_raw_0001/video.mp4`` into ``--work``, never
     committed): real-time factor = video seconds / wall seconds.
  2. ``vid2sim track`` on a 720p 30 fps clip of 60 s (the KITTI frames scaled to 1280 px,
     reflect-padded to 720 rows, played forward and back), analysed at the schedule's rate.

memory (peak RSS against video length, ``--lengths`` times the base length; ``--parts
track-memory`` or ``build-memory`` for one of the two):
  3. ``vid2sim track`` on the 43 s clip looped 1x, 4x (and 16x);
  4. ``vid2sim build`` with imported detections (KITTI raw 0001 looped to 1,500 frames times
     the length, the drive's OXTS fixes continued loop after loop, as
     ``benchmarks/bench_scale.py`` builds them): time and peak-RSS ratios.

``--compare COMMIT`` also runs the commands of the speed part with that commit's tree
(``git archive``), alternating with the working tree round by round, and prints the ratios.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from datetime import UTC, datetime
from pathlib import Path

import cv2
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_compare import export
from bench_scale import looped_inputs, raw_detections
from peakrss import VidCommand

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
RAW_FRAMES = 108


# --------------------------------------------------------------------------- clips


def _raw_frames(raw: Path) -> list:
    cap = cv2.VideoCapture(str(raw / "video.mp4"))
    frames = []
    while True:
        ok, image = cap.read()
        if not ok:
            break
        frames.append(image)
    cap.release()
    return frames


def _forward_and_back(n: int) -> list[int]:
    return list(range(n)) + list(range(n - 2, 0, -1))


def kitti_clip(raw: Path, work: Path, n_frames: int = 430) -> Path:
    """KITTI raw 0001 forward and back (``n_frames`` at 10 fps), cached in ``work``."""
    out = work / f"kitti_0001_fb_{n_frames}.mp4"
    if out.exists():
        return out
    frames = _raw_frames(raw)
    order = _forward_and_back(len(frames))
    h, w = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), 10.0, (w, h))
    for k in range(n_frames):
        writer.write(frames[order[k % len(order)]])
    writer.release()
    return out


def camera_720p(raw: Path, work: Path, shape: tuple[int, int]) -> Path:
    """The drive's camera.yaml for its frames scaled to 1280 px wide and padded to 720 rows."""
    out = work / "camera_720p.yaml"
    h, w = shape
    s = 1280 / w
    top = (720 - round(h * s)) // 2
    cam = yaml.safe_load((raw / "camera.yaml").read_text())
    cam.update(image_width=1280, image_height=720, fx=cam["fx"] * s, fy=cam["fy"] * s,
               cx=cam["cx"] * s, cy=cam["cy"] * s + top)
    out.write_text(yaml.safe_dump(cam, sort_keys=False))
    return out


def clip_720p(raw: Path, work: Path, seconds: float = 60.0) -> Path:
    """The KITTI frames at 1280x720, 30 fps, forward and back, ``seconds`` long (cached):
    each frame scaled to 1280 px wide (bilinear) and reflect-padded to 720 rows, so the road
    keeps its geometry (:func:`camera_720p` is its camera). Each 10 fps frame is shown once,
    at 30 fps: the drive plays 3x faster (a frame repeated three times would make the flow
    and the tracker's work trivial; the cost per frame is what this measures)."""
    out = work / f"kitti_0001_720p30_{seconds:g}s.mp4"
    frames = _raw_frames(raw)
    camera_720p(raw, work, frames[0].shape[:2])
    if out.exists():
        return out
    w, h = 1280, 720
    scaled = []
    for image in frames:
        s = cv2.resize(image, (w, round(image.shape[0] * w / image.shape[1])),
                       interpolation=cv2.INTER_LINEAR)
        pad = h - s.shape[0]
        scaled.append(cv2.copyMakeBorder(s, pad // 2, pad - pad // 2, 0, 0, cv2.BORDER_REFLECT))
    order = _forward_and_back(len(scaled))
    writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), 30.0, (w, h))
    for k in range(round(seconds * 30)):
        writer.write(scaled[order[k % len(order)]])
    writer.release()
    return out


# --------------------------------------------------------------------------- runs


def load_average() -> float:
    return os.getloadavg()[0]


def run(args: list[str], env: dict, tree: Path | None = None) -> dict:
    """One ``vid2sim`` command in a fresh process: wall, CPU, peak RSS, load before/after."""
    load0 = load_average()
    t0 = time.perf_counter()
    cmd = VidCommand(["-q", *args], {**env, **({"PYTHONPATH": str(tree)} if tree else {})})
    proc = subprocess.Popen(cmd.argv, cwd=tree or REPO, stdout=subprocess.DEVNULL, env=cmd.env)
    _, status, usage = os.wait4(proc.pid, 0)
    peak = cmd.peak_mib()
    wall = time.perf_counter() - t0
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"vid2sim {' '.join(args)} failed")
    return {"wall_s": wall, "cpu_s": usage.ru_utime + usage.ru_stime,
            "rss_mib": peak, "load": (load0 + load_average()) / 2}


def _line(label: str, seconds: float, r: dict) -> str:
    return (f"  {label:34s} {r['wall_s']:6.1f} s wall = {seconds / r['wall_s']:5.2f}x real "
            f"time, CPU {r['cpu_s']:6.1f} s ({seconds / r['cpu_s']:5.2f}x real time per core), "
            f"peak RSS {r['rss_mib']:4.0f} MiB, load {r['load']:.1f}")


def track_args(video: Path, camera: Path, out: Path) -> list[str]:
    return ["track", str(video), "--camera", str(camera), "--out", str(out)]


def speed(raw: Path, work: Path, env: dict, repeat: int, base_tree: Path | None,
          which: set[str]) -> None:
    clips = (("KITTI 0001 fwd+back 43 s, 10 fps", kitti_clip(raw, work), raw / "camera.yaml",
              43.0),
             ("720p 30 fps 60 s", clip_720p(raw, work), work / "camera_720p.yaml", 60.0))
    clips = tuple(c for c, name in zip(clips, ("kitti", "720p"), strict=True) if name in which)
    trees = {"new": None, **({"base": base_tree} if base_tree else {})}
    for label, video, camera, seconds in clips:
        print(f"\n{label} ({video.name}): vid2sim track", flush=True)
        best: dict[str, dict] = {}
        for k in range(repeat):
            for name, tree in trees.items():
                r = run(track_args(video, camera, work / f"tracks_{name}.csv"), env, tree)
                print(_line(f"round {k + 1} {name}", seconds, r), flush=True)
                if name not in best or r["wall_s"] < best[name]["wall_s"]:
                    best[name] = r
        for name, r in best.items():
            print(_line(f"best of {repeat} {name}", seconds, r), flush=True)
        if "base" in best:
            b, n = best["base"], best["new"]
            print(f"  new / base: wall {n['wall_s'] / b['wall_s']:.2f}, CPU "
                  f"{n['cpu_s'] / b['cpu_s']:.2f}, peak RSS {n['rss_mib'] / b['rss_mib']:.2f}")


def track_memory(raw: Path, work: Path, env: dict, lengths: list[int]) -> None:
    camera = raw / "camera.yaml"
    print("\nvid2sim track, peak RSS against video length (the 43 s clip looped)", flush=True)
    rows = {}
    for n in lengths:
        video = kitti_clip(raw, work, 430 * n)
        rows[n] = r = run(track_args(video, camera, work / "tracks_long.csv"), env)
        print(_line(f"{n:2d}x ({43 * n} s, {430 * n} frames)", 43.0 * n, r), flush=True)
    _ratios(rows)


def build_memory(raw: Path, work: Path, env: dict, lengths: list[int], models: Path) -> None:
    camera = raw / "camera.yaml"
    print("\nvid2sim build with imported detections (KITTI 0001 looped, its OXTS continued)",
          flush=True)
    dets = raw_detections(raw, work, models)
    rows = {}
    for n in lengths:
        paths = looped_inputs(raw, dets, 1500 * n, work)
        r = run(["build", str(paths["video"]), "--gps", str(paths["gps"]), "--camera",
                 str(camera), "--detections", str(paths["detections"]), "--offline", "--out",
                 str(paths["video"].parent / "build")], env)
        rows[n] = r
        print(_line(f"{n:2d}x ({150 * n} s, {1500 * n} frames)", 150.0 * n, r), flush=True)
    _ratios(rows)


def _ratios(rows: dict[int, dict]) -> None:
    ns = sorted(rows)
    for n in ns[1:]:
        a, b = rows[ns[0]], rows[n]
        print(f"  {n}x / {ns[0]}x: wall x{b['wall_s'] / a['wall_s']:.2f}, CPU "
              f"x{b['cpu_s'] / a['cpu_s']:.2f}, peak RSS x{b['rss_mib'] / a['rss_mib']:.2f}",
              flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=SHARED)
    parser.add_argument("--work", type=Path, default=Path("/tmp/vid2sim-bench-throughput"))
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--parts", default="speed,memory",
                        help="speed, memory (= track-memory and build-memory)")
    parser.add_argument("--clips", default="kitti,720p", help="clips of the speed part")
    parser.add_argument("--lengths", default="1,4", help="video lengths, times the base")
    parser.add_argument("--compare", default=None, help="a commit to run beside (speed part)")
    args = parser.parse_args(argv)
    raw, models = args.shared / "data" / "kitti_raw_0001", args.shared / "models"
    for p in (raw, models):
        if not p.is_dir():
            print(f"error: {p}: not found (the real data and the detector weights are in "
                  "../shared beside the repository; give --shared DIR)", file=sys.stderr)
            return 2
    args.work.mkdir(parents=True, exist_ok=True)
    env = {**os.environ, "VID2SIM_MODEL_DIR": str(models)}
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, check=False,
                            capture_output=True, text=True).stdout.strip()
    print(f"bench_throughput: {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, commit {commit}"
          f"{' (+ working tree)' if _dirty() else ''}, {os.cpu_count()} CPUs, load average "
          f"{' / '.join(f'{v:.1f}' for v in os.getloadavg())}", flush=True)
    parts = set(args.parts.split(","))
    with tempfile.TemporaryDirectory() as tmp:
        base_tree = None
        if args.compare:
            try:
                base_tree = export(args.compare, Path(tmp) / "base")
            except subprocess.CalledProcessError:
                print(f"error: {args.compare}: not a commit of {REPO}", file=sys.stderr)
                return 2
        if "speed" in parts:
            speed(raw, args.work, env, args.repeat, base_tree, set(args.clips.split(",")))
        lengths = [int(v) for v in args.lengths.split(",")]
        if parts & {"memory", "track-memory"}:
            track_memory(raw, args.work, env, lengths)
        if parts & {"memory", "build-memory"}:
            build_memory(raw, args.work, env, lengths, models)
    return 0


def _dirty() -> bool:
    return bool(subprocess.run(["git", "status", "--porcelain", "vid2sim"], cwd=REPO, check=False,
                               capture_output=True, text=True).stdout.strip())


if __name__ == "__main__":
    sys.exit(main())
