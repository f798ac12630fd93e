"""Replay a scenario at annotated keyframes, project its vehicles into the camera, score them.

Geometry: the ego trajectory is the pose of the vehicle-frame origin (the road point below
the camera, as :mod:`vid2sim.core.camera` defines it); an actor's trajectory is the centre of its
footprint. At time t an actor's centre (x, y) and heading go into the ego frame by

    x_fwd  =  cos(h_ego) dx + sin(h_ego) dy
    y_left = -sin(h_ego) dx + cos(h_ego) dy,    yaw = h_actor - h_ego

with (dx, dy) the ENU offset from the ego. Its outline (:mod:`vid2sim.core.outline`: tyres, widest
section, mirrors; the rear face where ranging's ``range_m`` put it) is projected through the
scenario camera: the box a detector or annotator draws. One reaching behind the camera is its
3D box cut at a near plane (the truncated box an annotator draws of a car alongside).

Occlusion rule: boxes are taken nearest first; a box whose image area is covered to at least
``OCCLUDED_FRACTION`` by the union of the boxes of nearer vehicles is dropped (annotators do
not label what they cannot see). Boxes, not silhouettes, are used, so the rule slightly
over-estimates occlusion.

"Hard" boxes: annotation guidelines differ on what is too small, too truncated or too hidden
to label (KITTI labels cars alongside; other sets skip them). A projected box is marked
``hard`` when it is under ``HARD_MIN_HEIGHT_PX`` high, less than ``HARD_MIN_IN_IMAGE`` of it
lies inside the image, the vehicle reaches behind the camera, or at least
``HARD_OCCLUDED_FRACTION`` of it is hidden. The metrics count a hard box that matches an
annotation as a TP but do not count an unmatched one as a FP, as the KITTI benchmark does
with objects outside its difficulty levels.
"""

from __future__ import annotations

import json
import logging
import math
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from shapely.geometry import box as shapely_box
from shapely.ops import unary_union

from vid2sim.base.defaults import IMAGE_FOLDER_FPS
from vid2sim.base.fileio import write_bytes_atomic, write_text_atomic
from vid2sim.core.camera import Camera, fit_camera_to_frames
from vid2sim.core.outline import CAR_SHAPE, CLASS_SHAPES, OutlineShape
from vid2sim.core.records import Keyframe, ProjectedBox
from vid2sim.core.scenario import Actor, Scenario, load
from vid2sim.core.videofile import image_files, read_frames, video_size_and_fps
from vid2sim.evaluate.annotations import describe, read_keyframes
from vid2sim.evaluate.metrics import score_keyframes
from vid2sim.evaluate.projection import NEAR_PLANE_M, BoxView, project_box_clipped  # noqa: F401
from vid2sim.evaluate.report import write_report
from vid2sim.evaluate.tracklet_keyframes import (
    CUBOID_PROJECTION,
    OUTLINE_PROJECTION,
    is_tracklet_file,
)

log = logging.getLogger(__name__)

OCCLUDED_FRACTION = 0.9
"""Share of a box's image area hidden behind nearer boxes at which it is dropped."""
HARD_OCCLUDED_FRACTION = 0.7
"""Share of a box's image area hidden behind nearer boxes from which it is "hard"."""
HARD_MIN_HEIGHT_PX = 10.0
"""Box height [px] below which a projected box is "hard"."""
HARD_MIN_IN_IMAGE = 0.5
"""Share of a projected box's area inside the image below which it is "hard"."""
TIME_TOLERANCE_S = 1e-3
"""Slack when testing whether a keyframe lies within an actor's trajectory [s]."""
ENV_ID = "vid2sim/Replay-v0"

# Overlay colours (BGR): annotations green, simulated boxes magenta, ignore regions grey.
_GT_BGR = (60, 200, 60)
_SIM_BGR = (230, 60, 230)
_IGNORE_BGR = (150, 150, 150)


