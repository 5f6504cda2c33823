"""Helpers shared by subcommand modules."""

from __future__ import annotations

import argparse

from ..io import FORMATS, open_sequence
from ..io.sequence import Sequence


def add_sequence_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", help="sequence: a directory (canonical, PandaSet, Waymo v2) or a file (Waymo v1 .tfrecord, Waymo v2 component .parquet)")
    parser.add_argument("--format", choices=FORMATS, default=None, help="force the reader (default: auto-detect)")


def load_sequence(args: argparse.Namespace) -> Sequence:
    return open_sequence(args.sequence, format=getattr(args, "format", None))


def example_epilog(*examples: str) -> str:
    return "Examples:\n" + "\n".join(f"  {e}" for e in examples)


def add_subcommand(subparsers, name: str, help: str, description: str, examples: list[str]) -> argparse.ArgumentParser:
    return subparsers.add_parser(name, help=help, description=description, epilog=example_epilog(*examples),
                                 formatter_class=argparse.RawDescriptionHelpFormatter)


def declare_outputs(parser: argparse.ArgumentParser, files: tuple[str, ...] = (), dirs: tuple[str, ...] = ()) -> None:
    """Name the options (argparse dests) that are output files or directories: ``main`` checks that each given
    one is writable before the command starts its work (:func:`check_outputs`)."""
    parser.set_defaults(output_files=tuple(files), output_dirs=tuple(dirs))


def check_outputs(args: argparse.Namespace) -> None:
    """Fail early (one line, exit code 2) when an output declared with :func:`declare_outputs` is not writable."""
    from ..io.atomic import ensure_writable

    for name in getattr(args, "output_files", ()):
        if getattr(args, name, None):
            ensure_writable(getattr(args, name))
    for name in getattr(args, "output_dirs", ()):
        if getattr(args, name, None):
            ensure_writable(getattr(args, name), directory=True)
