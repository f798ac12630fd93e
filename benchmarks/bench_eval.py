"""Benchmark the evaluation stage: replay projection (trajectories and gymnasium env), scoring,
and the whole ``run_eval`` (overlays, metrics.json, report.html) on a synthetic scenario with
many keyframes, plus KITTI tracking 0001/0016 where ../shared is present.

    python benchmarks/bench_eval.py [--actors 20] [--keyframes 100]
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from vid2sim.core.camera import load_camera
from vid2sim.core.records import AnnotatedBox, Keyframe
from vid2sim.core.scenario import save
from vid2sim.evaluate.metrics import score_keyframes
from vid2sim.evaluate.replay import _env_available, replay_boxes, run_eval
from vid2sim.samples.scenarios import parallel_traffic_scenario as make_scenario
from vid2sim.samples.scenarios import scenario_from_kitti_labels

DATA = Path(os.environ.get("VID2SIM_SHARED", Path(__file__).resolve().parents[2] / "shared")) / "data"


def _timed(label: str, fn, *args, **kwargs):
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    dt = time.perf_counter() - t0
    print(f"{label:<48s} {dt * 1000:9.1f} ms")
    return out, dt


def synthetic(n_actors: int, duration_s: float):
    actors = [(f"a{i}", 10.0 + 6.0 * i, 3.5 * ((i % 3) - 1), 8.0 + (i % 5), 0.0, duration_s)
              for i in range(n_actors)]
    return make_scenario(actors=actors, duration_s=duration_s)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--actors", type=int, default=20)
    ap.add_argument("--keyframes", type=int, default=100)
    args = ap.parse_args()
    duration_s = max(args.keyframes / 10.0, 1.0)
    sc = synthetic(args.actors, duration_s)
    times = [round(i * duration_s / args.keyframes, 6) for i in range(args.keyframes)]
    print(f"synthetic: {args.actors} actors, {args.keyframes} keyframes over {duration_s:.0f} s")
    boxes, dt = _timed("replay_boxes (trajectory interpolation)", replay_boxes, sc, times,
                       use_env=False)
    print(f"{'  per keyframe':<48s} {dt / len(times) * 1000:9.2f} ms")
    if _env_available():
        _timed("replay_boxes (vid2sim/Replay-v0, log mode)", replay_boxes, sc, times, use_env=True)
    # annotations = the simulated boxes themselves: scoring cost without geometry
    kfs = [Keyframe(i, t, str(i), [AnnotatedBox(b.box_px, "car", b.actor_id) for b in boxes[t]])
           for i, t in enumerate(times)]
    m, _ = _timed("score_keyframes", score_keyframes, kfs, boxes)
    assert m["f1"] == 1.0
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        save(sc, tmp / "scenario.json")
        frames = [{"name": str(k.frame), "index": k.frame, "labels": [
            {"id": b.id, "category": "car", "box2d": dict(zip(("x1", "y1", "x2", "y2"), b.box_px,
                                                              strict=True))} for b in k.boxes]}
            for k in kfs]
        (tmp / "kf.json").write_text(json.dumps(frames))
        _timed("run_eval (env, grey overlays, report)", run_eval, tmp / "scenario.json",
               tmp / "kf.json", out_dir=tmp / "out", fps=args.keyframes / duration_s)
        kitti = DATA / "kitti_tracking"
        if kitti.exists():
            for seq, numbers in (("0001", (10, 15, 20)), ("0016", (2, 7, 12))):
                label = kitti / "label_02" / f"{seq}.txt"
                cam = load_camera(kitti / "calib" / f"{seq}.txt")
                save(scenario_from_kitti_labels(label, numbers, 2.0, cam), tmp / f"{seq}.json")
                (m, summary), _ = _timed(f"run_eval KITTI {seq} (3D-label scenario)", run_eval,
                                         tmp / f"{seq}.json", label, video=kitti / "image_02" / seq,
                                         out_dir=tmp / seq, fps=2.0)
                print("   " + summary.replace("\n", "\n   "))
        else:
            print(f"KITTI tracking not found at {kitti}: skipped")


if __name__ == "__main__":
    main()
