"""``sot-apps bench motion``: accuracy of the motion export against ground truth (the paper's "motion
generation" figure); the evaluation itself is :mod:`sot_apps.evaluation.motion`."""

from __future__ import annotations

import argparse

from ..errors import InputError
from ..evaluation import DEV_TRACKS

__all__ = ["register"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", help="sequence directory with annotations")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--tracks-dir", metavar="DIR", help="directory holding track directories (track.json)")
    source.add_argument("--from-annotations", action="store_true",
                        help="sanity check: export the annotations themselves (errors = smoothing residuals)")
    parser.add_argument("--ids", nargs="+", default=list(DEV_TRACKS), metavar="ID",
                        help="object id prefixes (default: the 9 PandaSet dev tracks)")
    parser.add_argument("--horizon", type=int, default=30, help="k = 1..HORIZON frames after the start (default 30)")
    parser.add_argument("--plot", metavar="PNG", help="write the centre-error curve as a PNG")
    parser.add_argument("--json", metavar="FILE", help="write all figures as JSON")
    parser.set_defaults(bench_inputs=("tracks_dir",))   # --json and --plot never write into the tracks


def run(args: argparse.Namespace) -> int:
    from ..evaluation.motion import evaluate_motion, find_track_dirs, format_table, plot_accuracy
    from ..io import open_sequence
    from ..io.atomic import write_json
    from ..motion_export.sources import tracks_from_annotations, tracks_from_dirs
    from ..objects.smoother import ANNOTATION_SMOOTHER, TRACKER_SMOOTHER

    sequence = open_sequence(args.sequence, format=getattr(args, "format", None))
    if args.horizon < 1:
        raise InputError(None, "--horizon must be >= 1")
    if args.from_annotations:
        tracks = tracks_from_annotations(sequence, args.ids)
        smoother, source = ANNOTATION_SMOOTHER, "annotations (sanity check)"
    else:
        tracks = tracks_from_dirs(find_track_dirs(args.tracks_dir, args.ids), sequence)
        smoother, source = TRACKER_SMOOTHER, f"tracker outputs in {args.tracks_dir}"
    acc = evaluate_motion(sequence, tracks, args.horizon, smoother, source)
    print(format_table(acc))
    if args.plot:
        plot_accuracy(acc, args.plot, f"Motion export vs. ground truth, {sequence.id}, {len(tracks)} tracks")
        print(f"wrote plot: {args.plot}")
    if args.json:
        write_json(args.json, acc.to_json())
        print(f"wrote json: {args.json}")
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry (sot_apps/cli/bench.py)."""
    from . import module_docstring

    registry.add("motion", help="accuracy of the motion export against ground truth (centre, velocity, yaw rate)",
                 add_arguments=add_arguments, run=run,
                 description=module_docstring("sot_apps.evaluation.motion"))
