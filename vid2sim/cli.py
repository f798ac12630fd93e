"""Command-line interface: parse arguments, call one pipeline function, print a summary.

Exit codes: 0 success, 2 bad input or usage (one line ``error: <file>: <problem> (<hint>)``,
no traceback unless ``-v``), 1 internal error.
"""

from __future__ import annotations

import logging
import sys
import traceback
from pathlib import Path

import click

from vid2sim import __version__
from vid2sim.errors import InputError

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
@click.option("--rate", "rate_hz", type=click.FloatRange(min=0.1, max=100.0), default=10.0,
              show_default=True, help="Output sample rate of the ego trajectory [Hz].")
@click.option("--gps-offset", "gps_offset_s", type=float, default=None,
              help="Video time of the first fix [s], overriding the file's own clock.")
@click.option("--out", "out_path", type=EXISTING_PATH, required=True,
              help="Where to write ego.csv (t_s,lat,lon,x_m,y_m,heading_rad,speed_mps).")
def trace(gps_file: Path, rate_hz: float, gps_offset_s: float | None, out_path: Path) -> None:
    """Read a GPS trace (GPX, NMEA, BDD100K JSON, KITTI OXTS, CSV) and write the smoothed
    ego trajectory."""
    from vid2sim.geo.trace import run_trace

    summary = run_trace(gps_file, out_path, rate_hz=rate_hz, gps_offset_s=gps_offset_s)
    echo(summary)


# --------------------------------------------------------------------------- detect


@cli.command()
@click.argument("source", type=EXISTING_PATH)
@click.option("--detector", "detector_name", default="yolox-nano", show_default=True,
              help="Registry name (yolox-nano, picodet-s) or path to an .onnx file.")
@click.option("--model-dir", type=EXISTING_PATH, default=None,
              help="Folder with detector weights (else $VID2SIM_MODEL_DIR, then the user cache).")
@click.option("--detections", "detections_path", type=EXISTING_PATH, default=None,
              help="Import boxes (MOT-challenge CSV or Scalabel/BDD100K JSON) instead of "
                   "running a detector.")
@click.option("--detect-every", type=click.IntRange(min=1), default=1, show_default=True,
              help="Run the detector on every N-th frame; the tracker carries boxes between.")
@click.option("--score", type=float, default=None,
              help="Minimum score to start a track [0-1] (default 0.45).")
@click.option("--no-tiles", is_flag=True,
              help="Full frame only: faster, but misses more distant cars.")
@click.option("--out", "out_path", type=EXISTING_PATH, required=True,
              help="Where to write detections.csv (frame,t_s,track_id,category,score,x1,y1,x2,y2).")
def detect(source: Path, detector_name: str, model_dir: Path | None,
           detections_path: Path | None, detect_every: int, score: float | None,
           no_tiles: bool, out_path: Path) -> None:
    """Detect and track vehicles in a video or image folder."""
    from vid2sim.detect.pipeline import detect_video

    summary = detect_video(source, out_path, detector_name=detector_name, model_dir=model_dir,
                           detections_path=detections_path, detect_every=detect_every,
                           score=score, small_object_mode=not no_tiles,
                           progress=show_progress())
    echo(str(summary))


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


# --------------------------------------------------------------------------- entry point


def main(argv: list[str] | None = None) -> int:
    """Console entry point: maps errors to exit codes."""
    verbose = any(a in ("-v", "--verbose") or (a.startswith("-v") and set(a[1:]) == {"v"})
                  for a in (argv if argv is not None else sys.argv[1:]))
    try:
        cli.main(args=argv, prog_name="vid2sim", standalone_mode=False)
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
    except click.exceptions.Abort:
        click.echo("aborted", err=True)
        return 130
    except KeyboardInterrupt:
        click.echo("interrupted", err=True)
        return 130
    except BrokenPipeError:
        return 0
    except Exception as exc:  # noqa: BLE001 - the last line of defence for internal errors
        click.echo(f"internal error: {type(exc).__name__}: {exc} (run with -v for the traceback; "
                   "please report it)", err=True)
        if verbose:
            traceback.print_exc()
        return 1
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())


def entry_point() -> None:
    """The ``vid2sim`` console script."""
    sys.exit(main())
