"""Camera self-calibration on REAL footage re-imaged through known cameras, per clip.

    python benchmarks/bench_calibration.py [--seeds 0 1 2 3] [--modes pin dist]
                                           [--cache DIR] [--shared DIR] [--no-dgp]

(a) KITTI raw 0001 untouched (``video.mp4`` + OXTS; truth: ``camera.yaml``, 1.65 m);
(b) the same video re-imaged (``vid2sim.samples.reimage``) through a camera drawn at random
    per seed: field of view 50-72 deg, width 960-1280 px, principal point within 2 % of the
    centre, pitch and yaw within 2 deg, roll within 1 deg, and (``dist``) barrel distortion
    k1 -0.05..-0.3 (k2 = -k1 / 10) or (``pin``) none. Turning a camera about its centre
    changes no depth: the GPS, the road and the lidar truth stay, the camera is exactly the
    drawn one. The tool is given the video and the OXTS folder, never the camera;
(c) the TRI DGP front frames (``tri_dgp_front/scene_01``, 3 frames, no GPS), re-imaged with
    distortion: without motion the scale is not observable; the lens and horizon are.

Per clip: signed errors of fx [%], height [%], horizon row at the true principal point [px]
(the principal point is assumed at the image centre, so pitch differs by design), roll and
yaw [deg], k1; which cue fixed fx and the height; and the RANGE error the estimate alone
gives a point on the road straight ahead at 10, 20 and 40 m (seen through the true camera,
back-projected through the estimate): what the camera costs the ranging. CPU seconds of the
calibration (measurement + fit). Optional parts: (d) composite builds, (e) ``--ego-speed``,
(f) ``--sync``, (g) ``--cost`` (whole builds), (h) ``--stage-cost`` (the calibration stages
alone, CPU seconds).

Re-imaged clips are written to ``--cache`` (default /tmp/vid2sim-calib) and reused.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from vid2sim.app.inputs import Inputs
from vid2sim.app.selfcal import run_calibrate
from vid2sim.app.settings import Settings
from vid2sim.core.camera import Camera, load_camera
from vid2sim.samples.reimage import (
    draw_target_camera,
    reimage_frame,
    reimage_maps,
    write_reimaged_video,
)

RANGES_M = (10.0, 20.0, 40.0)


def range_errors(truth: Camera, est: Camera) -> list[float]:
    """Relative range error [%] of road points straight ahead (true camera -> pixels ->
    the estimate's road plane)."""
    out = []
    for r in RANGES_M:
        uv, ok = truth.project(np.array([[r, 0.0, 0.0]]))
        if not ok[0]:
            out.append(float("nan"))
            continue
        g, below = est.pixel_to_ground(uv)
        out.append(100.0 * (float(g[0, 0]) / r - 1.0) if below[0] else float("nan"))
    return out


def score(name: str, truth: Camera, est_path: Path, cpu_s: float) -> dict:
    est = load_camera(est_path)
    import yaml

    rec = yaml.safe_load(est_path.read_text())
    src = rec.get("source", {})
    return {"clip": name, "fx_pct": 100 * (est.fx / truth.fx - 1),
            "h_pct": 100 * (est.height_m / truth.height_m - 1),
            "horizon_px": est.horizon_y_px(truth.cx) - truth.horizon_y_px(),
            "roll_deg": est.roll_deg - truth.roll_deg, "yaw_deg": est.yaw_deg - truth.yaw_deg,
            "k1": est.dist[0] - truth.dist[0], "k1_true": truth.dist[0],
            "fx_src": src.get("fx", ""), "h_src": src.get("height_m", ""),
            "range_pct": range_errors(truth, est), "cpu_s": cpu_s}


def calibrate_clip(video: Path, gps: Path | None, out: Path, fps: float | None = None
                   ) -> float:
    t0 = time.process_time()
    run_calibrate(Inputs(video=video, gps=gps, fps=fps), out,
                  Settings(progress=False, camera_cache=False))
    return time.process_time() - t0


def kitti_clips(raw: Path, cache: Path, seeds: list[int], modes: list[str]) -> list[dict]:
    source = load_camera(raw / "camera.yaml")
    cap = cv2.VideoCapture(str(raw / "video.mp4"))
    w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    cap.release()
    source = replace(source, image_width=w, image_height=h)
    rows = []
    out = cache / "kitti_orig.camera.yaml"
    rows.append(score("kitti 0001", source, out, calibrate_clip(raw / "video.mp4", raw, out)))
    for mode in modes:
        for seed in seeds:
            target = draw_target_camera(source, seed, distorted=mode == "dist").camera
            clip = cache / f"kitti_{mode}_{seed}.mp4"
            if not clip.exists():
                write_reimaged_video(raw / "video.mp4", source, target, clip)
            out = cache / f"kitti_{mode}_{seed}.camera.yaml"
            rows.append(score(f"kitti {mode} {seed}", target, out,
                              calibrate_clip(clip, raw, out)))
            print(rows[-1], flush=True)
    return rows


def dgp_clip(shared: Path, cache: Path) -> dict | None:
    from vid2sim.evaluate.ranging.dgp import ground_camera, read_dgp_scene

    scene = shared / "tri_dgp_front" / "scene_01"
    if not scene.is_dir():
        return None
    frames = read_dgp_scene(scene)
    truth_src, _, _ = ground_camera(frames[0])
    folder = cache / "dgp_dist"
    # TRI's lens spans 48 deg across: the target sees a part of it
    target = draw_target_camera(truth_src, 7, distorted=True,
                                hfov_range_deg=(30.0, 40.0)).camera
    if not folder.exists():
        folder.mkdir(parents=True)
        maps = reimage_maps(target, truth_src)
        for i, f in enumerate(frames):
            cv2.imwrite(str(folder / f"{i:06d}.png"), reimage_frame(cv2.imread(str(f.image)),
                                                                    maps))
    out = cache / "dgp_dist.camera.yaml"
    return score("dgp dist", target, out, calibrate_clip(folder, None, out, fps=10.0))


def composite_build(raw: Path, shared: Path, cache: Path, seed: int, cam_seed: int) -> dict:
    """(d) A real car pasted ahead in the drive (``vid2sim.samples.composite``), the clip
    re-imaged through a distorted camera, ``vid2sim build`` with the OXTS and keyframes of
    the pasted car's truth box (mapped through the same camera) but no camera file: the lead
    range against the composite's exact truth, and the keyframes' mean IoU."""
    from vid2sim.app.build import build
    from vid2sim.app.settings import DetectorSettings
    from vid2sim.core.tables import read_tracks_csv
    from vid2sim.samples import composite as cp
    from vid2sim.samples.reimage import map_box

    source = load_camera(raw / "camera.yaml")
    source = replace(source, image_height=374)
    truth = cp.lead_profile(seed, 108)
    clip = cp.write_composite_clip(raw, cp.load_cutout(shared / "kitti_tracking", "polo"),
                                   truth, cache / f"comp_{seed}.mp4")
    target = draw_target_camera(source, cam_seed, distorted=True).camera
    video = write_reimaged_video(clip.video, source, target,
                                 cache / f"comp_{seed}_d{cam_seed}.mp4")
    boxes = [map_box(b, src_cam, target) if b is not None else None
             for b, src_cam in zip(clip.boxes_px, clip.cameras, strict=True)]
    frames = [{"name": f"{i:06d}.png", "index": i,
               "labels": [] if boxes[i] is None else [{"id": "lead", "category": "car",
                                                       "box2d": dict(zip(("x1", "y1", "x2",
                                                                          "y2"), boxes[i],
                                                                         strict=True))}]}
              for i in range(0, 108, 10)]
    kf = cache / f"comp_{seed}_d{cam_seed}_keyframes.json"
    kf.write_text(json.dumps(frames))
    t0 = time.process_time()
    res = build(Inputs(video=video, gps=raw, keyframes=kf),
                cache / f"build_comp_{seed}_d{cam_seed}",
                Settings(detector=DetectorSettings(model_dir=shared.parent / "models"),
                         allow_download=False, progress=False, camera_cache=False))
    cpu = time.process_time() - t0
    score = cp.score_lead(read_tracks_csv(res.files["tracks"]), truth, boxes)
    metrics = json.loads(Path(res.files["metrics"]).read_text())
    ious = [m["iou"] for k in metrics["per_keyframe"] for m in k.get("matches", [])]
    est = load_camera(res.files["camera"])
    return {"clip": f"composite {seed} cam {cam_seed}", "range_med_pct": 100
            * score.range_rel_err_median, "range_bias_pct": 100 * score.range_bias_median,
            "presence": score.presence, "iou": float(np.mean(ious)) if ious else float("nan"),
            "n_iou": len(ious), "true_range_m": (float(truth.range_m.min()),
                                                   float(truth.range_m.max())),
            "fx_pct": 100 * (est.fx / target.fx - 1),
            "h_pct": 100 * (est.height_m / target.height_m - 1),
            "k1": est.dist[0], "k1_true": target.dist[0], "build_cpu_s": cpu,
            "calib_s": res.stage_seconds.get("calibration cues", 0.0)
            + res.stage_seconds.get("calibrate camera", 0.0)}


def ego_speed_check(raw: Path) -> str:
    """(e) Camera-only ego speed on KITTI raw 0001 (video and camera file, no GPS) against
    the OXTS forward speed ``vf``: per flow pair and smoothed as the build smooths it.

    The video's container clock runs at 10 fps while the camera captured at 9.67 Hz
    (``image_00_timestamps.txt``): speeds per container second are 3.3 % below speeds per
    real second. Both are shown: against ``vf`` as is, and with the pairs timed by the
    camera's own timestamps."""
    from vid2sim.app.buildgeo import smoothed_speeds
    from vid2sim.app.selfcal import measure_cues_for, start_camera, visual_ego_speeds
    from vid2sim.detect.video import video_info
    from vid2sim.geo.readers import OXTS_VF, kitti_time_s, read_kitti_oxts_table

    inputs = Inputs(video=raw / "video.mp4", camera=raw / "camera.yaml")
    settings = Settings(progress=False, camera_cache=False)
    info = video_info(raw / "video.mp4")
    choice = start_camera(inputs, info, settings)
    t0 = time.process_time()
    measure_cues_for(choice, inputs, info, settings)
    speeds = visual_ego_speeds(choice, info, settings)
    cpu = time.process_time() - t0
    cam_t = np.array([kitti_time_s(s) for s in (raw / "image_00_timestamps.txt")
                      .read_text().split("\n") if s.strip()])
    ox_t = np.array([kitti_time_s(s) for s in (raw / "oxts" / "timestamps.txt")
                     .read_text().split("\n") if s.strip()])
    vf = read_kitti_oxts_table(raw / "oxts")[:, OXTS_VF]
    lines = []
    for label, (t, v) in (("per pair", (np.array([s[0] for s in speeds]),
                                        np.array([s[1] for s in speeds]))),
                          ("smoothed 1 s", smoothed_speeds(speeds))):
        frame = t * info.fps  # container time -> frame index (fractional)
        real = np.interp(frame, np.arange(len(cam_t)), cam_t - cam_t[0])
        truth = np.interp(real + cam_t[0], ox_t, vf)
        rate = np.gradient(real, frame).mean() * info.fps  # real seconds per container s
        for clock, vv in (("container clock", v), ("camera clock", v / rate)):
            err = vv - truth
            lines.append(f"camera-only ego speed, {label}, {clock}: RMSE "
                         f"{np.sqrt(np.mean(err ** 2)):.2f} m/s, bias {np.mean(err):+.2f} m/s "
                         f"over {len(err)} pairs ({truth.min():.1f}-{truth.max():.1f} m/s)")
    lines.append(f"  cues and speeds {cpu:.1f} s CPU")
    return "\n".join(lines)


def _oxts_csv(raw: Path, skip: int, out: Path, container_clock: bool = False) -> float:
    """The OXTS fixes from the ``skip``-th on as a CSV with no video clock (times on an
    arbitrary UTC base), speed and course from the INS; the true video time [s, container
    clock] of its first fix.

    KITTI's ``video.mp4`` plays its frames at 10 fps while the camera captured them every
    0.1032 s: video time runs 3.1 % slow against the OXTS's, which one offset cannot
    absorb (the sync fits a clock rate with the offset where the motion pins it). With
    ``container_clock`` the fixes are re-timed onto the video's clock through the camera's
    timestamps (the drive as a camera with a true frame clock would have recorded it)."""
    from vid2sim.geo.oxts import OXTS_LAT, OXTS_LON, OXTS_VE, OXTS_VN, OXTS_YAW
    from vid2sim.geo.readers import kitti_time_s, read_kitti_oxts_table

    table = read_kitti_oxts_table(raw / "oxts")
    ox_t = np.array([kitti_time_s(s) for s in (raw / "oxts" / "timestamps.txt")
                     .read_text().split("\n") if s.strip()])
    cam_t = np.array([kitti_time_s(s) for s in (raw / "image_00_timestamps.txt")
                      .read_text().split("\n") if s.strip()])
    cap = cv2.VideoCapture(str(raw / "video.mp4"))
    fps = cap.get(cv2.CAP_PROP_FPS)
    cap.release()
    video_t = np.interp(ox_t, cam_t, np.arange(len(cam_t)),
                        left=np.nan, right=np.nan) / fps
    # beyond the camera's span: the camera's mean interval
    dt = float(np.mean(np.diff(cam_t)))
    video_t = np.where(np.isfinite(video_t), video_t, (ox_t - cam_t[0]) / dt / fps)
    times = video_t if container_clock else ox_t - ox_t[0]
    rows = ["t,lat,lon,speed,heading"]
    for i in range(skip, len(table)):
        course = (90.0 - math.degrees(table[i, OXTS_YAW])) % 360.0
        rows.append(f"{1.3e9 + times[i]:.3f},{table[i, OXTS_LAT]:.8f},{table[i, OXTS_LON]:.8f},"
                    f"{math.hypot(table[i, OXTS_VN], table[i, OXTS_VE]):.3f},{course:.3f}")
    out.write_text("\n".join(rows) + "\n")
    # the fix's time as a (fractional) frame index of the camera's own timestamps, on the
    # container's clock (frame / fps): what the tool's video time is
    return float(video_t[skip])


def sync_check(raw: Path, cache: Path) -> list[dict]:
    """(f) GPS-video time sync on KITTI raw 0001: the OXTS as a CSV without a video clock,
    whole and with its first 1.5 s removed (the GPS starts late), on the OXTS's clock and
    re-timed onto the video's (:func:`_oxts_csv`); ``calibrate`` without a camera file or
    ``--gps-offset``: the estimated video time of the first fix against the truth from the
    camera's and the OXTS's timestamps."""
    rows = []
    for skip, clock in ((0, False), (15, False), (0, True), (15, True)):
        label = "video clock" if clock else "OXTS clock"
        gps = cache / f"oxts_skip{skip}_{clock}.csv"
        truth_s = _oxts_csv(raw, skip, gps, clock)
        out = cache / f"sync_skip{skip}_{clock}.camera.yaml"
        t0 = time.process_time()
        text = run_calibrate(Inputs(video=raw / "video.mp4", gps=gps), out,
                             Settings(progress=False, camera_cache=False))
        cpu = time.process_time() - t0
        import yaml

        rec = yaml.safe_load(out.read_text())
        off = rec.get("gps_offset_s") or {}
        rate = rec.get("gps_clock_rate") or {}
        est = load_camera(out)
        cam = load_camera(raw / "camera.yaml")
        rows.append({"clip": f"kitti 0001 gps -{skip / 10:.1f} s, {label}", "truth_s": truth_s,
                     "offset_s": off.get("value"), "std_s": off.get("std"),
                     "observable": off.get("observable"), "rate": rate.get("value"),
                     "rate_std": rate.get("std"), "rate_fitted": rate.get("fitted"),
                     "fx_pct": 100 * (est.fx / cam.fx - 1),
                     "h_pct": 100 * (est.height_m / cam.height_m - 1), "cpu_s": cpu,
                     "note": next((ln for ln in text.splitlines() if "time offset" in ln), "")})
    for r in rows:
        err = (r["offset_s"] - r["truth_s"]) if r["offset_s"] is not None else float("nan")
        print(f"time sync {r['clip']}: first fix at {r['offset_s']} s (std {r['std_s']}, "
              f"observable {r['observable']}), truth {r['truth_s']:+.3f} s, error "
              f"{err:+.3f} s; clock rate {r['rate']} (std {r['rate_std']}, fitted "
              f"{r['rate_fitted']}); fx {r['fx_pct']:+.1f} %, height {r['h_pct']:+.1f} %, "
              f"{r['cpu_s']:.1f} s CPU\n  {r['note']}")
    return rows


def cost_check(raw: Path, shared: Path, cache: Path) -> dict:
    """(g) What the self-calibration costs a build: the 60 s 720p clip of the speed
    benchmark (KITTI raw 0001 forward and backward at 30 fps), ``build`` without GPS with
    the true camera file (scaled) and without any: wall and CPU of each, and the
    calibration stages' seconds within the second."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import resource

    from bench_speed import make_720p_clip

    from vid2sim.app.build import build
    from vid2sim.app.settings import DetectorSettings

    clip = cache / "clip60_720p.mp4"
    if not clip.exists():
        make_720p_clip(raw, clip)
    src = load_camera(raw / "camera.yaml")
    k = 1280 / src.image_width
    pad = (720 - round(src.image_height * k)) // 2
    cam = replace(src, image_width=1280, image_height=720, fx=src.fx * k, fy=src.fy * k,
                  cx=src.cx * k, cy=src.cy * k + pad)
    cam_file = cache / "clip60_720p.camera.yaml"
    cam_file.write_text("\n".join(f"{key}: {getattr(cam, key)}" for key in (
        "image_width", "image_height", "fx", "fy", "cx", "cy", "height_m", "pitch_deg",
        "yaw_deg", "roll_deg")) + "\n")
    settings = Settings(detector=DetectorSettings(model_dir=shared.parent / "models"),
                        allow_download=False, progress=False, camera_cache=False)
    out = {}
    for label, camera in (("camera file", cam_file), ("self-calibrated", None)):
        w0, c0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_SELF)
        res = build(Inputs(video=clip, camera=camera), cache / f"build60_{camera is None}",
                    settings)
        c1 = resource.getrusage(resource.RUSAGE_SELF)
        out[label] = {"wall_s": time.perf_counter() - w0,
                      "cpu_s": c1.ru_utime + c1.ru_stime - c0.ru_utime - c0.ru_stime,
                      "stages": dict(res.stage_seconds)}
    a, b = out["camera file"], out["self-calibrated"]
    for key in dict.fromkeys([*a["stages"], *b["stages"]]):
        print(f"  {key}: {a['stages'].get(key, 0.0):.1f} s with the file, "
              f"{b['stages'].get(key, 0.0):.1f} s self-calibrated")
    calib = sum(v for k_, v in b["stages"].items() if k_ in ("calibration cues",
                                                              "calibrate camera"))
    print(f"cost on the 60 s 720p clip (no GPS): build with the camera file {a['wall_s']:.1f} s "
          f"wall / {a['cpu_s']:.1f} s CPU, self-calibrated {b['wall_s']:.1f} s / "
          f"{b['cpu_s']:.1f} s CPU: +{100 * (b['wall_s'] / a['wall_s'] - 1):.1f} % wall, "
          f"+{100 * (b['cpu_s'] / a['cpu_s'] - 1):.1f} % CPU; calibration stages {calib:.1f} s "
          f"= {100 * calib / a['wall_s']:.1f} % of the build with the file")
    return out


def stage_cost(raw: Path, cache: Path) -> dict:
    """(h) CPU seconds (user + sys, all threads) of the calibration stages alone: the 60 s
    720p clip of (g) without GPS or camera file (calibration cues, calibrate camera), and
    the GPS-video time sync of KITTI raw 0001 with its camera file and the OXTS of (f) with
    its first 1.5 s removed (the cues measured for the sync alone)."""
    import resource

    from vid2sim.app import selfcal
    from vid2sim.app.loaders import load_trace, load_video_info

    def cpu() -> float:
        r = resource.getrusage(resource.RUSAGE_SELF)
        return r.ru_utime + r.ru_stime

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_speed import make_720p_clip

    clip = cache / "clip60_720p.mp4"
    if not clip.exists():
        make_720p_clip(raw, clip)
    settings = Settings(progress=False, camera_cache=False, allow_download=False)
    inputs = Inputs(video=clip)
    info = load_video_info(inputs)
    choice = selfcal.start_camera(inputs, info, settings)
    c0 = cpu()
    selfcal.measure_cues_for(choice, inputs, info, settings)
    c1 = cpu()
    selfcal.finish_camera(choice, inputs, info, settings)
    out = {"cues_s": c1 - c0, "calibrate_s": cpu() - c1}
    gps = cache / "oxts_skip15_False.csv"
    truth = _oxts_csv(raw, 15, gps)
    inputs = Inputs(video=raw / "video.mp4", gps=gps, camera=raw / "camera.yaml")
    info = load_video_info(inputs)
    choice = selfcal.start_camera(inputs, info, settings)
    c0 = cpu()
    selfcal.sync_offset(choice, inputs, info, settings, load_trace(inputs))
    out.update(sync_s=cpu() - c0, sync_error_s=choice.offset.offset_s - truth)
    print(f"stage cost: 60 s 720p clip, no GPS: calibration cues {out['cues_s']:.2f} s CPU, "
          f"calibrate camera {out['calibrate_s']:.2f} s CPU; KITTI raw 0001 with its camera "
          f"file, GPS 1.5 s late: time sync {out['sync_s']:.2f} s CPU (offset error "
          f"{out['sync_error_s']:+.3f} s)")
    return out


def print_composite(rows: list[dict]) -> None:
    print(f"\n{'clip':<22}{'range m':>12}{'|err| med %':>12}{'bias %':>8}{'present':>8}"
          f"{'IoU':>6}{'(n)':>5}{'fx %':>7}{'h %':>7}{'k1':>7}{'(true)':>7}{'calib s':>8}")
    for r in rows:
        lo, hi = r["true_range_m"]
        print(f"{r['clip']:<22}{lo:>5.1f}-{hi:<6.1f}{r['range_med_pct']:>12.1f}"
              f"{r['range_bias_pct']:>+8.1f}{r['presence']:>8.2f}{r['iou']:>6.2f}"
              f"{r['n_iou']:>5d}{r['fx_pct']:>+7.1f}{r['h_pct']:>+7.1f}{r['k1']:>7.3f}"
              f"{r['k1_true']:>7.3f}{r['calib_s']:>8.1f}")


def print_table(rows: list[dict]) -> None:
    print(f"{'clip':<16}{'fx %':>7}{'h %':>7}{'hor px':>8}{'roll':>7}{'yaw':>7}{'k1 err':>8}"
          f"{'(k1)':>7}  range @10/20/40 m %     cpu s  fx / height from")
    for r in rows:
        rng = "/".join(f"{v:+.1f}" for v in r["range_pct"])
        print(f"{r['clip']:<16}{r['fx_pct']:>+7.1f}{r['h_pct']:>+7.1f}{r['horizon_px']:>+8.1f}"
              f"{r['roll_deg']:>+7.2f}{r['yaw_deg']:>+7.2f}{r['k1']:>+8.3f}{r['k1_true']:>7.2f}"
              f"  {rng:<22}{r['cpu_s']:>6.1f}  {r['fx_src']} / {r['h_src']}")
    kit = [r for r in rows if r["clip"].startswith("kitti")]
    for key in ("fx_pct", "h_pct", "horizon_px"):
        v = np.array([r[key] for r in kit])
        print(f"{key}: median |err| {np.median(np.abs(v)):.2f}, bias {np.median(v):+.2f}, "
              f"max |err| {np.abs(v).max():.2f} over {len(v)} KITTI clips")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3])
    parser.add_argument("--modes", nargs="+", default=["pin", "dist"], choices=["pin", "dist"])
    parser.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir())
                        / "vid2sim-calib")
    parser.add_argument("--shared", type=Path, default=Path(__file__).resolve().parents[2]
                        / "shared" / "data")
    parser.add_argument("--no-dgp", action="store_true")
    parser.add_argument("--composite", type=int, nargs="*", default=[],
                        help="also build composite clips of these seeds (a car ahead), "
                             "re-imaged through distorted camera draws 10 + seed")
    parser.add_argument("--only-composite", action="store_true")
    parser.add_argument("--ego-speed", action="store_true",
                        help="also the camera-only ego speed on KITTI raw 0001 against OXTS")
    parser.add_argument("--sync", action="store_true",
                        help="also the GPS-video time sync on KITTI raw 0001 (whole OXTS, and "
                             "its first 1.5 s removed)")
    parser.add_argument("--cost", action="store_true",
                        help="also build the 60 s 720p clip with and without a camera file")
    parser.add_argument("--stage-cost", action="store_true",
                        help="also the CPU of the calibration stages alone (60 s 720p clip "
                             "without GPS; the sync of KITTI raw 0001 with its camera file)")
    parser.add_argument("--json", type=Path, default=None, help="also write the rows here")
    args = parser.parse_args(argv)
    raw = args.shared / "kitti_raw_0001"
    if not (raw / "video.mp4").is_file():
        print(f"error: {raw}: not found (set --shared to the shared data folder)",
              file=sys.stderr)
        return 2
    args.cache.mkdir(parents=True, exist_ok=True)
    rows = []
    if not args.only_composite:
        rows = kitti_clips(raw, args.cache, args.seeds, args.modes)
        if not args.no_dgp:
            dgp = dgp_clip(args.shared, args.cache)
            if dgp is not None:
                rows.append(dgp)
        print_table(rows)
    if args.ego_speed:
        print(ego_speed_check(raw))
    extra = {}
    if args.sync:
        extra["sync"] = sync_check(raw, args.cache)
    if args.cost:
        extra["cost"] = cost_check(raw, args.shared, args.cache)
    if args.stage_cost:
        extra["stage_cost"] = stage_cost(raw, args.cache)
    comp = [composite_build(raw, args.shared, args.cache, s, 10 + s) for s in args.composite]
    if comp:
        print_composite(comp)
    rows += comp
    if args.json:
        args.json.write_text(json.dumps({"rows": rows, **extra}, indent=1, default=float))
    return 0 if all(math.isfinite(r["fx_pct"]) for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
