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


def not_a_file(path: str | Path, what: str = "file", report_as: str | Path | None = None) -> InputError:
    """The error for an input ``path`` that should be a readable file but is not: it is a directory, something
    else (a FIFO, a device), or missing. Reported under ``report_as`` (default: ``path`` itself)."""
    path = Path(path)
    if path.is_dir():
        problem = f"{what} is a directory, not a file"
    elif path.exists():
        problem = f"{what} is not a regular file"
    else:
        problem = f"{what} is missing"
    if report_as is not None:
        return InputError(report_as, f"{problem} ({path})")
    return InputError(path, problem)
