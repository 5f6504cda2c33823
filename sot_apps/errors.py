"""The one error type that reaches users: bad input, named by file and problem."""

from __future__ import annotations

from pathlib import Path


class InputError(Exception):
    """Bad input. The CLI prints ``error: <path>: <problem>`` on one line and exits with code 2."""

    def __init__(self, path: str | Path | None, problem: str) -> None:
        self.path = None if path is None else str(path)
        self.problem = " ".join(str(problem).split())  # always one line
        super().__init__(self.one_line())

    def one_line(self) -> str:
        return f"{self.path}: {self.problem}" if self.path else self.problem


class OutputError(InputError):
    """An output cannot be written (no space, no permission, read-only, a directory in the way).

    Printed like :class:`InputError` (``error: <final output path>: cannot write: <cause>``, exit code 2);
    the path is the file the user asked for, never a temporary sibling.
    """
