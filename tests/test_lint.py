"""The code stays lint-clean: ``ruff check .`` (pyflakes, bugbear, import order; configured in pyproject.toml) and
``mypy tracker sot_apps/apps`` (the tracker and the app protocol with the built-in apps) find nothing.

Both run from the repository root with this interpreter; mypy keeps its cache in ``.mypy_cache`` there, so only
the first run in a fresh clone analyses everything (about a minute on a busy machine; seconds afterwards).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", *args], cwd=ROOT, capture_output=True, text=True, timeout=600)


def test_ruff_finds_nothing():
    done = _run("ruff", "check", ".", "--output-format", "concise")
    assert done.returncode == 0, f"ruff check . (exit {done.returncode}):\n{done.stdout}{done.stderr}"


def test_mypy_finds_nothing_in_tracker_and_the_apps():
    done = _run("mypy", "tracker", "sot_apps/apps")
    assert done.returncode == 0, f"mypy tracker sot_apps/apps (exit {done.returncode}):\n{done.stdout}{done.stderr}"


def test_the_tracker_stays_small_enough_to_read():
    """The tracker's shape that issue 24 set: ``TrackerConfig`` nested per concern (at most 15 top-level fields),
    the ``Tracker`` class at most 350 lines, and ``Tracker.step`` a short sequence of named steps (at most 30
    lines of body, its signature and docstring not counted)."""
    import ast
    import dataclasses

    from tracker.config import TrackerConfig

    assert len(dataclasses.fields(TrackerConfig)) <= 15
    tree = ast.parse((ROOT / "tracker" / "sotracker.py").read_text(encoding="utf-8"))
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Tracker")
    assert cls.end_lineno is not None and cls.end_lineno - cls.lineno + 1 <= 350
    step = next(n for n in cls.body if isinstance(n, ast.FunctionDef) and n.name == "step")
    body = step.body[1:] if isinstance(step.body[0], ast.Expr) else step.body   # the docstring
    assert step.end_lineno is not None and step.end_lineno - body[0].lineno + 1 <= 30
