"""Sampled frames for the report of a build without keyframes: is the scene right?

Without annotated keyframes nothing scores the scenario, so the report shows a person what
the build saw next to what it made: for a few frames spread over the clip (and the frame of
every event), the video frame with the tracked boxes (id, lane relative to the ego lane,
range) and the ego lane's boundaries drawn on it, beside the highway-env render of the
scenario at the same moment (:class:`vid2sim.export.highway.ReplayEnv`, the logged ego),
its vehicles labelled with the same ids. One PNG per frame at full size; the report embeds a
smaller copy that links to it.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Mapping
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from vid2sim.base.fileio import write_bytes_atomic
from vid2sim.core.camera import Camera
from vid2sim.core.lead import ego_lane_at, lane_centre_m
from vid2sim.core.records import LaneTrack, RangedBox
from vid2sim.core.scenario import Event, Scenario
from vid2sim.core.videofile import read_frames
from vid2sim.detect.video import iter_frames
from vid2sim.evaluate.frames_config import FrameSampleConfig
from vid2sim.export.highway import ReplayEnv, enu_to_hw

# BGR colours by lane relative to the ego lane: the ego lane orange, left blue, right green,
# further lanes and unknown grey.
_LANE_COLOURS = {0: (0, 140, 255), 1: (255, 120, 40), -1: (60, 180, 60)}
_UNKNOWN = (150, 150, 150)
_BOUNDARY = (0, 230, 255)


def pick_frames(n_frames: int, fps: float, events: list[Event],
                config: FrameSampleConfig | None = None) -> list[tuple[int, str]]:
    """(frame index, what happens there) of the frames to show, in order: ``n_even`` spread
    over the clip and the frame of each event (its ``t_s`` times ``fps``)."""
    cfg = config or FrameSampleConfig()
    if n_frames <= 0:
        return []
    picks: dict[int, list[str]] = defaultdict(list)
    for k in np.unique(np.linspace(0, n_frames - 1, cfg.n_even).round().astype(int)):
        picks[int(k)]
    for ev in events[:cfg.max_event_frames]:
        k = int(np.clip(round(ev.t_s * fps), 0, n_frames - 1))
        picks[k].append(f"{ev.type} {ev.actor} ({ev.from_lane:+d} -> {ev.to_lane:+d})")
    return [(k, "; ".join(picks[k])) for k in sorted(picks)]


def lane_boundaries_px(camera: Camera, lanes: LaneTrack | None, t_s: float,
                       config: FrameSampleConfig | None = None) -> list[np.ndarray]:
    """The ego lane's left and right boundaries at ``t_s`` as (K, 2) pixel polylines (none
    where the lane is not known then)."""
    cfg = config or FrameSampleConfig()
    if lanes is None or len(lanes) == 0:
        return []
    at = ego_lane_at(lanes, np.array([t_s]))
    if not (np.isfinite(at.centre_m[0]) and np.isfinite(at.lane_width_m[0])):
        return []
    x = np.linspace(cfg.lane_near_m, cfg.lane_far_m, 40)
    centre = lane_centre_m(x, at.centre_m[0], at.heading_rad[0], at.curvature_inv_m[0])
    out = []
    for side in (0.5, -0.5):
        pts = np.column_stack((x, centre + side * at.lane_width_m[0], np.zeros_like(x)))
        uv, ok = camera.project(pts)
        if ok.sum() >= 2:
            out.append(uv[ok])
    return out


def draw_frame(image_bgr: np.ndarray, boxes: list[RangedBox], boundaries: list[np.ndarray]
               ) -> np.ndarray:
    """The frame with the lane boundaries and each box labelled ``#id lane range``; the box
    colour is its lane (orange the ego lane, blue left, green right, grey other or unknown),
    the lead's box thicker."""
    img = image_bgr.copy()
    for line in boundaries:
        cv2.polylines(img, [np.round(line).astype(np.int32)], False, _BOUNDARY, 2, cv2.LINE_AA)
    for b in boxes:
        lane = b.lane
        colour = _LANE_COLOURS.get(lane, _UNKNOWN) if lane is not None else _UNKNOWN
        p1, p2 = (round(b.x1), round(b.y1)), (round(b.x2), round(b.y2))
        cv2.rectangle(img, p1, p2, colour, 3 if b.is_lead else 2, cv2.LINE_8)
        lane_txt = "?" if lane is None else f"{lane:+d}" if lane else "0"
        rng = f" {b.range_m:.0f}m" if np.isfinite(b.range_m) else ""
        text = f"#{b.track_id} L{lane_txt}{rng}"
        org = (min(max(p1[0], 2), img.shape[1] - 120), max(p1[1] - 4, 14))
        cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 4, cv2.LINE_AA)
        cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, 0.55, colour, 2, cv2.LINE_AA)
    return img


