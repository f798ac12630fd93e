"""``vid2sim build``: the whole pipeline for one video, written into a staged folder.

Outputs: ``scenario.json``, ``scenario.xosc`` + ``road.xodr``, ``tracks.csv``, ``road.json``
(with GPS: the matched road and each fix's match, as ``vid2sim road`` writes it),
``report.html`` with its ``figures/``, and ``metrics.json`` + ``keyframes/`` with keyframes.

trace -> road -> detect/track/range -> assemble -> export -> evaluate. Each stage is a
function of a domain package that takes records and returns records; this module loads the
inputs (through :mod:`vid2sim.app.loaders`), passes records along, sorts the stages' notes
into warnings and assumptions, and writes the outputs.

All outputs are written into a staging folder (:func:`vid2sim.base.fileio.staged_folder`, created
before the first stage, on the output's filesystem) and moved in only when every stage has
succeeded, so a failed or interrupted build leaves no half-written files and does not clobber
an earlier build's files; a successful one replaces all of an earlier build's outputs.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from vid2sim import __version__
from vid2sim.app.buildgeo import (  # noqa: F401 - ego_without_gps, clip_ego_to_video: API
    clip_ego_to_video,
    ego_without_gps,
    geo_and_camera,
)
from vid2sim.app.calibrate import detector_boxes
from vid2sim.app.camerafile import camera_record, write_camera_file
from vid2sim.app.figures import stage_figures
from vid2sim.app.inputs import Inputs
from vid2sim.app.loaders import (
    load_boxes,
    load_keyframes_for,
    load_video_info,
    need_video,
)
from vid2sim.app.recording import video_clock, video_span_s, with_embedded_gps
from vid2sim.app.rendering import REPLAY_NAME, render_into_build
from vid2sim.app.selfcal import CameraChoice, camera_line, start_camera
from vid2sim.app.settings import Settings
from vid2sim.app.settings_file import changed_settings, settings_tree
from vid2sim.app.tracking import detect_and_range_with, lead_summary
from vid2sim.base.defaults import EGO_LENGTH_M
from vid2sim.base.fileio import staged_folder, write_text_atomic
from vid2sim.core import scenario as scenario_io
from vid2sim.core.camera import Camera
from vid2sim.core.records import EgoLateral, EgoTrack, Note, NoteKind, VideoInfo, notes_of
from vid2sim.core.scenario import Event, Source, dumps_canonical
from vid2sim.core.tables import write_tracks_csv
from vid2sim.detect.assign import relane
from vid2sim.detect.lanes.track import lane_track
from vid2sim.detect.ranging import EgoPath
from vid2sim.evaluate.frames import sample_frame_figures
from vid2sim.evaluate.replay import run_eval
from vid2sim.evaluate.report import write_report
from vid2sim.export.assemble import assemble_scenario
from vid2sim.export.events import scenario_events
from vid2sim.export.openscenario import write_openscenario
from vid2sim.export.scenelayout import SceneLayout, lay_out_scene
from vid2sim.geo import roads as geo_roads
from vid2sim.geo.course import road_course
from vid2sim.geo.lateral import fuse_lateral

#: Events listed one by one in the summary; more are counted.
MAX_SUMMARY_EVENTS = 8


@dataclass(slots=True)
class BuildResult:
    """What a build produced, for the CLI summary and for tests."""

    out_dir: Path
    files: dict[str, Path]
    duration_s: float
    distance_m: float
    n_actors: int
    lead_share: float
    lead_range_m: tuple[float, float, float] | None
    metrics: dict | None
    warnings: list[str]
    stage_seconds: dict[str, float] = field(default_factory=dict)
    #: the ego's lane, lane changes and lateral correction (from the lane markings)
    lateral: EgoLateral | None = None
    #: the road's cross-section and the parked cars placed on it
    scene: SceneLayout | None = None
    #: the scenario's lane-change events (cut-ins, cut-outs, lane changes)
    events: list[Event] = field(default_factory=list)

    def summary(self) -> str:
        lines = [(f"scenario: {self.duration_s:.1f} s, ego distance {self.distance_m:.0f} m, "
                  f"{self.n_actors} actors")]
        if self.lead_range_m is not None:
            lo, med, hi = self.lead_range_m
            lines.append(f"lead vehicle on {100 * self.lead_share:.0f}% of frames, range "
                         f"min {lo:.1f} / median {med:.1f} / max {hi:.1f} m")
        else:
            lines.append("no lead vehicle seen")
        if self.events:
            lines.append("events: " + ", ".join(
                f"{e.type} {e.actor} at {e.t_s:.1f} s ({e.from_lane:+d} -> {e.to_lane:+d})"
                for e in self.events[:MAX_SUMMARY_EVENTS])
                + (f" and {len(self.events) - MAX_SUMMARY_EVENTS} more"
                   if len(self.events) > MAX_SUMMARY_EVENTS else ""))
        if self.metrics:
            m = self.metrics
            lines.append(f"keyframes {m['keyframes']}: precision {m['precision']:.3f}, recall "
                         f"{m['recall']:.3f}, F1 {m['f1']:.3f}, mean IoU {m['mean_iou']:.3f}")
        lines.append("stages: " + ", ".join(f"{k} {v:.1f} s" for k, v in self.stage_seconds.items()))
        for w in self.warnings:
            lines.append(f"warning: {w}")
        lines.append("files:")
        lines.extend(f"  {p}" for p in self.files.values())
        return "\n".join(lines)


# --------------------------------------------------------------------------- pure helpers


def _road_under_the_actors(scenario, road_result):
    """The scenario with its map road run on along the matched route under the vehicles the
    camera saw ahead of the first or beyond the last fix (the road stage cuts the road a car
    length beyond the fixes; a replay needs road under every vehicle it replays)."""
    if road_result is None or not scenario.actors:
        return scenario
    xy = np.vstack([np.column_stack((a.trajectory.x, a.trajectory.y))
                    for a in scenario.actors])
    reach = max(a.length_m for a in scenario.actors) / 2.0 + EGO_LENGTH_M
    return replace(scenario, roads=geo_roads.cover_points(road_result, list(scenario.roads), xy,
                                                          reach))


def path_length_m(ego: EgoTrack) -> float:
    """Length of the ego's path [m]."""
    return float(np.hypot(np.diff(ego.x_m), np.diff(ego.y_m)).sum()) if len(ego.t_s) > 1 else 0.0


