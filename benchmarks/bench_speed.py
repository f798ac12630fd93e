"""Throughput of ``vid2sim track`` (issue 15) and the accuracy of the same settings, printed.

    python benchmarks/bench_speed.py [--shared ../shared] [--repeat 3] [--no-accuracy]
                                     [--no-speed] [--no-720p] [--quick-720p] [--seeds 0 1 ...]
    python benchmarks/bench_speed.py --options [--repeat 2]

``--options`` measures what each speed option of ``track``/``build`` (``OPTIONS``: longer
keyframe intervals, no tiles, the detector on every frame) buys and costs on KITTI raw 0001,
and prints one table: speed in-process, ``vid2sim detect`` recall/precision on the six
labelled frames, the composite clips' lead (as item 5 below), and the parked cars' range rate
against OXTS (as ``benchmarks/bench_parked_schedule.py``).

Speed (best of ``--repeat`` runs; the machine is shared, so every figure is also given as a
ratio to decoding the same video in the same process and run):

1. KITTI raw 0001 (``../shared/data/kitti_raw_0001``, 108 frames, 10 fps, 10.8 s): decode
   only, then ``track`` in-process (the application layer's ``run_track``, detector load
   included) for the default keyframe schedule and for the detector on every frame
   (``--keyframe-s 0``, the behaviour before the schedule): wall, x real time, x decode, time
   per stage (detector, optical flow, lane markings, tracker, ranging; "other" is decode,
   I/O and the rest), ONNX calls per frame, keyframe share and why keyframes were run. Then
   ``vid2sim track`` and ``vid2sim build`` as subprocesses (interpreter start and imports
   included), with their peak RSS.
2. A generated 720p 30 fps clip of 60 s (KITTI raw frames played forward and backward,
   scaled to 1280 px wide and reflect-padded to 720 rows): the same figures for ``track``.

Accuracy of the same two settings (``--no-accuracy`` skips it):

3. ``vid2sim detect`` on the six labelled KITTI tracking frames (a folder per sequence, as a
   user runs it), scored by ``score_against_kitti``: recall/precision (bar 0.85 / 0.85).
4. Real-box range error: ``vid2sim track`` on the same folders with ``camera_0001.yaml``;
   every output box matched (IoU >= 0.5) to a labelled car/van/truck is compared with the
   label's rear distance (Z - l/2): median |relative error| and signed median, near/far.
5. Composite clips (a real car pasted into KITTI raw 0001 at a known trajectory in the
   drive's measured ego lane, ``vid2sim.samples.composite``), the real detector through the
   schedule: lead range median |rel err|, bias, range-rate RMSE, presence (as
   benchmarks/bench_composite.py). A detector
   run depends on its frame only, so the default detector runs once on every frame and
   each setting gets the boxes of its keyframes from that pass.
6. The demo sample built with the real detector: keyframe F1 and mean IoU.
"""

from __future__ import annotations

import argparse
import csv
import functools
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from peakrss import VidCommand

from vid2sim.app.demo import run_demo
from vid2sim.app.inputs import Inputs
from vid2sim.app.loaders import load_detector_for
from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.app.tracking import run_track
from vid2sim.core.boxes import iou_matrix
from vid2sim.core.camera import fit_camera_to_frames, load_camera
from vid2sim.core.records import Detection
from vid2sim.detect import pipeline
from vid2sim.detect.lanes.vanishing import HorizonEstimator
from vid2sim.detect.tracking.flow import MedianFlow
from vid2sim.detect.tracking.tracker import Tracker
from vid2sim.detect.vehicles.detector import OnnxDetector
from vid2sim.detect.vehicles.external import (
    MatchCounts,
    read_kitti_tracking_labels,
    score_against_kitti,
)
from vid2sim.detect.video import iter_frames, video_info
from vid2sim.evaluate.ranging.static import ego_motion, evaluate_parked
from vid2sim.samples import composite as cp
from vid2sim.samples.cutin import in_lane, measure_ego_lane

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
STAGE_TIMES: dict[str, float] = defaultdict(float)
CALLS: dict[str, int] = defaultdict(int)


