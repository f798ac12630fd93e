"""Accuracy and speed of monocular ranging (issue 5), printed as a table.

    python benchmarks/bench_ranging.py [--clips 6] [--seconds 30] [--kitti] [--kitti-rate]
                                       [--video] [--parked]

1. Synthetic clips with known truth (generated here; boxes are the hull of each vehicle's
   outline, tyres, arches and mirrors, not a cuboid): a pitched dash-cam whose camera file
   says "level", body pitch on the suspension and braking nose-dives, a road that is not a
   plane (a grade change ahead, cross-fall), a lead that speeds up and brakes at random,
   traffic in the neighbouring lanes (cars of fleet-spread widths and lengths, trucks), a
   cut-in, box noise and missed detections. Reported: median |relative range error| (lead, all), lead range-rate
   RMSE, share of frames with a true lead where the lead chosen is the right vehicle.
2. ``--kitti``: single-frame ranging (with the cuboid outline: a label's 2D box is its projected
   cuboid) of the labelled boxes of every 10th frame of all KITTI
   tracking sequences in ``../shared/data/kitti_tracking`` (median |rel. error| per range bin).
3. ``--kitti-rate``: range RATE on real data: the labelled boxes of every frame (10 Hz) of all
   KITTI tracking sequences as tracks, against the rate of the labelled rear distance Z - l/2
   (a local quadratic fit over 1.1 s, see :func:`kitti_rate_truth`); RMSE and median |error|
   of the labelled ego-lane lead and of all vehicles per range bin, lead range error and the
   share of lead frames where the labelled lead is the one marked ``is_lead``.
4. ``--video``: wall time of ``vid2sim track`` on ``../shared/data/kitti_raw_0001/video.mp4``.
5. Speed of ``range_tracks`` alone, in boxes per second.

``--parked``: range RATE through the real detector on ``kitti_raw_0001/video.mp4``: the parked
cars' rates against the exact rate of a static object from the OXTS speed and yaw rate, per
range bin and per track, their ranges against the odometry, with detect_every 1 and 2 (the
truth lives in vid2sim/evaluate/ranging/, shared with tests/detect/test_ranging_parked.py).
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.app.tracking import run_track
from vid2sim.core.camera import Camera, fit_camera_to_frames, load_camera
from vid2sim.core.outline import CAR_SHAPE, TRUCK_SHAPE, OutlineShape, project_outline
from vid2sim.core.records import TrackedBox
from vid2sim.detect.pipeline import detect_and_range, range_and_assign
from vid2sim.detect.ranging import RangingConfig, cuboid_config
from vid2sim.detect.tracking.tracker import TrackerConfig
from vid2sim.detect.vehicles.detector import load_detector
from vid2sim.detect.vehicles.external import read_kitti_tracking_labels
from vid2sim.detect.video import video_info
from vid2sim.evaluate.ranging.kitti import (
    RATE_BINS_M,
    join_rows,
    kitti_label_boxes,
    kitti_rate_figures,
    kitti_rate_rows,
)
from vid2sim.evaluate.ranging.static import ego_motion, evaluate_parked

SHARED = Path(__file__).resolve().parents[1].parent / "shared"


def _random_profile(rng, duration_s: float, dt: float, x0: float, lo: float, hi: float):
    """Range x(t) and rate v(t) of a vehicle whose relative acceleration changes every ~2 s
    (sigma 1.5 m/s^2, braking bursts to -5 m/s^2), kept between ``lo`` and ``hi`` metres."""
    n = round(duration_s / dt)
    x, v = np.zeros(n), np.zeros(n)
    x[0], acc = x0, 0.0
    for k in range(1, n):
        if k % 20 == 0:
            acc = float(rng.normal(0, 1.5)) if rng.random() > 0.15 else -5.0
        if (x[k - 1] < lo + 5 and acc < 0) or (x[k - 1] > hi - 5 and acc > 0):
            acc = -acc
        v[k] = float(np.clip(v[k - 1] + acc * dt, -12, 12))
        x[k] = x[k - 1] + 0.5 * (v[k - 1] + v[k]) * dt
    return x, v


def _car_size(rng) -> tuple[float, float, float]:
    """Width, length and height [m] of a passenger car drawn from the fleet: body widths
    1.60-1.90 m about a 1.75 m mean, lengths 3.6-5.0 m, heights 1.40 m (saloons) to 1.75 m
    (SUVs) about 1.52 m (see DEFAULT_PRIORS in vid2sim/detect/ranging/config.py; the draws are independent of the
    priors' exact means so that no cue is exact by construction)."""
    return (float(np.clip(rng.normal(1.75, 0.12), 1.55, 2.0)),
            float(np.clip(rng.normal(4.4, 0.45), 3.5, 5.2)),
            float(np.clip(rng.normal(1.52, 0.10), 1.35, 1.85)))


def _car_shape(rng) -> OutlineShape:
    """A passenger car's outline drawn from the fleet about the class shape (see
    vid2sim/core/outline.py for the sources): tyre contact 0.6-1.1 m ahead of the rear face (city
    cars to saloons), the rear face 0.05-0.18 m narrower on each side, mirrors 0.06-0.14 m out,
    the rear bumper 0.25-0.45 m high. Drawn independently of the class shape's exact values,
    so that no cue is exact by construction."""
    contact = float(np.clip(rng.normal(0.85, 0.12), 0.6, 1.1))
    return replace(CAR_SHAPE, contact_m=contact, widest_m=contact,
                   rear_inset_m=float(np.clip(rng.normal(0.11, 0.04), 0.05, 0.18)),
                   mirror_out_m=float(np.clip(rng.normal(0.1, 0.02), 0.06, 0.14)),
                   rear_clearance_m=float(np.clip(rng.normal(0.35, 0.05), 0.25, 0.45)))


def _truck_shape(rng) -> OutlineShape:
    """A truck seen from behind: square box body, underrun guard 0.4-0.55 m high, last axle
    1.5-3 m ahead of the rear, mirrors 0.2-0.3 m out."""
    return replace(TRUCK_SHAPE, contact_m=float(rng.uniform(1.5, 3.0)),
                   rear_clearance_m=float(rng.uniform(0.4, 0.55)),
                   mirror_out_m=float(rng.uniform(0.2, 0.3)))


def road_height_m(x_m: float, y_m: float, grade_change: float, grade_start_m: float) -> float:
    """Height of the road [m] at (x, y) relative to the plane under the ego wheels: a change
    of grade ``grade_change`` (e.g. a sag or crest ahead) from ``grade_start_m`` on, and a
    2.5 % cross-fall from the crown at the centre line (y = +1.8 m) down to the kerbs."""
    return (grade_change * max(x_m - grade_start_m, 0.0)
            - 0.025 * (abs(y_m - 1.8) - 1.8))


def synthetic_clip(seed: int, duration_s: float = 30.0, dt: float = 0.1, flat: bool = False,
                   pitching: bool = True):
    """Boxes, truth {(frame, id): (range, lateral, rate)}, true lead id per frame, camera file,
    true mean pitch [deg] and lane-marking horizon hints [px] (emulated).

    Unless ``flat``, the road is not a plane: a grade change of N(0, 2 %) begins 15-60 m
    ahead and the lanes have cross-fall (:func:`road_height_m`). Boxes are the hull of each
    vehicle's outline as the camera sees it (:func:`vid2sim.core.outline.project_outline`: tyre
    contact, widest section, mirrors; outlines drawn by :func:`_car_shape` and
    :func:`_truck_shape`), not projected cuboids."""
    rng = np.random.default_rng(seed)
    # The outlines come from their own stream, so the trajectories and sizes are those of
    # the cuboid boxes this bench used before issue 13.
    shape_rng = np.random.default_rng(10_000 + seed)
    hfov = float(rng.uniform(70, 100))
    cam_file = Camera.default_for(1280, 720, hfov_deg=hfov)
    true_pitch = float(rng.uniform(-2.0, 2.0))
    n = round(duration_s / dt)
    vehicles = []  # (id, x[n], y[n], v[n], W, L, H, category)
    x_lead, v_lead = _random_profile(rng, duration_s, dt, float(rng.uniform(20, 40)), 20, 70)
    x, v = x_lead, v_lead
    vehicles.append((1, x, np.full(n, rng.normal(0, 0.3)), v, *_car_size(rng), "car"))
    tid = 2
    for lane_y in (3.6, -3.6, 7.2):
        for _ in range(2):
            x, v = _random_profile(rng, duration_s, dt, float(rng.uniform(10, 70)), 6, 90)
            truck = rng.random() < 0.25
            # Trucks: 2.55 m bodies (smaller ones 2.3 m; the mirrors are in the outline).
            w_m, l_m, h_m = ((min(float(rng.uniform(2.3, 3.0)), 2.55), 10.0,
                              float(rng.uniform(3.0, 4.0))) if truck else _car_size(rng))
            vehicles.append((tid, x, np.full(n, lane_y + rng.normal(0, 0.3)), v, w_m, l_m,
                             h_m, "truck" if truck else "car"))
            tid += 1
    # A cut-in from the right at a random time, ending in the ego lane.
    t_cut = int(rng.uniform(0.3, 0.7) * n)
    y_cut = np.clip(-3.6 + 3.6 * (np.arange(n) - t_cut) / 25.0, -3.6, 0.0)
    # It cuts in 7-15 m in front of the lead (a gap that varies, never overlapping).
    period_s, phase = float(rng.uniform(8, 15)), float(rng.uniform(0, 2 * math.pi))
    w = 2 * math.pi / period_s
    t_all = np.arange(n) * dt
    gap = 11.0 + 4.0 * np.sin(w * t_all + phase)
    gap_rate = 4.0 * w * np.cos(w * t_all + phase)
    x, v = x_lead - gap, v_lead - gap_rate
    vehicles.append((tid, x, y_cut, v, *_car_size(rng), "car"))
    shapes = {vid: (_truck_shape(shape_rng) if cat == "truck" else _car_shape(shape_rng))
              for vid, *_, cat in vehicles}
    grade_change = 0.0 if flat else float(rng.normal(0, 0.02))
    grade_start_m = float(rng.uniform(15, 60))

    # Body pitch on the suspension: AR(1) with 0.5 s correlation and 0.15 deg spread, plus
    # two braking nose-dives of 0.8 deg for 2 s (ramps of 0.3 s).
    a = math.exp(-dt / 0.5)
    body = np.zeros(n)
    for k in range(1, n):
        body[k] = a * body[k - 1] + math.sqrt(1 - a * a) * 0.15 * float(rng.normal()) * pitching
    t = np.arange(n) * dt
    for t0 in rng.uniform(2, duration_s - 4, 2):
        body += 0.8 * pitching * np.clip(np.minimum(t - t0, t0 + 2.0 - t) / 0.3, 0, 1)

    boxes, truth, true_lead, hints = [], {}, {}, []
    lim = np.array([0, 0, 1279, 719], dtype=float)
    for k in range(n):
        cam = cam_file.with_pitch(true_pitch + body[k])
        if k % 5 == 0:  # what HorizonEstimator gives on every 5th frame (~2 px scatter)
            hints.append(cam.horizon_y_px() + float(rng.normal(0, 2.0)))
        in_lane = []
        for vid, xs, ys, vs, w, length, h, cat in vehicles:
            # A vehicle dz above the ego's road plane looks like a camera dz lower.
            dz = 0.0 if flat else road_height_m(xs[k], ys[k], grade_change, grade_start_m)
            box = project_outline(replace(cam, height_m=cam.height_m - dz), xs[k], ys[k], w,
                                  h, length, shapes[vid])
            if box is None:
                continue
            if abs(ys[k]) < 1.8:
                in_lane.append((xs[k], vid))
            if rng.random() < 0.05:  # missed detection
                continue
            b = np.array(box)
            size = np.array([b[2] - b[0], b[3] - b[1]] * 2)
            noisy = b + rng.normal(0, 1.0 + 0.02 * size)
            b = np.where(np.isclose(b, lim), b, noisy)
            boxes.append(TrackedBox(k, round(k * dt, 6), vid, cat, 0.9, *b))
            truth[(k, vid)] = (xs[k], ys[k], vs[k])
        if in_lane:
            true_lead[k] = min(in_lane)[1]
    return boxes, truth, true_lead, cam_file, true_pitch, hints


def bench_synthetic(n_clips: int, seconds: float, lane_hints: bool) -> None:
    what = "with emulated lane-marking hints" if lane_hints else "vehicles only, no lane hints"
    print(f"synthetic clips ({seconds:g} s at 10 Hz, pitched camera, file says level; {what}):")
    print("  seed  pitch  est.pitch  source               lead|rel|  all|rel|  "
          "lead rate RMSE  lead right")
    agg = {"lead": [], "all": [], "rate": [], "hit": [], "x": [], "present": [], "lat": []}
    for seed in range(n_clips):
        boxes, truth, true_lead, cam, pitch, hints = synthetic_clip(seed, seconds)
        res = range_and_assign(boxes, cam, horizon_hints_px=hints if lane_hints else None)
        rel_all, rel_lead, rate_err, x_lead, lat_err = [], [], [], [], []
        chosen = {b.frame: b.track_id for b in res.boxes if b.is_lead}
        for b in res.boxes:
            x, y, v = truth[(b.frame, b.track_id)]
            rel_all.append(abs(b.range_m - x) / x)
            if x < 40:
                lat_err.append(abs(b.lateral_m - y))
            if true_lead.get(b.frame) == b.track_id:
                rel_lead.append(abs(b.range_m - x) / x)
                if np.isfinite(b.range_rate_mps):
                    rate_err.append(b.range_rate_mps - v)
                    x_lead.append(x)
        have = {(b.frame, b.track_id) for b in boxes}
        # Frames where the true lead was detected (a missed box cannot be chosen).
        hit = np.mean([chosen.get(k) == tid for k, tid in true_lead.items() if (k, tid) in have])
        present = np.mean([k in chosen for k, tid in true_lead.items() if (k, tid) in have])
        rmse = math.sqrt(np.mean(np.square(rate_err)))
        print(f"  {seed:4d}  {pitch:+5.2f}  {res.pitch_deg_estimated:+9.2f}  "
              f"{res.horizon_source:19s}  {np.median(rel_lead):9.3%}  {np.median(rel_all):8.3%}"
              f"  {rmse:10.3f} m/s  {hit:9.1%}")
        agg["lead"] += rel_lead
        agg["all"] += rel_all
        agg["rate"] += rate_err
        agg["x"] += x_lead
        agg["hit"].append(hit)
        agg["present"].append(present)
        agg["lat"] += lat_err
    rate, x = np.array(agg["rate"]), np.array(agg["x"])
    near = math.sqrt(np.mean(np.square(rate[x < 40])))
    print(f"  all   lead median |rel range err| {np.median(agg['lead']):.2%}, all vehicles "
          f"{np.median(agg['all']):.2%}; lead range-rate RMSE {near:.3f} m/s below 40 m, "
          f"{math.sqrt(np.mean(np.square(rate))):.3f} m/s at all ranges (to 70 m); a lead on "
          f"{np.mean(agg['present']):.1%} and the right one on {np.mean(agg['hit']):.1%} of "
          "frames with a detected true lead; median |lateral error| below 40 m "
          f"{np.median(agg['lat']):.2f} m")


def bench_kitti() -> None:
    data = SHARED / "data" / "kitti_tracking"
    if not data.exists():
        print(f"KITTI tracking labels not found at {data}: skipped")
        return
    cat = {"Car": "car", "Van": "car", "Truck": "truck"}
    # The label boxes are projected cuboids: ranged with the cuboid outline (what they are).
    for name, cfg in (("guessed pitch (std 1 deg)",
                       cuboid_config(RangingConfig(camera_pitch_std_deg=1.0))),
                      ("default (a calibration's pitch: std 0.25 deg)", cuboid_config()),
                      ("calibrated camera (pitch std 0.05 deg)",
                       cuboid_config(RangingConfig(camera_pitch_std_deg=0.05)))):
        rows = []
        for lab in sorted((data / "label_02").glob("*.txt")):
            cam = load_camera(data / "calib" / lab.name)
            labels = read_kitti_tracking_labels(lab)
            for frame in sorted(labels)[::10]:
                objs = [o for o in labels[frame] if o.type in cat]
                if not objs:
                    continue
                res = range_and_assign([TrackedBox(frame, 0.0, o.track_id, cat[o.type], 1.0,
                                               *o.box_px) for o in objs], cam, config=cfg)
                for o, b in zip(objs, res.boxes, strict=True):
                    if o.box_px[3] - o.box_px[1] >= 25:
                        clean = o.truncated == 0 and o.occluded <= 1
                        rows.append((o.location_m[2] - o.size_hwl_m[2] / 2, b.range_m, clean))
        a = np.array(rows, dtype=float)
        for label, sel in (("all", np.ones(len(a), bool)), ("clean", a[:, 2] > 0)):
            t, e = a[sel, 0], a[sel, 1]
            rel = np.abs(e - t) / t
            bins = []
            for lo, hi in ((0, 20), (20, 40), (40, np.inf)):
                m = (t >= lo) & (t < hi)
                bins.append(f"{lo}-{hi:g} m: {np.median(rel[m]):.1%} (n={m.sum()})")
            print(f"KITTI labelled boxes, single frame, {name}, {label}: " + "; ".join(bins)
                  + f"; below 40 m {np.median(rel[t < 40]):.1%}")


# --------------------------------------------------------------------------- KITTI range rate


def bench_kitti_rate() -> None:
    data = SHARED / "data" / "kitti_tracking"
    if not data.exists():
        print(f"KITTI tracking labels not found at {data}: skipped")
        return
    per_seq = {}
    for lab in sorted((data / "label_02").glob("*.txt")):
        objs, boxes = kitti_label_boxes(lab)
        res = range_and_assign(boxes, load_camera(data / "calib" / lab.name),
                           config=cuboid_config())  # label boxes are projected cuboids
        per_seq[lab.stem] = kitti_rate_rows(objs, res.boxes)
    print("KITTI tracking, labelled boxes of every frame (10 Hz) as tracks, default config; "
          "range rate [m/s] against the labels' rear distance (quadratic over 1.1 s):")
    print("  seq   lead: frames  n  RMSE  med|e|  range|rel|  same  any   all<40: n   RMSE  "
          "med|e|  p90|e|   0-20 RMSE  20-40 RMSE  40+ RMSE   truth resid")
    table = {**per_seq, "all": join_rows(per_seq)}
    for name, rows in table.items():
        f = kitti_rate_figures(rows)
        print(f"  {name:4s}  {f['lead_frames']:12d} {f['lead_n']:4d} {f['lead_rmse']:5.2f} "
              f"{f['lead_med']:6.2f}  {f['lead_range_rel']:9.1%}  {f['lead_same']:4.0%} "
              f"{f['lead_any']:4.0%}  {f['all_n']:9d} {f['all_rmse']:6.2f} {f['all_med']:6.2f} "
              f"{f['all_p90']:6.2f}"
              f"   {f['bin_0-20_rmse']:9.2f}  {f['bin_20-40_rmse']:10.2f}  "
              f"{f['bin_40-inf_rmse']:8.2f}   {f['truth_resid_m'] * 100:5.1f} cm")
    f = kitti_rate_figures(table["all"])
    print(f"  truth: fit residual {f['truth_resid_m'] * 100:.1f} cm RMS -> slope noise "
          f"~{f['truth_rate_floor']:.3f} m/s if white; medians per bin: "
          + ", ".join(f"{lo:g}-{hi:g} m {f[f'bin_{lo:g}-{hi:g}_med']:.2f} m/s "
                      f"(n={f[f'bin_{lo:g}-{hi:g}_n']})" for lo, hi in RATE_BINS_M))


def bench_video() -> None:
    raw = SHARED / "data" / "kitti_raw_0001"
    if not raw.exists():
        print("KITTI raw 0001 not found: skipped")
        return
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        settings = Settings(detector=DetectorSettings(model_dir=SHARED / "models"),
                            progress=False)
        summary = run_track(Inputs(video=raw / "video.mp4", camera=raw / "camera.yaml"),
                            Path(tmp) / "tracks.csv", settings)
        print(f"vid2sim track on KITTI raw 0001: {time.perf_counter() - t0:.1f} s\n{summary}")


def run_pipeline(drive: Path, model_dir: Path, detect_every: int = 1):
    """The real pipeline on a drive's ``video.mp4`` and ``camera.yaml`` as ``vid2sim track``
    runs it (YOLOX-nano, the tracker's low score threshold): (RangingResult, camera used)."""
    video = drive / "video.mp4"
    info = video_info(video)
    camera, _ = fit_camera_to_frames(load_camera(drive / "camera.yaml"), info.width,
                                     info.height)
    detector = load_detector("yolox-nano", model_dir, score_threshold=TrackerConfig().low_score)
    result, camera, _ = detect_and_range(video, camera, detector=detector,
                                         detect_every=detect_every, progress=False)
    return result, camera


def bench_parked() -> None:
    """Range rate of the parked cars of KITTI raw 0001 through the real detector, tracker and
    ranging, against the OXTS ego motion (the truth and the table live in
    vid2sim/evaluate/ranging/static.py, shared with tests/detect/test_ranging_parked.py)."""
    raw, models = SHARED / "data" / "kitti_raw_0001", SHARED / "models"
    if not raw.exists() or not models.exists():
        print(f"KITTI raw 0001 or the detector weights not found under {SHARED}: skipped")
        return
    motion = ego_motion(raw)
    for every in (1, 2):
        t0 = time.perf_counter()
        result, camera = run_pipeline(raw, models, detect_every=every)
        label = f"KITTI raw 0001, detect_every={every} ({time.perf_counter() - t0:.0f} s)"
        print(evaluate_parked(result, camera, motion).report(label))


def bench_speed() -> None:
    boxes = []
    for seed in range(4):
        b, *_ = synthetic_clip(100 + seed, 120.0)
        boxes += [TrackedBox(x.frame + 1200 * seed, x.t_s + 120 * seed, x.track_id + 100 * seed,
                             x.category, x.score, x.x1, x.y1, x.x2, x.y2) for x in b]
    cam = Camera.default_for(1280, 720)
    t0 = time.perf_counter()
    range_and_assign(boxes, cam)
    dt = time.perf_counter() - t0
    print(f"range_tracks: {len(boxes)} boxes in {dt:.2f} s ({len(boxes) / dt:.0f} boxes/s)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clips", type=int, default=6)
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--kitti", action="store_true", help="also the KITTI labelled boxes")
    ap.add_argument("--kitti-rate", action="store_true",
                    help="only the range rate on the KITTI labelled boxes as 10 Hz tracks")
    ap.add_argument("--video", action="store_true", help="also vid2sim track on KITTI raw")
    ap.add_argument("--parked", action="store_true",
                    help="also range rate of KITTI raw 0001's parked cars vs the OXTS")
    args = ap.parse_args()
    if args.kitti_rate:
        bench_kitti_rate()
        return
    bench_synthetic(args.clips, args.seconds, lane_hints=False)
    bench_synthetic(args.clips, args.seconds, lane_hints=True)
    bench_speed()
    if args.kitti:
        bench_kitti()
    if args.video:
        bench_video()
    if args.parked:
        bench_parked()


if __name__ == "__main__":
    main()