class _Stages:
    """Times each stage and prints its name (progress per stage)."""

    def __init__(self, report: Callable[[str], None] | None):
        self.report = report
        self.seconds: dict[str, float] = {}

    def run(self, name: str, fn, *args, **kwargs):
        if self.report:
            self.report(f"[{len(self.seconds) + 1}] {name} ...")
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        self.seconds[name] = time.perf_counter() - t0
        return out


# --------------------------------------------------------------------------- build


def _write_tables(staging: Path, scenario, ranging, road_result) -> dict[str, Path]:
    """scenario.json, tracks.csv and (with GPS) road.json into ``staging``; their names."""
    files = {"scenario": Path("scenario.json"), "tracks": Path("tracks.csv")}
    scenario_io.save(scenario, staging / "scenario.json")
    write_tracks_csv(ranging.boxes, staging / "tracks.csv")
    if road_result is not None:
        # The road stage's own output, as `vid2sim road` writes it (matches per fix).
        write_text_atomic(staging / "road.json",
                          dumps_canonical(geo_roads.road_json(road_result)))
        files["road"] = Path("road.json")
    return files


#: Every output `vid2sim build` may write into its folder. A build owns them: a rebuild
#: removes those it does not write again (a rebuild without keyframes leaves no old
#: metrics.json or keyframes/), and the highway-env export of an earlier scenario.json
#: (replay.py, preview.png), which would otherwise describe a scenario no longer there.
BUILD_OUTPUTS: tuple[str, ...] = (
    "scenario.json", "scenario.xosc", "road.xodr", "tracks.csv", "road.json", "report.html",
    "figures", "metrics.json", "keyframes", "replay.py", "preview.png", REPLAY_NAME,
    "camera.yaml")


