"""``sot-apps bench tracker SEQUENCE``: SOTracker speed (ms per frame) and Acc/Rob per preset, one core.

The measurement runs in a child process started with ``OMP_NUM_THREADS=OPENBLAS_NUM_THREADS=
MKL_NUM_THREADS=1`` (set before numpy is imported) and pinned to one CPU with ``sched_setaffinity``, so
the figures are single-threaded. Per preset, every selected track is tracked from its first
ground-truth box over its annotated span (default: the moving vehicle tracks, i.e. the 9 PandaSet
dev tracks on pandaset_002); frames are read and cached before timing, so the per-frame times
(``FrameEstimate.time_ms``) hold only the tracker's work. Frame 1 (with the wide ICP search) is
included in median/mean/p90 and also reported alone. The machine is shared: the load average is
printed with the table.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from typing import Any

from . import format_machine, machine_description, pin_one_core

__all__ = ["register", "add_arguments", "run", "run_benchmark", "format_table"]

_CHILD_ENV = "SOT_APPS_BENCH_CHILD"
_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", help="annotated sequence, e.g. ../shared/data/pandaset_002")
    parser.add_argument("--preset", nargs="+", default=["full"], metavar="NAME",
                        help="tracker presets (default: full; 'all' = every preset)")
    parser.add_argument("--tracks", metavar="ID,...", help="track id prefixes (default: all moving vehicle tracks)")
    parser.add_argument("--offline", action="store_true", help="also time the offline refinement")
    parser.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    parser.add_argument("--in-process", action="store_true",
                        help="measure in this process (no single-threaded child; thread variables as they are)")


def _child_argv(args: argparse.Namespace) -> list[str]:
    argv = ["bench", "tracker", str(args.sequence), "--preset", *args.preset]
    if args.tracks:
        argv += ["--tracks", args.tracks]
    if args.offline:
        argv.append("--offline")
    if args.json:
        argv += ["--json", str(args.json)]
    return argv


def run_benchmark(sequence_path: str, presets: list[str], tracks: list[str] | None, offline: bool) -> dict[str, Any]:
    from ..eval import evaluate, resolve_presets
    from ..io import open_sequence

    pinned = pin_one_core()
    sequence = open_sequence(sequence_path)
    report = evaluate(sequence, tracks, resolve_presets(presets), offline=offline, with_shape=False)
    machine = machine_description() | {"pinning": pinned}
    rows = [{"row": r.name, "acc": r.pooled["acc"], "rob": r.pooled["rob"], **r.timing} for r in report.rows]
    return {"sequence": str(sequence.root), "tracks": [t.track_id for t in report.tracks],
            "frames_per_preset": report.rows[0].timing["frames"] if report.rows else 0,
            "machine": machine, "rows": rows}


def format_table(result: dict[str, Any]) -> str:
    header = ["preset", "median ms", "mean ms", "p90 ms", "frame-1 ms", "median ms (k>=2)", "Acc", "Rob"]
    body = [[r["row"], f"{r['median_ms']:.1f}", f"{r['mean_ms']:.1f}", f"{r['p90_ms']:.1f}", f"{r['frame1_mean_ms']:.1f}",
             f"{r['median_ms_excl_frame1']:.1f}", f"{100 * r['acc']:.1f}", f"{100 * r['rob']:.1f}"] for r in result["rows"]]
    widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(header)]
    fmt = lambda cells: "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(cells, widths)))  # noqa: E731
    lines = [f"sequence: {result['sequence']}",
             f"tracks: {len(result['tracks'])} ({', '.join(t[:8] for t in result['tracks'])}); "
             f"{result['frames_per_preset']} tracked frames per preset (k >= 1)",
             "", fmt(header), "  ".join("-" * w for w in widths)] + [fmt(b) for b in body]
    lines += ["", "ms per frame: tracker time (crop, ground removal, association, optimisation), sweep reading excluded;",
              "frame 1's wide search is included in median/mean/p90. Acc/Rob in % (pooled, frames 1..n-1).",
              "", "machine:", format_machine(result["machine"])]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    if not args.in_process and os.environ.get(_CHILD_ENV) != "1":
        env = dict(os.environ)
        env.update({name: "1" for name in _THREAD_VARS})
        env[_CHILD_ENV] = "1"
        return subprocess.call([sys.executable, "-m", "sot_apps.cli.main", *_child_argv(args)], env=env)
    from ..io.atomic import write_json

    tracks = [t for t in args.tracks.split(",") if t] if args.tracks else None
    result = run_benchmark(args.sequence, args.preset, tracks, args.offline)
    print(format_table(result))
    if args.json:
        write_json(args.json, result)
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry."""
    registry.add("tracker", help="SOTracker ms/frame (median/mean/p90, one core) and Acc/Rob per preset",
                 add_arguments=add_arguments, run=run, description=__doc__)
