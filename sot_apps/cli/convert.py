"""``sot-apps convert``: write any readable sequence in the canonical format, or its annotations as label files."""

from __future__ import annotations

import argparse
import sys

from .common import add_sequence_argument, add_subcommand, declare_outputs, load_sequence


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "convert", help="convert a sequence (PandaSet, AV2, nuScenes, KITTI, ...) to the canonical format",
        description="Write SEQUENCE in the canonical format (sequence.json + points/*.npz + camera images, see "
                    "docs/data-formats.md). Files are written atomically and sequence.json last; rerunning after an "
                    "interruption resumes (point files that already hold the right points are kept). With --labels, "
                    "write only the sequence's annotations: KITTI tracking label_02 (+ calib; 2D boxes projected "
                    "into KITTI's camera 2, else the dataset's front camera) or an AV2 annotations.feather (AV2 categories, "
                    "num_interior_pts counted from the sweeps).",
        examples=["sot-apps convert ../shared/data/pandaset_002 --out out/pandaset_002",
                  "sot-apps convert ../shared/data/readers/kitti_tracking_labels/training/label_02/0012.txt --out out/kitti_0012",
                  "sot-apps convert ../shared/data/readers/av2_sensor_test/sensor/val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede --out out/av2",
                  "sot-apps convert ../shared/data/readers/kitti_tracking_labels/training/label_02/0000.txt --labels kitti --out out/kitti_labels",
                  "sot-apps convert ../shared/data/readers/av2_sensor_test/sensor/val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede --labels av2 --out out/av2_labels"])
    add_sequence_argument(parser)
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument("--labels", choices=("kitti", "av2"),
                        help="write only the annotations: DIR/label_02/NNNN.txt + DIR/calib/NNNN.txt (kitti) or "
                             "DIR/annotations.feather (av2)")
    parser.set_defaults(func=run)
    declare_outputs(parser, dirs=("out",))
    return parser


def run(args: argparse.Namespace) -> int:
    from ..io.canonical import write_sequence

    print(f"reading {args.sequence} ...", flush=True)
    seq = load_sequence(args)
    if args.labels:
        from ..io.label_export import export_labels

        for line in export_labels(seq, args.labels, args.out):
            print(line)
        return 0
    images = sum(len(c.frames) for c in seq.cameras.values())
    print(f"converting {seq.id}: {len(seq)} point files and {images} camera images -> {args.out} (rerun resumes)",
          flush=True)
    path = write_sequence(seq, args.out, progress=sys.stderr.isatty())
    print(f"wrote {path} ({len(seq)} frames, {len(seq.cameras)} cameras, {len(seq.tracks())} annotated tracks)")
    return 0