def _drop_occluded(boxes: list[ProjectedBox]) -> list[ProjectedBox]:
    """Apply the occlusion rule (module docstring): drop boxes hidden to
    ``OCCLUDED_FRACTION``, mark those hidden to ``HARD_OCCLUDED_FRACTION`` hard; input
    order is kept."""
    order = sorted(range(len(boxes)), key=lambda i: boxes[i].range_m)
    nearer = None
    keep: dict[int, ProjectedBox] = {}
    for i in order:
        poly = shapely_box(*boxes[i].box_px)
        hidden = 0.0
        if nearer is not None and poly.area > 0:
            hidden = poly.intersection(nearer).area / poly.area
        if hidden < OCCLUDED_FRACTION:
            b = boxes[i]
            keep[i] = replace(b, hard=True) if hidden >= HARD_OCCLUDED_FRACTION else b
        # A hidden vehicle still hides what is behind it.
        nearer = poly if nearer is None else unary_union([nearer, poly])
    return [keep[i] for i in range(len(boxes)) if i in keep]


# --------------------------------------------------------------------------- poses


def _actor_active(actor: Actor, t_s: float) -> bool:
    t = actor.trajectory.t
    return bool(t[0] - TIME_TOLERANCE_S <= t_s <= t[-1] + TIME_TOLERANCE_S)


def poses_at(scenario: Scenario, t_s: float
                             ) -> tuple[tuple[float, float, float], dict[str, tuple[float, float, float]]]:
    """Ego and active actors' (x, y, heading) in ENU [m, m, rad] at ``t_s``, interpolated."""
    e = scenario.ego.trajectory.state_at(t_s)
    ego = (float(e["x"]), float(e["y"]), float(e["heading"]))
    actors = {}
    for a in scenario.actors:
        if _actor_active(a, t_s):
            s = a.trajectory.state_at(t_s)
            actors[a.id] = (float(s["x"]), float(s["y"]), float(s["heading"]))
    return ego, actors


def _env_available() -> bool:
    """True when the ``vid2sim/Replay-v0`` environment is registered (``import vid2sim``)."""
    try:
        import gymnasium

        import vid2sim  # noqa: F401 - registers the environment
    except ImportError:
        return False
    return ENV_ID in gymnasium.registry


# Step rates tried for the environment [Hz]: keyframes from a video fall on its frame grid,
# so stepping at that rate lands exactly on them.
_GRID_RATES_HZ = (10.0, 20.0, 2.0, 5.0, 30.0, 25.0, 15.0, 24.0, 50.0, 60.0, 30000 / 1001,
                  60000 / 1001, 24000 / 1001, 12.0, 6.0, 4.0, 3.0, 1.0)


def _grid_rate_hz(t0_s: float, times_s: list[float]) -> float | None:
    """A step rate whose grid (from ``t0_s``) holds every time, or None."""
    for rate in _GRID_RATES_HZ:
        k = (np.asarray(times_s, dtype=float) - t0_s) * rate
        if np.all(np.abs(k - np.round(k)) < 1e-6 * max(rate, 1.0)):
            return rate
    return None


def _poses_from_env(scenario: Scenario, times_s: list[float]
                    ) -> dict[float, tuple[tuple[float, float, float],
                                           dict[str, tuple[float, float, float]]]]:
    """Ego and actor poses (ENU x, y, heading) read from the gymnasium environment.

    The environment replays the ego's log (``ego_mode="log"``) and is stepped forward to each
    keyframe. Its step rate is chosen so that keyframes fall on steps; where no common rate
    exists it steps at 10 Hz to the last step before a keyframe and asks the environment for
    the logged states at the keyframe time itself (``vehicle_states(t_s)``).
    """
    import gymnasium

    t0 = float(scenario.ego.trajectory.t[0])
    grid = _grid_rate_hz(t0, [t for t in times_s if t >= t0])
    rate = grid if grid is not None else 10.0
    env = gymnasium.make(ENV_ID, scenario=scenario, ego_mode="log", disable_env_checker=True,
                         config={"simulation_frequency": rate, "policy_frequency": rate})
    out = {}
    try:
        env.reset(seed=0)
        sim = env.unwrapped
        action = np.zeros(env.action_space.shape, dtype=env.action_space.dtype)
        done = False
        for t in sorted(set(times_s)):
            while not done and sim.t_s + 1.0 / rate <= t + 1e-6:
                _, _, terminated, truncated, _ = env.step(action)
                done = terminated or truncated
            on_step = abs(sim.t_s - t) <= 1e-6
            states = sim.vehicle_states() if on_step else sim.vehicle_states(max(t, t0))
            ego_state, actor_states = states[0], states[1:]
            out[t] = ((ego_state.x_m, ego_state.y_m, ego_state.heading_rad),
                      {a.id: (a.x_m, a.y_m, a.heading_rad) for a in actor_states})
    finally:
        env.close()
    return out


