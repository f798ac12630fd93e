"""The stages wired together: video (+ GPS, map, camera) -> scenario, simulator files, report.

``build`` runs trace -> road -> detect/track -> range -> assemble -> export -> evaluate for one
video. Each stage is a function of another module that takes records and returns records;
this module only passes them along, collects warnings and writes the outputs.

All outputs of a build are written into a staging folder beside ``out_dir`` and moved into
``out_dir`` only when every stage has succeeded, so a failed build leaves no half-written
files (and does not clobber an earlier build's files).
"""

from __future__ import annotations

import logging
import shutil
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from vid2sim import __version__
from vid2sim.camera import Camera, fit_camera_to_frames, load_camera
from vid2sim.errors import InputError
from vid2sim.fileio import sha256_path
from vid2sim.records import EgoTrack, Origin, RangedBox

log = logging.getLogger(__name__)

# Ego dimensions when nothing better is known: a mid-size passenger car.
EGO_LENGTH_M, EGO_WIDTH_M, EGO_HEIGHT_M = 4.6, 1.85, 1.5


@dataclass(slots=True)
class BuildOptions:
    """Everything ``vid2sim build`` was asked to do (recorded in the scenario's source)."""

    video: Path
    out_dir: Path
    gps: Path | None = None
    map_path: Path | None = None
    camera_path: Path | None = None
    detector: str | None = None
    model_dir: Path | None = None
    detections: Path | None = None
    keyframes: Path | None = None
    detect_every: int = 1
    ego_speed_mps: float = 0.0
    gps_offset_s: float | None = None
    rate_hz: float = 10.0
    fps: float | None = None
    allow_download: bool = True
    progress: bool = True
    threads: int = 2
    """onnxruntime intra-op threads of the detector (a batch gives each job cores / jobs)."""


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

    def summary(self) -> str:
        lines = [(f"scenario: {self.duration_s:.1f} s, ego distance {self.distance_m:.0f} m, "
                  f"{self.n_actors} actors")]
        if self.lead_range_m is not None:
            lo, med, hi = self.lead_range_m
            lines.append(f"lead vehicle on {100 * self.lead_share:.0f}% of frames, range "
                         f"min {lo:.1f} / median {med:.1f} / max {hi:.1f} m")
        else:
            lines.append("no lead vehicle seen")
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


def ego_without_gps(duration_s: float, speed_mps: float, rate_hz: float) -> EgoTrack:
    """A straight ego drive heading east from the ENU origin at a constant speed.

    Used when no GPS trace is given: the scenario is then camera-relative (speed 0) or
    relative to an assumed constant ego speed.
    """
    n = max(2, int(np.floor(duration_s * rate_hz)) + 1)
    t = np.arange(n) / rate_hz
    x = speed_mps * t
    zeros = np.zeros(n)
    return EgoTrack(origin=Origin(0.0, 0.0, 0.0), t_s=t, x_m=x, y_m=zeros.copy(),
                    heading_rad=zeros.copy(), speed_mps=np.full(n, float(speed_mps)),
                    lat_deg=zeros.copy(), lon_deg=zeros.copy())


def clip_ego_to_video(ego: EgoTrack, duration_s: float) -> tuple[EgoTrack, list[str]]:
    """Keep the ego samples inside the video's time span [0, duration] (scenario clock)."""
    warnings: list[str] = []
    keep = (ego.t_s >= -1e-9) & (ego.t_s <= duration_s + 1e-9)
    if keep.sum() < 2:
        raise InputError(None, f"the GPS trace does not overlap the video (GPS covers "
                         f"{ego.t_s[0]:.1f}..{ego.t_s[-1]:.1f} s of video time, the video "
                         f"0..{duration_s:.1f} s)", "check the clocks or pass --gps-offset")
    if ego.t_s[0] > 0.5:
        warnings.append(f"GPS starts {ego.t_s[0]:.1f} s after the first video frame")
    if ego.t_s[-1] < duration_s - 0.5:
        warnings.append(f"GPS ends {duration_s - ego.t_s[-1]:.1f} s before the last video frame")
    if keep.all():
        return ego, warnings
    fields = {name: (getattr(ego, name)[keep] if isinstance(getattr(ego, name), np.ndarray)
                     else getattr(ego, name)) for name in EgoTrack.__slots__}
    return EgoTrack(**fields), warnings


