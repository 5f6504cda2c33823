"""Environment faults on this machine: a full disk (a small tmpfs), a read-only directory, interrupts, a lost
Dask worker. Mounting needs root (tests and CI run as root on the same kind of machine); if the kernel or the
container forbids ``mount`` the tests fail loudly instead of skipping."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

CLI = [sys.executable, "-m", "sot_apps.cli.main"]
_TQDM = re.compile(r"\d+%\||\d+/\d+ \[|it/s\]|/s\]$")


def run_cli(args: list[str], timeout: float = 300, **kwargs) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    env.pop("SOT_APPS_DEBUG", None)
    return subprocess.run([*CLI, *map(str, args)], capture_output=True, text=True, timeout=timeout, env=env, **kwargs)


def message_lines(stderr: str) -> list[str]:
    """The lines of ``stderr`` without tqdm progress-bar redraws."""
    parts = re.split(r"[\r\n]", stderr)
    return [p for p in (s.strip() for s in parts) if p and not _TQDM.search(p)]


def _mount(args: list[str], where: Path) -> None:
    where.mkdir(parents=True, exist_ok=True)
    done = subprocess.run(["mount", *args, str(where)], capture_output=True, text=True)
    if done.returncode != 0:
        pytest.fail(f"cannot mount a tmpfs at {where} (needs root and mount rights): {done.stderr.strip()}")


def _umount(where: Path) -> None:
    subprocess.run(["umount", "-l", str(where)], capture_output=True)


@pytest.fixture
def full_disk(tmp_path):
    """A 1 MiB tmpfs filled to the last byte: every data write fails with ENOSPC (file creation still works)."""
    where = tmp_path / "full"
    _mount(["-t", "tmpfs", "-o", "size=1m", "tmpfs"], where)
    filler = where / "filler"
    try:
        with open(filler, "wb") as handle:
            while True:
                handle.write(b"\0" * 4096)
                handle.flush()
    except OSError as exc:
        assert exc.errno == 28, exc
    yield where
    _umount(where)


@pytest.fixture
def readonly_dir(tmp_path):
    """A read-only tmpfs: as root, chmod does not stop writes, a read-only mount does (EROFS)."""
    where = tmp_path / "ro"
    _mount(["-t", "tmpfs", "-o", "ro,size=64k", "tmpfs"], where)
    with pytest.raises(OSError) as info:
        (where / "probe").write_bytes(b"x")
    assert info.value.errno == 30   # EROFS
    yield where
    _umount(where)


def left_files(root: Path, keep: tuple[str, ...] = ("filler",)) -> list[str]:
    return sorted(p.relative_to(root).as_posix() for p in root.rglob("*") if p.name not in keep)


@pytest.fixture(scope="session")
def world(tmp_path_factory) -> Path:
    """A tiny synthetic world: 3 frames, 2 moving vehicles, 16-beam LiDAR, a 320x240 camera."""
    from sot_apps.synth import write_world

    return write_world(tmp_path_factory.mktemp("fault_world") / "world", frames=3, vehicles=2, sensor="vlp16",
                       seed=4, cameras=True, camera_size=(320, 240))
