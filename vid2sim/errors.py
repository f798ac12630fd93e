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