def gym_renders(scenario: Scenario, times_s: list[float], fps: float,
                config: FrameSampleConfig | None = None) -> dict[float, np.ndarray]:
    """BGR renders of the scenario in highway-env (the logged ego) at ``times_s``, turned so
    the ego drives up the picture like the camera looks, its vehicles labelled with their
    ids. Every vehicle is put on its log at each time (:meth:`ReplayEnv.show_logged`), the
    environment configured at the video's frame rate.

    highway-env draws the world north up with the ego in the middle; the square render is
    turned about the ego by its heading and cut to :attr:`FrameSampleConfig.render_behind_m`
    behind it.
    """
    cfg = config or FrameSampleConfig()
    size = cfg.render_size_px
    env = ReplayEnv(scenario, ego_mode="log", render_mode="rgb_array",
                    config={"simulation_frequency": fps, "policy_frequency": fps,
                            "screen_width": size, "screen_height": size,
                            "centering_position": [0.5, 0.5],
                            "scaling": cfg.render_scale_px_per_m})
    out: dict[float, np.ndarray] = {}
    try:
        env.reset(seed=0)
        for t in sorted(set(times_s)):
            # the logged world at t directly: stepping there is a step per video frame
            env.show_logged(t)
            out[t] = _ego_up(env, cv2.cvtColor(env.render(), cv2.COLOR_RGB2BGR), cfg)
    finally:
        env.close()
    return out


def _ego_up(env: ReplayEnv, img: np.ndarray, cfg: FrameSampleConfig) -> np.ndarray:
    """The render turned so the ego heads up, cut below it, each vehicle's id written beside
    it (highway-env's own pixel mapping, then the same turn)."""
    states = env.vehicle_states()
    ego = states[0]
    surface = getattr(getattr(env, "viewer", None), "sim_surface", None)
    h, w = img.shape[:2]
    if surface is not None:
        cx, cy = (float(v) for v in surface.pos2pix(*(float(a) for a in
                                                      enu_to_hw(ego.x_m, ego.y_m))))
    else:  # pragma: no cover - highway-env always has a viewer after render()
        cx, cy = w / 2.0, h / 2.0
    # the picture is a north-up map (highway-env mirrors y, the screen mirrors it back): the
    # ego's heading on it is its ENU heading; turn it to 90 deg (up)
    m = cv2.getRotationMatrix2D((cx, cy), 90.0 - np.degrees(ego.heading_rad), 1.0)
    turned = cv2.warpAffine(img, m, (w, h), borderValue=(100, 100, 100))
    if surface is not None:
        for state in states:
            px, py = surface.pos2pix(*(float(a) for a in enu_to_hw(state.x_m, state.y_m)))
            u, v = m @ np.array([px, py, 1.0])
            if 0 <= u < w and 0 <= v < h:
                org = (int(u) + 8, int(v) + 4)
                cv2.putText(turned, str(state.id), org, cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                            (255, 255, 255), 3, cv2.LINE_AA)
                cv2.putText(turned, str(state.id), org, cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                            (20, 20, 20), 1, cv2.LINE_AA)
    bottom = int(np.clip(round(cy + cfg.render_behind_m * cfg.render_scale_px_per_m), 1, h))
    return turned[:bottom]