def _timed(name: str, fn):
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            STAGE_TIMES[name] += time.perf_counter() - t0
    return wrapper


def _instrument() -> None:
    """Time the stages by wrapping their entry points (a benchmark only)."""
    OnnxDetector.detect = _timed("detector", OnnxDetector.detect)
    MedianFlow.carry = _timed("flow", MedianFlow.carry)
    HorizonEstimator.add_frame = _timed("lanes", HorizonEstimator.add_frame)
    Tracker.update = _timed("tracker", Tracker.update)
    pipeline.range_tracks = _timed("ranging", pipeline.range_tracks)
    original_run = OnnxDetector._raw_many, OnnxDetector._raw

    def count_many(self, images, *args):
        CALLS["onnx"] += len({self._prepare(im)[0].shape for im in images})
        return original_run[0](self, images, *args)

    def count_one(self, image, *args):
        CALLS["onnx"] += 1
        return original_run[1](self, image, *args)

    OnnxDetector._raw_many = count_many
    OnnxDetector._raw = count_one


def decode_seconds(video: Path) -> float:
    t0 = time.perf_counter()
    for _ in iter_frames(video):
        pass
    return time.perf_counter() - t0


def settings_for(model_dir: Path, options: dict | None = None) -> Settings:
    """The default settings with the detector options in ``options`` (DetectorSettings
    fields) changed."""
    d = replace(DetectorSettings(model_dir=model_dir), **(options or {}))
    return Settings(detector=d, progress=False, allow_download=False)


def cli_flags(options: dict) -> list[str]:
    """The ``vid2sim detect/track`` flags of ``options``."""
    flags = []
    if "keyframe_s" in options:
        flags += ["--keyframe-s", str(options["keyframe_s"])]
    if options.get("tiles") is False:
        flags.append("--no-tiles")
    return flags


CONFIGS = (("default (keyframes)", {}), ("every frame", {"keyframe_s": 0.0}))
#: What a user can trade for speed (``--options``): the flags of ``track``/``build``.
OPTIONS = (("default", {}), ("--keyframe-s 0.6", {"keyframe_s": 0.6}),
           ("--no-tiles", {"tiles": False}),
           ("--no-tiles --keyframe-s 0.6", {"tiles": False, "keyframe_s": 0.6}),
           ("--keyframe-s 0 (every frame)", {"keyframe_s": 0.0}))
#: The figures of each option, for the summary table of ``--options``.
SUMMARY: dict[str, dict[str, str]] = defaultdict(dict)


def speed(label: str, video: Path, camera: Path | None, model_dir: Path, repeat: int,
          configs=CONFIGS) -> None:
    info = video_info(video)
    duration = info.n_frames / info.fps
    print(f"\n{label}: {video.name}, {info.n_frames} frames, {info.width}x{info.height}, "
          f"{info.fps:g} fps, {duration:.1f} s")
    dec = min(decode_seconds(video) for _ in range(repeat))
    print(f"  decode only: {dec:.2f} s = {duration / dec:.1f}x real time")
    for name, options in configs:
        best = None
        for _ in range(repeat):
            STAGE_TIMES.clear()
            CALLS.clear()
            stats: dict = {}
            original = pipeline.run_detect

            def run_detect(*args, _stats=stats, _original=original, **kwargs):
                kwargs["stats"] = _stats
                return _original(*args, **kwargs)

            pipeline.run_detect = run_detect
            with tempfile.TemporaryDirectory() as tmp:
                t0, c0 = time.perf_counter(), time.process_time()
                run_track(Inputs(video=video, camera=camera), Path(tmp) / "tracks.csv",
                          settings_for(model_dir, options))
                wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            pipeline.run_detect = original
            dec_again = decode_seconds(video)
            if best is None or wall / dec_again < best[0]:
                best = (wall / dec_again, wall, dict(STAGE_TIMES), dict(CALLS), stats, cpu)
        ratio, wall, stages, calls, stats, cpu = best
        known = sum(stages.values())
        parts = ", ".join(f"{k} {1e3 * v / info.n_frames:.1f}" for k, v in stages.items())
        print(f"  track {name:20s}: {wall:6.2f} s = {duration / wall:5.2f}x real time, "
              f"{ratio:5.1f}x decode, CPU {cpu:.2f} s (all threads); stage wall ms/frame "
              f"(lanes run in the decoding thread, beside the rest): {parts}, other "
              f"{1e3 * (wall - known) / info.n_frames:.1f}; ONNX calls/frame "
              f"{calls.get('onnx', 0) / info.n_frames:.2f}; keyframes "
              f"{stats.get('keyframes', 0)}/{stats.get('frames', 0)} "
              f"{stats.get('keyframe_reasons', {})}")
        SUMMARY[name]["speed"] = (f"{wall:.2f} s = {duration / wall:.1f}x real time, "
                                  f"{ratio:.0f}x decode, CPU {cpu:.1f} s")


