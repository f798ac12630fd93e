"""Camera self-calibration in the application: measure the cues, sync the clocks, fit.

One streamed pass over the video decodes a subset of frames: a flow pair (two frames
``pair_interval_s`` apart) every ``pair_every_s`` (fewer on long clips: at most
``max_pairs``) and ``line_frames`` frames for lane segments and straight edges, a few of
which are kept, downscaled, to measure the lane width once the camera is known. The GPS
(through the geo stage's smoothed trajectory) gives each pair's motion on the video clock;
without ``--gps-offset`` and without a clock in the GPS file, the clocks are synced first
(:mod:`vid2sim.calib.sync`). The pure estimation is :mod:`vid2sim.calib`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import Settings
from vid2sim.base.errors import InputError, MissingInputError
from vid2sim.calib import (
    CalibrationConfig,
    CalibrationInput,
    CameraPrior,
    LaneWidthPrior,
    with_lanes,
)
from vid2sim.calib import calibrate as fit_camera
from vid2sim.calib.sync import SyncConfig, estimate_time_offset
from vid2sim.core.calibration import (
    CameraEstimate,
    EgoMotionSample,
    FlowPair,
    FrameLines,
    LaneWidthSample,
    TimeOffset,
)
from vid2sim.core.camera import Camera
from vid2sim.core.records import EgoTrack, GpsTrace, Note, VideoInfo
from vid2sim.detect.lanes.linecues import frame_lines
from vid2sim.detect.lanes.markings import LaneMarkingDetector
from vid2sim.detect.tracking.groundflow import lower_image_flow
from vid2sim.detect.video import iter_frames
from vid2sim.geo.oxts import OXTS_YAW
from vid2sim.geo.readers import OXTS_VF, read_kitti_oxts_table, read_kitti_stamps

#: Frames kept (downscaled to this width) for the lane width once the camera is known.
HELD_FRAME_WIDTH_PX = 960
#: Mean grey level below which a clip is too dark to see the road in [0-255] (night
#: footage without street lights: the road's texture is sensor noise).
MIN_BRIGHTNESS = 18.0
#: A calibration needs this many flow pairs with road points, or lane segments.
MIN_PAIRS = 5
#: A GPS trace whose fastest speed over the clip is below this never moved [m/s].
MIN_GPS_SPEED_MPS = 0.5
#: GPS formats whose heading comes from an inertial unit (KITTI's OXTS RT3003: 0.1 deg
#: heading, OXTS datasheet), good to weigh a gentle turn's image shift against.
INS_FORMATS = ("kitti_oxts",)
#: Heading-rate noise of such a unit over a pair [rad/s].
INS_YAW_RATE_STD = 0.002


@dataclass(slots=True)
class Cues:
    """The measured cues of one clip, and frames kept for the lane width."""

    pairs: list[FlowPair]
    lines: list[FrameLines]
    held: dict[int, np.ndarray] = field(default_factory=dict)
    brightness: float = float("nan")
    #: flow points dropped inside vehicle boxes, and the pairs whose frames were searched
    masked_points: int = 0
    masked_pairs: int = 0


#: Vehicle boxes (x1, y1, x2, y2) [px] of a frame: (frame index, BGR image) -> boxes.
VehicleBoxes = Callable[[int, np.ndarray], list[tuple[float, float, float, float]]]


def detector_boxes(detector, imported: dict | None = None) -> VehicleBoxes | None:
    """The vehicle boxes of a frame from the build's imported boxes (by frame) or its
    detector; None when it has neither."""
    if imported is not None:
        return lambda i, _img: [d.box_px for d in imported.get(i, [])]
    if detector is None:
        return None
    return lambda _i, img: [d.box_px for d in detector.detect(img)]


def without_vehicles(pair: FlowPair, boxes: list[tuple[float, float, float, float]],
                     pad: float) -> tuple[FlowPair, int]:
    """The pair without its points inside any box widened by ``pad`` of its size (in
    either frame): a car ahead is not road, and the rest of the pair's road still counts."""
    if not boxes or not len(pair.points_a):
        return pair, 0
    keep = np.ones(len(pair.points_a), bool)
    for x1, y1, x2, y2 in boxes:
        dx, dy = pad * (x2 - x1), pad * (y2 - y1)
        for pts in (pair.points_a, pair.points_b):
            keep &= ~((pts[:, 0] >= x1 - dx) & (pts[:, 0] <= x2 + dx)
                      & (pts[:, 1] >= y1 - dy) & (pts[:, 1] <= y2 + dy))
    n = int((~keep).sum())
    return replace(pair, points_a=pair.points_a[keep], points_b=pair.points_b[keep]), n


