"""The detection stage wired: stream frames -> detect (or import boxes) -> track -> range.

This is the I/O edge of ``detect/``: it reads frames and calls the pure stages (detector,
tracker, lane markings, ranging) one frame at a time.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np

from vid2sim.base.errors import ImpossibleValueError, InconsistentInputError
from vid2sim.core.camera import Camera, PitchSource
from vid2sim.core.records import Detection, Frame, LaneTrack, Note, RangingResult, TrackedBox
from vid2sim.core.videofile import skipped_frames_note
from vid2sim.detect.assign import relane
from vid2sim.detect.lanes.markings import LaneMarkingConfig, LaneMarkingDetector
from vid2sim.detect.lanes.track import LaneTrackConfig, track_lanes
from vid2sim.detect.lanes.vanishing import HorizonEstimator, yaw_for_vanishing_column
from vid2sim.detect.rail import RailConfig, find_rail_tracks, keep_trams_from_lead, relabel
from vid2sim.detect.ranging import (
    EgoPath,
    RangingConfig,
    choose_horizon,
    pitch_for_horizon,
    range_tracks,
)
from vid2sim.detect.schedule import KeyframeSchedule, ScheduleConfig
from vid2sim.detect.tracking.flow import FlowConfig, MedianFlow
from vid2sim.detect.tracking.tracker import Tracker, TrackerConfig
from vid2sim.detect.vehicles.detector import Detector
from vid2sim.detect.video import folder_frame_steps, iter_frames, prefetch, video_info


def run_detect(source: Path, *, detector: Detector | None,
               detections: dict[int, list[Detection]] | None = None, detect_every: int = 1,
               progress: bool = True, on_frame: Callable[[Frame], None] | None = None,
               tracker_config: TrackerConfig | None = None, fps: float | None = None,
               schedule: ScheduleConfig | None = None, flow: FlowConfig | None = None,
               stats: dict | None = None, capture_clock: bool = False,
               skipped_frames: list[int] | None = None,
               frame_times: dict[int, float] | None = None) -> list[TrackedBox]:
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
        Imported boxes, 0-based frame -> detections (see :mod:`vid2sim.detect.vehicles.external`);
        used instead of a detector. Frames absent from the dict are treated as frames where
        nothing was found when they are multiples of ``detect_every``.
    detect_every : int
        Detect on frames 0, N, 2N, ...; the tracker carries (predicts) boxes in between and
        those frames are not decoded at all.
    progress : bool
        Show a tqdm bar on stderr.
    on_frame : callable, optional
        Called with every decoded frame (image present), in frame order, in the decoding
        thread (:func:`~vid2sim.detect.video.prefetch`), e.g. to measure lane markings: it
        works on the next frames while the detector and the tracker work on this one, so it
        must keep to its own state until this function returns (by then every frame has been
        shown to it). Its errors are raised here.
    tracker_config : TrackerConfig, optional
        Tracker thresholds.
    fps : float, optional
        Frame rate for image folders [frames/s] (default 10).
    schedule : ScheduleConfig, optional
        With a detector and ``detect_every`` 1: run the detector on keyframes only
        (:mod:`vid2sim.detect.schedule`) and carry the boxes between them by optical flow
        (:mod:`vid2sim.detect.tracking.flow`, settings ``flow``). None: the detector runs on every
        ``detect_every``-th frame and the tracker predicts between.
    stats : dict, optional
        Filled with counts for summaries and benchmarks: ``frames``, ``keyframes``.
    capture_clock : bool
        For an image folder whose names number every N-th frame (``000010, 000015, ...``):
        associate on the numbering's clock (0.5 s apart at 10 fps), so a folder of sparse
        keyframes is tracked as sparse input; the rows keep one frame per image. For
        ``detect`` only: ranging filters over the rows' time, which stays the output's.
    skipped_frames : list of int, optional
        Receives the indices of corrupt or missing frames, skipped (the tracker predicts
        across them).
    frame_times : dict, optional
        Receives every streamed frame's time (0-based index -> ``t_s`` [s], the container's
        clock), so later stages can decode a few frames by seeking and still know their time.

    Returns
    -------
    list of TrackedBox
        One row per confirmed track per frame it is alive in, sorted by frame then track id.
    """
    from tqdm import tqdm  # progress bars only where frames are streamed

    if detector is None and detections is None:
        raise ValueError("run_detect needs a detector or imported detections")
    if detect_every < 1:
        raise ImpossibleValueError(None, f"--detect-every must be >= 1, got {detect_every}")
    info = video_info(source, fps=fps)
    tracker = Tracker(tracker_config, image_size_px=(info.width, info.height))
    # An image folder of every N-th frame (names 000010, 000015, ...) is timed one frame per
    # image, as the annotations and the scenario expect; with capture_clock the tracker's
    # association clock follows the numbering, so it sees the real spacing (sparse: motion
    # model first, a single confident box kept).
    steps = folder_frame_steps(source) if capture_clock else None
    clock = (None if steps is None or steps == list(range(len(steps)))
             else np.asarray(steps, dtype=float) / info.fps)
    keys = (KeyframeSchedule(schedule, info.width)
            if schedule is not None and detector is not None and detect_every == 1 else None)
    carrier = MedianFlow(flow) if keys is not None else None
    rows: list[TrackedBox] = []
    n_seen = n_detected = 0
    # Imported boxes need no pixels: decode only if someone looks at the image.
    decode_every = detect_every if (detector is not None or on_frame is not None) else 0
    frames = iter_frames(source, every=decode_every or 1_000_000_000, fps=fps,
                         skipped=skipped_frames)
    # the optical flow's grey image is made in the decoding thread, ahead of its carry
    observers = ([lambda frame: carrier.prepare(frame.index, frame.image_bgr)]
                 if carrier is not None else [])
    if on_frame is not None:
        observers.append(on_frame)
    if observers:
        frames = _observed(frames, observers)
    frames = prefetch(frames)
    with tqdm(total=info.n_frames or None, unit="frame", desc="detect",
              disable=not progress) as bar:
        for frame in frames:
            shown_t_s = frame.t_s
            if frame_times is not None:
                frame_times[frame.index] = shown_t_s
            if clock is not None:
                frame = replace(frame, t_s=float(clock[frame.index]))
            before = len(rows)
            if keys is not None:
                rows.extend(_scheduled_step(frame, detector, tracker, keys, carrier))
            else:
                is_detect_frame = frame.index % detect_every == 0
                if not is_detect_frame:
                    found = None
                elif detections is not None:
                    found = detections.get(frame.index, [])
                else:
                    found = detector.detect(frame.image_bgr)
                n_detected += found is not None
                rows.extend(tracker.update(frame.index, frame.t_s, found))
            if clock is not None:
                rows[before:] = [replace(r, t_s=shown_t_s) for r in rows[before:]]
            n_seen = frame.index + 1
            bar.update(1)
    if stats is not None:
        stats["frames"] = n_seen
        stats["keyframes"] = keys.n_keyframes if keys is not None else n_detected
        stats["keyframe_reasons"] = dict(keys.reasons) if keys is not None else {}
    box_frames = [f for f, dets in (detections or {}).items() if dets]
    if box_frames and min(box_frames) >= n_seen:
        # Boxes made for another (longer) video: an empty result would look like an empty road.
        raise InconsistentInputError(source, f"none of the imported boxes falls on the video's {n_seen} "
                         f"frames (boxes on 0-based frames {min(box_frames)}.."
                         f"{max(box_frames)})", "is the detections file for this video?")
    return tracker.finalize(rows)