def path_length_m(ego: EgoTrack) -> float:
    return float(np.hypot(np.diff(ego.x_m), np.diff(ego.y_m)).sum()) if len(ego.t_s) > 1 else 0.0


# --------------------------------------------------------------------------- build


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


def build(opts: BuildOptions, report: Callable[[str], None] | None = None) -> BuildResult:
    """Run the whole pipeline for one video and write its outputs into ``opts.out_dir``.

    Parameters
    ----------
    opts : BuildOptions
        Inputs and options.
    report : callable, optional
        Receives one line per stage as it starts (progress).
    """
    from vid2sim import scenario as scenario_io
    from vid2sim.detect.ranging import detect_and_range, summarize, write_tracks_csv
    from vid2sim.detect.video import video_info
    from vid2sim.export.assemble import assemble_scenario
    from vid2sim.export.openscenario import write_openscenario
    from vid2sim.scenario import Source

    stages = _Stages(report)
    warnings: list[str] = []
    assumptions: list[str] = []
    out_dir = Path(opts.out_dir)

    # Check every input before any long work, so a typo fails in a second, not a minute.
    for label, p in (("video", opts.video), ("GPS", opts.gps), ("map", opts.map_path),
                     ("camera", opts.camera_path), ("detections", opts.detections),
                     ("keyframes", opts.keyframes)):
        if p is not None and not Path(p).exists():
            raise InputError(p, f"no such {label} file")
    if opts.detect_every < 1:
        raise InputError(None, f"--detect-every must be >= 1, got {opts.detect_every}")

    info = video_info(opts.video, fps=opts.fps)
    video_duration_s = (info.n_frames - 1) / info.fps if info.n_frames > 1 else 0.0

    if opts.camera_path is not None:
        camera = load_camera(opts.camera_path)
        camera, note = fit_camera_to_frames(camera, info.width, info.height, opts.camera_path)
        if note:
            warnings.append(note)
    else:
        camera = Camera.default_for(info.width, info.height)
        warnings.extend(camera.assumptions)

    # ---- the detector (or imported boxes) before any long work: missing weights fail fast
    detector = None
    imported = None
    if opts.detections is not None:
        from vid2sim.detect.external import read_detections

        imported = read_detections(opts.detections)
        detector_label = f"imported detections {Path(opts.detections).name}"
    else:
        from vid2sim.detect.detector import load_detector
        from vid2sim.detect.models import DEFAULT_DETECTOR

        name = opts.detector or DEFAULT_DETECTOR
        from vid2sim.detect.tracker import TrackerConfig

        # Weak boxes feed the tracker's second association stage (ByteTrack), so the
        # detector keeps everything above the tracker's low threshold.
        detector = load_detector(name, model_dir=opts.model_dir,
                                 score_threshold=TrackerConfig().low_score,
                                 threads=max(1, int(opts.threads)))
        detector_label = f"detector {name}"
    # ---- geo: ego trajectory and road
    roads = []
    road_result = None
    trace = None
    if opts.gps is not None:
        from vid2sim.geo.readers import read_gps
        from vid2sim.geo.trace import smooth_ego

        trace = stages.run("read GPS", read_gps, opts.gps)
        ego, trace_stats = stages.run("smooth ego trajectory", smooth_ego, trace,
                                      rate_hz=opts.rate_hz, gps_offset_s=opts.gps_offset_s)
        warnings.extend(getattr(trace_stats, "warnings", []) or [])
        ego, clip_warnings = clip_ego_to_video(ego, video_duration_s)
        warnings.extend(clip_warnings)
        from vid2sim.geo.roads import build_road

        road_result = stages.run("road and map matching", build_road, trace, ego, opts.map_path,
                                 allow_download=opts.allow_download)
        roads = list(road_result.roads)
        warnings.extend(road_result.warnings)
    else:
        ego = ego_without_gps(video_duration_s, opts.ego_speed_mps, opts.rate_hz)
        assumptions.append(
            f"no GPS: the ego drives a straight road heading east at {opts.ego_speed_mps:g} m/s "
            "from an arbitrary origin (lat 0, lon 0)"
            + (" (a camera-relative scenario)" if opts.ego_speed_mps == 0 else ""))

    # ---- detect, track, range
    ranging, camera, ranging_notes = stages.run(
        "detect, track and range", detect_and_range, Path(opts.video), camera,
        detector=detector, detections=imported, detect_every=opts.detect_every, fps=opts.fps,
        progress=opts.progress)
    assumptions.extend(ranging_notes)
    warnings.extend(ranging.warnings)
    assumptions.append(
        f"horizon at row {ranging.horizon_y_px:.1f} px (pitch {ranging.pitch_deg_estimated:.2f} "
        f"deg) from {ranging.horizon_source}")
    camera_used = camera.with_pitch(ranging.pitch_deg_estimated)

    # ---- assemble and write into a staging folder
    inputs = []
    for role, p in (("video", opts.video), ("gps", opts.gps), ("map", opts.map_path),
                    ("camera", opts.camera_path), ("detections", opts.detections),
                    ("keyframes", opts.keyframes)):
        if p is not None:
            inputs.append({"role": role, "name": Path(p).name, "sha256": sha256_path(p)})
    # Options that change the scenario (not where files are, nor how fast it is made): an
    # input file is recorded by its name, as in ``inputs``, so the same inputs reached from
    # another folder or by an absolute path still give a byte-identical scenario.json.
    options = {k: (Path(v).name if isinstance(v, Path) else v) for k, v in asdict(opts).items()
               if k not in ("video", "out_dir", "progress", "model_dir", "threads")}
    options["detector_used"] = detector_label
    options["fps"] = info.fps
    source = Source(inputs=inputs, tool_version=__version__, options=options,
                    assumptions=assumptions)
    scenario, assemble_warnings = stages.run("assemble scenario", assemble_scenario, ego, roads,
                                             ranging.boxes, camera_used, source=source)
    warnings.extend(assemble_warnings)

    out_dir.parent.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", dir=out_dir.parent))
    try:
        files: dict[str, Path] = {}
        scenario_io.save(scenario, staging / "scenario.json")
        files["scenario"] = Path("scenario.json")
        write_tracks_csv(ranging.boxes, staging / "tracks.csv")
        files["tracks"] = Path("tracks.csv")
        xosc, xodr = stages.run("export OpenSCENARIO/OpenDRIVE", write_openscenario, scenario,
                                staging)
        files["openscenario"] = Path(xosc.name)
        files["opendrive"] = Path(xodr.name)

        figures = _stage_figures(staging / "figures", road_result, trace, ego, ranging.boxes)
        metrics = None
        if opts.keyframes is not None:
            from vid2sim.evaluate.replay import run_eval

            # run_eval writes metrics.json, the keyframe overlays and the one report.html,
            # with this build's figures, warnings and inputs added.
            metrics, _ = stages.run("replay evaluation", run_eval, staging / "scenario.json",
                                    opts.keyframes, video=Path(opts.video), out_dir=staging,
                                    fps=opts.fps, extra_figures=figures,
                                    extra_warnings=warnings,
                                    report_inputs=_input_paths(opts),
                                    # the staging folder's random name would make metrics.json
                                    # differ between identical builds
                                    scenario_label=str(out_dir / "scenario.json"))
            files["metrics"] = Path("metrics.json")
        else:
            from vid2sim.evaluate.report import write_report

            write_report(staging / "report.html", scenario=scenario, metrics=None,
                         extra_figures=figures, warnings=warnings, inputs=_input_paths(opts))
        files["report"] = Path("report.html")
        out_dir.mkdir(parents=True, exist_ok=True)
        for child in staging.iterdir():
            target = out_dir / child.name
            if target.is_dir() and not target.is_symlink():
                shutil.rmtree(target)
            child.replace(target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)

    lead = summarize(ranging, info.n_frames)
    lead_share = lead["lead_share"]
    lead_range = (None if not np.isfinite(lead["lead_range_median_m"]) else
                  (lead["lead_range_min_m"], lead["lead_range_median_m"], lead["lead_range_max_m"]))
    return BuildResult(
        out_dir=out_dir, files={k: out_dir / v for k, v in files.items()},
        duration_s=scenario.duration_s, distance_m=path_length_m(ego),
        n_actors=len(scenario.actors), lead_share=lead_share, lead_range_m=lead_range,
        metrics=metrics, warnings=warnings, stage_seconds=stages.seconds)