def cli_runs(raw: Path, model_dir: Path, repeat: int) -> None:
    """`vid2sim track` and `vid2sim build` as a user runs them: wall and peak RSS."""
    env = {**os.environ, "VID2SIM_MODEL_DIR": str(model_dir)}
    video = raw / "video.mp4"
    print("\nCLI on KITTI raw 0001 (subprocess: interpreter start and imports included)")
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        cmds = {
            "track": ["track", str(video), "--camera", str(raw / "camera.yaml"),
                      "--out", f"{tmp}/tracks.csv"],
            "build": ["build", str(video), "--gps", str(raw), "--camera",
                      str(raw / "camera.yaml"), "--offline", "--out", f"{tmp}/build"],
        }
        for name, args in cmds.items():
            best = (np.inf, 0.0, 0.0)
            for _ in range(repeat):
                t0 = time.perf_counter()
                cmd = VidCommand(["-q", *args], env)
                proc = subprocess.Popen(cmd.argv, env=cmd.env, stdout=subprocess.DEVNULL)
                _, status, usage = os.wait4(proc.pid, 0)
                peak = cmd.peak_mib()
                proc.returncode = os.waitstatus_to_exitcode(status)
                wall = time.perf_counter() - t0
                if proc.returncode != 0:
                    print(f"  {name}: exit {proc.returncode}")
                    break
                best = min(best, (wall, usage.ru_utime + usage.ru_stime,
                                  peak))
            results[name] = best
            print(f"  vid2sim {name}: {best[0]:.2f} s wall, CPU {best[1]:.2f} s, peak RSS "
                  f"{best[2]:.0f} MiB")
    if "track" in results and "build" in results:
        print(f"  build / track: {results['build'][0] / results['track'][0]:.2f} wall (bar <= "
              f"1.5), {results['build'][1] / results['track'][1]:.2f} CPU")


def make_720p_clip(raw: Path, out: Path, seconds: float = 60.0) -> Path:
    """KITTI raw frames forward and backward at 30 fps, 1280 px wide, reflect-padded to 720."""
    frames = [f.image_bgr for f in iter_frames(raw / "video.mp4")]
    w, h = 1280, 720
    scaled = []
    for im in frames:
        s = cv2.resize(im, (w, round(im.shape[0] * w / im.shape[1])),
                       interpolation=cv2.INTER_LINEAR)
        pad = h - s.shape[0]
        scaled.append(cv2.copyMakeBorder(s, pad // 2, pad - pad // 2, 0, 0, cv2.BORDER_REFLECT))
    order = list(range(len(scaled))) + list(range(len(scaled) - 2, 0, -1))
    writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), 30.0, (w, h))
    for k in range(round(seconds * 30)):
        writer.write(scaled[order[k % len(order)]])
    writer.release()
    return out


# --------------------------------------------------------------------------- accuracy


