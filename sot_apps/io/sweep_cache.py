"""A one-time conversion cache of decoded sweeps: a reader's output per frame as plain ``.npy`` columns.

Reading a sweep from its dataset costs tens of milliseconds (PandaSet: zip decompression, the world-to-ego
transform, per-point times; Waymo: range-image decoding). :func:`with_sweep_cache` wraps a
:class:`~sot_apps.io.sequence.Sequence` so that each frame is converted once and every later read, by any
process, loads its float32 ``xyz``, float32 ``intensity`` and int64 ``time_offset_ns`` columns as they were
decoded (bit for bit) from uncompressed ``.npy`` files (< 1 ms for 100k points). Per-point masks derived
from a sweep (the tracker's whole-sweep ground, keyed by its parameters) can be stored with it
(:meth:`SweepCache.store_mask`), so every process and later run reuses them.

Where: ``$SOT_APPS_CACHE_DIR`` (``off`` disables the cache), else ``$XDG_CACHE_HOME/sot-apps/sweeps``, else
``~/.cache/sot-apps/sweeps``; never inside an input directory. Layout:
``ROOT/<sequence key>/<frame:06d>-<frame key>/{xyz,intensity,time_offset_ns}.npy``, where the sequence key
hashes the sequence's resolved path and format, and the frame key hashes what the decoded sweep depends on:
the frame's source file (resolved path, size, modification time in ns), its timestamp and ego pose, the
frame index and the reader's code (the source of the module that decodes it). A changed source, pose or
reader gives another key: the old entry of that frame is removed and the frame converted again, so a cached
sweep is never stale. Entries are written to a temporary directory and renamed into place (concurrent
workers converting the same frame are safe; a killed one leaves no entry). When a new sequence directory is
made, the least recently used sequences are removed while the cache is larger than
``$SOT_APPS_CACHE_MAX_GB`` (default 20).
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from .sequence import Sequence, Sweep

__all__ = ["cache_root", "with_sweep_cache", "SweepCache", "CACHE_ENV", "code_digest"]

CACHE_ENV = "SOT_APPS_CACHE_DIR"
MAX_GB_ENV = "SOT_APPS_CACHE_MAX_GB"
COLUMNS = ("xyz", "intensity", "time_offset_ns")
_FORMAT_VERSION = b"sweep-cache-1"


def cache_root() -> Path | None:
    """The cache directory (see the module doc), or None when ``$SOT_APPS_CACHE_DIR`` is ``off``."""
    given = os.environ.get(CACHE_ENV)
    if given:
        return None if given.strip().lower() == "off" else Path(given).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "sot-apps" / "sweeps"


def _digest(*parts: bytes) -> str:
    h = hashlib.sha256(_FORMAT_VERSION)
    for p in parts:
        h.update(len(p).to_bytes(8, "little"))
        h.update(p)
    return h.hexdigest()


_code_digests: dict[str, bytes] = {}


def code_digest(loader) -> bytes:
    """Digest of the source of the module defining the function ``loader`` (e.g. the one that decodes the sweeps:
    a changed reader invalidates its entries)."""
    filename = getattr(getattr(loader, "__code__", None), "co_filename", None)
    if filename is None:
        return repr(loader).encode()
    if filename not in _code_digests:
        try:
            _code_digests[filename] = hashlib.sha256(Path(filename).read_bytes()).digest()
        except OSError:
            _code_digests[filename] = filename.encode()
    return _code_digests[filename]


class SweepCache:
    """The cache of one sequence: ``load(index)`` returns the frame's cached sweep, converting it on a miss."""

    def __init__(self, seq: Sequence, root: Path, loader) -> None:
        self.seq, self.loader = seq, loader
        self.directory = root / _digest(str(Path(seq.root).resolve()).encode(), seq.format.encode())[:24]
        self.code = code_digest(loader)
        self.hits = self.misses = 0

    def frame_key(self, index: int) -> str:
        info = self.seq.frames[index]
        source = b""
        if info.points_path is not None:
            path = Path(info.points_path)
            try:
                stat = path.stat()
                source = f"{path.resolve()}|{stat.st_size}|{stat.st_mtime_ns}".encode()
            except OSError:   # the reader reports a missing file
                source = str(path).encode()
        pose = np.ascontiguousarray(info.world_from_ego, dtype=np.float64).tobytes()
        return _digest(source, str(index).encode(), str(int(info.timestamp_ns)).encode(), pose, self.code)[:20]

    def entry(self, index: int) -> Path:
        return self.directory / f"{index:06d}-{self.frame_key(index)}"

    def load(self, index: int) -> Sweep:
        entry = self.entry(index)
        try:
            columns = {name: np.load(entry / f"{name}.npy", allow_pickle=False) for name in COLUMNS
                       if (entry / f"{name}.npy").is_file()}
        except (OSError, ValueError):
            columns = {}
        if "xyz" in columns:
            self.hits += 1
            return Sweep(xyz=columns["xyz"], intensity=columns.get("intensity"),
                         time_offset_ns=columns.get("time_offset_ns"))
        self.misses += 1
        sweep = self.loader(index)
        try:
            self._store(index, entry, sweep)
        except OSError:   # a full or read-only cache never stops a read
            pass
        return sweep

    @staticmethod
    def of(seq: Sequence) -> "SweepCache | None":
        """The cache ``seq`` reads its sweeps through, or None."""
        cache = getattr(getattr(seq, "load_sweep", None), "__self__", None)
        return cache if isinstance(cache, SweepCache) else None

    def load_mask(self, index: int, name: str) -> np.ndarray | None:
        """A boolean per-point array stored with frame ``index``'s entry (e.g. its ground mask), or None."""
        try:
            with np.load(self.entry(index) / f"{name}.npz", allow_pickle=False) as data:
                return np.unpackbits(data["bits"], count=int(data["count"])).astype(bool)
        except (OSError, ValueError, KeyError):
            return None

    def store_mask(self, index: int, name: str, mask: np.ndarray) -> None:
        """Store a boolean per-point array with frame ``index``'s entry (when the entry exists; atomically)."""
        entry = self.entry(index)
        if not entry.is_dir():
            return
        try:
            handle, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".npz", dir=entry)
            with os.fdopen(handle, "wb") as out:
                np.savez(out, bits=np.packbits(np.asarray(mask, dtype=bool)), count=np.int64(len(mask)))
            os.replace(tmp, entry / f"{name}.npz")
        except OSError:
            pass

    def _store(self, index: int, entry: Path, sweep: Sweep) -> None:
        fresh = not self.directory.is_dir()
        self.directory.mkdir(parents=True, exist_ok=True)
        if fresh:
            _evict(self.directory.parent, keep=self.directory)
        for stale in self.directory.glob(f"{index:06d}-*"):   # the frame's entry under an older key
            if stale != entry:
                shutil.rmtree(stale, ignore_errors=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{index:06d}-", dir=self.directory))
        try:
            for name in COLUMNS:
                value = getattr(sweep, name)
                if value is not None:
                    np.save(tmp / f"{name}.npy", np.ascontiguousarray(value), allow_pickle=False)
            try:
                os.rename(tmp, entry)
            except OSError:   # another process stored it first
                pass
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        os.utime(self.directory)   # the sequence was used now (least-recently-used eviction)


def _evict(root: Path, keep: Path) -> None:
    """Remove the least recently used sequence directories while ``root`` holds more than the size limit."""
    try:
        limit = float(os.environ.get(MAX_GB_ENV, "20")) * 1e9
    except ValueError:
        limit = 20e9
    entries = []
    for d in root.iterdir():
        if d.is_dir() and d != keep:
            size = sum(f.stat().st_size for f in d.rglob("*") if f.is_file())
            entries.append((d.stat().st_mtime, size, d))
    total = sum(e[1] for e in entries)
    for _, size, d in sorted(entries):
        if total <= limit:
            break
        shutil.rmtree(d, ignore_errors=True)
        total -= size


def with_sweep_cache(seq: Sequence, root: Path | None = None) -> Sequence:
    """``seq`` reading its sweeps through the cache (in place; also returned). ``root``: the cache directory
    (default :func:`cache_root`); no cache (``off``) leaves ``seq`` as it is."""
    root = cache_root() if root is None else Path(root)
    if root is None or isinstance(getattr(seq.load_sweep, "__self__", None), SweepCache):
        return seq
    try:
        seq_root = Path(seq.root).resolve()
        if root.resolve() == seq_root or seq_root in root.resolve().parents:   # never write into an input
            print(f"warning: the sweep cache {root} lies inside the input {seq_root}; reading without it",
                  file=sys.stderr)
            return seq
    except OSError:
        return seq
    seq.load_sweep = SweepCache(seq, root, seq.load_sweep).load
    return seq
