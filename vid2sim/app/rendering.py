"""``vid2sim render`` and ``vid2sim build --render``: the replay video of a build.

``render`` reads a build folder (``scenario.json``, ``tracks.csv``, ``report.html``), checks
every input before any drawing (the folder is a build's, the video is the build's: its frame
size and length; the times and rate asked for lie within it; the output can be written),
draws the replay (:mod:`vid2sim.evaluate.replayvideo`) into a temporary file beside the
output and renames it into place. A video written into the build folder is put into the
folder's ``report.html`` (:func:`vid2sim.evaluate.report.with_replay`), itself rewritten
atomically. ``build --render`` does the same inside the build's staging folder, with the
lane-marking track it has in memory.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

from vid2sim.app.loaders import load_keyframes_for
from vid2sim.base.errors import (
    ImpossibleValueError,
    InconsistentInputError,
    MissingInputError,
    OutputError,
)
from vid2sim.base.fileio import (
    atomic_path,
    check_output_file,
    parse_json,
    read_input_text,
    sha256_path,
    write_text_atomic,
)
from vid2sim.core import scenario as scenario_io
from vid2sim.core.camera import Camera
from vid2sim.core.records import Keyframe, LaneTrack, RangedBox, VideoInfo
from vid2sim.core.scenario import Scenario
from vid2sim.core.tables import iter_tracks_csv
from vid2sim.detect.video import video_info
from vid2sim.evaluate.annotations import read_keyframes
from vid2sim.evaluate.frames import pick_frames
from vid2sim.evaluate.replayvideo import (
    ReplayResult,
    ReplaySource,
    ReplayVideoConfig,
    replay_times,
    write_build_replay,
)
from vid2sim.evaluate.report import replay_section, with_replay
from vid2sim.evaluate.videoout import browser_playable

#: The replay's name in a build folder.
REPLAY_NAME = "replay.mp4"
#: Highest output frame rate [frames/s]: above a 240 fps camera's there is nothing to show.
MAX_RENDER_FPS = 240.0


@dataclass(frozen=True, slots=True)
class RenderRequest:
    """What ``vid2sim render`` was asked: the build folder, the output, the video, the span
    [s] and rate [frames/s] (None: the whole clip at the video's rate), keyframes."""

    build_dir: Path
    out: Path
    video: Path | None = None
    t_from_s: float | None = None
    t_to_s: float | None = None
    fps: float | None = None
    keyframes: Path | None = None


@dataclass(frozen=True, slots=True)
class _Clip:
    """The checked time base: the clip's first and last times [s], its rate, frame count."""

    t_first_s: float
    t_last_s: float
    fps: float
    n_frames: int


def _load_build(build_dir: Path) -> Scenario:
    if not build_dir.is_dir():
        raise MissingInputError(build_dir, "no such build folder",
                                "give the folder `vid2sim build --out` wrote")
    path = build_dir / "scenario.json"
    if not path.is_file():
        raise MissingInputError(path, "not found: this is not a build folder",
                                "give the folder `vid2sim build --out` wrote")
    return scenario_io.load(path)


def _recorded_fps(scenario: Scenario) -> float | None:
    v = scenario.source.options.get("fps")
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and v > 0 \
        else None


def _check_video(video: Path, scenario: Scenario, camera: Camera) -> tuple[VideoInfo, list[str]]:
    """The video's facts, refused when it is not the build's (another size or length); a note
    when its bytes differ from the recorded fingerprint but it fits (a re-encode)."""
    info = video_info(video, fps=_recorded_fps(scenario))
    if (info.width, info.height) != (camera.image_width, camera.image_height):
        raise InconsistentInputError(video, f"frames are {info.width}x{info.height} px, the "
                                     f"build's camera {camera.image_width}x"
                                     f"{camera.image_height} px", "give the build's video")
    n_built = scenario.source.options.get("n_frames")
    span = scenario.ego.trajectory.t[-1]
    if isinstance(n_built, int) and not isinstance(n_built, bool):
        if info.n_frames != n_built:
            raise InconsistentInputError(video, f"{info.n_frames} frames, the build's video had "
                                         f"{n_built}", "give the build's video")
    elif (info.n_frames - 1) / info.fps < span - 1.5 / info.fps:
        raise InconsistentInputError(video, f"lasts {(info.n_frames - 1) / info.fps:.2f} s, the "
                                     f"scenario {span:.2f} s", "give the build's video")
    notes = []
    recorded = [i for i in scenario.source.inputs if isinstance(i, dict)
                and i.get("role") == "video" and i.get("sha256")]
    if recorded and recorded[0]["sha256"] != sha256_path(video):
        notes.append(f"{video.name} is not the file the build read (its sha256 differs); its "
                     "size and length match, so it is taken as a copy of that video")
    return info, notes


def _clip(scenario: Scenario, info: VideoInfo | None) -> _Clip:
    """The clip's time base: the video's; without one, the build's video as recorded (its
    frame count and rate), else the ego trajectory's span at 10 frames/s."""
    if info is not None:
        return _Clip(0.0, (info.n_frames - 1) / info.fps, info.fps, info.n_frames)
    rate = _recorded_fps(scenario)
    n = scenario.source.options.get("n_frames")
    if rate is not None and isinstance(n, int) and not isinstance(n, bool) and n > 0:
        return _Clip(0.0, (n - 1) / rate, rate, n)
    rate = rate or 10.0
    ego = scenario.ego.trajectory
    return _Clip(float(ego.t[0]), float(ego.t[-1]), rate,
                 math.floor((ego.t[-1] - ego.t[0]) * rate + 1e-6) + 1)


def _span(request: RenderRequest, clip: _Clip) -> tuple[float, float, float]:
    """(from, to, fps) checked against the clip."""
    fps = clip.fps if request.fps is None else float(request.fps)
    if not (math.isfinite(fps) and 0 < fps <= MAX_RENDER_FPS):
        raise ImpossibleValueError(None, f"--fps must be in (0, {MAX_RENDER_FPS:g}] frames/s, "
                                   f"got {request.fps}")
    t0 = clip.t_first_s if request.t_from_s is None else float(request.t_from_s)
    t1 = clip.t_last_s if request.t_to_s is None else float(request.t_to_s)
    for name, v in (("--from", t0), ("--to", t1)):
        if not math.isfinite(v):
            raise ImpossibleValueError(None, f"{name} must be a finite time [s], got {v}")
        if not clip.t_first_s - 1e-6 <= v <= clip.t_last_s + 1e-6:
            raise InconsistentInputError(None, f"{name} {v:g} s lies outside the clip's "
                                         f"{clip.t_first_s:g}-{clip.t_last_s:g} s")
    if t1 <= t0:
        raise ImpossibleValueError(None, f"--to ({t1:g} s) must be later than --from "
                                   f"({t0:g} s)")
    return t0, t1, fps


def _keyframes(path: Path | None, video: Path | None, info: VideoInfo | None,
               fps: float) -> list[Keyframe]:
    if path is None:
        return []
    if video is not None and info is not None:
        return load_keyframes_for(path, video, info)
    return read_keyframes(path, fps=fps)


def _moments(scenario: Scenario, clip: _Clip, t0: float, t1: float,
             metrics: dict | None) -> list[tuple[str, float, int | None]]:
    """The report's rows to jump to: events, the sampled frames, keyframes, in time order."""
    rows = [(f"{e.type} {e.actor} ({e.from_lane:+d} -> {e.to_lane:+d})", e.t_s,
             round(e.t_s * clip.fps)) for e in scenario.events]
    rows += [(what or "sampled frame", k / clip.fps, k)
             for k, what in pick_frames(clip.n_frames, clip.fps, [])]
    for k in (metrics or {}).get("per_keyframe") or []:
        if isinstance(k.get("t_s"), (int, float)):
            rows.append((f"keyframe {k.get('name')}", float(k["t_s"]),
                         round(float(k["t_s"]) * clip.fps)))
    return sorted((r for r in rows if t0 - 1e-6 <= r[1] <= t1 + 1e-6), key=lambda r: r[1])


def _summary(result: ReplayResult, cpu_s: float, span_s: float, notes: list[str],
             report: Path | None) -> str:
    codec = "H.264" if result.codec == "h264" else "MPEG-4"
    lines = [(f"wrote {result.path}: {result.frames} frames, {result.width}x{result.height} px "
              f"at {result.fps:g} frames/s, {codec} ({cpu_s:.1f} s CPU, "
              f"{cpu_s / max(span_s, 1e-9):.2f}x the clip's time)")]
    if not browser_playable(result.codec):
        lines.append("warning: MPEG-4 part 2 plays in video players, not in browsers (PyAV's "
                     "FFmpeg has no libx264 here: install one that has for H.264)")
    lines += [f"warning: {n}" for n in notes]
    if report is not None:
        lines.append(f"put the video into {report}")
    return "\n".join(lines)


def _metrics(build_dir: Path) -> dict | None:
    path = build_dir / "metrics.json"
    if not path.is_file():
        return None
    data = parse_json(read_input_text(path), path)
    return data if isinstance(data, dict) else None


def _patched_report(build_dir: Path, out: Path, result: ReplayResult,
                    moments: list[tuple[str, float, int | None]], t0: float) -> str | None:
    """The build's report.html with the replay in it, when the video lies in the build
    folder and the folder has a report; else None."""
    report = build_dir / "report.html"
    try:
        href = out.resolve().relative_to(build_dir.resolve()).as_posix()
    except ValueError:
        return None
    if not report.is_file():
        return None
    caption = (f"{result.frames} frames, {result.width}x{result.height} px, {result.fps:g} "
               f"frames/s, {'H.264' if result.codec == 'h264' else 'MPEG-4 part 2'}; scenario "
               f"time {t0:.2f} s at its start.")
    section = replay_section(href, moments, t_from_s=t0, caption=caption,
                             playable=browser_playable(result.codec))
    return with_replay(read_input_text(report), section)


def run_render(request: RenderRequest, config: ReplayVideoConfig | None = None,
               progress: bool = False) -> str:
    """``vid2sim render``: check every input, draw the replay of a build folder into
    ``request.out`` (atomically), put it into the folder's report when it is written there;
    returns the summary."""
    build_dir, out = Path(request.build_dir), Path(request.out)
    scenario = _load_build(build_dir)
    camera = Camera.from_dict(scenario.camera, build_dir / "scenario.json")
    if out.suffix.lower() != ".mp4":
        raise OutputError(out, "the replay is an MP4 video", f"name it e.g. {REPLAY_NAME}")
    check_output_file(out)
    info, notes = (None, [])
    if request.video is not None:
        info, notes = _check_video(Path(request.video), scenario, camera)
    clip = _clip(scenario, info)
    t0, t1, fps = _span(request, clip)
    keyframes = _keyframes(request.keyframes, request.video, info, clip.fps)
    tracks = build_dir / "tracks.csv"
    if tracks.is_file():
        next(iter(iter_tracks_csv(tracks)), None)  # a broken header fails before drawing

        def boxes():
            return iter_tracks_csv(tracks)
    else:
        notes.append(f"{tracks} not found: no detected boxes drawn")

        def boxes():
            return iter(())
    if request.video is None:
        notes.append("no --video: the camera half is a grey canvas")
    source = ReplaySource(scenario, camera, boxes, keyframes=keyframes, scenario_fps=clip.fps)
    cpu0 = time.process_time()
    with atomic_path(out) as tmp:
        result = write_build_replay(source, replay_times(t0, t1, fps), tmp,
                                    video=request.video, video_fps=_recorded_fps(scenario),
                                    config=config, fps=fps, progress=progress)
        report = _patched_report(build_dir, out, result, _moments(
            scenario, clip, t0, t1, _metrics(build_dir)), t0)
    result = ReplayResult(out, result.frames, result.width, result.height, result.fps,
                          result.codec)
    if report is not None:
        write_text_atomic(build_dir / "report.html", report)
    return _summary(result, time.process_time() - cpu0, t1 - t0 + 1.0 / fps, notes,
                    build_dir / "report.html" if report is not None else None)


def render_into_build(staging: Path, scenario: Scenario, camera: Camera,
                      boxes: list[RangedBox], lanes: LaneTrack | None, video: Path,
                      info: VideoInfo, keyframes: list[Keyframe], video_fps: float | None,
                      config: ReplayVideoConfig | None = None, progress: bool = False
                      ) -> ReplayResult:
    """``build --render``: the replay of the build being staged, written as
    ``staging/replay.mp4`` and put into ``staging/report.html``."""
    ordered = sorted(boxes, key=lambda b: (b.frame, b.track_id))
    clip = _Clip(0.0, (info.n_frames - 1) / info.fps, info.fps, info.n_frames)
    source = ReplaySource(scenario, camera, lambda: iter(ordered), lanes=lanes,
                          keyframes=keyframes, scenario_fps=info.fps)
    out = staging / REPLAY_NAME
    result = write_build_replay(source, replay_times(0.0, clip.t_last_s, clip.fps), out,
                                video=video, video_fps=video_fps, config=config,
                                fps=clip.fps, progress=progress)
    report = _patched_report(staging, out, result, _moments(
        scenario, clip, 0.0, clip.t_last_s, _metrics(staging)), 0.0)
    if report is not None:
        write_text_atomic(staging / "report.html", report)
    return result