def run_cli(args: list[str], model_dir: Path) -> None:
    env = {**os.environ, "VID2SIM_MODEL_DIR": str(model_dir)}
    subprocess.run([sys.executable, "-m", "vid2sim", "-q", *args], env=env, check=True)


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def sparse_folders(tracking: Path, model_dir: Path, name: str, options: dict) -> None:
    """vid2sim detect and track on each labelled folder: recall/precision, range error."""
    counts = MatchCounts(0, 0, 0, 0)
    errors: list[tuple[float, float]] = []  # (true rear distance, relative error)
    with tempfile.TemporaryDirectory() as tmp:
        for seq in ("0001", "0016"):
            folder = tracking / "image_02" / seq
            labels = read_kitti_tracking_labels(tracking / "label_02" / f"{seq}.txt")
            pngs = sorted(folder.glob("*.png"))
            det_csv, trk_csv = Path(tmp) / f"d{seq}.csv", Path(tmp) / f"t{seq}.csv"
            run_cli(["detect", str(folder), *cli_flags(options), "--out", str(det_csv)],
                    model_dir)
            run_cli(["track", str(folder), "--camera", str(tracking / "camera_0001.yaml"),
                     *cli_flags(options), "--out", str(trk_csv)], model_dir)
            dets, trks = read_rows(det_csv), read_rows(trk_csv)
            for i, png in enumerate(pngs):
                frame_labels = labels.get(int(png.stem), [])
                found = [Detection(tuple(float(r[k]) for k in ("x1", "y1", "x2", "y2")),
                                   float(r["score"]), r["category"])
                         for r in dets if int(r["frame"]) == i]
                counts = counts + score_against_kitti(found, frame_labels)
                vehicles = [lab for lab in frame_labels if lab.type in ("Car", "Van", "Truck")]
                rows = [r for r in trks if int(r["frame"]) == i and r["range_m"] not in ("", "nan")]
                if not vehicles or not rows:
                    continue
                iou = iou_matrix(np.array([[float(r[k]) for k in ("x1", "y1", "x2", "y2")]
                                           for r in rows]),
                                 np.array([lab.box_px for lab in vehicles]))
                for j, r in enumerate(rows):
                    k = int(iou[j].argmax())
                    if iou[j, k] >= 0.5:
                        truth = vehicles[k].location_m[2] - vehicles[k].size_hwl_m[2] / 2
                        errors.append((truth, (float(r["range_m"]) - truth) / truth))
    e = np.array(errors).reshape(-1, 2)
    near, far = e[e[:, 0] < 20], e[e[:, 0] >= 20]

    def fmt(a: np.ndarray) -> str:
        if len(a) == 0:
            return "-"
        return (f"|rel| {100 * np.median(np.abs(a[:, 1])):.1f} %, bias "
                f"{100 * np.median(a[:, 1]):+.1f} % ({len(a)})")

    print(f"  {name}: detect on the 6 labelled frames recall "
          f"{counts.recall:.2f} precision {counts.precision:.2f} ({counts.n_found}/"
          f"{counts.n_targets}, {counts.n_false}/{counts.n_detections} false); track range: "
          f"all {fmt(e)}; < 20 m {fmt(near)}; >= 20 m {fmt(far)}")
    SUMMARY[name]["detect"] = f"{counts.recall:.2f} / {counts.precision:.2f}"


class FrameCache:
    """The default detector's boxes of every frame of a clip, found once: a full run of the
    detector depends on its frame only, so the keyframe schedule gets the boxes it would
    compute. A keyframe that looks at part of the frame (a second look at a new track) runs
    the detector on that part."""

    def __init__(self, detector, video: Path):
        self.detector = detector
        self.input_size_px = detector.input_size_px
        self.boxes = {f.index: detector.detect(f.image_bgr) for f in iter_frames(video)}
        self.images: dict[bytes, int] = {}

    def full_look(self, width_px: int, height_px: int):
        return self.detector.full_look(width_px, height_px)

    def detect(self, image_bgr: np.ndarray, look=None) -> list[Detection]:
        if look is not None:
            return self.detector.detect(image_bgr, look)
        key = image_bgr.tobytes()[:: 9973]  # frames differ; a sparse fingerprint finds them
        return self.boxes[self.images[key]]

    def learn(self, video: Path) -> None:
        for f in iter_frames(video):
            self.images[f.image_bgr.tobytes()[:: 9973]] = f.index