def _observed(frames: Iterator[Frame], observers: list[Callable[[Frame], None]]
              ) -> Iterator[Frame]:
    """``frames``, each decoded one shown to every observer first (in the decoding thread)."""
    for frame in frames:
        if frame.image_bgr is not None:
            for observe in observers:
                observe(frame)
        yield frame


def _scheduled_step(frame: Frame, detector: Detector, tracker: Tracker,
                    keys: KeyframeSchedule, carrier: MedianFlow) -> list[TrackedBox]:
    """One frame of the keyframe schedule: detect, or carry the shown boxes by flow."""
    if keys.is_keyframe(frame.t_s):
        found = detector.detect(frame.image_bgr)
        out = tracker.update(frame.index, frame.t_s, found)
        carrier.carry(frame.image_bgr, [], frame.index)  # keeps this frame for the next carry
        keys.after_keyframe(tracker, frame.t_s)
        return out
    ids, boxes = tracker.shown_boxes()
    moved, ok = carrier.carry(frame.image_bgr, boxes, frame.index)
    out = tracker.update(frame.index, frame.t_s, None,
                         measured={tid: moved[i] for i, tid in enumerate(ids) if ok[i]})
    keys.after_carry(tracker, {tid: bool(ok[i]) for i, tid in enumerate(ids)})
    return out