def build(inputs: Inputs, out_dir: Path, settings: Settings | None = None,
          report: Callable[[str], None] | None = None,
          extra_notes: list[Note] | None = None) -> BuildResult:
    """Run the whole pipeline for one video and write its outputs into ``out_dir``.

    Parameters
    ----------
    inputs : Inputs
        The video and what comes with it (GPS, map, camera, boxes, keyframes, time base).
    out_dir : Path
        Output folder. Its vid2sim outputs (:data:`BUILD_OUTPUTS`) are replaced only when the
        build succeeds; other files in it are left alone.
    settings : Settings, optional
        Detector, tracker, ranging, smoothing and assembly settings (defaults otherwise).
    report : callable, optional
        Receives one line per stage as it starts (progress).
    extra_notes : list of Note, optional
        What the caller learnt about the inputs (segments joined), kept with the build's.
    """
    settings = settings or Settings()
    out_dir = Path(out_dir)
    # Every input before any long work, so a typo fails in a second, not a minute.
    settings.check()
    inputs.check()
    video = need_video(inputs)
    info = load_video_info(inputs)
    # The camera file (or its prior) before any long work: a bad value fails in a second.
    choice = start_camera(inputs, info, settings)
    notes: list = []
    # A recording that carries its GPS (GoPro, dash-cams) is its own GPS input.
    inputs, gps_notes = with_embedded_gps(inputs)
    notes.extend([*(extra_notes or []), *gps_notes])
    if inputs.keyframes is not None:
        load_keyframes_for(inputs.keyframes, video, info, inputs.fps,
                           inputs.keyframe_calib, inputs.keyframe_rate_hz)
    # The detector (or imported boxes) before any long work: missing weights fail fast.
    detector, imported, boxes_label = load_boxes(inputs, settings)
    choice.vehicles = detector_boxes(detector, imported)  # cars ahead are not road
    # The output folder last of the checks, first of the work: a read-only or full disk
    # fails now, and everything is written into a staging folder moved into place at the
    # end (removed on an error, Ctrl-C or SIGTERM).
    with staged_folder(out_dir, BUILD_OUTPUTS) as staging:
        return _build_into(staging, out_dir, inputs, settings, info, choice, notes, detector,
                           imported, boxes_label, _Stages(report))