def boxes_at(scenario: Scenario, camera: Camera, ego: tuple[float, float, float],
             actors: dict[str, tuple[float, float, float]],
             outlines: dict[str, OutlineShape] | None = CLASS_SHAPES) -> list[ProjectedBox]:
    """Project actors given in ENU (x, y, heading) seen from the ego pose (x, y, heading).

    Returns the visible, not occluded boxes in scenario actor order.
    """
    ex, ey, eh = ego
    c, s = math.cos(eh), math.sin(eh)
    out = []
    for a in scenario.actors:
        if a.id not in actors:
            continue
        ax, ay, ah = actors[a.id]
        dx, dy = ax - ex, ay - ey
        # on the ground it stands on (the ranging measured it beside the ego's road plane)
        center = np.array([c * dx + s * dy, -s * dx + c * dy, a.ground_m])
        view = project_box_clipped(camera, center, a.length_m, a.width_m, a.height_m, ah - eh,
                                   outline=outlines and outlines.get(a.category, CAR_SHAPE))
        if view is not None:
            hard = (view.box_px[3] - view.box_px[1] < HARD_MIN_HEIGHT_PX
                    or view.in_image_fraction < HARD_MIN_IN_IMAGE or view.behind_camera)
            out.append(ProjectedBox(actor_id=a.id, box_px=view.box_px, category=a.category,
                                    range_m=view.range_m, hard=hard))
    return _drop_occluded(out)


def replay_boxes(scenario: Scenario, times_s: list[float], *, use_env: bool = True,
                 camera: Camera | None = None,
                 outlines: dict[str, OutlineShape] | None = CLASS_SHAPES
                 ) -> dict[float, list[ProjectedBox]]:
    """Simulated vehicles' image boxes at each requested time.

    Parameters
    ----------
    scenario : Scenario
        The scenario to replay (ego on its logged trajectory).
    times_s : list of float
        Keyframe times on the scenario clock [s].
    use_env : bool
        Take poses from the ``vid2sim/Replay-v0`` environment stepped to each time; when the
        environment is not installed, poses are interpolated from the trajectories (the
        environment replays the same trajectories) and a warning is logged.
    camera : Camera, optional
        Camera to project through; default the scenario's.
    outlines : dict, optional
        Per-category outline (:mod:`vid2sim.core.outline`); None projects 3D boxes (the boxes of
        a world drawn as cuboids, such as the demo sample's).

    Returns
    -------
    dict
        ``{t_s: [ProjectedBox, ...]}`` keyed by the given times.
    """
    cam = camera if camera is not None else Camera.from_dict(scenario.camera)
    times = [float(t) for t in times_s]
    if use_env and _env_available():
        poses = _poses_from_env(scenario, times)
    else:
        if use_env:
            log.warning("%s is not available: poses interpolated from the trajectories", ENV_ID)
        poses = {t: poses_at(scenario, t) for t in times}
    return {t: boxes_at(scenario, cam, *poses[t], outlines) for t in times}


# --------------------------------------------------------------------------- video frames