LANE_INTERVAL_S = 0.2
"""Lane markings are measured on one frame per this interval [s] (every 2nd frame at 10 fps,
every 6th at 30 fps): about 6 ms a frame at 640 px wide, and ranging takes the median of the
rows within a window of a second or more about each frame (lane_horizon_offsets), which
half as many rows still fill."""

def range_and_assign(boxes: list[TrackedBox], camera: Camera, *,
                     config: RangingConfig | None = None, lanes: LaneTrack | None = None,
                     **ranging_options) -> RangingResult:
    """Ranging (:func:`vid2sim.detect.ranging.range_tracks`) followed by the one lane and
    lead assignment (:func:`vid2sim.detect.assign.relane`), for tracked boxes that need no
    tram search (evaluations and benchmarks on labelled boxes)."""
    config = config or RangingConfig()
    result = range_tracks(boxes, camera, config=config, lanes=lanes, **ranging_options)
    result.boxes = relane(result.boxes, config, result.lanes)
    return result


# The lane vanishing point moves on curves; a median over this many sampled frames (every
# 5th video frame: 2 s at 25 fps) is needed before it is trusted as straight ahead.
MIN_LANE_FRAMES_FOR_YAW = 10
# A windscreen mount turned more than this is implausible: more likely a long curve.
MAX_YAW_CORRECTION_DEG = 5.0


