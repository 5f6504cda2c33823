"""Completion markers (for resuming) and the run manifest (what ran, config, versions, checksums).

A unit of work is finished when its marker ``<dir>/.done/<name>.json`` exists, was written for the
same configuration by the same code (:func:`code_digest`), and every output it lists still has the
recorded checksum. Markers are written atomically after the outputs, so an interrupted unit has no marker
and simply runs again; a unit finished by an older version of the toolkit runs again too.
"""

from __future__ import annotations

import functools
import hashlib
import json
import platform
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

from ..io.atomic import write_json
from ..io.checksums import sha256_file

__all__ = ["sha256_file", "config_digest", "code_digest", "DoneMarker", "versions", "write_manifest"]


def config_digest(config: Any) -> str:
    """A stable digest of a JSON-serialisable configuration."""
    text = json.dumps(config, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


@functools.lru_cache(maxsize=1)
def code_digest() -> str:
    """A digest of the toolkit's own source: every ``.py`` and ``.c`` file of the ``tracker`` and ``sot_apps``
    packages (path and content). Computed once per process."""
    import sot_apps
    import tracker

    digest = hashlib.sha256()
    for package in (tracker, sot_apps):
        root = Path(package.__file__).resolve().parent
        for path in sorted(p for p in root.rglob("*") if p.suffix in (".py", ".c") and p.is_file()):
            digest.update(f"{package.__name__}/{path.relative_to(root).as_posix()}\n".encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


@dataclass(frozen=True)
class DoneMarker:
    """The marker of one unit of work (``name``) under ``root``."""

    root: Path
    name: str

    @property
    def path(self) -> Path:
        safe = self.name.replace("/", "__")
        return Path(self.root) / ".done" / f"{safe}.json"

    def is_done(self, digest: str) -> bool:
        try:
            record = json.loads(self.path.read_text())
        except (OSError, json.JSONDecodeError):
            return False
        if record.get("config") != digest:
            return False
        for rel, checksum in record.get("outputs", {}).items():
            target = Path(self.root) / rel
            if not target.is_file() or sha256_file(target) != checksum:
                return False
        return True

    def mark(self, digest: str, outputs: Iterable[str | Path], extra: dict | None = None) -> dict[str, str]:
        root = Path(self.root)
        checksums = {}
        for out in outputs:
            out = Path(out)
            rel = out.relative_to(root) if out.is_absolute() else out
            checksums[str(rel)] = sha256_file(root / rel)
        write_json(self.path, {"name": self.name, "config": digest, "outputs": checksums,
                               "finished_unix": time.time(), **(extra or {})})
        return checksums

    def record(self) -> dict:
        """The marker's JSON (empty when missing or unreadable)."""
        try:
            return dict(json.loads(self.path.read_text()))
        except (OSError, json.JSONDecodeError, ValueError):
            return {}

    def outputs(self) -> dict[str, str]:
        try:
            return dict(json.loads(self.path.read_text()).get("outputs", {}))
        except (OSError, json.JSONDecodeError):
            return {}


def versions() -> dict[str, str]:
    """Versions of the toolkit and the libraries whose results it depends on."""
    from importlib import metadata

    out = {"python": sys.version.split()[0], "platform": platform.platform(), "sot-apps source": code_digest()}
    for dist in ("sot-apps", "numpy", "scipy", "opencv-python-headless", "trimesh", "embreex", "pyrender",
                 "mcap", "foxglove-sdk", "dask", "distributed"):
        try:
            out[dist] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            continue
    return out


def write_manifest(out_dir: str | Path, config: dict, stages: list[dict], started_unix: float,
                   extra: dict | None = None) -> Path:
    """Write ``out_dir/manifest.json``: config, versions, per-stage units with status and checksums
    (+ ``extra`` top-level entries, e.g. ``track_health``)."""
    out_dir = Path(out_dir)
    path = out_dir / "manifest.json"
    write_json(path, {
        "schema": "sot-apps/manifest", "version": 1,
        "config": config, "versions": versions(),
        "started_unix": started_unix, "finished_unix": time.time(),
        "stages": stages, **(extra or {}),
    })
    return path