def draw_overlay(image_bgr: np.ndarray | None, camera: Camera, keyframe: Keyframe,
                 boxes: list[ProjectedBox], frame_stats: dict | None = None) -> bytes:
    """PNG bytes: the frame (or a grey canvas) with annotated boxes (green), ignore regions
    (grey) and simulated boxes (magenta, labelled with the actor id and range; thin lines
    for hard boxes)."""
    if image_bgr is None:
        img = np.full((camera.image_height, camera.image_width, 3), 110, np.uint8)
    else:
        img = image_bgr.copy()
    scale = max(img.shape[1] / 1280.0, 0.5)
    thick = max(1, round(2 * scale))
    # Simulated boxes first and thicker, annotations on top, so both show where they agree.
    for p in boxes:
        p1 = (round(p.box_px[0]), round(p.box_px[1]))
        p2 = (round(p.box_px[2]), round(p.box_px[3]))
        # thin: a "hard" box that counts only when matched
        cv2.rectangle(img, p1, p2, _SIM_BGR, 1 if p.hard else thick, cv2.LINE_AA)
        cv2.putText(img, f"{p.actor_id} {p.range_m:.0f}m", (p1[0] + 2, max(p1[1] - 4, 10)),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.4 * scale, _SIM_BGR, 1, cv2.LINE_AA)
    for b in keyframe.boxes:
        p1 = (round(b.box_px[0]), round(b.box_px[1]))
        p2 = (round(b.box_px[2]), round(b.box_px[3]))
        cv2.rectangle(img, p1, p2, _IGNORE_BGR if b.ignore else _GT_BGR,
                      1 if b.ignore else max(1, thick - 1), cv2.LINE_AA)
    text = f"t={keyframe.t_s:.2f}s  annotated (green)  simulated (magenta, thin: hard)"
    if frame_stats is not None:
        text += f"  TP {frame_stats['tp']} FP {frame_stats['fp']} FN {frame_stats['fn']}"
    # A dark banner keeps the caption legible on any frame.
    font_scale = 0.5 * scale
    (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, font_scale, 1)
    cv2.rectangle(img, (0, 0), (tw + 16, th + base + 10), (30, 30, 30), cv2.FILLED)
    cv2.putText(img, text, (8, th + 5), cv2.FONT_HERSHEY_SIMPLEX, font_scale,
                (255, 255, 255), 1, cv2.LINE_AA)
    ok, png = cv2.imencode(".png", img)
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 BGR image
        raise RuntimeError("PNG encoding failed")
    return png.tobytes()


# --------------------------------------------------------------------------- the eval stage


def _scenario_fps(scenario: Scenario) -> float | None:
    for key in ("fps", "video_fps"):
        v = scenario.source.options.get(key)
        if isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0:
            return float(v)
    return None


def _safe_name(name: str) -> str:
    keep = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in name)
    return keep.strip("._")[:60] or "frame"


