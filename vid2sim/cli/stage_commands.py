"""Single-stage commands: trace, road, detect, track, models."""

from __future__ import annotations

from pathlib import Path

import click

from vid2sim.app.inputs import Inputs
from vid2sim.base.defaults import EGO_RATE_HZ
from vid2sim.base.errors import MissingInputError
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
)

# --------------------------------------------------------------------------- trace


@cli.command()
@click.argument("gps_file", type=EXISTING_PATH)
@click.option("--rate", "rate_hz", type=click.FloatRange(min=0.1, max=100.0), default=EGO_RATE_HZ,
              show_default=True, help="Output sample rate of the ego trajectory [Hz].")
@click.option("--gps-offset", "gps_offset_s", type=float, default=None,
              help="Video time of the first fix [s], overriding the file's own clock.")
@click.option("--out", "out_path", type=EXISTING_PATH, required=True,
              help="Where to write ego.csv (t_s,lat,lon,x_m,y_m,heading_rad,speed_mps).")
@config_option
def trace(gps_file: Path, rate_hz: float, gps_offset_s: float | None, out_path: Path) -> None:
    """Read a GPS trace (GPX, NMEA, BDD100K JSON, KITTI OXTS, CSV) and write the smoothed
    ego trajectory."""
    from vid2sim.app.gpsroad import run_trace

    check_out_file(out_path, "ego.csv")
    echo(run_trace(Inputs(gps=gps_file, gps_offset_s=gps_offset_s), out_path,
                   settings_from(rate_hz=rate_hz)))


# --------------------------------------------------------------------------- road


@cli.command()
@click.argument("gps_file", type=EXISTING_PATH)
@click.option("--map", "map_path", type=EXISTING_PATH, default=None,
              help="OpenStreetMap extract (.osm XML or .osm.pbf). Default: download the "
                   "trace's area (cached), or derive the road from the trajectory offline.")
@click.option("--out", "out_path", type=EXISTING_PATH, required=True,
              help="Where to write road.json (origin, roads, route_osm_way_ids, matches).")
@click.option("--plot", "plot_path", type=EXISTING_PATH, default=None,
              help="Also draw roads, fixes, matched route and ego path to this PNG.")
@click.option("--gps-offset", "gps_offset_s", type=float, default=None,
              help="Video time of the first fix [s], overriding the file's own clock.")
@click.option("--no-download", is_flag=True, help="Never fetch OpenStreetMap data.")
@click.option("--cache-dir", type=EXISTING_PATH, default=None,
              help="Map cache: parsed map files and downloads [default: ~/.cache/vid2sim/osm, "
                   "or $VID2SIM_CACHE_DIR/osm].")
@config_option
def road(gps_file: Path, map_path: Path | None, out_path: Path, plot_path: Path | None,
         gps_offset_s: float | None, no_download: bool, cache_dir: Path | None) -> None:
    """Match a GPS trace to OpenStreetMap and write the driven road with its lanes."""
    from vid2sim.app.gpsroad import run_road

    check_out_file(out_path, "road.json")
    if plot_path is not None:
        check_out_file(plot_path, "road.png")
    settings = settings_from(allow_download=not no_download, osm_cache_dir=cache_dir)
    echo(run_road(Inputs(gps=gps_file, map=map_path, gps_offset_s=gps_offset_s), out_path,
                  settings, plot_path=plot_path))


# --------------------------------------------------------------------------- detect


@cli.command()
@click.argument("source", type=EXISTING_PATH)
@detector_options
@frame_source_options
@click.option("--out", "out_path", type=EXISTING_PATH, required=True,
              help="Where to write detections.csv (frame,t_s,track_id,category,score,x1,y1,x2,y2).")
