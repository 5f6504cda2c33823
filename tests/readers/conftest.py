"""Fixtures for the reader tests (real files of other datasets, never copied into the repo)."""

from __future__ import annotations

from pathlib import Path

import pytest

from .paths import READERS


@pytest.fixture(scope="session")
def readers_root() -> Path:
    """Missing data is a failure, not a skip."""
    if not (READERS / "README.md").is_file():
        pytest.fail(f"real reader files not found at {READERS} (set SOT_APPS_READERS)")
    return READERS