def run_eval(scenario_path: str | Path, keyframes_path: str | Path, *, video: Path | None = None,
             out_dir: Path, fps: float | None = None, use_env: bool = True,
             extra_figures: list[tuple[str, bytes | Path]] | None = None,
             extra_warnings: list[str] | None = None, report_inputs: dict | None = None,
             scenario_label: str | None = None,
             outlines: dict[str, OutlineShape] | None = CLASS_SHAPES,
             keyframe_calib: Path | None = None,
             keyframe_rate_hz: float | None = None) -> tuple[dict, str]:
    """Replay a scenario at its annotated keyframes and score it.

    Writes ``out_dir/metrics.json``, ``out_dir/keyframes/*.png`` (overlays) and
    ``out_dir/report.html``.

    Parameters
    ----------
    scenario_path : path
        scenario.json.
    keyframes_path : path
        Annotations (Scalabel/BDD100K JSON, KITTI label_02, CVAT for video XML).
    video : Path, optional
        The video (file or image folder) the scenario was built from, for overlays and for
        mapping image names to frames; without it overlays use a grey canvas.
    out_dir : Path
        Output folder (created).
    fps : float, optional
        Video frame rate [frames/s]; default the container's rate, else the scenario's
        recorded ``fps`` option (image folders), else the annotation format's default.
    use_env : bool
        Replay in the gymnasium environment where available (see :func:`replay_boxes`).
    extra_figures, extra_warnings, report_inputs : optional
        Passed on to the report by a caller that ran more stages (``vid2sim build``): figures
        as (title, PNG bytes or path), warnings shown before this stage's, inputs shown
        instead of this stage's own.
    scenario_label : str, optional
        How metrics.json names the scenario (a build evaluates a staged copy and gives the
        final path here), default ``scenario_path``.
    outlines : dict, optional
        Per-category vehicle outlines to project (see :func:`replay_boxes`); None: 3D boxes.
        Against KITTI tracklet keyframes (projected lidar cuboids) the vehicles are always
        projected as 3D boxes, cuboid hull against cuboid hull; ``metrics["projection"]``
        says which projection was used.
    keyframe_calib, keyframe_rate_hz : optional
        Tracklet keyframes only: calibration folder and keyframes a second (see
        :func:`vid2sim.evaluate.annotations.read_keyframes`).

    Returns
    -------
    (metrics, summary)
        The metrics.json content and a few human-readable lines.
    """
    scenario_path, keyframes_path, out_dir = Path(scenario_path), Path(keyframes_path), Path(out_dir)
    video = Path(video) if video is not None else None
    scenario = load(scenario_path)
    warnings: list[str] = []  # this stage's, in metrics.json and the summary
    camera, frame_names, video_fps = _camera_and_frames(scenario, scenario_path, video, warnings)
    rate = _frame_rate(fps, video_fps, scenario, video, warnings)
    keyframes = _keyframes_on_the_clock(keyframes_path, rate, frame_names, scenario, warnings,
                                        camera, keyframe_calib, keyframe_rate_hz)
    cuboids = is_tracklet_file(keyframes_path)
    if cuboids:  # lidar cuboids are scored against the replay's cuboids
        outlines = None
    env_used = use_env and _env_available()
    if use_env and not env_used:
        warnings.append(f"{ENV_ID} not available: vehicle poses interpolated from the "
                        "scenario trajectories")
    times = [k.t_s for k in keyframes]
    boxes = replay_boxes(scenario, times, use_env=env_used, camera=camera, outlines=outlines)
    metrics = score_keyframes(keyframes, boxes)
    metrics["replay"] = "gymnasium " + ENV_ID if env_used else "trajectory interpolation"
    metrics["projection"] = (CUBOID_PROJECTION if outlines is None and cuboids else
                             "3D box hull" if outlines is None else OUTLINE_PROJECTION)
    metrics["inputs"] = {"scenario": scenario_label or str(scenario_path),
                         "keyframes": str(keyframes_path),
                         "video": str(video) if video is not None else None, "fps": rate}
    images = _write_overlays(out_dir, video, keyframes, metrics, camera, boxes, warnings)
    metrics["warnings"] = warnings
    write_text_atomic(out_dir / "metrics.json",
                      json.dumps(_json_safe(metrics), indent=1, sort_keys=False) + "\n")
    write_report(out_dir / "report.html", scenario=scenario, metrics=metrics,
                 keyframe_images=images, extra_figures=list(extra_figures or []),
                 warnings=[*(extra_warnings or []), *warnings],
                 inputs=report_inputs or metrics["inputs"])
    return metrics, _summary(metrics, keyframes, out_dir)


def _camera_and_frames(scenario: Scenario, scenario_path: Path, video: Path | None,
                       warnings: list[str]) -> tuple[Camera, list[str] | None, float | None]:
    """The scenario's camera fitted to the video's frames (a crop or resize noted in
    ``warnings``), the image folder's frame names, and the video's own frame rate."""
    camera = Camera.from_dict(scenario.camera, scenario_path)
    if video is None:
        return camera, None, None
    vw, vh, video_fps = video_size_and_fps(video)
    frame_names = [p.name for p in image_files(video)] if video.is_dir() else None
    camera, note = fit_camera_to_frames(camera, vw, vh, scenario_path)
    if note:
        warnings.append(f"scenario {note}")
    return camera, frame_names, video_fps


def _frame_rate(fps: float | None, video_fps: float | None, scenario: Scenario,
                video: Path | None, warnings: list[str]) -> float | None:
    """The rate that turns frame numbers into times: ``--fps``, else the video's, else the
    scenario's recorded one; an image folder without any gets build's default (noted)."""
    rate = fps or video_fps or _scenario_fps(scenario)
    if rate is None and video is not None and video.is_dir():
        rate = IMAGE_FOLDER_FPS
        warnings.append(f"no frame rate given for the image folder: assumed {IMAGE_FOLDER_FPS:g} "
                        "frames/s as vid2sim build does (pass --fps)")
    return rate


