"""The second half of ``vid2sim build``: from the ranged boxes to the written files.

The ego's lateral place from the lane markings, the vehicles' lanes, the scenario assembled,
the street's cross-section, lane-change events, then the files: ``scenario.json``,
``tracks.csv``, ``road.json``, OpenSCENARIO/OpenDRIVE, the figures, the replay evaluation or
the sampled frames, and the report.

Kept apart from :mod:`vid2sim.app.build` because it loads the export, evaluation and plotting
stacks (scipy, matplotlib, pandas, highway-env with pygame, scenariogeneration: 1.5-2.5 s of
imports on the 2-core reference machine) that the detection stage does not use: ``build``
imports this module in a background thread while the video is detected (issue 15).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from vid2sim import __version__
from vid2sim import scenario as scenario_io
from vid2sim.app.figures import stage_figures
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import Settings
from vid2sim.camera import Camera
from vid2sim.detect.lane_track import lane_track
from vid2sim.detect.lead import relane
from vid2sim.evaluate.frames import sample_frame_figures
from vid2sim.evaluate.replay import run_eval
from vid2sim.evaluate.report import write_report
from vid2sim.export.assemble import assemble_scenario
from vid2sim.export.events import scenario_events
from vid2sim.export.openscenario import write_openscenario
from vid2sim.export.scenelayout import SceneLayout, lay_out_scene
from vid2sim.fileio import write_text_atomic
from vid2sim.geo import roads as geo_roads
from vid2sim.geo.course import road_course
from vid2sim.geo.lateral import fuse_lateral
from vid2sim.records import (
    EgoLateral,
    EgoTrack,
    GpsTrace,
    NoteKind,
    RangingResult,
    RoadResult,
    VideoInfo,
    notes_of,
)
from vid2sim.scenario import Scenario, Source, dumps_canonical
from vid2sim.tables import write_tracks_csv


class StageRunner(Protocol):
    """Runs a named stage (timing it, reporting progress) and returns what it returns."""

    def run(self, name: str, fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any: ...


@dataclass(slots=True)
class Outputs:
    """What the second half of a build made, for the build's result."""

    files: dict[str, Path]  # names inside the output folder
    scenario: Scenario
    lateral: EgoLateral
    scene: SceneLayout
    metrics: dict | None
    warnings: list[str]


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


def write_outputs(staging: Path, out_dir: Path, inputs: Inputs, settings: Settings,
                  stages: StageRunner, *, info: VideoInfo, video: Path, ego: EgoTrack,
                  roads: list, road_result: RoadResult | None, trace: GpsTrace | None,
                  ranging: RangingResult, camera_used: Camera, notes: list,
                  ego_noise_m: float | None, boxes_label: str, detector_used: bool) -> Outputs:
    """The stages after detection, writing into ``staging`` (``out_dir`` once moved).

    ``notes`` are the build's notes so far (warnings, assumptions, estimates); this adds the
    later stages' and sorts them into the scenario's source and the build's warnings.
    """
    # ---- the ego's lateral position from the lane markings (GPS keeps the along-track one)
    lateral = stages.run("ego lateral position", fuse_lateral, ego, ranging.lanes, road_result,
                         speed_known=inputs.gps is not None,
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
    options = {**inputs.recorded(), **settings.recorded(detector_used=detector_used),
               "detector_used": boxes_label,
               "fps": info.fps}
    source = Source(inputs=inputs.fingerprints(), tool_version=__version__, options=options,
                    assumptions=[str(a) for a in assumptions])
    scenario, assemble_warnings = stages.run("assemble scenario", assemble_scenario, ego, roads,
                                             ranging.boxes, camera_used, source=source,
                                             config=settings.assemble,
                                             ego_noise_m=ego_noise_m)
    warnings.extend(assemble_warnings)
    # ---- the street: the road's lanes from the video (and map), parked cars on their strip
    scene = stages.run("road cross-section", lay_out_scene, scenario, lateral)
    scenario = scene.scenario
    warnings.extend(notes_of(scene.notes, NoteKind.WARNING))
    scenario.source.assumptions.extend(str(n) for n in scene.notes
                                       if getattr(n, "kind", None) is not NoteKind.WARNING)
    scenario.source.warnings = [str(w) for w in warnings]
    # ---- lane-change events: the actors' (lanes counted from the ego lane the ranging
    # used) and the ego's own
    scenario.events = stages.run("lane-change events", scenario_events, ranging.boxes,
                                 ranging.lanes, scenario.actors, lateral.lane_changes,
                                 settings.ranging.lane_width_m, scenario.ego.trajectory)

    # ---- write into the staging folder (moved into place by the caller)
    files = stages.run("write scenario and tables", _write_tables, staging, scenario, ranging,
                       road_result)
    xosc, xodr = stages.run("export OpenSCENARIO/OpenDRIVE", write_openscenario, scenario,
                            staging)
    files["openscenario"] = Path(xosc.name)
    files["opendrive"] = Path(xodr.name)
    figures = stages.run("figures", stage_figures, staging / "figures", road_result, trace, ego,
                         ranging.boxes)
    report_inputs = {**inputs.labelled_paths(), "output folder": str(out_dir)}
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
                                outlines=settings.ranging.outlines)
        files["metrics"] = Path("metrics.json")
    else:
        # Nothing scores the scene: show sampled frames with what the build saw beside the
        # simulator's view of the same moment, for a person to judge.
        frames = stages.run("sampled frames", sample_frame_figures,
                            staging / "figures" / "frames", video, camera_used, ranging.boxes,
                            ranging.lanes, scenario, info.fps, info.n_frames,
                            video_fps=inputs.fps, progress=settings.progress,
                            frame_times_s=ranging.frame_times_s)
        stages.run("report", write_report, staging / "report.html", scenario=scenario,
                   metrics=None, extra_figures=figures, warnings=warnings, inputs=report_inputs,
                   frame_images=[(c, p, p.relative_to(staging).as_posix()) for c, p in frames])
    files["report"] = Path("report.html")

    return Outputs(files=files, scenario=scenario, lateral=lateral, scene=scene, metrics=metrics,
                   warnings=warnings)