def plan_frames(info: VideoInfo, cfg: CalibrationConfig) -> tuple[list[int], int, list[int]]:
    """Frames a pair starts at, the pair's frame gap, and the line frames."""
    fps = info.fps if info.fps > 0 else 10.0
    gap = max(1, round(cfg.pair_interval_s * fps))
    duration = info.n_frames / fps
    every = max(cfg.pair_every_s, duration / max(cfg.max_pairs, 1))
    step = max(1, round(every * fps))
    starts = list(range(0, max(info.n_frames - gap, 0), step))
    n_lines = min(cfg.line_frames, info.n_frames)
    lines = sorted({int(i) for i in np.linspace(0, info.n_frames - 1, n_lines)}) if n_lines else []
    return starts, gap, lines


def measure_cues(video: Path, info: VideoInfo, fps: float | None, cfg: CalibrationConfig,
                 vehicles: VehicleBoxes | None = None, for_sync: bool = False) -> Cues:
    """Stream the planned frames once and measure flow pairs and line evidence (with
    ``vehicles``, each pair's points on the vehicles of its earlier frame dropped;
    ``for_sync``: only what the time sync uses, no edge chains and no frames kept for the lane
    width)."""
    starts, gap, line_frames = plan_frames(info, cfg)
    ends = {s + gap: s for s in starts}
    # edge chains cost ~0.1 s a frame: every other one
    chains_at = set() if for_sync else set(line_frames[::2])
    wanted = set(starts) | set(ends) | set(line_frames)
    cues = Cues(pairs=[], lines=[])
    pending: dict[int, tuple[np.ndarray, float]] = {}
    grey_means = []
    for frame in iter_frames(video, fps=fps, only=wanted):
        img = frame.image_bgr
        if img is None:
            continue
        i = frame.index
        if i in starts:
            pending[i] = (img, frame.t_s)
        if i in ends and ends[i] in pending:
            a, t_a = pending.pop(ends[i])
            pair = lower_image_flow(a, img, ends[i], i, t_a, frame.t_s)
            if vehicles is not None:
                pair, n = without_vehicles(pair, vehicles(ends[i], a), cfg.vehicle_mask_pad)
                cues.masked_points += n
                cues.masked_pairs += 1
            cues.pairs.append(pair)
        if i in line_frames:
            cues.lines.append(frame_lines(img, i, frame.t_s, with_chains=i in chains_at))
            grey_means.append(float(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY).mean()))
            if for_sync:
                continue
            scale = min(1.0, HELD_FRAME_WIDTH_PX / img.shape[1])
            cues.held[i] = cv2.resize(img, None, fx=scale, fy=scale,
                                      interpolation=cv2.INTER_AREA) if scale < 1 else img
    cues.brightness = float(np.median(grey_means)) if grey_means else float("nan")
    return cues


def check_cues(cues: Cues, video: Path) -> str | None:
    """Why the clip cannot be calibrated (too dark, too short), or None."""
    if np.isfinite(cues.brightness) and cues.brightness < MIN_BRIGHTNESS:
        return (f"too dark to calibrate (mean grey level {cues.brightness:.0f} of 255): the "
                "road's texture and markings are not visible")
    usable = sum(len(p.points_a) >= 10 for p in cues.pairs)
    segments = sum(len(fl.segments) for fl in cues.lines)
    if usable < MIN_PAIRS and segments < 10:
        return (f"too short or too featureless to calibrate ({usable} frame pairs with road "
                f"texture, {segments} line segments; at least {MIN_PAIRS} pairs or lane "
                "markings are needed)")
    return None


def _ins_heading(trace: GpsTrace) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(UTC time, forward speed, heading CCW [rad]) of a KITTI OXTS folder's inertial unit."""
    if trace.format != "kitti_oxts" or trace.path is None:
        return None
    folder = Path(trace.path)
    folder = folder / "oxts" if (folder / "oxts" / "timestamps.txt").is_file() else folder
    try:
        table = read_kitti_oxts_table(folder)
        t = np.array(read_kitti_stamps(folder / "timestamps.txt"), float)
    except (InputError, OSError, ValueError):
        return None
    if len(t) != len(table):
        return None
    return t, table[:, OXTS_VF], np.unwrap(table[:, OXTS_YAW])


