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
