"""Fixtures for IO tests: the tiny synthetic canonical sequence, generated once per session."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def tiny_dir(tmp_path_factory) -> Path:
    from sot_apps.io.tiny import make_tiny_sequence

    return make_tiny_sequence(tmp_path_factory.mktemp("tiny") / "seq")


@pytest.fixture
def tiny_copy(tiny_dir, tmp_path) -> Path:
    """A private, writable copy of the tiny sequence."""
    return Path(shutil.copytree(tiny_dir, tmp_path / "tiny"))
