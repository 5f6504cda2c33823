"""Shared fixtures. Real-data tests read ../shared/data/pandaset_002 (never copied into the repo)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PANDASET_002 = Path(os.environ.get("SOT_APPS_PANDASET", REPO.parent / "shared" / "data" / "pandaset_002"))


@pytest.fixture(autouse=True, scope="session")
def sweep_cache_in_tmp(tmp_path_factory):
    """The pipeline reads sweeps through the user's sweep cache (sot_apps.io.sweep_cache): in tests, a temporary
    one (worker processes and CLI subprocesses inherit it)."""
    previous = os.environ.get("SOT_APPS_CACHE_DIR")
    os.environ["SOT_APPS_CACHE_DIR"] = str(tmp_path_factory.mktemp("sweep_cache"))
    yield
    if previous is None:
        os.environ.pop("SOT_APPS_CACHE_DIR", None)
    else:
        os.environ["SOT_APPS_CACHE_DIR"] = previous


@pytest.fixture(scope="session")
def pandaset_root() -> Path:
    """The real PandaSet sequence 002. Missing data is a failure, not a skip: CI has it beside the repo."""
    if not (PANDASET_002 / "lidar" / "poses.json").is_file():
        pytest.fail(f"real data not found at {PANDASET_002} (set SOT_APPS_PANDASET)")
    return PANDASET_002


@pytest.fixture(scope="session")
def pandaset(pandaset_root):
    from sot_apps.io import open_sequence

    return open_sequence(pandaset_root)


@pytest.fixture(scope="session")
def tiny_dir(tmp_path_factory) -> Path:
    """The tiny synthetic canonical sequence, generated once per session."""
    from sot_apps.io.tiny import make_tiny_sequence

    return make_tiny_sequence(tmp_path_factory.mktemp("tiny") / "seq")


@pytest.fixture
def tiny_copy(tiny_dir, tmp_path) -> Path:
    """A private, writable copy of the tiny sequence."""
    import shutil

    return Path(shutil.copytree(tiny_dir, tmp_path / "tiny"))
