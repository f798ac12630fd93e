"""The detection stage wired: stream frames -> detect (or import boxes) -> track -> detections.csv."""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from vid2sim.detect.detector import DEFAULT_DETECTOR, Detector, load_detector
from vid2sim.detect.tracker import Tracker, TrackerConfig
from vid2sim.detect.video import iter_frames, video_info
from vid2sim.errors import InputError
from vid2sim.fileio import atomic_open
from vid2sim.records import Detection, Frame, TrackedBox

CSV_COLUMNS = ("frame", "t_s", "track_id", "category", "score", "x1", "y1", "x2", "y2")


def run_detect(source: Path, *, detector: Detector | None,
               detections: dict[int, list[Detection]] | None = None, detect_every: int = 1,
               progress: bool = True, on_frame: Callable[[Frame], None] | None = None,
               tracker_config: TrackerConfig | None = None, fps: float | None = None,
               ) -> list[TrackedBox]:
    """Detect and track vehicles through a video, one frame in memory at a time.

    Parameters
    ----------
    source : Path
        Video file or folder of images.
    detector : Detector or None
        Runs on every ``detect_every``-th frame. None with ``detections`` given: the imported
        boxes are used; None without: the default detector (YOLOX-nano with tiles, weights
        from $VID2SIM_MODEL_DIR or the user cache) is loaded.
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

    Returns
    -------
    list of TrackedBox
        One row per confirmed track per frame it is alive in, sorted by frame then track id.
    """
    from tqdm import tqdm

    if detector is None and detections is None:
        # low threshold: boxes between 0.1 and the tracker's high score feed stage two
        detector = load_detector(DEFAULT_DETECTOR, score_threshold=TrackerConfig().low_score)
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
        for frame in iter_frames(source, every=decode_every or 1_000_000_000, fps=fps):
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


def write_detections_csv(boxes: list[TrackedBox], path: Path) -> None:
    """Write tracked boxes as ``frame,t_s,track_id,category,score,x1,y1,x2,y2`` (atomic).

    Times in seconds (6 decimals), boxes in pixels (2 decimals).
    """
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as fh:
        fh.write(",".join(CSV_COLUMNS) + "\n")
        for b in boxes:
            fh.write(f"{b.frame},{b.t_s:.6f},{b.track_id},{b.category},{b.score:.4f},"
                     f"{b.x1:.2f},{b.y1:.2f},{b.x2:.2f},{b.y2:.2f}\n")


@dataclass(slots=True)
class DetectSummary:
    """What ``vid2sim detect`` did (printed by the CLI)."""

    source: Path
    out_path: Path
    n_frames: int
    elapsed_s: float
    n_rows: int
    n_tracks: int
    tracks_per_category: dict[str, int] = field(default_factory=dict)
    detector: str = ""

    @property
    def fps(self) -> float:
        """Frames processed per second of wall time."""
        return self.n_frames / self.elapsed_s if self.elapsed_s > 0 else float("nan")

    def __str__(self) -> str:
        cats = ", ".join(f"{k} {v}" for k, v in sorted(self.tracks_per_category.items()))
        return (f"{self.source}: {self.n_frames} frames in {self.elapsed_s:.1f} s "
                f"({self.fps:.1f} frames/s) with {self.detector}; {self.n_tracks} tracks"
                f"{' (' + cats + ')' if cats else ''}, {self.n_rows} rows -> {self.out_path}")


def detect_video(source: Path, out_path: Path, *, detector_name: str = DEFAULT_DETECTOR,
                 model_dir: Path | None = None, detections_path: Path | None = None,
                 detect_every: int = 1, score: float | None = None,
                 small_object_mode: bool = True, progress: bool = True,
                 fps: float | None = None, refine: int | None = None) -> DetectSummary:
    """``vid2sim detect``: detect (or import), track, write ``detections.csv``.

    Parameters
    ----------
    source, out_path : Path
        Video or image folder; output CSV.
    detector_name : str
        Registry name or .onnx path (ignored with ``detections_path``).
    model_dir : Path, optional
        Folder searched first for weights.
    detections_path : Path, optional
        MOT CSV or Scalabel JSON with boxes to use instead of a detector.
    detect_every : int
        Run the detector on every N-th frame.
    score : float, optional
        Minimum score for a detection to start or confidently continue a track (default
        0.45); weaker boxes down to 0.1 only continue tracks.
    small_object_mode : bool
        Extra tiles for distant cars.
    progress : bool
        Progress bar.
    fps : float, optional
        Frame rate of an image folder [frames/s] (default 10).
    refine : int, optional
        Lead candidates re-detected on a crop per frame, 0 = off (default: the detector's,
        see :meth:`vid2sim.detect.detector.OnnxDetector.refine`).
    """
    from vid2sim.detect.external import read_detections

    source = Path(source)
    config = TrackerConfig()
    if score is not None:
        if not 0.0 < score < 1.0:
            raise InputError(None, f"--score must be between 0 and 1, got {score}")
        config = TrackerConfig(high_score=score, new_track_score=min(0.99, score + 0.05),
                               low_score=min(config.low_score, score))
    # The video first: a mistyped path should not be reported as missing weights.
    n_frames = video_info(source, fps=fps).n_frames
    detector = None
    imported = None
    if detections_path is not None:
        imported = read_detections(detections_path)
        label = f"imported boxes ({Path(detections_path).name})"
    else:
        detector = load_detector(detector_name, model_dir, score_threshold=config.low_score,
                                 small_object_mode=small_object_mode, refine_max_boxes=refine)
        label = f"{detector_name}{' + tiles' if small_object_mode else ''}"
        if detector.refine_max_boxes > 0:
            label += f" + {detector.refine_max_boxes} refined"
    start = time.perf_counter()
    boxes = run_detect(source, detector=detector, detections=imported,
                       detect_every=detect_every, progress=progress, tracker_config=config,
                       fps=fps)
    elapsed = time.perf_counter() - start
    write_detections_csv(boxes, out_path)
    per_track = {b.track_id: b.category for b in boxes}
    return DetectSummary(source=source, out_path=Path(out_path), n_frames=n_frames,
                         elapsed_s=elapsed, n_rows=len(boxes), n_tracks=len(per_track),
                         tracks_per_category=dict(Counter(per_track.values())), detector=label)