def _keyframes_on_the_clock(keyframes_path: Path, rate: float | None,
                            frame_names: list[str] | None, scenario: Scenario,
                            warnings: list[str], camera: Camera, calib_dir: Path | None,
                            rate_hz: float | None) -> list[Keyframe]:
    """The annotated keyframes, each with its video frame (timestamps give times, the rate
    the frame to seek); those outside the scenario's time span noted in ``warnings``.
    A tracklet file's cuboids are projected through ``calib_dir``'s calibration into the
    camera's image, sampled at ``rate_hz``."""
    keyframes = read_keyframes(keyframes_path, fps=rate, frame_names=frame_names,
                               calib_dir=calib_dir, rate_hz=rate_hz,
                               image_size_px=(camera.image_width, camera.image_height))
    if rate is not None:
        for k in keyframes:
            if k.frame is None:
                k.frame = round(k.t_s * rate)
    t0, t1 = scenario.ego.trajectory.t[0], scenario.ego.trajectory.t[-1]
    outside = [k.name for k in keyframes if not t0 - 0.05 <= k.t_s <= t1 + 0.05]
    if outside:
        warnings.append(f"{len(outside)} keyframe(s) lie outside the scenario's "
                        f"{t0:.2f}-{t1:.2f} s (first: {outside[0]}); the ego is held at its "
                        "first/last pose there")
    return keyframes


def _write_overlays(out_dir: Path, video: Path | None, keyframes: list[Keyframe],
                    metrics: dict, camera: Camera, boxes: dict, warnings: list[str]
                    ) -> list[tuple[str, bytes]]:
    """One overlay PNG per keyframe in ``out_dir/keyframes`` (on its video frame, or grey
    where the video has none), named in each keyframe's stats; (caption, PNG) for the
    report."""
    frames = read_frames(video, [k.frame for k in keyframes]) if video is not None else {}
    if video is not None:
        missing = [k.name for k in keyframes if k.frame not in frames]
        if missing:
            warnings.append(f"{len(missing)} keyframe(s) have no video frame (first: "
                            f"{missing[0]}); drawn on a grey canvas")
    images = []
    for n, (k, stats) in enumerate(zip(keyframes, metrics["per_keyframe"], strict=True)):
        png = draw_overlay(frames.get(k.frame), camera, k, boxes[k.t_s], stats)
        fname = f"{n:04d}_{_safe_name(k.name)}.png"
        write_bytes_atomic(out_dir / "keyframes" / fname, png)
        stats["overlay"] = f"keyframes/{fname}"
        f1 = "n/a" if stats["f1"] is None else f"{stats['f1']:.2f}"
        images.append((f"{k.name}  t={k.t_s:.2f} s  F1 {f1}", png))
    return images


def _json_safe(obj):
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, np.generic):
        return _json_safe(obj.item())
    return obj


def _fmt(x: float | None, spec: str = ".3f") -> str:
    return "n/a" if x is None else format(x, spec)


def _summary(m: dict, keyframes: list[Keyframe], out_dir: Path) -> str:
    d = describe(keyframes)
    ref = m["reference_study"]
    rng = m["range_error"]
    lines = [
        (f"keyframes: {m['keyframes']} ({d['boxes']} annotated vehicles, "
         f"{d['ignore_regions']} ignore regions, t {d['t_first_s']:.2f}-{d['t_last_s']:.2f} s)"),
        (f"standard:  TP {m['tp']}  FP {m['fp']}  FN {m['fn']}  precision {_fmt(m['precision'])}"
         f"  recall {_fmt(m['recall'])}  F1 {_fmt(m['f1'])}  mean IoU {_fmt(m['mean_iou'])}"),
        (f"reference: TP {ref['tp']}  FP {ref['fp']}  FN {ref['fn']}  precision "
         f"{_fmt(ref['precision'])}  recall {_fmt(ref['recall'])}  F1 {_fmt(ref['f1'])}"),
        f"projection: {m.get('projection', 'n/a')}",
    ]
    if rng["pairs"]:
        lines.append(f"range error: {rng['pairs']} pairs, mean |e| {rng['mean_abs_m']:.2f} m, "
                     f"median |e| {rng['median_abs_m']:.2f} m, mean signed "
                     f"{rng['mean_signed_m']:+.2f} m")
    lines.append(f"replay: {m['replay']}")
    for w in m.get("warnings", []):
        lines.append(f"warning: {w}")
    lines.append(f"wrote {out_dir / 'metrics.json'}, {out_dir / 'report.html'}, "
                 f"{len(keyframes)} overlays in {out_dir / 'keyframes'}")
    return "\n".join(lines)
