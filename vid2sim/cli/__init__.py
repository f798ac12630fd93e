"""Command-line interface: parse arguments, call one application function, print a summary.

Exit codes: 0 success, 2 bad input or usage (one line ``error: <file>: <problem> (<hint>)``,
no traceback unless ``-v``), 1 internal error, 130/143 interrupted by SIGINT/SIGTERM.

Commands are thin: they turn options into :class:`~vid2sim.app.inputs.Inputs` and
:class:`~vid2sim.app.settings.Settings`, call one application function and print its
summary. Each command imports its application module when it runs, so that
``vid2sim --help`` does not load onnxruntime, osmnx or highway-env.
"""

from vid2sim.cli import batch_commands, scenario_commands, stage_commands  # noqa: F401 - register
from vid2sim.cli.group import cli
from vid2sim.cli.main import entry_point, main

__all__ = ["cli", "entry_point", "main"]