def composite(shared: Path, model_dir: Path, seeds: list[int], configs=CONFIGS) -> None:
    data = shared / "data"
    raw, tracking = data / "kitti_raw_0001", data / "kitti_tracking"
    cutout = cp.load_cutout(tracking, "polo")
    info = video_info(raw / "video.mp4")
    camera, _ = fit_camera_to_frames(load_camera(raw / "camera.yaml"), info.width, info.height)
    lane = measure_ego_lane(raw, camera, 108)
    with tempfile.TemporaryDirectory() as tmp:
        clips = []
        for seed in seeds:
            # in the drive's measured lane, as benchmarks/bench_composite.py (not --on-axis)
            truth = in_lane(cp.lead_profile(seed, 108), lane)
            clips.append((truth, cp.write_composite_clip(raw, cutout, truth,
                                                         Path(tmp) / f"c{seed}.mp4")))
        caches: dict[tuple, list[FrameCache]] = {}
        for name, options in configs:
            settings = settings_for(model_dir, options)
            d = settings.detector
            key = (d.tiles, d.refine)  # what the detector's boxes depend on
            if key not in caches:
                detector = load_detector_for(settings)
                caches[key] = []
                for _, clip in clips:
                    cache = FrameCache(detector, clip.video)
                    cache.learn(clip.video)
                    caches[key].append(cache)
            composite_score(raw, [(t, c, k) for (t, c), k in zip(clips, caches[key],
                                                                   strict=True)],
                            seeds, name, settings)


def composite_score(raw: Path, clips: list, seeds: list[int], name: str,
                    settings: Settings) -> None:
    schedule = settings.detector.schedule()
    rel, sign, rate, present = [], [], [], []
    for truth, clip, cache in clips:
        info = video_info(clip.video)
        camera, _ = fit_camera_to_frames(load_camera(raw / "camera.yaml"), info.width,
                                         info.height)
        result, _, _ = pipeline.detect_and_range(clip.video, camera, detector=cache,
                                                 progress=False, schedule=schedule)
        lead = {b.frame: b for b in result.boxes if b.is_lead}
        for i, tb in enumerate(clip.boxes_px):
            b = lead.get(i)
            ok = b is not None and tb is not None and cp.box_iou(
                (b.x1, b.y1, b.x2, b.y2), tb) >= 0.5
            present.append(ok)
            if ok:
                err = (b.range_m - truth.range_m[i]) / truth.range_m[i]
                rel.append(abs(err))
                sign.append(err)
                if np.isfinite(b.range_rate_mps):
                    rate.append(b.range_rate_mps - truth.range_rate_mps[i])
    figures = (f"lead range |rel| median {100 * np.median(rel):.1f} %, bias "
               f"{100 * np.median(sign):+.1f} %, rate RMSE "
               f"{np.sqrt(np.mean(np.square(rate))):.2f} m/s, presence "
               f"{100 * np.mean(present):.0f} %")
    print(f"  {name}: composite seeds {seeds}: {figures}")
    SUMMARY[name]["composite"] = (f"range {100 * np.median(rel):.1f} % (bias "
                                  f"{100 * np.median(sign):+.1f} %), rate RMSE "
                                  f"{np.sqrt(np.mean(np.square(rate))):.2f} m/s, presence "
                                  f"{100 * np.mean(present):.0f} %")


def parked(raw: Path, model_dir: Path, name: str, options: dict) -> None:
    """The parked cars of KITTI raw 0001 against OXTS (as benchmarks/bench_parked_schedule.py):
    real truth nobody here produced."""
    settings = settings_for(model_dir, options)
    video = raw / "video.mp4"
    info = video_info(video)
    camera, _ = fit_camera_to_frames(load_camera(raw / "camera.yaml"), info.width, info.height)
    d = settings.detector
    result, cam, _ = pipeline.detect_and_range(
        video, camera, detector=load_detector_for(settings), progress=False,
        detect_every=d.detect_every, schedule=d.schedule())
    report = evaluate_parked(result, cam, ego_motion(raw)).report(name)
    line = next(x for x in report.splitlines() if x.strip().startswith("all"))
    print(f"  {name}: parked cars' range rate vs OXTS, {line.strip()}")
    n, rmse, med, bias = re.findall(r"[-+]?\d+\.?\d*", line)[:4]
    SUMMARY[name]["parked"] = (f"median abs error {med} m/s, signed {bias}, RMSE {rmse} "
                               f"({n} boxes)")


