"""The detection stage wired: stream frames -> detect (or import boxes) -> track -> range.

This is the I/O edge of ``detect/``: it reads frames and calls the pure stages (detector,
tracker, lane markings, ranging) one frame at a time.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from vid2sim.camera import Camera
from vid2sim.detect.detector import Detector
from vid2sim.detect.lanes import HorizonEstimator, yaw_for_vanishing_column
from vid2sim.detect.ranging import RangingConfig, range_tracks
from vid2sim.detect.tracker import Tracker, TrackerConfig
from vid2sim.detect.video import iter_frames, video_info
from vid2sim.errors import InputError
from vid2sim.records import Detection, Frame, Note, RangingResult, TrackedBox
from vid2sim.videofile import skipped_frames_note


def run_detect(source: Path, *, detector: Detector | None,
               detections: dict[int, list[Detection]] | None = None, detect_every: int = 1,
               progress: bool = True, on_frame: Callable[[Frame], None] | None = None,
               tracker_config: TrackerConfig | None = None, fps: float | None = None,
               skipped_frames: list[int] | None = None) -> list[TrackedBox]:
    """Detect and track vehicles through a video, one frame in memory at a time.

    Parameters
    ----------
    source : Path
        Video file or folder of images.
    detector : Detector or None
        Runs on every ``detect_every``-th frame; None with ``detections`` given (the imported
        boxes are used). Detectors are loaded by the application layer
        (:func:`vid2sim.app.loaders.load_detector_for`).
    detections : dict, optional
        Imported boxes, 0-based frame -> detections (see :mod:`vid2sim.detect.external`);
        used instead of a detector. Frames absent from the dict are treated as frames where
        nothing was found when they are multiples of ``detect_every``.
    detect_every : int
        Detect on frames 0, N, 2N, ...; the tracker carries (predicts) boxes in between and
        those frames are not decoded at all.
    progress : bool
        Show a tqdm bar on stderr.
    on_frame : callable, optional
        Called with every decoded frame (image present) before detection, e.g. to estimate
        the horizon from lane markings.
    tracker_config : TrackerConfig, optional
        Tracker thresholds.
    fps : float, optional
        Frame rate for image folders [frames/s] (default 10).
    skipped_frames : list of int, optional
        Receives the indices of corrupt or missing frames, skipped (the tracker predicts
        across them).

    Returns
    -------
    list of TrackedBox
        One row per confirmed track per frame it is alive in, sorted by frame then track id.
    """
    from tqdm import tqdm

    if detector is None and detections is None:
        raise ValueError("run_detect needs a detector or imported detections")
    if detect_every < 1:
        raise InputError(None, f"--detect-every must be >= 1, got {detect_every}")
    info = video_info(source, fps=fps)
    tracker = Tracker(tracker_config, image_size_px=(info.width, info.height))
    rows: list[TrackedBox] = []
    n_seen = 0
    # Imported boxes need no pixels: decode only if someone looks at the image.
    decode_every = detect_every if (detector is not None or on_frame is not None) else 0
    with tqdm(total=info.n_frames or None, unit="frame", desc="detect",
              disable=not progress) as bar:
        for frame in iter_frames(source, every=decode_every or 1_000_000_000, fps=fps,
                                 skipped=skipped_frames):
            if frame.image_bgr is not None and on_frame is not None:
                on_frame(frame)
            is_detect_frame = frame.index % detect_every == 0
            if not is_detect_frame:
                found = None
            elif detections is not None:
                found = detections.get(frame.index, [])
            else:
                found = detector.detect(frame.image_bgr)
            rows.extend(tracker.update(frame.index, frame.t_s, found))
            n_seen = frame.index + 1
            bar.update(1)
    box_frames = [f for f, dets in (detections or {}).items() if dets]
    if box_frames and min(box_frames) >= n_seen:
        # Boxes made for another (longer) video: an empty result would look like an empty road.
        raise InputError(source, f"none of the imported boxes falls on the video's {n_seen} "
                         f"frames (boxes on 0-based frames {min(box_frames)}.."
                         f"{max(box_frames)})", "is the detections file for this video?")
    return tracker.finalize(rows)


# The lane vanishing point moves on curves; a median over this many sampled frames (every
# 5th video frame: 2 s at 25 fps) is needed before it is trusted as straight ahead.
MIN_LANE_FRAMES_FOR_YAW = 10
# A windscreen mount turned more than this is implausible: more likely a long curve.
MAX_YAW_CORRECTION_DEG = 5.0


def detect_and_range(video: Path, camera: Camera, *, detector, detections=None,
                     detect_every: int = 1, fps: float | None = None, progress: bool = True,
                     config: RangingConfig | None = None,
                     tracker_config: TrackerConfig | None = None
                     ) -> tuple[RangingResult, Camera, list[Note]]:
    """Detect (or import), track and range every vehicle of a video: the shared core of
    ``vid2sim track`` and ``vid2sim build``.

    While frames stream, lane markings give per-frame horizon rows and the vanishing column;
    the column corrects the camera's yaw (so the ego corridor follows the lane) when enough
    frames agree and the correction is plausible for a mounting.

    Parameters
    ----------
    video : Path
        Video file or image folder.
    camera : Camera
        The camera at the video's frame size.
    detector : Detector or None
        Runs on every ``detect_every``-th frame; None with ``detections``.
    detections : dict, optional
        Imported boxes, 0-based frame -> detections.
    fps : float, optional
        Frame rate of an image folder [frames/s].

    Returns
    -------
    result : RangingResult
    camera : Camera
        The camera used for ranging (yaw possibly corrected).
    notes : list of Note
        What was estimated and why, for the summary.
    """
    notes: list[Note] = []
    # Every decoded frame: about 6 ms at 640 px wide, and the per-frame rows follow the
    # horizon's drift (see lane_horizon_offsets).
    horizon_est = HorizonEstimator(camera, every=1)
    skipped: list[int] = []
    boxes = run_detect(video, detector=detector, detections=detections,
                       detect_every=detect_every, progress=progress, fps=fps,
                       tracker_config=tracker_config, skipped_frames=skipped,
                       on_frame=lambda frame: horizon_est.add_frame(frame.image_bgr,
                                                                    frame.index))
    if skipped:
        notes.append(Note.warning(f"{Path(video).name}: {skipped_frames_note(skipped)}"))
    # Lane markings also say where straight ahead is: correct the camera's yaw so the ego
    # corridor runs along the lane rather than along a slightly turned camera axis.
    column, n_col = horizon_est.estimate_column()
    if column is not None and n_col >= MIN_LANE_FRAMES_FOR_YAW:
        yaw = yaw_for_vanishing_column(camera, column)
        if abs(yaw - camera.yaw_deg) <= MAX_YAW_CORRECTION_DEG:
            notes.append(Note.estimate(
                f"camera yaw {yaw:+.2f} deg from the lane markings' vanishing point "
                f"({n_col} frames; camera file said {camera.yaw_deg:+.2f})"))
            camera = replace(camera, yaw_deg=yaw)
        else:
            notes.append(Note.warning(
                f"lane markings point {yaw - camera.yaw_deg:+.1f} deg off the camera axis: "
                "implausible for a mounting, yaw not changed"))
    result = range_tracks(boxes, camera, horizon_hints_px=horizon_est.rows_px,
                          horizon_hint_frames=horizon_est.frames, config=config)
    return result, camera, notes
