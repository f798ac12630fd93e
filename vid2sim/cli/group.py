"""The ``vid2sim`` command group and its global options (-v, -q, --version)."""

from __future__ import annotations

import logging

import click

from vid2sim import __version__
from vid2sim.cli.options import _Context


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
