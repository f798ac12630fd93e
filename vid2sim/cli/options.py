"""What the commands share: output path checks, the detector options, settings from options, quiet/progress."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import click

from vid2sim.app.settings import DetectorSettings, Settings
from vid2sim.app.settings_file import load_settings
from vid2sim.base.defaults import IMAGE_FOLDER_FPS
from vid2sim.base.errors import OutputError
from vid2sim.detect.vehicles.models import DEFAULT_DETECTOR
from vid2sim.detect.vehicles.windows import REFINE_MAX_BOXES

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
        raise OutputError(path, "is a folder", f"give the output file name, e.g. {example}")
    _check_parents(path)


def check_out_dir(path: Path) -> None:
    """Refuse an output folder path that is an existing file, before any work is done."""
    if path.exists() and not path.is_dir():
        raise OutputError(path, "is a file, not a folder", "give an output folder")
    _check_parents(path)


def _check_parents(path: Path) -> None:
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise OutputError(path, f"{parent} is a file, not a folder",
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


def tracklet_options(fn):
    """How KITTI raw tracklets become keyframes (``--keyframes tracklet_labels.xml``)."""
    options = [
        click.option("--keyframe-calib", "keyframe_calib", type=EXISTING_PATH, default=None,
                     help="KITTI tracklet keyframes: the folder of the drive's "
                          "calib_velo_to_cam.txt and calib_cam_to_cam.txt (default: the "
                          "XML's folder)."),
        click.option("--keyframe-rate", "keyframe_rate_hz",
                     type=click.FloatRange(min=0, min_open=True), default=None,
                     help="KITTI tracklet keyframes a second, e.g. 1 (default: every frame)."),
    ]
    for option in reversed(options):
        fn = option(fn)
    return fn


_CONFIG_KEY = "vid2sim.config"


def _remember_config(ctx: click.Context, _param, value: Path | None) -> Path | None:
    if value is not None:
        ctx.meta[_CONFIG_KEY] = value
    return value


def config_option(fn):
    """``--config FILE``: a settings file (any branch of the settings tree, see ``vid2sim
    settings``); the command's own options given on the command line win over it."""
    return click.option("--config", "config_path", type=EXISTING_PATH, default=None,
                        expose_value=False, callback=_remember_config, is_eager=True,
                        metavar="SETTINGS.yaml",
                        help="Settings file: any part of the settings tree (`vid2sim settings` "
                             "prints it); options on the command line win.")(fn)


#: The detector options' CLI names -> the DetectorSettings fields they set.
_DETECTOR_FIELDS = {"detector_name": "name", "model_dir": "model_dir", "detect_every":
                    "detect_every", "score": "score", "refine": "refine",
                    "keyframe_s": "keyframe_s", "no_tiles": "tiles"}


def settings_from(**options) -> Settings:
    """The run's :class:`Settings`: the defaults, then the ``--config`` file, then the
    options given on the command line (detector options by their CLI names; other keywords
    are Settings fields, e.g. ``allow_download``, set where they differ from the default)."""
    ctx = click.get_current_context(silent=True)
    config = ctx.meta.get(_CONFIG_KEY) if ctx is not None else None
    settings = load_settings(config) if config is not None else Settings()
    detector = {}
    for name, value in options.items():
        if name in _DETECTOR_FIELDS and _given(ctx, name, value):
            detector[_DETECTOR_FIELDS[name]] = not value if name == "no_tiles" else value
    fields = {k: v for k, v in options.items() if k not in _DETECTOR_FIELDS
              and v != getattr(Settings(), k)}
    return replace(settings, detector=replace(settings.detector, **detector),
                   progress=show_progress(), **fields)


def _given(ctx: click.Context | None, name: str, value) -> bool:
    """Whether an option was set by the user (command line or environment), not defaulted;
    outside a click command every value counts as given."""
    if ctx is None or name not in ctx.params:
        return value is not None
    source = ctx.get_parameter_source(name)
    return source not in (None, click.core.ParameterSource.DEFAULT,
                          click.core.ParameterSource.DEFAULT_MAP)
