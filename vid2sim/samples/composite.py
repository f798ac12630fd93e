"""Semi-synthetic test clips with exact truth: a real car composited into a real drive.

A car seen from behind is cut out of a labelled KITTI tracking frame (its 3D label gives its
size and the range of its rear face) and pasted into every frame of the KITTI raw drive
``2011_09_26_drive_0001`` (``../shared/data/kitti_raw_0001/video.mp4``) as a lead vehicle at a
chosen trajectory. The truth of every frame (range of the rear, lateral offset of the centre,
range rate) is therefore exact, while the background, the road, the camera and the vehicle's
pixels are all real: the closest stand-in for a recorded clip with lidar range to a lead.

The cut-out and the paste are in :mod:`vid2sim.samples.cutout`.

Body pitch. The ego body pitches on its suspension and with the road, and every real object in
the video moves with it. The target camera of each frame gets the OXTS pitch of that frame
relative to the drive's mean (positive = nose down, as the camera's ``pitch_deg``), so the pasted
car moves with the road like the parked cars do (the ranging's per-frame pitch estimate compares
exactly these cues). That the OXTS pitch is the image's motion is checked on the video itself:
the frame-to-frame vertical shift of the far background (phase correlation) follows
``-f * d(pitch)`` with correlation -0.98 and the same spread (0.70 vs 0.73 px).

Occlusion. The paste is drawn over the background: right for the far road, the tram and the
parked cars at the sides (all further away or beside the ego lane); the trajectories stay in the
ego lane (|lateral| <= 0.4 m), where nothing in this drive is nearer than the lead.

Pure functions do the geometry and pixels; :func:`load_cutout` reads the KITTI frame and
:func:`write_composite_clip` streams the video one frame at a time into a temporary file that
is renamed when complete.

KITTI material: CC BY-NC-SA 3.0, Geiger, Lenz, Stiller, Urtasun, "Vision meets Robotics: The
KITTI Dataset", IJRR 2013. It is read at run time and never copied into the project.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from vid2sim.base.errors import FormatError, InconsistentInputError
from vid2sim.base.fileio import write_text_atomic
from vid2sim.core.boxes import iou_matrix
from vid2sim.core.camera import Camera, fit_camera_to_frames, load_camera
from vid2sim.geo.readers import OXTS_PITCH, read_kitti_oxts_table
from vid2sim.samples.clipfile import staged_video
from vid2sim.samples.cutout import (  # noqa: F401 - re-exported: composite is the samples' API
    CARS,
    CarCutout,
    cut_out_car,
    is_rear_view,
    label_corners,
    load_cutout,
    paste_car,
    paste_transform,
    read_kitti_projection,
    read_labels_with_yaw,
    truth_box,
)

# The drive's frames: the KITTI raw left grayscale camera at 10 Hz.
DEFAULT_FPS = 10.0


# --------------------------------------------------------------------------- trajectories


@dataclass(frozen=True)
class LeadTruth:
    """The lead's exact trajectory at the frame times.

    ``range_m``: x of its rear in the ego vehicle frame; ``lateral_m``: y of its centre (left
    positive); ``range_rate_mps``: d(range)/dt; ``rel_accel_mps2``: d(range rate)/dt.
    """

    t_s: np.ndarray
    range_m: np.ndarray
    lateral_m: np.ndarray
    range_rate_mps: np.ndarray
    rel_accel_mps2: np.ndarray
    seed: int


def _moving_average(x: np.ndarray, n: int) -> np.ndarray:
    if n <= 1:
        return x
    pad = np.concatenate((np.full(n, x[0]), x, np.full(n, x[-1])))
    return np.convolve(pad, np.ones(n) / n, mode="same")[n:-n]


def lead_profile(seed: int, n_frames: int, fps: float = DEFAULT_FPS, *,
                 range_bounds_m: tuple[float, float] = (8.0, 45.0), max_speed_mps: float = 6.0,
                 max_brake_mps2: float = 4.0, max_lateral_m: float = 0.4,
                 dt_s: float = 0.005) -> LeadTruth:
    """A seeded lead trajectory with one braking and one opening phase.

    The relative acceleration is a sequence of phases (hold, brake at ``max_brake_mps2`` - 0.8 to ``max_brake_mps2``
    until closing at 3 to ``max_speed_mps``, hold, accelerate at 1.5 to 3 m/s^2 until opening
    at 2 to ``max_speed_mps``, hold, in random order brake-first or open-first), smoothed over
    0.3 s (jerk-limited like a driver's pedal), integrated exactly on a fine grid; the start
    range is drawn from the interval that keeps the whole trajectory in ``range_bounds_m``.
    The lateral offset is a slow sine (period 6-15 s) about an offset, within
    +-``max_lateral_m``.

    Returns
    -------
    LeadTruth
        Sampled at frame times ``i / fps``.
    """
    rng = np.random.default_rng(seed)
    duration = n_frames / fps
    t = np.arange(0.0, duration + dt_s, dt_s)
    lo, hi = range_bounds_m
    for _attempt in range(200):
        brake = -rng.uniform(max_brake_mps2 - 0.8, max_brake_mps2)
        accel = rng.uniform(1.5, 3.0)
        v_close = -rng.uniform(3.0, max_speed_mps)
        v_open = rng.uniform(2.0, max_speed_mps)
        v0 = rng.uniform(-1.0, 1.0)
        holds = rng.uniform(0.3, 2.0, size=3)
        order = [(brake, v_close), (accel, v_open)]
        if rng.random() < 0.5:
            order.reverse()
        # Piecewise-constant acceleration: hold, phase 1, hold, phase 2, hold...
        a = np.zeros_like(t)
        v = v0
        tc = holds[0]
        for (acc, target), hold in zip(order, holds[1:], strict=True):
            dur = (target - v) / acc
            a[(t >= tc) & (t < tc + dur)] = acc
            v = target
            tc += dur + hold
        if tc > duration:
            continue
        a = _moving_average(a, max(1, round(0.3 / dt_s)))
        vel = v0 + np.concatenate(([0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * dt_s)))
        disp = np.concatenate(([0.0], np.cumsum(0.5 * (vel[1:] + vel[:-1]) * dt_s)))
        r_lo, r_hi = lo - disp.min(), hi - disp.max()
        if r_hi <= r_lo or np.abs(vel).max() > max_speed_mps + 1e-9:
            continue
        r0 = rng.uniform(r_lo + 0.1 * (r_hi - r_lo), r_hi - 0.1 * (r_hi - r_lo))
        rng_m = r0 + disp
        break
    else:  # pragma: no cover - the phases above always fit within a few attempts
        raise RuntimeError(f"no lead trajectory within {range_bounds_m} m for seed {seed}")
    amp = rng.uniform(0.05, 0.25)
    offset = rng.uniform(-(max_lateral_m - amp), max_lateral_m - amp)
    period, phase = rng.uniform(6.0, 15.0), rng.uniform(0, 2 * math.pi)
    t_f = np.arange(n_frames) / fps
    idx = np.clip(np.rint(t_f / dt_s).astype(int), 0, len(t) - 1)
    lateral = offset + amp * np.sin(2 * math.pi * t_f / period + phase)
    return LeadTruth(t_s=t_f, range_m=rng_m[idx], lateral_m=lateral, range_rate_mps=vel[idx],
                     rel_accel_mps2=a[idx], seed=seed)


# --------------------------------------------------------------------------- the drive


def read_oxts_pitch(raw_dir: Path) -> np.ndarray:
    """OXTS pitch of every frame of a KITTI raw drive [rad] (positive = nose down)."""
    return read_kitti_oxts_table(raw_dir)[:, OXTS_PITCH]


def frame_cameras(camera: Camera, pitch_rad: np.ndarray | None, n_frames: int
                  ) -> list[Camera]:
    """The target camera of each frame: ``camera`` pitched by the body pitch relative to the
    drive's mean (None: the camera unchanged in every frame)."""
    if pitch_rad is None:
        return [camera] * n_frames
    rel = np.degrees(np.asarray(pitch_rad, dtype=float) - float(np.mean(pitch_rad)))
    if rel.size < n_frames:
        raise InconsistentInputError(None, f"{rel.size} pitch samples for {n_frames} frames")
    return [camera.with_pitch(camera.pitch_deg + float(d)) for d in rel[:n_frames]]


@dataclass(frozen=True)
class CompositeClip:
    """A written clip: the video, its truth file and the truth itself."""

    video: Path
    truth_json: Path
    truth: LeadTruth
    boxes_px: list[tuple[float, float, float, float] | None]
    camera: Camera
    cameras: list[Camera]
    cutout_source: str


def write_composite_clip(raw_dir: Path, cutout: CarCutout, truth: LeadTruth, out_path: Path,
                         *, use_body_pitch: bool = True) -> CompositeClip:
    """Composite the car into every frame of the drive and write the clip and its truth.

    Frames are read, pasted and written one at a time; the video goes to a hidden temporary
    file beside ``out_path`` renamed over it when complete, and ``<out_path>.truth.json``
    (per frame: t_s, range_m, lateral_m, range_rate_mps, rel_accel_mps2, box_px) is written
    atomically after it. ``box_px`` is the box of the pasted outline (:func:`truth_box`) in
    the frame's pitched camera.

    Parameters
    ----------
    raw_dir : Path
        The KITTI raw drive folder (``video.mp4``, ``camera.yaml``, ``oxts/``).
    cutout : CarCutout
        The car.
    truth : LeadTruth
        Its trajectory, one sample per video frame.
    out_path : Path
        ``.mp4`` (mp4v) or ``.avi`` (MJPG).
    use_body_pitch : bool
        Move the car with the OXTS body pitch (see the module docstring).
    """
    raw_dir, out_path = Path(raw_dir), Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    video = raw_dir / "video.mp4"
    cap = cv2.VideoCapture(str(video))
    if not cap.isOpened():
        raise FormatError(video, "OpenCV cannot open this video")
    width = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH))
    height = int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
    fps = float(cap.get(cv2.CAP_PROP_FPS)) or DEFAULT_FPS
    n_frames = len(truth.t_s)
    camera, _ = fit_camera_to_frames(load_camera(raw_dir / "camera.yaml"), width, height)
    pitch = read_oxts_pitch(raw_dir) if use_body_pitch else None
    cams = frame_cameras(camera, pitch, n_frames)
    boxes: list[tuple[float, float, float, float] | None] = []
    try:
        with staged_video(out_path, (width, height), fps) as writer:
            for i in range(n_frames):
                ok, frame = cap.read()
                if not ok:
                    raise InconsistentInputError(
                        video, f"video ends at frame {i}, truth has {n_frames}")
                r, y = float(truth.range_m[i]), float(truth.lateral_m[i])
                writer.write(paste_car(frame, cutout, cams[i], r, y))
                boxes.append(truth_box(cutout, cams[i], r, y))
    finally:
        cap.release()
    truth_path = out_path.with_name(out_path.name + ".truth.json")
    write_text_atomic(truth_path, truth_to_json(truth, boxes, cutout, use_body_pitch))
    return CompositeClip(out_path, truth_path, truth, boxes, camera, cams, cutout.source)


