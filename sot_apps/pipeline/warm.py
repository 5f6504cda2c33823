"""The workers' fork server, warmed for a run: it opens the run's sequences once, so every worker forked from it
(local processes and a Dask LocalCluster's) starts with them in its worker-local cache
(:func:`sot_apps.io.opened.open_cached`) instead of each opening them at its first task (~0.1-0.3 s of CPU per
worker for a PandaSet sequence: its cuboids), and freezes its garbage collector, so the workers' collections never
walk (and copy-on-write) the objects the server imported.

The server imports this module last (``ExecutorSession.prestart``) with :data:`WARM_VARIABLE` in its environment:
the sequences as JSON ``[[path, format], ...]``. Imported anywhere else (the variable unset) it does nothing.
:func:`pipeline_sequences` reads them from a pipeline file with :mod:`json` alone, so that ``sot-apps run`` can start
the server before its own imports.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

__all__ = ["WARM_VARIABLE", "WARM_MAX_SEQUENCES", "sequence_path", "pipeline_sequences", "warm_environment", "server_ready"]

WARM_VARIABLE = "SOT_APPS_WARM_SEQUENCES"
# the server opens the sequences only for a run of at most this many: then every worker tracks chunks of the same
# few sequences and would open each of them; with more, a worker opens only those of its own tasks, and the server
# opening them all would hold back every worker's start (the sequence cache keeps 8 anyway)
WARM_MAX_SEQUENCES = 2

# in a warmed fork server and the workers forked from it: the server's CPU seconds and unix time when it had
# imported its modules and opened the sequences, i.e. when it could fork a ready worker (pipeline.accounting)
server_ready: dict[str, float] | None = None


def sequence_path(base: str | Path, path: str) -> str:
    """A pipeline file's sequence path: a relative one resolved against the file's directory ``base``."""
    return path if Path(path).is_absolute() else str((Path(base) / path).resolve())


def pipeline_sequences(pipeline: str | Path) -> list[tuple[str, str | None]]:
    """The ``(path, format)`` of every sequence of a pipeline file, read without validating it (empty when it cannot
    be read: :func:`sot_apps.pipeline.config.load_config` reports that)."""
    try:
        doc = json.loads(Path(pipeline).read_text(encoding="utf-8"))
        return [(sequence_path(Path(pipeline).parent, s["path"]), s.get("format")) for s in doc["sequences"]]
    except Exception:  # noqa: BLE001 - a warm-up only
        return []


def warm_environment(sources: list[tuple[str, str | None]]) -> dict[str, str]:
    """The environment that makes the fork server open ``sources`` (none when there are more than
    :data:`WARM_MAX_SEQUENCES`) and freeze its objects when it imports this module."""
    sources = sources if len(sources) <= WARM_MAX_SEQUENCES else []
    return {WARM_VARIABLE: json.dumps([[path, format] for path, format in sources])}


def _warm_this_process() -> None:
    import gc
    import time

    global server_ready

    try:
        from .plan import open_sequences

        open_sequences([(str(path), format) for path, format in json.loads(os.environ.pop(WARM_VARIABLE))])
    except Exception:  # noqa: BLE001 - the fork server must start whatever happens; the tasks report errors
        pass
    gc.freeze()
    server_ready = {"cpu_s": round(time.process_time(), 4), "unix": time.time()}


if WARM_VARIABLE in os.environ:
    _warm_this_process()
