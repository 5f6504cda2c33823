"""Where a saved result comes from: the commands that made it, the date (UTC) and the machine (CPU, cores).

Result JSON carries it as ``"provenance": {"commands": [...], "date": "...Z", "machine": {"cpu", "cores"}}``;
docs/results.md is generated from such files (:mod:`sot_apps.report.results`).
"""

from __future__ import annotations

import datetime
import os
import platform
import shlex
import sys
from typing import Any, Sequence

__all__ = ["cpu_model", "machine_stamp", "provenance_record", "invoked_command"]


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo), else what the platform says."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as handle:
            for line in handle:
                if line.lower().startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine_stamp() -> dict[str, str]:
    """This machine's CPU model and logical core count."""
    return {"cpu": cpu_model(), "cores": f"{os.cpu_count()} logical"}


def invoked_command(argv: Sequence[str] | None = None) -> str:
    """This process's command line as ``sot-apps ARGS`` (``argv``: default ``sys.argv``); when the program is not
    ``sot-apps`` (``python -m sot_apps.cli.main`` counts as it), the whole command line as it is."""
    argv = list(sys.argv if argv is None else argv)
    if argv and os.path.basename(argv[0]) in ("sot-apps", "main.py", "__main__.py"):
        return shlex.join(["sot-apps", *argv[1:]])
    return shlex.join(argv)


def provenance_record(commands: Sequence[str], date: str | None = None, note: str = "") -> dict[str, Any]:
    """The ``provenance`` record of a result made on this machine (``date``: ISO 8601 UTC, default now)."""
    when = date or datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ")
    record: dict[str, Any] = {"commands": list(commands), "date": when, "machine": machine_stamp()}
    if note:
        record["note"] = note
    return record
