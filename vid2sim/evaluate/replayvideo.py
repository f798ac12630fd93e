"""The replay video of a build: the camera beside the scenario, frame by frame, in sync.

Each frame of the video (the build's video, or a grey canvas without one) is drawn as

    +----------------------------------+-----------------+
    | camera: detected boxes, scenario | bird's-eye view |
    | vehicles projected back, lanes   | of the scenario |
    +----------------------------------+ (ego up)        |
    | strip: time, speeds, lead, TTC   |                 |
    +----------------------------------+-----------------+

(:mod:`vid2sim.evaluate.overlay`, :mod:`vid2sim.evaluate.birdseye`,
:mod:`vid2sim.evaluate.timeline`), and encoded as it is drawn
(:mod:`vid2sim.evaluate.videoout`). The output's frame ``k`` shows the scenario time
``t_from + k / fps`` and the video frame nearest to it, so the replay keeps the scenario's
clock whatever its frame rate. Streamed: one decoded frame, one drawn frame and the boxes of
one frame are held at a time; what grows with the clip is a few numbers per output frame
(the strip's series) and the scenario itself.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from vid2sim.core.camera import Camera
from vid2sim.core.outline import CLASS_SHAPES, OutlineShape
from vid2sim.core.records import Frame, Keyframe, LaneTrack, RangedBox
from vid2sim.core.scenario import Scenario
from vid2sim.detect.video import iter_frames, prefetch
from vid2sim.evaluate.birdseye import BirdsEye, Mark, lane_edges_at
from vid2sim.evaluate.frames import lane_boundaries_px
from vid2sim.evaluate.overlay import draw_camera, lane_edges_px, scenario_in_camera
from vid2sim.evaluate.replayconfig import ReplayVideoConfig, StripConfig
from vid2sim.evaluate.scenetime import SceneClock
from vid2sim.evaluate.timeline import Moment, Plot, Strip, Trace, ttc_s
from vid2sim.evaluate.videoout import VideoOut

_GAP_BGR = (235, 235, 235)
_EVENT_BGR = {"cut_in": (0, 165, 255), "cut_out": (255, 200, 0), "lane_change": (255, 120, 255)}


@dataclass(frozen=True, slots=True)
class Layout:
    """Pixel sizes of the parts: camera ``cam_w x cam_h``, strip ``cam_w x strip_h``,
    bird's-eye ``bev_w x (cam_h + strip_h)``, a ``gap`` between."""

    cam_w: int
    cam_h: int
    strip_h: int
    bev_w: int
    gap: int = 4

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the whole frame."""
        return self.cam_w + self.gap + self.bev_w, self.cam_h + self.strip_h


def layout_for(cam_w: int, cam_h: int, config: ReplayVideoConfig | None = None) -> Layout:
    """The layout for a video of ``cam_w x cam_h`` (see :class:`ReplayVideoConfig`)."""
    cfg = config or ReplayVideoConfig()
    strip_h = max(cfg.strip_min_px, round(cfg.strip_share * cam_h))
    bev_w = max(math.ceil(cfg.birdseye_share * cam_w),
                round(cfg.birdseye_aspect * (cam_h + strip_h)))
    return Layout(cam_w, cam_h, strip_h, bev_w + bev_w % 2)


def replay_times(t_from_s: float, t_to_s: float, fps: float) -> np.ndarray:
    """The scenario times of the output frames: ``t_from + k / fps`` up to ``t_to``."""
    n = max(1, math.floor((t_to_s - t_from_s) * fps + 1e-6) + 1)
    return t_from_s + np.arange(n) / fps


@dataclass(slots=True)
class ReplaySource:
    """What a build replay draws.

    :param boxes: a fresh iterator of the build's ranged boxes in frame order each call
        (a list's, or a ``tracks.csv`` streamed)
    :param lanes: the lane-marking track (its boundaries drawn) where the caller has it
    :param scenario_fps: frame rate that turns times into frame numbers without a video
    """

    scenario: Scenario
    camera: Camera
    boxes: Callable[[], Iterable[RangedBox]]
    lanes: LaneTrack | None = None
    keyframes: list[Keyframe] = field(default_factory=list)
    outlines: dict[str, OutlineShape] | None = field(default_factory=lambda: CLASS_SHAPES)
    scenario_fps: float = 10.0


@dataclass(frozen=True, slots=True)
class ReplayResult:
    """What was written: frames, size [px], rate [frames/s], codec."""

    path: Path
    frames: int
    width: int
    height: int
    fps: float
    codec: str


class _FrameBoxes:
    """The boxes of one frame at a time from a stream in frame order."""

    def __init__(self, boxes: Iterable[RangedBox]):
        self._it = iter(boxes)
        self._next = next(self._it, None)
        self._frame, self._boxes = -1, []

    def at(self, frame: int) -> list[RangedBox]:
        if frame == self._frame:
            return self._boxes
        while self._next is not None and self._next.frame < frame:
            self._next = next(self._it, None)
        out = []
        while self._next is not None and self._next.frame == frame:
            out.append(self._next)
            self._next = next(self._it, None)
        self._frame, self._boxes = frame, out
        return out


def frames_at(video: Path, times_s: np.ndarray, video_fps: float | None = None
              ) -> Iterator[Frame]:
    """For each time, the video frame nearest to it (the latest not later than half an
    output period past it), decoding the video once in a background thread."""
    half = 0.5 * (times_s[1] - times_s[0]) if len(times_s) > 1 else 0.05
    stream = prefetch(iter_frames(video, fps=video_fps))
    try:
        cur = next(stream)
        nxt = next(stream, None)
        for t in times_s:
            while nxt is not None and nxt.t_s <= t + half - 1e-9:
                cur, nxt = nxt, next(stream, None)
            yield cur
    finally:
        stream.close()


def _series(source: ReplaySource, times_s: np.ndarray) -> dict[str, np.ndarray]:
    """The strip's numbers at every output time: ego speed, the lead's id, range and closing
    speed, TTC (one pass of the scene clock)."""
    clock = SceneClock(source.scenario)
    n = len(times_s)
    out = {k: np.full(n, np.nan) for k in ("ego_mps", "range_m", "closing_mps")}
    out["lead"] = np.full(n, "", dtype=object)
    t_ego = source.scenario.ego.trajectory.t
    for k, t in enumerate(times_s):
        ego, actors = clock.at(float(t))
        if not t_ego[0] - 1e-3 <= t <= t_ego[-1] + 1e-3:
            continue  # the ego is held at an end of its trajectory: no speed, no lead
        out["ego_mps"][k] = ego.speed_mps
        lead = clock.lead(ego, actors)
        if lead is not None:
            out["lead"][k] = lead.id
            out["range_m"][k], out["closing_mps"][k] = lead.range_m, lead.closing_mps
    out["ttc_s"] = ttc_s(out["range_m"], out["closing_mps"])
    return out


def _detected_lead(boxes: Iterable[RangedBox], t0: float, t1: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(times, ranges) of the detected lead (``is_lead`` rows) within [t0, t1]."""
    pts = [(b.t_s, b.range_m) for b in boxes if b.is_lead and t0 - 1e-6 <= b.t_s <= t1 + 1e-6]
    arr = np.array(pts, dtype=float).reshape(-1, 2)
    return arr[:, 0], arr[:, 1]


def build_strip(source: ReplaySource, times_s: np.ndarray, series: dict[str, np.ndarray],
                width: int, height: int, config: StripConfig) -> Strip:
    """The strip of a build replay: lead range (scenario line, detection dots), ego speed,
    the TTC band and the scenario's events."""
    t0, t1 = float(times_s[0]), float(times_s[-1])
    det_t, det_r = _detected_lead(source.boxes(), t0, t1)
    # the detections' dots first, the scenario's line over them
    plots = [Plot("lead range [m]", [
                 Trace("video (detected)", det_t, det_r, (0, 200, 255), "dots"),
                 Trace("scenario", times_s, series["range_m"], (90, 90, 255))]),
             Plot("ego speed [m/s]", [Trace("ego", times_s, series["ego_mps"], (80, 220, 80))])]
    moments = [Moment(e.t_s, f"{e.type.replace('_', '-')} {e.actor}",
                      _EVENT_BGR.get(e.type, (255, 255, 255)))
               for e in source.scenario.events if t0 - 1e-6 <= e.t_s <= t1 + 1e-6]
    return Strip(width, height, t0, t1, plots, (times_s, series["ttc_s"]), moments, config)


def strip_line(t_s: float, frame: int | None, series: dict[str, np.ndarray], k: int) -> str:
    """The strip's line of numbers at output frame ``k``."""
    v = series["ego_mps"][k]
    parts = [f"t {t_s:5.1f} s"]
    if frame is not None:
        parts.append(f"frame {frame}")
    if not np.isfinite(v):
        parts.append("ego held: beyond its trajectory")
        return "   ".join(parts)
    parts.append(f"ego {v:4.1f} m/s ({3.6 * v:3.0f} km/h)")
    lead = series["lead"][k]
    if lead:
        ttc = series["ttc_s"][k]
        parts.append(f"lead {lead}: {series['range_m'][k]:.1f} m, closing "
                     f"{series['closing_mps'][k]:+.1f} m/s, TTC "
                     + (f"{ttc:.1f} s" if np.isfinite(ttc) else "-"))
    else:
        parts.append("no lead")
    return "   ".join(parts)


class BuildReplay:
    """Draws the frames of one build's replay (module docstring)."""

    def __init__(self, source: ReplaySource, times_s: np.ndarray,
                 config: ReplayVideoConfig | None = None):
        self.source, self.times = source, np.asarray(times_s, dtype=float)
        self.config = cfg = config or ReplayVideoConfig()
        cam = source.camera
        self.layout = lay = layout_for(cam.image_width, cam.image_height, cfg)
        self.birdseye = BirdsEye(source.scenario.roads, lay.bev_w, lay.cam_h + lay.strip_h,
                                 cfg.birdseye)
        self.series = _series(source, self.times)
        self.strip = build_strip(source, self.times, self.series, lay.cam_w, lay.strip_h,
                                 cfg.strip)
        self.clock = SceneClock(source.scenario)
        self.keyframes = {(k.frame if k.frame is not None
                           else round(k.t_s * source.scenario_fps)): k for k in source.keyframes}
        w, h = lay.size
        self.canvas = np.full((h, w, 3), _GAP_BGR, np.uint8)

    def draw(self, k: int, frame: Frame | None, boxes: list[RangedBox]) -> np.ndarray:
        """The picture of output frame ``k`` (the canvas, reused: copy it to keep it)."""
        src, lay, t = self.source, self.layout, float(self.times[k])
        index = frame.index if frame is not None else round(t * src.scenario_fps)
        cam = self.canvas[:lay.cam_h, :lay.cam_w]
        if frame is not None and frame.image_bgr is not None:
            cam[:] = frame.image_bgr[:lay.cam_h, :lay.cam_w]
        else:
            cam[:] = self.config.canvas_grey
        ego, actors = self.clock.at(t)
        xyh = {i: p.xyh for i, p in actors.items()}
        sims = scenario_in_camera(src.scenario, src.camera, ego.xyh, xyh, boxes, src.outlines)
        edges = lane_edges_at(self.birdseye.roads, ego.x_m, ego.y_m)
        draw_camera(cam, boxes, sims,
                    lane_edges_px(src.camera, ego.xyh, edges or (), self.config.overlay),
                    lane_boundaries_px(src.camera, src.lanes, t) if src.lanes is not None
                    else (), self.keyframes.get(index), self.config.overlay)
        lead = self.series["lead"][k]
        marks = [Mark("ego", *ego.xyh, src.scenario.ego.length_m, src.scenario.ego.width_m,
                      "ego")]
        for i, p in actors.items():
            a = self.clock.actor(i)
            kind = "lead" if i == lead else "static" if a.static else "actor"
            marks.append(Mark(i, *p.xyh, a.length_m, a.width_m, kind))
        bev = self.birdseye.draw(ego.xyh, marks, [(b.range_m, b.lateral_m) for b in boxes],
                                 title=f"scenario (bird's-eye) t={t:.1f} s")
        self.canvas[:, lay.cam_w + lay.gap:] = bev
        self.canvas[lay.cam_h:, :lay.cam_w] = self.strip.draw(
            t, strip_line(t, index if frame is not None else None, self.series, k))
        return self.canvas


def write_build_replay(source: ReplaySource, times_s: np.ndarray, out_path: Path,
                       video: Path | None = None, video_fps: float | None = None,
                       config: ReplayVideoConfig | None = None, fps: float | None = None,
                       progress: bool = False) -> ReplayResult:
    """Draw and encode the replay of ``source`` at ``times_s`` into ``out_path`` (written in
    place: the caller stages it). ``video``: the build's video (its frames must be the
    camera's size); ``fps``: the output's rate (default the spacing of ``times_s``)."""
    replay = BuildReplay(source, times_s, config)
    rate = fps or (round(1.0 / float(np.median(np.diff(times_s))), 6) if len(times_s) > 1
                   else source.scenario_fps)
    w, h = replay.layout.size
    frames = (frames_at(video, replay.times, video_fps) if video is not None
              else itertools.repeat(None, len(replay.times)))
    boxes = _FrameBoxes(source.boxes())
    with VideoOut(out_path, w, h, rate, config=replay.config.encoder) as out:
        try:
            for k, frame in enumerate(tqdm(frames, total=len(replay.times), unit="frame",
                                           desc="render", disable=not progress, leave=False)):
                t = float(replay.times[k])
                index = frame.index if frame is not None else round(t * source.scenario_fps)
                out.write(replay.draw(k, frame, boxes.at(index)))
        finally:
            if hasattr(frames, "close"):
                frames.close()
    return ReplayResult(Path(out_path), out.frames, *out.size, rate, out.codec)