def _input_paths(opts: BuildOptions) -> dict[str, str]:
    """Where this run's inputs and outputs are, for the report's "this run" table."""
    paths = {"video": opts.video, "GPS": opts.gps, "map": opts.map_path,
             "camera": opts.camera_path, "detections": opts.detections,
             "keyframes": opts.keyframes, "output folder": opts.out_dir}
    return {k: str(v) for k, v in paths.items() if v is not None}


def _stage_figures(fig_dir: Path, road_result, trace, ego: EgoTrack,
                   boxes: list[RangedBox]) -> list[tuple[str, Path]]:
    """PNG figures of the stages for the report (road match, lead range, top-down tracks)."""
    fig_dir.mkdir(parents=True, exist_ok=True)
    figures: list[tuple[str, Path]] = []
    if road_result is not None and trace is not None:
        from vid2sim.geo.roads import plot_road

        path = fig_dir / "road.png"
        plot_road(road_result, trace, ego, path)
        figures.append(("OSM roads, GPS fixes, matched route and smoothed ego path", path))
    try:
        from vid2sim.detect import plots
    except ImportError:  # pragma: no cover - plots are optional decoration
        return figures
    if boxes:
        path = fig_dir / "lead_range.png"
        plots.plot_lead(boxes, path)
        figures.append(("Lead range and range rate (band: one sigma)", path))
        path = fig_dir / "tracks_topdown.png"
        plots.plot_topdown(boxes, path)
        figures.append(("Top-down view of all tracks (camera frame)", path))
    return figures


