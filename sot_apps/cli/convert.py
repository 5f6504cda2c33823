"""``sot-apps convert``: write any readable sequence in the canonical format."""

from __future__ import annotations

import argparse
import sys

from ..io.canonical import write_sequence
from .common import add_sequence_argument, add_subcommand, declare_outputs, load_sequence


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "convert", help="convert a sequence (e.g. PandaSet) to the canonical format",
        description="Write SEQUENCE in the canonical format (sequence.json + points/*.npz + camera images, see "
                    "docs/data-formats.md). Files are written atomically and sequence.json last; rerunning after an "
                    "interruption resumes (point files that already hold the right points are kept).",
        examples=["sot-apps convert ../shared/data/pandaset_002 --out out/pandaset_002"])
    add_sequence_argument(parser)
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.set_defaults(func=run)
    declare_outputs(parser, dirs=("out",))
    return parser


def run(args: argparse.Namespace) -> int:
    seq = load_sequence(args)
    path = write_sequence(seq, args.out, progress=sys.stderr.isatty())
    print(f"wrote {path} ({len(seq)} frames, {len(seq.cameras)} cameras, {len(seq.tracks())} annotated tracks)")
    return 0