def _write_outputs(staging: Path, out_dir: Path, inputs: Inputs, settings: Settings,
                   info: VideoInfo, camera_used: Camera, ranging, scenario, road_result, trace,
                   ego, warnings: list[str], stages: _Stages, choice: CameraChoice
                   ) -> tuple[dict[str, Path], dict | None]:
    """Write the build's outputs into ``staging`` (moved into place by the caller): tables,
    OpenSCENARIO/OpenDRIVE, figures, the evaluation or the sampled frames, the report, and
    with ``settings.render_replay`` the replay video; ``(files, metrics)``."""
    video = need_video(inputs)
    files = stages.run("write scenario and tables", _write_tables, staging, scenario, ranging,
                       road_result)
    xosc, xodr = stages.run("export OpenSCENARIO/OpenDRIVE", write_openscenario, scenario,
                            staging)
    files["openscenario"] = Path(xosc.name)
    files["opendrive"] = Path(xodr.name)
    figures = stages.run("figures", stage_figures, staging / "figures", road_result, trace, ego,
                         ranging.boxes)
    changed = changed_settings(settings)
    report_inputs = {**inputs.labelled_paths(), "output folder": str(out_dir),
                     "settings changed from the defaults": ", ".join(
                         f"{k} = {v}" for k, v in changed.items()) or "none",
                     "camera used": camera_line(choice)}
    metrics = None
    if inputs.keyframes is not None:
        # run_eval writes metrics.json, the keyframe overlays and the one report.html,
        # with this build's figures, warnings and inputs added.
        metrics, _ = stages.run("replay evaluation", run_eval, staging / "scenario.json",
                                inputs.keyframes, video=video, out_dir=staging,
                                fps=inputs.fps, extra_figures=figures,
                                extra_warnings=warnings, report_inputs=report_inputs,
                                # the staging folder's random name would make metrics.json
                                # differ between identical builds
                                scenario_label=str(out_dir / "scenario.json"),
                                # actors drawn with the outlines the ranging read
                                # (as cuboids against tracklet keyframes)
                                outlines=settings.ranging.outlines,
                                keyframe_calib=inputs.keyframe_calib,
                                keyframe_rate_hz=inputs.keyframe_rate_hz)
        files["metrics"] = Path("metrics.json")
    else:
        # Nothing scores the scene: show sampled frames with what the build saw beside the
        # simulator's view of the same moment, for a person to judge.
        frames = stages.run("sampled frames", sample_frame_figures,
                            staging / "figures" / "frames", video, camera_used, ranging.boxes,
                            ranging.lanes, scenario, info.fps, info.n_frames,
                            video_fps=inputs.fps, config=settings.frames,
                            progress=settings.progress, frame_times_s=ranging.frame_times_s)
        stages.run("report", write_report, staging / "report.html", scenario=scenario,
                   metrics=None, extra_figures=figures, warnings=warnings, inputs=report_inputs,
                   frame_images=[(c, p, p.relative_to(staging).as_posix()) for c, p in frames])
    files["report"] = Path("report.html")
    if choice.estimate is not None:
        files["camera"] = Path("camera.yaml")
    if settings.render_replay:
        # the replay of the whole clip, put into the report written above
        keyframes = (load_keyframes_for(inputs.keyframes, video, info, inputs.fps,
                                        inputs.keyframe_calib, inputs.keyframe_rate_hz)
                     if inputs.keyframes is not None else [])
        stages.run("replay video", render_into_build, staging, scenario, camera_used,
                   ranging.boxes, ranging.lanes, video, info, keyframes, inputs.fps,
                   settings.replay, settings.progress)
        files["replay"] = Path(REPLAY_NAME)
    return files, metrics