@config_option
def detect(source: Path, detections_path: Path | None, fps: float | None, out_path: Path,
           **detector) -> None:
    """Detect and track vehicles in a video or image folder."""
    from vid2sim.app.tracking import run_detect_command

    check_out_file(out_path, "detections.csv")
    inputs = Inputs(video=source, detections=detections_path, fps=fps)
    echo(str(run_detect_command(inputs, out_path, settings_from(**detector))))


# --------------------------------------------------------------------------- track


@cli.command()
@click.argument("video", type=EXISTING_PATH)
@click.option("--camera", "camera_path", type=EXISTING_PATH, default=None,
              help="Camera YAML or KITTI calibration (default: a 90 deg dash-cam guess).")
@detector_options
@frame_source_options
@click.option("--plots", "plot_dir", type=EXISTING_PATH, default=None,
              help="Folder for lead.png (lead range/range rate) and topdown.png.")
@click.option("--out", "out_path", type=EXISTING_PATH, required=True,
              help="Where to write tracks.csv (frame,t_s,track_id,category,score,x1,y1,x2,y2,"
                   "range_m,lateral_m,range_rate_mps,range_std_m,is_lead).")
@config_option
def track(video: Path, camera_path: Path | None, detections_path: Path | None,
          fps: float | None, plot_dir: Path | None, out_path: Path, **detector) -> None:
    """Track vehicles and measure their range, lateral offset and range rate (no GPS needed)."""
    from vid2sim.app.tracking import run_track

    check_out_file(out_path, "tracks.csv")
    if plot_dir is not None:
        check_out_dir(plot_dir)
    inputs = Inputs(video=video, camera=camera_path, detections=detections_path, fps=fps)
    echo(run_track(inputs, out_path, settings_from(**detector), plot_dir=plot_dir))


@cli.group()
def models() -> None:
    """Detector weights: list the known models, download them."""


@models.command("list")
@click.option("--model-dir", type=EXISTING_PATH, default=None, help="Extra folder to search.")
def models_list(model_dir: Path | None) -> None:
    """Known detectors and where their weights were found."""
    from vid2sim.detect.vehicles.models import describe_models

    echo(describe_models(model_dir))


@models.command("pull")
@click.argument("name")
@click.option("--dir", "dest_dir", type=EXISTING_PATH, default=None,
              help="Download into this folder instead of the user cache.")
def models_pull(name: str, dest_dir: Path | None) -> None:
    """Download a detector's weights and verify their sha256."""
    from vid2sim.detect.vehicles.models import pull

    path = pull(name, dest_dir, progress=show_progress())
    echo(f"{name}: verified -> {path}")


# --------------------------------------------------------------------------- probe


@cli.command()
@click.argument("videos", nargs=-1, required=True, type=EXISTING_PATH, metavar="VIDEO...")
@click.pass_context
def probe(ctx: click.Context, videos: tuple[Path, ...]) -> None:
    """What recordings hold: codec, size, frame rate and its variability, rotation, duration,
    start time and the telemetry tracks (GPS inside the video) with their fix rates. Exit 2
    if a file cannot be read as a video."""
    from vid2sim.app.probe import probe_table

    for v in videos:
        if not v.is_file():
            raise MissingInputError(v, "no such video file", "give video files")
    table, n_bad = probe_table(list(videos))
    echo(table)
    if n_bad:
        ctx.exit(2)


# --------------------------------------------------------------------------- settings


@cli.command("settings")
@click.option("--changed", is_flag=True, help="Only the settings that differ from the defaults.")
@config_option
def settings_cmd(changed: bool) -> None:
    """Print the settings tree as YAML: every stage's tuned numbers (with --config FILE, as
    that file sets them). Save it, edit what you need, and give it to any command with
    --config; scenario.json records the tree a build used (source.settings)."""
    from vid2sim.app.settings_file import changed_settings, settings_yaml

    settings = settings_from()
    if changed:
        for name, value in changed_settings(settings).items():
            click.echo(f"{name}: {value}")
    else:
        click.echo(settings_yaml(settings), nl=False)
