"""The video-only commands (``detect``, ``track``): slices of ``build`` that need no GPS,
map or scenario.

Kept apart from :mod:`vid2sim.app.commands` so that these two commands load only the
detection stack (numpy, OpenCV, onnxruntime, the tracker) and not the road, export and
evaluation stacks (scipy.optimize, matplotlib, shapely, networkx) before the first frame.
``tests/test_architecture.py`` checks that importing this module stays free of them.

Each command takes the run's :class:`~vid2sim.app.inputs.Inputs` and
:class:`~vid2sim.app.settings.Settings`, loads what it needs through
:mod:`vid2sim.app.loaders`, checks that its output can be written before any work, runs the
stage and writes its output atomically; each returns what the CLI prints.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vid2sim.app.calibrate import detector_boxes
from vid2sim.app.camerafile import write_camera_file
from vid2sim.app.inputs import Inputs
from vid2sim.app.loaders import load_boxes, load_video_info, need_video
from vid2sim.app.selfcal import (
    CameraChoice,
    camera_line,
    finish_camera,
    measure_cues_for,
    start_camera,
)
from vid2sim.app.settings import Settings
from vid2sim.base.fileio import check_output_file, check_output_folder
from vid2sim.core.records import NoteKind, RangingResult
from vid2sim.core.tables import write_detections_csv, write_tracks_csv
from vid2sim.core.videofile import skipped_frames_note
from vid2sim.detect.pipeline import detect_and_range, run_detect
from vid2sim.detect.plots import plot_lead, plot_topdown

# --------------------------------------------------------------------------- detect


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
    skipped_frames: list[int] = field(default_factory=list)

    @property
    def fps(self) -> float:
        """Frames processed per second of wall time."""
        return self.n_frames / self.elapsed_s if self.elapsed_s > 0 else float("nan")

    def __str__(self) -> str:
        cats = ", ".join(f"{k} {v}" for k, v in sorted(self.tracks_per_category.items()))
        return (f"{self.source}: {self.n_frames} frames in {self.elapsed_s:.1f} s "
                f"({self.fps:.1f} frames/s) with {self.detector}; {self.n_tracks} tracks"
                f"{' (' + cats + ')' if cats else ''}, {self.n_rows} rows -> {self.out_path}"
                + (f"\nwarning: {skipped_frames_note(self.skipped_frames)}"
                   if self.skipped_frames else ""))


def run_detect_command(inputs: Inputs, out_path: Path,
                       settings: Settings | None = None) -> DetectSummary:
    """``vid2sim detect``: detect (or import) and track vehicles, write ``detections.csv``."""
    settings = settings or Settings()
    settings.check()
    inputs.check()
    source = need_video(inputs)
    # The video first: a mistyped path should not be reported as missing weights.
    n_frames = load_video_info(inputs).n_frames
    detector, imported, label = load_boxes(inputs, settings)
    check_output_file(out_path)
    start = time.perf_counter()
    skipped: list[int] = []
    boxes = run_detect(source, detector=detector, detections=imported,
                       detect_every=settings.detector.detect_every, progress=settings.progress,
                       tracker_config=settings.tracker_config(), fps=inputs.fps,
                       schedule=settings.schedule_config(), capture_clock=True,
                       skipped_frames=skipped, flow=settings.flow)
    elapsed = time.perf_counter() - start
    write_detections_csv(boxes, out_path)
    per_track = {b.track_id: b.category for b in boxes}
    return DetectSummary(source=source, out_path=Path(out_path), n_frames=n_frames,
                         elapsed_s=elapsed, n_rows=len(boxes), n_tracks=len(per_track),
                         tracks_per_category=dict(Counter(per_track.values())), detector=label,
                         skipped_frames=skipped)


# --------------------------------------------------------------------------- track


def lead_summary(result: RangingResult, n_frames: int) -> dict[str, float]:
    """Figures for the summary: tracks, lead presence share, lead range min/median/max [m]."""
    lead = [b for b in result.boxes if b.is_lead and np.isfinite(b.range_m)]
    rng = np.array([b.range_m for b in lead])
    lead_frames = {b.frame for b in lead}
    return {
        "tracks": len({b.track_id for b in result.boxes}),
        "lead_share": len(lead_frames) / n_frames if n_frames else float("nan"),
        "lead_tracks": len({b.track_id for b in lead}),
        "lead_range_min_m": float(rng.min()) if rng.size else float("nan"),
        "lead_range_median_m": float(np.median(rng)) if rng.size else float("nan"),
        "lead_range_max_m": float(rng.max()) if rng.size else float("nan"),
    }


def _camera_without_gps(choice: CameraChoice, inputs: Inputs, info, settings: Settings):
    """The camera file's, or the clip's self-calibration (no GPS: its scale from priors)."""
    if choice.calibrating:
        measure_cues_for(choice, inputs, info, settings)
    return finish_camera(choice, inputs, info, settings)


def detect_and_range_with(settings: Settings, inputs: Inputs, video: Path, camera, detector,
                          imported, assign_lanes: bool = True, ego_path=None):
    """The detection stage (:func:`vid2sim.detect.pipeline.detect_and_range`) with every one
    of its settings from the run's tree: what ``track`` and ``build`` run (``build`` with
    GPS gives the ego's path: standing vehicles are ranged from its motion)."""
    return detect_and_range(
        video, camera, detector=detector, detections=imported,
        detect_every=settings.detector.detect_every, fps=inputs.fps,
        progress=settings.progress, config=settings.ranging,
        tracker_config=settings.tracker_config(), schedule=settings.schedule_config(),
        assign_lanes=assign_lanes, flow=settings.flow, markings=settings.markings,
        lane_config=settings.lanes, rail=settings.rail, ego_path=ego_path)


