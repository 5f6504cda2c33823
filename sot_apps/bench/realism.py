"""``sot-apps bench realism``: simulated vs real vehicle scans (Chamfer, point-count ratio); the method is
described in :mod:`sot_apps.evaluation.realism`."""

from __future__ import annotations

import argparse
import time

from ..evaluation import DEV_TRACKS

__all__ = ["register"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", help="annotated sequence (e.g. ../shared/data/pandaset_002)")
    parser.add_argument("--ids", nargs="+", default=list(DEV_TRACKS), metavar="ID",
                        help="track id prefixes (default: the 9 PandaSet dev tracks)")
    parser.add_argument("--sensor", default="pandaset_pandar64",
                        help="sensor preset or JSON (default pandaset_pandar64: PandaSet's Pandar64 with its range drop)")
    parser.add_argument("--frames-per-track", type=int, default=3, help="held-out frames per track (default 3)")
    parser.add_argument("--min-points", type=int, default=20, help="minimum real points in the box (default 20)")
    parser.add_argument("--origin-z", type=float, default=0.0,
                        help="height of the simulated optical centre above the LiDAR frame origin (m, default 0: the "
                             "reader's LiDAR frame, for PandaSet the measured optical centre; what-if experiments)")
    parser.add_argument("--origin", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                        help="the simulated optical centre in the LiDAR frame (m), e.g. from `sensor fit --align`; "
                             "overrides --origin-z")
    parser.add_argument("--json", metavar="FILE", help="also write the rows as JSON")


def run(args: argparse.Namespace) -> int:
    import sys

    from ..evaluation.realism import evaluate_realism, format_tables
    from ..io import open_sequence
    from ..io.atomic import write_json

    start = time.perf_counter()
    seq = open_sequence(args.sequence)
    rows = evaluate_realism(seq, args.ids, args.sensor, args.frames_per_track, args.min_points, args.origin_z,
                            progress=sys.stderr.isatty(), origin=tuple(args.origin) if args.origin else None)
    print(format_tables(rows, args.sensor, time.perf_counter() - start))
    if args.origin:
        print("simulated optical centre at ({:g}, {:g}, {:g}) m in the LiDAR frame".format(*args.origin))
    elif args.origin_z:
        print(f"simulated optical centre {args.origin_z:g} m above the LiDAR frame origin")
    if args.json:
        write_json(args.json, [dict(r.__dict__, ratio=r.ratio) for r in rows])
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry (sot_apps/cli/bench.py)."""
    from . import module_docstring

    registry.add("realism", help="simulated vs real vehicle scans on PandaSet (Chamfer, point-count ratio)",
                 add_arguments=add_arguments, run=run, description=module_docstring("sot_apps.evaluation.realism"))