def gps_series(trace: GpsTrace, t0_utc_s: float, ego: EgoTrack | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(time from ``t0_utc_s`` [s], speed [m/s], heading [rad, counter-clockwise, unwrapped])
    as sharp as the trace has them: an inertial unit's heading and forward speed (KITTI
    OXTS), else the fixes' Doppler speed and course, else the smoothed trajectory ``ego``
    (already on that clock). The smoothed track's heading lags a turn and its speed a
    braking: on KITTI raw 0001 the focal length came out 7 % short from its heading
    changes, 11 % from the course (whose change over the turn exceeds the heading's by 12 %
    as the car's sideslip changes), 3 % from the OXTS heading."""
    ins = _ins_heading(trace)
    fixes = trace.fixes
    if ins is not None:
        return ins[0] - t0_utc_s, ins[1], ins[2]
    if len(fixes) >= 2 and all(f.speed_mps is not None and f.course_deg is not None
                               for f in fixes):
        t = np.array([f.t_utc_s - t0_utc_s for f in fixes])
        speed = np.array([f.speed_mps for f in fixes], float)
        # course: degrees clockwise from north -> counter-clockwise radians, unwrapped
        return t, speed, np.unwrap(-np.radians(np.array([f.course_deg for f in fixes], float)))
    if ego is None:
        return None
    return np.asarray(ego.t_s, float), np.asarray(ego.speed_mps, float), np.unwrap(
        ego.heading_rad)


def motion_from_series(series: tuple[np.ndarray, np.ndarray, np.ndarray],
                       pairs: list[FlowPair], cfg: CalibrationConfig, yaw_rate_std: float
                       ) -> list[EgoMotionSample]:
    """Each pair's GPS motion on the video clock (pairs outside the GPS's span get none)."""
    t, speed, heading = series
    out = []
    for p in pairs:
        if not (t[0] <= p.t_a_s and p.t_b_s <= t[-1]):
            continue
        grid = np.linspace(p.t_a_s, p.t_b_s, 5)
        d = float(np.trapezoid(np.interp(grid, t, speed), grid))
        dpsi = float(np.interp(p.t_b_s, t, heading) - np.interp(p.t_a_s, t, heading))
        out.append(EgoMotionSample(p.frame_a, d, dpsi, cfg.gps_speed_std_mps * p.dt_s
                                   + cfg.gps_scale_std * abs(d), yaw_rate_std * p.dt_s))
    return out


def lane_widths(camera: Camera, held: dict[int, np.ndarray]) -> list[LaneWidthSample]:
    """The ego lane's width in each kept frame, measured with ``camera``."""
    if not held:
        return []
    any_frame = next(iter(held.values()))
    cam = camera.scaled_to(any_frame.shape[1], any_frame.shape[0])
    det = LaneMarkingDetector(cam)
    out = []
    for i, img in sorted(held.items()):
        obs = det.measure(img, i)
        if np.isfinite(obs.lane_width_m):
            out.append(LaneWidthSample(i, float(obs.lane_width_m), camera.height_m))
    return out


def visual_profiles(est: CameraEstimate, pairs: list[FlowPair]
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(t_a, t_b, speed, heading change) of the pairs the fit used (visual, in the fit's
    scales)."""
    by_t = {round(t, 6): v for t, v in est.speeds}
    rows = []
    for p in pairs:
        tm = round(0.5 * (p.t_a_s + p.t_b_s), 6)
        if tm in by_t and p.frame_a in est.yaw_changes:
            rows.append((p.t_a_s, p.t_b_s, by_t[tm], est.yaw_changes[p.frame_a]))
    arr = np.array(rows, float).reshape(-1, 4)
    return arr[:, 0], arr[:, 1], arr[:, 2], arr[:, 3]


def yaw_rate_std_for(trace: GpsTrace | None, cfg: CalibrationConfig) -> float:
    return INS_YAW_RATE_STD if trace is not None and trace.format in INS_FORMATS \
        else cfg.gps_yaw_rate_std


def gps_moves(ego: EgoTrack, duration_s: float) -> bool:
    inside = (ego.t_s >= -0.5) & (ego.t_s <= duration_s + 0.5)
    return bool(inside.any() and np.nanmax(ego.speed_mps[inside]) >= MIN_GPS_SPEED_MPS)


def fit_cues(cues: Cues, info: VideoInfo, prior: CameraPrior, cfg: CalibrationConfig,
             motion: list[EgoMotionSample] | None = None, lane_prior: LaneWidthPrior | None
             = None, gps_label: str = "") -> CameraEstimate:
    """The camera of the cues (the lane width folded in from the kept frames)."""
    inp = CalibrationInput(width_px=info.width, height_px=info.height, pairs=cues.pairs,
                           lines=cues.lines, prior=prior, motion=motion or None,
                           lane_prior=lane_prior, gps_label=gps_label,
                           vehicle_points_masked=cues.masked_points)
    est, sol = fit_camera(inp, cfg)
    samples = lane_widths(est.camera, cues.held)
    est = with_lanes(sol, inp, samples, cfg)
    est.yaw_changes = {int(sol.problem.pairs.frame_a[k]): float(sol.m[k, 1])
                       for k in range(sol.problem.pairs.n_pairs)} if sol.problem.pairs else {}
    return est


def sync_clock(cues: Cues, info: VideoInfo, prior: CameraPrior, trace: GpsTrace,
               ego_gps_clock: EgoTrack, cfg: CalibrationConfig,
               sync_cfg: SyncConfig | None = None) -> TimeOffset:
    """The video time of the GPS's first fix, from the visual and GPS motion profiles
    (``ego_gps_clock``: the trajectory smoothed with the first fix at t = 0).

    The provisional fit leaves out the edge chains (the plumb-line distortion): on KITTI
    raw 0001 the four sync cases read the same offsets to 1 ms without them, at 0.7 of
    the fit's 2.2 CPU s less (docs/calibration.md)."""
    visual = fit_cues(replace(cues, held={}, lines=[replace(fl, chains=()) for fl in cues.lines]),
                      info, prior, cfg)
    ta, tb, v, w = visual_profiles(visual, cues.pairs)
    first = min(f.t_utc_s for f in trace.fixes)
    series = gps_series(trace, first, ego_gps_clock)
    return estimate_time_offset(ta, tb, v, w, *series, config=sync_cfg)


def lane_prior_from_roads(roads: list, road_source: str | None,
                          cfg: CalibrationConfig) -> LaneWidthPrior:
    """The lane width of the matched OpenStreetMap road, or the named prior."""
    if road_source == "osm" and roads:
        r = roads[0]
        ways = ",".join(str(w) for w in r.osm_way_ids[:3])
        return LaneWidthPrior(float(r.lane_width_m), cfg.lane_width_prior_std_m,
                              f"OpenStreetMap way {ways} (highway={r.highway})")
    return LaneWidthPrior(cfg.lane_width_prior_m, cfg.lane_width_prior_std_m,
                          "lane width prior: urban 3.0-3.25 m, main roads 3.5 m (RASt 06), "
                          "US 3.3-3.6 m (FHWA)")


def default_prior_camera(info: VideoInfo, prior: CameraPrior, cfg: CalibrationConfig,
                         why: str) -> tuple[Camera, list[Note]]:
    """The prior camera where nothing can be calibrated, with a warning naming it."""
    v = prior.values
    f0 = (info.width / 2.0) / math.tan(math.radians(cfg.hfov_prior_deg) / 2.0)
    cam = Camera(image_width=info.width, image_height=info.height, fx=v.get("fx", f0),
                 fy=v.get("fx", f0), cx=v.get("cx", (info.width - 1) / 2.0),
                 cy=v.get("cy", (info.height - 1) / 2.0),
                 dist=(v.get("k1", 0.0), v.get("k2", 0.0), 0.0, 0.0, 0.0),
                 height_m=v.get("height_m", cfg.height_prior_m),
                 pitch_deg=v.get("pitch_deg", 0.0), yaw_deg=v.get("yaw_deg", 0.0),
                 roll_deg=v.get("roll_deg", 0.0))
    return cam, [Note.warning(f"camera not calibrated: {why}; the prior camera is used: "
                              f"fx {cam.fx:.0f} px ({cfg.hfov_prior_deg:g} deg field of view), "
                              f"{cam.height_m:g} m above the road, no distortion, level "
                              "(ranges scale with focal length x height)")]


def require_video(inputs: Inputs) -> Path:
    if inputs.video is None:
        raise MissingInputError(None, "no video given")
    return Path(inputs.video)


def calibration_config(settings: Settings) -> CalibrationConfig:
    cfg = settings.calibration
    cfg.check()
    return cfg