# --------------------------------------------------------------------------- demo


def run_demo(out_dir: Path, *, seed: int = 7, model_dir: Path | None = None,
             detector: str | None = None, force_detections: bool = False,
             progress: bool = True, report: Callable[[str], None] | None = None) -> BuildResult:
    """Generate the synthetic Helsinki sample into ``out_dir/sample`` and build + evaluate it
    into ``out_dir/build``.

    Runs the real detector where weights are found (``model_dir``, ``$VID2SIM_MODEL_DIR``,
    the user cache); otherwise, or with ``force_detections``, it imports the sample's noisy
    detection file and says so.
    """
    from datasets.demo_sample import generate_demo_sample, helsinki_pbf_path
    from vid2sim.detect.models import DEFAULT_DETECTOR, resolve_model

    say = report or (lambda _msg: None)
    out_dir = Path(out_dir)
    say(f"generating the demo sample (seed {seed}) in {out_dir / 'sample'} ...")
    sample = generate_demo_sample(out_dir / "sample", seed=seed)
    say(f"  {sample.n_frames} frames {sample.width}x{sample.height} at {sample.fps:g} fps, "
        f"{sample.n_keyframes} keyframes, rendered in {sample.render_s:.1f} s")
    use_detections = force_detections
    if not use_detections:
        try:
            resolve_model(detector or DEFAULT_DETECTOR, model_dir=model_dir)
        except InputError as exc:
            say(f"no detector weights ({exc}); using the sample's noisy detection file "
                f"{sample.detections.name} instead (pass --model-dir or set VID2SIM_MODEL_DIR "
                "to run the real detector)")
            use_detections = True
    if use_detections and force_detections:
        say(f"using the sample's noisy detection file {sample.detections.name} (--use-detections)")
    if not use_detections:
        say(f"running the real detector {detector or DEFAULT_DETECTOR} on the rendered frames")
    opts = BuildOptions(video=sample.video, out_dir=out_dir / "build", gps=sample.gps,
                        map_path=helsinki_pbf_path(), camera_path=sample.camera,
                        detector=detector, model_dir=model_dir,
                        detections=sample.detections if use_detections else None,
                        keyframes=sample.keyframes, allow_download=False, progress=progress)
    result = build(opts, report=say)
    say(result.summary())
    return result