def run_track(inputs: Inputs, out_path: Path, settings: Settings | None = None,
              plot_dir: Path | None = None) -> str:
    """``vid2sim track``: detect and track vehicles, range them, write ``tracks.csv``.

    Returns a few lines of summary: tracks, frames, lead presence, horizon and its source,
    lead range figures, notes.
    """
    settings = settings or Settings()
    settings.check()
    inputs.check()
    video = need_video(inputs)
    info = load_video_info(inputs)
    choice = start_camera(inputs, info, settings)
    detector, imported, source = load_boxes(inputs, settings)
    choice.vehicles = detector_boxes(detector, imported)  # cars ahead are not road
    check_output_file(out_path)
    if plot_dir is not None:
        check_output_folder(plot_dir)
    camera = _camera_without_gps(choice, inputs, info, settings)
    notes = list(choice.notes)
    result, camera, stage_notes = detect_and_range_with(settings, inputs, video, camera,
                                                        detector, imported)
    notes += stage_notes
    write_tracks_csv(result.boxes, out_path)
    lines = [f"{video}: {info.n_frames} frames, boxes from {source}", camera_line(choice)]
    if choice.estimate is not None:
        cam_path = Path(out_path).with_suffix(".camera.yaml")
        write_camera_file(choice.estimate, cam_path, Path(video).name)
        lines.append(f"camera file -> {cam_path}")
    lines += [f"warning: {n}" if getattr(n, "kind", None) is NoteKind.WARNING else str(n)
              for n in notes]
    s = lead_summary(result, info.n_frames)
    lines.append(f"{s['tracks']} tracks, {len(result.boxes)} rows -> {out_path}")
    lines.append(f"horizon {result.horizon_y_px:.1f} px (pitch {result.pitch_deg_estimated:+.2f} "
                 f"deg) from {result.horizon_source}; camera file said "
                 f"{camera.horizon_y_px():.1f} px (pitch {camera.pitch_deg:+.2f} deg)")
    if np.isfinite(s["lead_range_median_m"]):
        lines.append(f"lead present on {100 * s['lead_share']:.0f}% of frames "
                     f"({s['lead_tracks']} lead vehicles); lead range min/median/max "
                     f"{s['lead_range_min_m']:.1f}/{s['lead_range_median_m']:.1f}/"
                     f"{s['lead_range_max_m']:.1f} m")
    else:
        lines.append("no lead vehicle in the ego lane")
    if plot_dir is not None:
        plot_dir = Path(plot_dir)
        p1 = plot_lead(result.boxes, plot_dir / "lead.png")
        p2 = plot_topdown(result.boxes, plot_dir / "topdown.png", settings.ranging.lane_width_m)
        lines.append(f"plots: {p1}, {p2}")
    lines += [f"note: {w}" for w in result.warnings]
    return "\n".join(lines)
