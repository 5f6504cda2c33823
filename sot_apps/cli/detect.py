"""``sot-apps detect``: vehicle detections of a sequence (model-free detector or simulated), and their AP."""

from __future__ import annotations

import argparse
import sys

from ..errors import InputError
from .common import (
    add_detections_arguments,
    add_sequence_argument,
    add_subcommand,
    declare_outputs,
    load_detections,
    load_sequence,
    simulated_detections,
)


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "detect", help="detect vehicles (model-free, or simulated from ground truth) and score them",
        description="Write vehicle detections of every frame (WORLD boxes, data_schema/detections.schema.json). "
                    "Default: the model-free detector (3 accumulated sweeps, ground removal, range-adaptive BEV "
                    "clustering, L-shape boxes with size priors, a score calibrated on synthetic ground truth; no "
                    "learned network). --simulate PROFILE: ground truth with a detector's errors (docs/detection.md). "
                    "--evaluate prints BEV AP at IoU 0.5 / 0.7 by range band against the annotations (vehicles) and the "
                    "recall / precision at score >= 0.5 within 40 m; "
                    "with --detections FILE it scores that file instead of detecting, and --out writes it in our "
                    "JSON format (e.g. KITTI or nuScenes detections converted).",
        examples=["sot-apps detect ../shared/data/pandaset_002 --out dets.json --evaluate",
                  "sot-apps detect ../shared/data/pandaset_002 --simulate learned --seed 1 --out sim.json",
                  "sot-apps detect ../shared/data/pandaset_002 --detections dets.json --evaluate --3d"])
    add_sequence_argument(parser)
    parser.add_argument("--out", metavar="FILE", help="detections JSON to write")
    parser.add_argument("--simulate", metavar="PROFILE", help="simulated detections (learned, noisy, clean)")
    parser.add_argument("--seed", type=int, default=0, help="seed of --simulate (default 0)")
    parser.add_argument("--evaluate", action="store_true", help="print the AP table against the annotations")
    parser.add_argument("--3d", dest="three_d", action="store_true", help="with --evaluate: also 3D AP")
    parser.add_argument("--json", metavar="FILE", help="with --evaluate: write the AP rows as JSON")
    parser.add_argument("--frames", type=_frames, metavar="A:B:STEP",
                        help="only these frames: A:B:STEP (B excluded) or a comma-separated list (default all)")
    add_detections_arguments(parser)
    declare_outputs(parser, files=("out", "json"), inputs=("sequence", "detections", "kitti_calib"))
    parser.set_defaults(func=run)
    return parser


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from ..io.atomic import write_json
    from ..io.detections import write_detections
    from ..objects.selection import DEFAULT_SELECTION

    if not args.out and not args.evaluate:
        raise InputError(None, "nothing to do: give --out FILE and/or --evaluate")
    sequence = load_sequence(args)
    frames = _in_sequence(args.frames, sequence)
    progress = lambda frames: tqdm(frames, desc="detect", unit="frame", file=sys.stderr, leave=False)  # noqa: E731
    detections = load_detections(args, sequence)
    if detections is None and args.simulate:
        detections = simulated_detections(sequence, args.simulate, args.seed, progress)
    elif detections is None:
        from ..detection.detector import detect_sequence

        detections = detect_sequence(sequence, frames=frames, progress=progress)
    if frames is not None:
        detections = {k: d for k, d in detections.items() if k in set(frames)}
    if args.out:
        path = write_detections(args.out, detections, sequence.id)
        source = f" (read from --detections {args.detections}, written in our JSON format)" if args.detections else ""
        print(f"wrote {path}: {sum(len(d) for d in detections.values())} boxes in {len(detections)} frames{source}")
    if args.evaluate:
        from ..evaluation.detection import (
            OperatingPoint,
            ap_table,
            format_ap_table,
            ground_truth_frames,
            only_labels,
            operating_point,
            rows_for_json,
        )

        if not sequence.annotations:
            raise InputError(sequence.root, "--evaluate needs annotations")
        vehicles = DEFAULT_SELECTION.vehicle_labels(sequence)
        everything = ground_truth_frames(sequence, None, frames)     # other classes: don't-care at the operating point
        truth = only_labels(everything, vehicles)
        rows = ap_table(detections, truth, kinds=("bev", "3d") if args.three_d else ("bev",))
        print(format_ap_table(rows))
        point = operating_point(detections, everything, OperatingPoint(labels=vehicles))
        print(f"score >= 0.5, BEV IoU >= 0.5, within 40 m: recall {point['recall']:.2f} of {point['n_gt']} vehicles "
              f"with >= 50 points, precision {point['precision']:.2f} of {point['n_det']} detections")
        if args.json:
            write_json(args.json, rows_for_json(rows))
    return 0


def _frames(text: str) -> tuple:
    """``A:B:STEP`` -> ("range", A, B, STEP); ``1,5,9`` -> ("list", 1, 5, 9)."""
    try:
        if ":" in text:
            parts = [int(p) if p else None for p in text.split(":")]
            if len(parts) > 3:
                raise ValueError
            return ("range", *(parts + [None] * (3 - len(parts))))
        return ("list", *(int(p) for p in text.split(",")))
    except ValueError:
        raise argparse.ArgumentTypeError(f"frames must be A:B:STEP or a comma-separated list, not {text!r}") from None


def _in_sequence(frames: tuple | None, sequence) -> list[int] | None:
    if frames is None:
        return None
    if frames[0] == "range":
        return list(range(len(sequence)))[slice(*frames[1:])]
    bad = [k for k in frames[1:] if not 0 <= k < len(sequence)]
    if bad:
        raise InputError(sequence.root, f"--frames {bad[0]} is out of range: the sequence has frames 0..{len(sequence) - 1}")
    return list(frames[1:])