def _build_into(staging: Path, out_dir: Path, inputs: Inputs, settings: Settings,
                info: VideoInfo, choice: CameraChoice, notes: list, detector, imported,
                boxes_label: str, stages: _Stages) -> BuildResult:
    """The stages of :func:`build`, writing into ``staging`` (``out_dir`` once moved)."""
    video = need_video(inputs)
    # The frames' clock is the container's (variable frame rates keep their times).
    clock, container = video_clock(video, info)
    video_duration_s = video_span_s(info, container)

    # ---- geo: ego trajectory, road and the camera (file or self-calibrated)
    geo = geo_and_camera(stages, inputs, settings, info, choice, video_duration_s, notes)
    inputs, ego, camera, trace = geo.inputs, geo.ego, geo.camera, geo.trace
    road_result, roads, ego_noise_m = geo.road_result, geo.roads, geo.ego_noise_m

    # ---- detect, track, range (with GPS the ego's own motion ranges the standing vehicles)
    ego_path = EgoPath.from_track(ego, ego_noise_m) if inputs.gps is not None else None
    ranging, camera, ranging_notes = stages.run(
        "detect, track and range", detect_and_range_with, settings, inputs, video, camera,
        detector, imported, assign_lanes=inputs.gps is None, ego_path=ego_path)
    notes.extend(ranging_notes)
    notes.extend(ranging.warnings)
    notes.append(Note.estimate(
        f"horizon at row {ranging.horizon_y_px:.1f} px (pitch {ranging.pitch_deg_estimated:.2f} "
        f"deg) from {ranging.horizon_source}"))
    camera_used = camera.with_pitch(ranging.pitch_deg_estimated)
    # ---- the ego's lateral position from the lane markings (GPS keeps the along-track one)
    lateral = stages.run("ego lateral position", fuse_lateral, ego, ranging.lanes, road_result,
                         config=settings.lateral, speed_known=inputs.gps is not None,
                         refilter=lambda track, speed: lane_track(
                             track.observations, settings.lanes, speed_mps=speed))
    ego = lateral.ego
    notes.extend(lateral.notes)
    if inputs.gps is not None:
        # With a trajectory the road's course ahead is where the ego drove: lanes (and the
        # lead) beyond the lane model's reach follow it.
        ranging.boxes = stages.run("lanes of the vehicles", relane, ranging.boxes,
                                   settings.ranging, ranging.lanes, road_course(lateral),
                                   ranging.never_lead_tracks)
    warnings = notes_of(notes, NoteKind.WARNING)
    assumptions = [n for n in notes if getattr(n, "kind", None) in (NoteKind.ASSUMPTION,
                                                                     NoteKind.ESTIMATE)]

    # ---- assemble
    options = {**inputs.recorded(), **settings.recorded(detector_used=detector is not None),
               "detector_used": boxes_label,
               "fps": info.fps, "n_frames": info.n_frames, "video_clock": clock}
    source = Source(inputs=inputs.fingerprints(), tool_version=__version__, options=options,
                    assumptions=[str(a) for a in assumptions],
                    settings=settings_tree(settings))
    scenario, assemble_warnings = stages.run("assemble scenario", assemble_scenario, ego, roads,
                                             ranging.boxes, camera_used, source=source,
                                             config=settings.assemble,
                                             ego_noise_m=ego_noise_m,
                                             standing_tracks=ranging.standing_tracks,
                                             ground_m_by_track={
                                                 t: g[0] for t, g in
                                                 ranging.ground_m_by_track.items()})
    warnings.extend(assemble_warnings)
    if choice.estimate is not None:
        # the camera the ranging used, with the calibration's spread and sources
        scenario.camera = {**camera_record(choice.estimate, scenario=True),
                           **scenario.camera}
        write_camera_file(choice.estimate, staging / "camera.yaml", video.name)
    # ---- the street: the road's lanes from the video (and map), parked cars on their strip
    scene = stages.run("road cross-section", lay_out_scene, _road_under_the_actors(
        scenario, road_result), lateral, settings.layout_config())
    scenario = scene.scenario
    warnings.extend(notes_of(scene.notes, NoteKind.WARNING))
    scenario.source.assumptions.extend(str(n) for n in scene.notes
                                       if getattr(n, "kind", None) is not NoteKind.WARNING)
    scenario.source.warnings = [str(w) for w in warnings]
    # ---- lane-change events: the actors' (lanes counted from the ego lane the ranging
    # used) and the ego's own
    scenario.events = stages.run("lane-change events", scenario_events, ranging.boxes,
                                 ranging.lanes, scenario.actors, lateral.lane_changes,
                                 settings.ranging.lane_width_m, scenario.ego.trajectory,
                                 settings.events)

    # ---- write into the staging folder (moved into place by the caller)
    files, metrics = _write_outputs(staging, out_dir, inputs, settings, info, camera_used,
                                    ranging, scenario, road_result, trace, ego, warnings, stages,
                                    choice)

    lead = lead_summary(ranging, info.n_frames)
    lead_range = (None if not np.isfinite(lead["lead_range_median_m"]) else
                  (lead["lead_range_min_m"], lead["lead_range_median_m"], lead["lead_range_max_m"]))
    return BuildResult(
        out_dir=out_dir, files={k: out_dir / v for k, v in files.items()},
        duration_s=scenario.duration_s, distance_m=path_length_m(ego),
        n_actors=len(scenario.actors), lead_share=lead["lead_share"], lead_range_m=lead_range,
        metrics=metrics, warnings=warnings, stage_seconds=stages.seconds, lateral=lateral,
        scene=scene, events=list(scenario.events))

