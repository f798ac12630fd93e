"""Error types that the CLI turns into one line and an exit code."""

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


class ScenarioError(InputError):
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
