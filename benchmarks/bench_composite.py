"""Lead ranging on composite clips (a real KITTI car pasted into the real KITTI raw drive 0001
at a known trajectory; see ``vid2sim/samples/composite.py``), with the real detector, printed as a table.

    python benchmarks/bench_composite.py [--seeds 0 1 2 3] [--cars polo] [--cache DIR]
                                         [--no-pitch] [--keyframes] [--on-axis]

The car keeps its seeded lateral offsets (within 0.4 m) from the middle of the drive's real ego
lane (measured on the drive without the car, ``vid2sim.samples.cutin.measure_ego_lane``), so
it stays in that lane at 40 m; ``--on-axis`` takes them from the camera's axis instead, as the
clips did before issue 19: there the car beyond 30 m is often in the next lane (the axis is
1.8 m RMS off the real lane at 40 m) and the lead only 77 % of the frames (95 % in the lane).

Per clip and overall: lead range median |relative error| (and the signed median, the bias),
lead range-rate RMSE, lead presence (share of all frames whose chosen lead is the pasted car,
by box IoU >= 0.5 with the truth projection), plus diagnostics: detector recall on the pasted
car, frames where any track is on it, the track ids on it (several = id switches), the width the
ranging learnt for it against the pasted outline's width, and the horizon used. The bars on a
recorded clip with lidar truth are: median |rel err| <= 8 %, rate RMSE <= 0.5 m/s, presence
>= 95 %.

Measured with crop refinement, per-frame lane-marking horizons and weak boxes taking up a
briefly lost track (seeds 0-5, 108 frames each): lead range median |rel err| 3.0 % (bias
+3.0 %), range-rate RMSE 0.59 m/s over all lead frames (per clip 0.40-0.63, and 0.83 on
seed 0, whose car stays 31-41 m away), presence 100 %. Steps on the same detections: without
the weak take-up 3.1 %, 0.78 m/s, 96 % (seed 5 lost its far car for 22 frames after one
missed frame); without the per-frame horizon 5.3 %, 0.85 m/s; without refinement (the
centre window alone) 5.2 %, 1.00 m/s, 96 %; before the centre window (e83fd4b) 4.6 %,
1.05 m/s, 92 %. Why the rate bar is still missed: the per-frame range errors are correlated
over several frames (the detector's box errors on one car change slowly with its scale and
background), so the filter cannot average them away, and at 30-45 m one pixel of bottom edge
is 3 % of range (seed 0 reads +6 % at 40 m, 0 % at 33 m, which is range rate). Range: the
ranging learns 1.56-1.63 m for a car whose rear outline is 1.45 m (prior 1.75 m), so the
width cue reads long. The pasted car is harsher than a real one: narrow (no mirrors), shaded,
no cast shadow. Without the OXTS body pitch (``--no-pitch``) the rate RMSE was 1.09 m/s at
b5c7d87.

``--keyframes``: also ``vid2sim build`` each clip (video, OXTS, camera; the real detector)
with the composited car's truth box on every 10th frame as Scalabel keyframes, and report the
keyframe mean IoU of the replayed scenario (its actors projected as outlines) and the lead's
matches; the other cars of the drive are not annotated, so precision is not meaningful.

Detector output of each clip is cached in ``--cache`` (default /tmp/composite/cache) keyed by
car and seed, so re-runs only re-track and re-range; delete it after changing the compositing
or the detector.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from vid2sim.app.build import build
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.core.camera import fit_camera_to_frames, load_camera
from vid2sim.core.records import Detection
from vid2sim.detect.pipeline import detect_and_range
from vid2sim.detect.video import video_info
from vid2sim.samples import composite as cp
from vid2sim.samples.cutin import EgoLaneWorld, in_lane, measure_ego_lane

SHARED = Path(__file__).resolve().parents[1].parent / "shared"
N_FRAMES = 108


class RecordingDetector:
    """Wraps a detector and keeps what it found per call (frame order)."""

    def __init__(self, detector):
        self.detector = detector
        self.found: list[list[Detection]] = []

    def detect(self, image_bgr):
        dets = self.detector.detect(image_bgr)
        self.found.append(dets)
        return dets


def detections_for(clip: cp.CompositeClip, cache: Path, model_dir: Path
                   ) -> dict[int, list[Detection]]:
    """Per-frame detections of the real detector on the clip (cached)."""
    if cache.is_file():
        rows = json.loads(cache.read_text())
        return {int(k): [Detection(tuple(d[0]), d[1], d[2]) for d in v] for k, v in rows.items()}
    from vid2sim.detect.tracking.tracker import TrackerConfig
    from vid2sim.detect.vehicles.detector import load_detector
    from vid2sim.detect.video import iter_frames

    det = load_detector("yolox-nano", model_dir, score_threshold=TrackerConfig().low_score)
    out = {f.index: det.detect(f.image_bgr) for f in iter_frames(clip.video)}
    cache.parent.mkdir(parents=True, exist_ok=True)
    cache.write_text(json.dumps({k: [[list(d.box_px), d.score, d.category] for d in v]
                                 for k, v in out.items()}))
    return out


def run_clip(car: str, seed: int, raw_dir: Path, tracking_dir: Path, model_dir: Path,
             work: Path, cache_dir: Path, body_pitch: bool,
             lane: EgoLaneWorld | None = None) -> dict:
    cutout = cp.load_cutout(tracking_dir, car)
    truth = cp.lead_profile(seed, N_FRAMES)
    if lane is not None:
        truth = in_lane(truth, lane)
    clip = cp.write_composite_clip(raw_dir, cutout, truth, work / f"{car}_{seed}.mp4",
                                   use_body_pitch=body_pitch)
    tag = (f"{car}_{seed}{'' if body_pitch else '_nopitch'}"
           f"{'' if lane is None else '_inlane'}")
    t0 = time.perf_counter()
    dets = detections_for(clip, cache_dir / f"{tag}.json", model_dir)
    t_det = time.perf_counter() - t0
    info = video_info(clip.video)
    camera, _ = fit_camera_to_frames(load_camera(raw_dir / "camera.yaml"), info.width,
                                     info.height)
    result, _, _ = detect_and_range(clip.video, camera, detector=None, detections=dets,
                                    progress=False)
    vis_boxes = clip.boxes_px  # the pasted outline's projection in each frame
    score = cp.score_lead(result.boxes, truth, vis_boxes)
    recall = np.mean([tb is not None and any(cp.box_iou(d.box_px, tb) >= 0.5
                                             for d in dets.get(i, []))
                      for i, tb in enumerate(vis_boxes)])
    widths = [result.width_m_by_track.get(t, float("nan")) for t in score.car_track_ids]
    return {"car": car, "seed": seed, "score": score, "recall": float(recall),
            "widths": widths, "visible_width": cutout.visible_width_m,
            "horizon": f"{result.horizon_y_px:.1f} px ({result.horizon_source})",
            "range": (float(truth.range_m.min()), float(truth.range_m.max())),
            "detect_s": t_det, "result": result, "truth": truth, "boxes": vis_boxes,
            "dets": dets}


KEYFRAME_EVERY = 10


def keyframe_iou(r: dict, raw_dir: Path, model_dir: Path, work: Path) -> tuple[float, int]:
    """Build the clip and score the replay against the car's truth boxes at keyframes: mean
    IoU of the matched lead boxes and how many keyframes matched."""
    frames = []
    for i in range(0, N_FRAMES, KEYFRAME_EVERY):
        tb = r["boxes"][i]
        labels = [] if tb is None else [{"id": "lead", "category": "car",
                                         "box2d": dict(zip(("x1", "y1", "x2", "y2"), tb,
                                                           strict=True))}]
        frames.append({"name": f"{i:06d}.png", "index": i, "labels": labels})
    kf = work / f"{r['car']}_{r['seed']}_keyframes.json"
    kf.write_text(json.dumps(frames))
    settings = Settings(detector=DetectorSettings(model_dir=model_dir), allow_download=False,
                        progress=False)
    result = build(Inputs(video=work / f"{r['car']}_{r['seed']}.mp4", gps=raw_dir,
                          camera=raw_dir / "camera.yaml", keyframes=kf),
                   work / f"build_{r['car']}_{r['seed']}", settings)
    metrics = json.loads(Path(result.files["metrics"]).read_text())
    ious = [m["iou"] for k in metrics["per_keyframe"] for m in k.get("matches", [])]
    return (float(np.mean(ious)) if ious else float("nan")), len(ious)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5])
    parser.add_argument("--cars", nargs="+", default=["polo"], choices=sorted(cp.CARS))
    parser.add_argument("--shared", type=Path, default=SHARED)
    parser.add_argument("--cache", type=Path, default=Path("/tmp/composite/cache"))
    parser.add_argument("--no-pitch", action="store_true",
                        help="paste without the OXTS body pitch")
    parser.add_argument("--keyframes", action="store_true",
                        help="also build each clip and score the replay at keyframes")
    parser.add_argument("--on-axis", action="store_true",
                        help="the car's lateral offsets from the camera's axis (the clips "
                             "before issue 19) instead of the middle of the drive's measured "
                             "ego lane")
    args = parser.parse_args(argv)
    data = args.shared / "data"
    raw_dir, tracking_dir = data / "kitti_raw_0001", data / "kitti_tracking"
    model_dir = args.shared / "models"
    for p in (raw_dir, tracking_dir, model_dir):
        if not p.exists():
            print(f"missing {p}", file=sys.stderr)
            return 2
    print(f"{'car':9s} {'seed':>4s} {'range m':>11s} {'|rel| med':>9s} {'bias':>7s} "
          f"{'rate RMSE':>9s} {'present':>7s} {'wrong':>5s} {'tracked':>7s} {'recall':>6s} "
          f"{'ids':>8s} {'width learnt/pasted m':>21s}  horizon")
    rel_all, sign_all, rate_all, pres_all = [], [], [], []
    keyframe_ious: list[float] = []
    diag: list[tuple[float, ...]] = []  # per lead frame on the car: r, est, rate, est rate, acc
    missed: list[tuple[float, float]] = []  # per frame without the car as lead: r, best score
    lane = None
    if not args.on_axis:
        info = video_info(raw_dir / "video.mp4")
        camera, _ = fit_camera_to_frames(load_camera(raw_dir / "camera.yaml"), info.width,
                                         info.height)
        lane = measure_ego_lane(raw_dir, camera, N_FRAMES)
    with tempfile.TemporaryDirectory() as tmp:
        for car in args.cars:
            for seed in args.seeds:
                r = run_clip(car, seed, raw_dir, tracking_dir, model_dir, Path(tmp), args.cache,
                             not args.no_pitch, lane)
                if args.keyframes:
                    iou, n = keyframe_iou(r, raw_dir, model_dir, Path(tmp))
                    keyframe_ious.append(iou)
                    print(f"{car:9s} {seed:4d} keyframes: lead matched on {n} of "
                          f"{len(range(0, N_FRAMES, KEYFRAME_EVERY))}, mean IoU {iou:.3f}")
                s = r["score"]
                widths = "/".join(f"{w:.2f}" for w in r["widths"]) or "-"
                print(f"{car:9s} {seed:4d} {r['range'][0]:5.1f}-{r['range'][1]:4.1f} "
                      f"{100 * s.range_rel_err_median:8.1f}% {100 * s.range_bias_median:+6.1f}% "
                      f"{s.range_rate_rmse_mps:9.2f} {100 * s.presence:6.0f}% "
                      f"{s.wrong_lead_frames:5d} {100 * s.tracked_share:6.0f}% "
                      f"{100 * r['recall']:5.0f}% {','.join(map(str, s.car_track_ids)):>8s} "
                      f"{widths:>14s}/{r['visible_width']:.2f}  {r['horizon']}", flush=True)
                res, truth = r["result"], r["truth"]
                lead = {b.frame: b for b in res.boxes if b.is_lead}
                for i, tb in enumerate(r["boxes"]):
                    b = lead.get(i)
                    ok = b is not None and tb is not None and cp.box_iou(
                        (b.x1, b.y1, b.x2, b.y2), tb) >= 0.5
                    pres_all.append(ok)
                    if not ok and tb is not None:
                        best = max([d.score for d in r["dets"].get(i, [])
                                    if cp.box_iou(d.box_px, tb) >= 0.5] + [0.0])
                        missed.append((float(truth.range_m[i]), best))
                    if ok:
                        diag.append((truth.range_m[i], b.range_m, truth.range_rate_mps[i],
                                     b.range_rate_mps, truth.rel_accel_mps2[i]))
                        e = (b.range_m - truth.range_m[i]) / truth.range_m[i]
                        rel_all.append(abs(e))
                        sign_all.append(e)
                        if np.isfinite(b.range_rate_mps):
                            rate_all.append(b.range_rate_mps - truth.range_rate_mps[i])
    print(f"{'overall':9s} {'':4s} {'':11s} {100 * np.median(rel_all):8.1f}% "
          f"{100 * np.median(sign_all):+6.1f}% {np.sqrt(np.mean(np.square(rate_all))):9.2f} "
          f"{100 * np.mean(pres_all):6.0f}%   (bars: <= 8 %, <= 0.5 m/s, >= 95 %)")
    if keyframe_ious:
        print(f"keyframe mean IoU of the replayed lead over the clips: "
              f"{np.mean(keyframe_ious):.3f} (bar 0.7)")
    print_diagnostics(np.array(diag, dtype=float).reshape(-1, 5),
                      np.array(missed, dtype=float).reshape(-1, 2))
    return 0


def print_diagnostics(rows: np.ndarray, missed: np.ndarray) -> None:
    """Why figures miss: range bias by range, rate error by phase, frames without the car."""
    print("\nlead frames on the car, by true range:")
    rel = (rows[:, 1] - rows[:, 0]) / rows[:, 0]
    for lo, hi in ((8, 15), (15, 22), (22, 30), (30, 46)):
        m = (rows[:, 0] >= lo) & (rows[:, 0] < hi)
        if m.any():
            print(f"  {lo:2d}-{hi:2d} m: {m.sum():4d} frames, signed median {100 * np.median(rel[m]):+5.1f}%"
                  f", |rel| median {100 * np.median(np.abs(rel[m])):4.1f}%")
    err = rows[:, 3] - rows[:, 2]
    print("range-rate error by phase of the relative acceleration:")
    for name, m in (("braking  < -1 m/s^2", rows[:, 4] < -1), ("steady |a| <= 1", np.abs(rows[:, 4]) <= 1),
                    ("opening  >  1 m/s^2", rows[:, 4] > 1)):
        m = m & np.isfinite(err)
        if m.any():
            print(f"  {name}: {m.sum():4d} frames, RMSE {np.sqrt(np.mean(err[m] ** 2)):.2f} m/s, "
                  f"mean {np.mean(err[m]):+.2f} m/s (+ = estimate lags a falling rate)")
    if missed.size:
        print(f"frames without the car as lead: {len(missed)}; true range median "
              f"{np.median(missed[:, 0]):.1f} m; detector's best score on the car there: median "
              f"{np.median(missed[:, 1]):.2f}, {100 * np.mean(missed[:, 1] >= 0.5):.0f}% >= 0.5 "
              "(the tracker's new-track score)")


if __name__ == "__main__":
    raise SystemExit(main())