def demo(model_dir: Path, name: str, options: dict) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        result = run_demo(Path(tmp), settings=settings_for(model_dir, options))
        wall = time.perf_counter() - t0
    m = result.metrics or {}
    print(f"  {name}: demo with the real detector: keyframe F1 "
          f"{m.get('f1', float('nan')):.3f}, mean IoU {m.get('mean_iou', float('nan')):.3f} "
          f"(build {wall:.0f} s)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shared", type=Path, default=SHARED)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--no-accuracy", action="store_true")
    parser.add_argument("--no-speed", action="store_true")
    parser.add_argument("--no-720p", action="store_true")
    parser.add_argument("--quick-720p", action="store_true",
                        help="the 720p clip with the default settings only")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5])
    parser.add_argument("--options", action="store_true",
                        help="what each speed option of track/build buys and costs, on KITTI "
                        "raw 0001 (speed, labelled frames, composite clips, parked cars)")
    args = parser.parse_args(argv)
    data, model_dir = args.shared / "data", args.shared / "models"
    raw = data / "kitti_raw_0001"
    for p in (raw, data / "kitti_tracking", model_dir):
        if not p.exists():
            print(f"error: {p}: not found (the real data and the detector weights are in ../shared beside the repository; give --shared DIR)", file=sys.stderr)
            return 2
    if args.options:
        return options_table(args, raw, model_dir)
    if not args.no_speed:
        _instrument()
        speed("KITTI raw 0001", raw / "video.mp4", raw / "camera.yaml", model_dir, args.repeat)
        cli_runs(raw, model_dir, args.repeat)
        if not args.no_720p:
            with tempfile.TemporaryDirectory() as tmp:
                clip = make_720p_clip(raw, Path(tmp) / "clip720.mp4")
                speed("generated 720p clip", clip, None, model_dir, max(1, args.repeat - 1),
                      CONFIGS[:1] if args.quick_720p else CONFIGS)
    if not args.no_accuracy:
        print("\naccuracy, default keyframes against the detector on every frame")
        for name, options in CONFIGS:
            sparse_folders(data / "kitti_tracking", model_dir, name, options)
        composite(args.shared, model_dir, args.seeds)
        for name, options in CONFIGS:
            demo(model_dir, name, options)
    print(f"\npeak RSS of this process {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
    return 0


def options_table(args, raw: Path, model_dir: Path) -> int:
    """``--options``: every entry of :data:`OPTIONS` measured on the same clips, then one
    table (speed on KITTI raw 0001 in-process; recall/precision of ``vid2sim detect`` on the
    six labelled frames; the composite clips' lead; the parked cars against OXTS)."""
    _instrument()
    speed("KITTI raw 0001", raw / "video.mp4", raw / "camera.yaml", model_dir, args.repeat,
          OPTIONS)
    print("\naccuracy of each option")
    for name, options in OPTIONS:
        sparse_folders(args.shared / "data" / "kitti_tracking", model_dir, name, options)
    composite(args.shared, model_dir, args.seeds, OPTIONS)
    for name, options in OPTIONS:
        parked(raw, model_dir, name, options)
    print("\n| option | track, KITTI raw 0001 | detect recall / precision | composite lead | "
          "parked cars vs OXTS |\n| --- | --- | --- | --- | --- |")
    for name, _ in OPTIONS:
        row = SUMMARY[name]
        print(f"| `{name}` | {row.get('speed', '-')} | {row.get('detect', '-')} | "
              f"{row.get('composite', '-')} | {row.get('parked', '-')} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