def truth_to_json(truth: LeadTruth, boxes: list, cutout: CarCutout, body_pitch: bool) -> str:
    """The truth file's text: car, seed and one record per frame."""
    frames = [{"frame": i, "t_s": round(float(truth.t_s[i]), 6),
               "range_m": round(float(truth.range_m[i]), 6),
               "lateral_m": round(float(truth.lateral_m[i]), 6),
               "range_rate_mps": round(float(truth.range_rate_mps[i]), 6),
               "rel_accel_mps2": round(float(truth.rel_accel_mps2[i]), 6),
               "box_px": None if boxes[i] is None else [round(v, 2) for v in boxes[i]]}
              for i in range(len(truth.t_s))]
    doc = {"car": cutout.source, "seed": truth.seed, "body_pitch_from_oxts": body_pitch,
           "size_hwl_m": [cutout.height_m, cutout.width_m, cutout.length_m],
           "frames": frames}
    return json.dumps(doc, indent=1) + "\n"



# --------------------------------------------------------------------------- scoring


def box_iou(a: tuple[float, float, float, float], b: tuple[float, float, float, float]
            ) -> float:
    """Intersection over union of two (x1, y1, x2, y2) boxes (the tracker's IoU)."""
    return float(iou_matrix(np.array([a]), np.array([b]))[0, 0])


