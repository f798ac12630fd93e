"""The one place each shared input is loaded: video facts, camera, detector, boxes, GPS.

Every command that needs one of these calls the loader here, so a camera is fitted to the
frames, a detector gets its thresholds, and the GPS gets its time base the same way in
``track``, ``build`` and ``batch``.
"""

from __future__ import annotations

from pathlib import Path

from vid2sim.app.gpsinputs import load_trace, smooth_trace  # noqa: F401 - the GPS inputs
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import Settings
from vid2sim.base.errors import InconsistentInputError, MissingInputError
from vid2sim.core.camera import Camera, fit_camera_to_frames, load_camera
from vid2sim.core.records import (
    Detection,
    Keyframe,
    Note,
    VideoInfo,
)
from vid2sim.core.videofile import image_files
from vid2sim.detect.vehicles.detector import OnnxDetector, load_detector
from vid2sim.detect.vehicles.external import read_detections
from vid2sim.detect.vehicles.models import resolve_model
from vid2sim.detect.video import video_info
from vid2sim.evaluate.annotations import read_keyframes


def need_video(inputs: Inputs) -> Path:
    """The video path, or an input error for a command that needs one."""
    if inputs.video is None:
        raise MissingInputError(None, "no video given")
    return Path(inputs.video)


def load_video_info(inputs: Inputs) -> VideoInfo:
    """Size, rate and frame count of the video (image folders timed at ``inputs.fps``)."""
    return video_info(need_video(inputs), fps=inputs.fps)


def load_camera_for(inputs: Inputs, info: VideoInfo) -> tuple[Camera, list[Note]]:
    """The camera of ``inputs.camera`` fitted to the frames, or a default camera, with notes.

    A camera file for another image size is taken as a crop or a resize when it can be one
    (a note says so), else refused.
    """
    if inputs.camera is None:
        # A warning, not only an assumption: ranges scale with the guessed focal length and
        # height. The scenario's source records the camera's assumptions as well.
        cam = Camera.default_for(info.width, info.height)
        return cam, [Note.warning(f"no --camera: {a}") for a in cam.assumptions]
    cam, note = fit_camera_to_frames(load_camera(inputs.camera), info.width, info.height,
                                     inputs.camera)
    return cam, [Note.warning(note)] if note else []


_KEPT_DETECTORS: dict[tuple, OnnxDetector] | None = None
"""Detectors loaded in this process, by their settings and weights (None: not kept)."""


def keep_loaded_detectors() -> None:
    """From now on keep each detector loaded in this process for the next run with the same
    settings and weights (a batch worker building row after row): the session is built and
    the weights read once per process. Detectors are safe to share between runs (their
    sessions are thread-safe and they hold no state between frames)."""
    global _KEPT_DETECTORS
    if _KEPT_DETECTORS is None:
        _KEPT_DETECTORS = {}


def load_detector_for(settings: Settings) -> OnnxDetector:
    """The detector of ``settings.detector``; it keeps every box above the tracker's low
    score, since weak boxes feed the tracker's second association stage (ByteTrack)."""
    d = settings.detector
    options = {"score_threshold": settings.tracker_config().low_score,
               "small_object_mode": d.tiles, "refine_max_boxes": d.refine,
               "threads": max(1, int(d.threads))}
    if _KEPT_DETECTORS is None:
        return load_detector(d.name, d.model_dir, **options)
    weights = resolve_model(d.name, d.model_dir)
    stat = weights.stat()
    key = (str(weights), stat.st_size, stat.st_mtime_ns, d.name, *sorted(options.items()))
    if key not in _KEPT_DETECTORS:
        _KEPT_DETECTORS[key] = load_detector(d.name, d.model_dir, **options)
    return _KEPT_DETECTORS[key]


def load_boxes(inputs: Inputs, settings: Settings
               ) -> tuple[OnnxDetector | None, dict[int, list[Detection]] | None, str]:
    """Either the imported boxes of ``inputs.detections`` or the detector, and a label
    saying which (for summaries and the scenario's source)."""
    if inputs.detections is not None:
        return (None, read_detections(Path(inputs.detections)),
                f"imported boxes ({Path(inputs.detections).name})")
    detector = load_detector_for(settings)
    label = settings.detector.label()
    if detector.refine_max_boxes > 0:
        label += f" + {detector.refine_max_boxes} refined"
    return detector, None, label


def load_keyframes_for(keyframes: Path, video: Path, info: VideoInfo,
                       fps: float | None = None, calib_dir: Path | None = None,
                       rate_hz: float | None = None) -> list[Keyframe]:
    """The annotated keyframes on the video's frames, checked against the video.

    Frame numbers and times are read as the evaluation reads them (an image folder's frames
    matched by name, times at ``fps`` or the video's rate). Run before any detection: a
    keyframe file for another video must fail in a second, not be scored as a zero on a grey
    canvas after the whole build.

    Raises
    ------
    InputError
        If no keyframe matches a frame of the video, or any lies beyond its last frame.
    """
    rate = float(fps or info.fps)
    names = [p.name for p in image_files(video)] if Path(video).is_dir() else None
    frames = read_keyframes(keyframes, fps=rate, frame_names=names, calib_dir=calib_dir,
                            rate_hz=rate_hz, image_size_px=(info.width, info.height))
    if not frames:
        raise InconsistentInputError(
            keyframes, "no annotated keyframe matches a frame of the video "
            f"({info.n_frames} frames)", "are the annotations for this video?")
    index = [k.frame if k.frame is not None else round(k.t_s * rate) for k in frames]
    outside = [(k, f) for k, f in zip(frames, index, strict=True)
               if not 0 <= f < info.n_frames]
    if outside:
        k, f = outside[0]
        raise InconsistentInputError(
            keyframes, f"{len(outside)} of {len(frames)} keyframes lie outside the "
            f"video's {info.n_frames} frames (first: {k.name!r}, frame {f})",
            "are the annotations for this video, at this frame rate?")
    return frames
