"""Error types that the CLI turns into one line and an exit code.

Every user mistake is an :class:`InputError` (exit 2); its subclasses name the kind of
mistake, so that callers and tests check the class and messages stay free to improve.
"""

from __future__ import annotations

from pathlib import Path


class InputError(Exception):
    """A user mistake: a bad file, a bad option value, input that cannot be used.

    The CLI prints ``error: <path>: <problem> (<hint>)`` and exits with code 2.
    """

    def __init__(self, path: str | Path | None, problem: str, hint: str | None = None):
        self.path = str(path) if path is not None else None
        self.problem = problem
        self.hint = hint
        super().__init__(str(self))

    def __str__(self) -> str:
        text = f"{self.path}: {self.problem}" if self.path else self.problem
        if self.hint:
            text += f" ({self.hint})"
        return text

    def naming(self, path: str | Path | None) -> InputError:
        """The same error, of the same class and with the same fields, naming ``path``: for a
        helper's error that the caller, who knows the file, raises again."""
        renamed = type(self).__new__(type(self))
        renamed.__dict__.update(self.__dict__)
        renamed.path = str(path) if path is not None else None
        renamed.args = (str(renamed),)
        return renamed


class MissingInputError(InputError):
    """A file or folder that is not there, not readable, or of the wrong kind (a folder where a
    file was expected), or an input the run needs that was not given (no video, no ``--fps``
    for frame numbers): the user names another path or adds the input."""


class FormatError(InputError):
    """Content that cannot be read as the format it claims or that the reader detected: broken
    syntax, a missing column or key, binary where text was expected, an unknown format."""


class ImpossibleValueError(InputError):
    """A number that is not finite or lies outside its physical range (a camera 1e6 degrees
    pitched, a speed of 900 m/s, a negative box width), in a file or an option."""


class InconsistentInputError(InputError):
    """Inputs each readable on their own that contradict each other or the physics of one
    drive: fixes of two drives in one trace, keyframes beyond the video, a camera file for
    another image size, a map that does not cover the trace."""


class OutputError(InputError):
    """An output location the user must fix: read-only, a file where a folder is needed, a
    disk that filled during the run."""


class ScenarioError(FormatError):
    """A scenario.json that does not follow the schema; ``field`` names the offending field."""

    def __init__(self, path: str | Path | None, field: str, problem: str):
        self.field = field
        super().__init__(path, f"field '{field}': {problem}")


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised in the main thread like Ctrl-C's ``KeyboardInterrupt``, so
    that the same cleanup runs (staging folders and temporary files removed, old outputs
    kept). ``signum`` is the signal's number; the CLI exits with 128 + signum."""

    def __init__(self, signum: int):
        self.signum = signum
        super().__init__(f"signal {signum}")
