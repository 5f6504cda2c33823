"""Helpers shared by subcommand modules."""

from __future__ import annotations

import argparse

from ..io import FORMATS, open_sequence
from ..io.sequence import Sequence


def add_sequence_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", help="sequence: canonical or PandaSet directory, Waymo v1 .tfrecord or v2 directory/component .parquet, Argoverse 2 log, nuScenes root (DIR#scene), KITTI tracking (label_02/SSSS.txt or DIR#SSSS), KITTI object / View-of-Delft folder")
    parser.add_argument("--format", choices=FORMATS, default=None, help="force the reader (default: auto-detect)")


def load_sequence(args: argparse.Namespace) -> Sequence:
    return open_sequence(args.sequence, format=getattr(args, "format", None))


def example_epilog(*examples: str) -> str:
    return "Examples:\n" + "\n".join(f"  {e}" for e in examples)


def add_subcommand(subparsers, name: str, help: str, description: str, examples: list[str]) -> argparse.ArgumentParser:
    return subparsers.add_parser(name, help=help, description=description, epilog=example_epilog(*examples),
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