def detect_and_range(video: Path, camera: Camera, *, detector, detections=None,
                     detect_every: int = 1, fps: float | None = None, progress: bool = True,
                     config: RangingConfig | None = None,
                     tracker_config: TrackerConfig | None = None,
                     schedule: ScheduleConfig | None = None, stats: dict | None = None,
                     lane_every: int | None = None, assign_lanes: bool = True,
                     flow: FlowConfig | None = None, markings: LaneMarkingConfig | None = None,
                     lane_config: LaneTrackConfig | None = None, rail: RailConfig | None = None,
                     ego_path: EgoPath | None = None
                     ) -> tuple[RangingResult, Camera, list[Note]]:
    """Detect (or import), track and range every vehicle of a video: the shared core of
    ``vid2sim track`` and ``vid2sim build``.

    While frames stream, lane markings give per-frame horizon rows and the vanishing column;
    the column corrects the camera's yaw (so the ego corridor follows the lane) when enough
    frames agree and the correction is plausible for a mounting. The ego lane is measured
    from the same frames (``result.lanes``, a :class:`~vid2sim.core.records.LaneTrack`).

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
    schedule : ScheduleConfig, optional
        Detector keyframes with optical flow between (see :func:`run_detect`).
    stats : dict, optional
        Filled with the counts of :func:`run_detect`.
    lane_every : int, optional
        Measure lane markings on every N-th decoded frame (default: one frame per
        ``LANE_INTERVAL_S``).
    assign_lanes : bool
        Assign the vehicles' lanes and the lead (:func:`vid2sim.detect.assign.relane`) from
        the lane track; False when the caller will assign them once the road's course is
        known (``vid2sim build`` with GPS), so that they are assigned in one pass.
    flow, markings, lane_config, rail : optional
        The optical flow between keyframes, the lane-marking measurement, the lane track and
        the tram search settings (their classes' defaults otherwise).
    ego_path : EgoPath, optional
        The ego's trajectory (``vid2sim build`` with GPS): standing vehicles are then ranged
        from the ego's own motion (:mod:`vid2sim.detect.ranging.surface`). Its direction of
        travel starts from the camera file's axis (the body's, when the lane markings turned
        the camera towards their vanishing point) and is refined from the standing vehicles.

    Returns
    -------
    result : RangingResult
    camera : Camera
        The camera used for ranging (yaw possibly corrected).
    notes : list of Note
        What was estimated and why, for the summary.
    """
    notes: list[Note] = []
    if lane_every is None:
        lane_every = max(1, round(LANE_INTERVAL_S * video_info(video, fps=fps).fps))
    horizon_est = HorizonEstimator(camera, every=lane_every)
    # The lane markings as a measurement (the ego lane per frame, ~3 ms at 1242x375): every
    # decoded frame, since the ego's lateral position is filtered from them.
    marking_detector = LaneMarkingDetector(camera, markings)
    lane_obs = []

    def on_frame(frame: Frame) -> None:
        horizon_est.add_frame(frame.image_bgr, frame.index)
        lane_obs.append(marking_detector.measure(frame.image_bgr, frame.index, frame.t_s))

    skipped: list[int] = []
    frame_times: dict[int, float] = {}
    boxes = run_detect(video, detector=detector, detections=detections,
                       detect_every=detect_every, progress=progress, fps=fps,
                       tracker_config=tracker_config, schedule=schedule, stats=stats,
                       on_frame=on_frame, skipped_frames=skipped, frame_times=frame_times,
                       flow=flow)
    if skipped:
        notes.append(Note.warning(f"{Path(video).name}: {skipped_frames_note(skipped)}"))
    yaw_before = camera.yaw_deg
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
    # The ego lane first: vehicles' lanes (and so the lead) are counted from it.
    lanes = track_lanes(lane_obs, math.radians(camera.yaw_deg - yaw_before), lane_config)

    config = config or RangingConfig()
    # Trams first (the detector's, and tall vehicles beyond the kerb), at the pitch the
    # ranging will estimate, so that each is ranged once with the tram's size.
    chosen = choose_horizon(boxes, camera, config, horizon_est.rows_px)
    rail_tracks = find_rail_tracks(boxes, lanes, camera.with_pitch(
        pitch_for_horizon(camera, chosen[0])), rail)
    if rail_tracks.relabelled:
        # the trams' sizes change the vehicles' horizon: ranging chooses it again
        boxes, chosen = relabel(boxes, rail_tracks.relabelled), None
    if ego_path is not None and camera.pitch_source is not PitchSource.DEFAULT:
        # a camera file states the mounting: the body (and its travel) lies along its axis
        ego_path = replace(ego_path, travel_yaw_rad=math.radians(camera.yaw_deg - yaw_before))
    result = range_tracks(boxes, camera, horizon_hints_px=horizon_est.rows_px,
                          horizon_hint_frames=horizon_est.frames, config=config, lanes=lanes,
                          horizon=chosen, ego_path=ego_path)
    result, rail_notes = keep_trams_from_lead(result, rail_tracks)
    result.frame_times_s = frame_times
    notes.extend(rail_notes)
    if assign_lanes:
        result.boxes = relane(result.boxes, config, result.lanes,
                              never_lead_tracks=result.never_lead_tracks)
    return result, camera, notes