@dataclass(frozen=True)
class LeadScore:
    """Lead figures of one clip against the composite's truth.

    ``presence``: share of all frames whose chosen lead is the composited car (box IoU with
    the truth projection >= the threshold); ``range_rel_err_median``: median |range error| /
    true range and ``range_bias_median`` the median signed one, over those frames;
    ``range_rate_rmse_mps`` over those of them with a rate; ``tracked_share``: frames where any
    track is on the car; ``car_track_ids``: the tracks that were (more than one: id switches).
    """

    n_frames: int
    presence: float
    range_rel_err_median: float
    range_bias_median: float
    range_rate_rmse_mps: float
    tracked_share: float
    car_track_ids: tuple[int, ...]
    wrong_lead_frames: int


def score_lead(boxes: list, truth: LeadTruth, truth_boxes: list, min_iou: float = 0.5
               ) -> LeadScore:
    """Score ranged boxes (:class:`vid2sim.core.records.RangedBox`) of a composite clip.

    Parameters
    ----------
    boxes : list of RangedBox
        Output of the ranging for the clip.
    truth : LeadTruth
        The composited car's trajectory.
    truth_boxes : list
        Its pixel box per frame (None where off the image), e.g. :func:`truth_box`.
    min_iou : float
        A box is on the car from this IoU with the truth box.
    """
    n = len(truth.t_s)
    by_frame: dict[int, list] = {}
    for b in boxes:
        by_frame.setdefault(b.frame, []).append(b)
    rel, signed, rate_err = [], [], []
    present = tracked = wrong = 0
    ids: set[int] = set()
    for i in range(n):
        tb = truth_boxes[i]
        rows = by_frame.get(i, [])
        on_car = [b for b in rows
                  if tb is not None and box_iou((b.x1, b.y1, b.x2, b.y2), tb) >= min_iou]
        tracked += bool(on_car)
        ids.update(b.track_id for b in on_car)
        lead = [b for b in rows if b.is_lead]
        if not lead:
            continue
        if not any(b in on_car for b in lead):
            wrong += 1
            continue
        b = lead[0]
        present += 1
        r = float(truth.range_m[i])
        rel.append(abs(b.range_m - r) / r)
        signed.append((b.range_m - r) / r)
        if np.isfinite(b.range_rate_mps):
            rate_err.append(b.range_rate_mps - float(truth.range_rate_mps[i]))
    nan = float("nan")
    return LeadScore(
        n_frames=n, presence=present / n if n else nan,
        range_rel_err_median=float(np.median(rel)) if rel else nan,
        range_bias_median=float(np.median(signed)) if signed else nan,
        range_rate_rmse_mps=float(np.sqrt(np.mean(np.square(rate_err)))) if rate_err else nan,
        tracked_share=tracked / n if n else nan, car_track_ids=tuple(sorted(ids)),
        wrong_lead_frames=wrong)