def side_by_side(camera_bgr: np.ndarray, render_bgr: np.ndarray) -> np.ndarray:
    """The camera frame and the render beside it, the render scaled to the frame's height."""
    h = camera_bgr.shape[0]
    scale = h / render_bgr.shape[0]
    render = cv2.resize(render_bgr, (max(1, round(render_bgr.shape[1] * scale)), h),
                        interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    gap = np.full((h, 8, 3), 255, np.uint8)
    return np.hstack((camera_bgr, gap, render))


def sample_frame_figures(out_dir: Path, video: Path, camera: Camera, boxes: list[RangedBox],
                         lanes: LaneTrack | None, scenario: Scenario, fps: float,
                         n_frames: int, video_fps: float | None = None,
                         config: FrameSampleConfig | None = None, progress: bool = False,
                         frame_times_s: Mapping[int, float] | None = None
                         ) -> list[tuple[str, Path]]:
    """Draw the sampled frames (module docstring) into ``out_dir``; (caption, PNG path) each.

    Parameters
    ----------
    out_dir : folder for ``frame_NNNNNN.png``
    video : the build's video (streamed once; only the picked frames are kept)
    camera : the camera the ranging used (with its estimated pitch)
    boxes : the ranged boxes with lanes
    lanes : the ego lane track the lanes were counted from
    scenario : the built scenario (its events pick frames; it is rendered)
    fps : the video's frame rate [frames/s]
    n_frames : frames in the video
    video_fps : the frame rate of an image folder (videos carry their own)
    progress : a progress bar over the frames read (stderr)
    frame_times_s : every frame's time (index -> s), as the detection stage streamed them:
        with it the picked frames are decoded by seeking over long gaps
        (:func:`vid2sim.core.videofile.read_frames`) instead of decoding the video up to the last
        pick, and timed from it
    """
    cfg = config or FrameSampleConfig()
    picks = dict(pick_frames(n_frames, fps, scenario.events, cfg))
    if not picks:
        return []
    by_frame: dict[int, list[RangedBox]] = defaultdict(list)
    for b in boxes:
        if b.frame in picks:
            by_frame[b.frame].append(b)
    images: dict[int, tuple[float, np.ndarray]] = {}
    if frame_times_s is not None and all(i in frame_times_s for i in picks):
        # a long clip's last pick is minutes in: seek there rather than decode every frame
        images = {i: (frame_times_s[i], img) for i, img in read_frames(video, list(picks)).items()}
    else:
        last = max(picks)
        # only the picked frames are converted; the others are grabbed (decoded, not copied)
        for frame in tqdm(iter_frames(video, fps=video_fps, only=picks), total=last + 1,
                          unit="frame", desc="sampled frames", disable=not progress,
                          leave=False):
            if frame.index in picks and frame.image_bgr is not None:
                images[frame.index] = (frame.t_s, frame.image_bgr)
            if frame.index >= last:
                break
    renders = gym_renders(scenario, [t for t, _ in images.values()], fps, cfg)
    out_dir.mkdir(parents=True, exist_ok=True)
    figures = []
    for index, (t_s, img) in sorted(images.items()):
        drawn = draw_frame(cv2.resize(img, (camera.image_width, camera.image_height))
                           if img.shape[:2] != (camera.image_height, camera.image_width)
                           else img, by_frame.get(index, []),
                           lane_boundaries_px(camera, lanes, t_s, cfg))
        ok, png = cv2.imencode(".png", side_by_side(drawn, renders[t_s]))
        if not ok:  # pragma: no cover - PNG encoding of a BGR array does not fail
            raise RuntimeError("PNG encoding failed")
        path = out_dir / f"frame_{index:06d}.png"
        write_bytes_atomic(path, png.tobytes())
        what = picks[index]
        figures.append((f"frame {index} ({t_s:.1f} s)" + (f": {what}" if what else ""), path))
    return figures
