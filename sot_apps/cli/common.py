"""Helpers shared by subcommand modules."""

from __future__ import annotations

import argparse
import math
from typing import TYPE_CHECKING

from ..io import FORMATS

if TYPE_CHECKING:
    from ..io.sequence import Sequence


def add_sequence_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", help="sequence: canonical or PandaSet directory, Waymo v1 .tfrecord or v2 directory/component .parquet, Argoverse 2 log, nuScenes root (DIR#scene), KITTI tracking (label_02/SSSS.txt or DIR#SSSS), KITTI object / View-of-Delft folder")
    parser.add_argument("--format", choices=FORMATS, default=None, help="force the reader (default: auto-detect)")


def load_sequence(args: argparse.Namespace) -> Sequence:
    """The sequence of ``args.sequence``; the outputs are checked once more against the directory the reader
    actually reads (a KITTI label file or a Waymo component names a file; the reader reads its dataset root)."""
    from ..io import open_sequence

    sequence = open_sequence(args.sequence, format=getattr(args, "format", None))
    if getattr(args, "output_files", None) is not None:
        from ..io.outputs import PathArg, check_no_clobber

        check_no_clobber([PathArg("SEQUENCE", sequence.root)], _declared_outputs(args))
    return sequence


def example_epilog(*examples: str) -> str:
    return "Examples:\n" + "\n".join(f"  {e}" for e in examples)


class SubcommandListed(Exception):
    """Raised by :func:`add_subcommand` when the CLI only lists the subcommands (``sot-apps --help``, ``sot-apps``
    alone): the subcommand's name and help line are in place, the rest of its ``register`` (its options and the
    imports they need) is skipped."""


def add_subcommand(subparsers, name: str, help: str, description: str, examples: list[str]) -> argparse.ArgumentParser:
    parser = subparsers.add_parser(name, help=help, description=description, epilog=example_epilog(*examples),
                                   formatter_class=argparse.RawDescriptionHelpFormatter)
    if getattr(subparsers, "listing_only", False):
        raise SubcommandListed(name)
    return parser


def add_action(subparsers, name: str, help: str, description: str, examples: list[str]) -> argparse.ArgumentParser:
    """A nested action (``bank build``, ``sensor fit``) with examples in its ``--help``."""
    return subparsers.add_parser(name, help=help, description=description, epilog=example_epilog(*examples),
                                 formatter_class=argparse.RawDescriptionHelpFormatter)


def add_detections_arguments(parser: argparse.ArgumentParser) -> None:
    """``--detections FILE`` (+ its format and KITTI calib) for the Det / Det+SOT presets."""
    parser.add_argument("--detections", metavar="FILE",
                        help="detections for the det / det_sot presets: our detections JSON, KITTI label text with a "
                             "score column (file or directory), or nuScenes results JSON (docs/detection.md)")
    parser.add_argument("--detections-format", choices=("json", "kitti", "nuscenes"), default=None,
                        help="format of --detections (default: from the content)")
    parser.add_argument("--kitti-calib", metavar="FILE",
                        help="KITTI calib file of KITTI detections (default: KITTI's camera axes at the LiDAR origin)")


def load_detections(args: argparse.Namespace, sequence: Sequence):
    """The detections named by ``--detections`` (world boxes per frame), or None."""
    if not getattr(args, "detections", None):
        return None
    from ..io.detections import read_sequence_detections

    return read_sequence_detections(args.detections, sequence, args.detections_format, args.kitti_calib)


def check_profile(profile: str) -> None:
    """An unknown simulated-detection profile is an InputError."""
    from ..detection.simulate import NOISE_PROFILES
    from ..errors import InputError

    if profile not in NOISE_PROFILES:
        raise InputError(None, f"unknown detection profile {profile!r}; known: {', '.join(NOISE_PROFILES)}")


def simulated_detections(sequence: Sequence, profile: str, seed: int, progress=None):
    """Simulated vehicle detections (docs/detection.md) of ``sequence``."""
    from ..detection.simulate import simulate_detections
    from ..objects.selection import DEFAULT_SELECTION

    check_profile(profile)
    return simulate_detections(sequence, profile, seed, DEFAULT_SELECTION.vehicle_labels(sequence), progress)


def _option_names(parser: argparse.ArgumentParser, dests: tuple[str, ...]) -> tuple[tuple[str, str], ...]:
    """``(dest, how the user wrote it)`` pairs: ``("json", "--json")``, ``("sequence", "SEQUENCE")``."""
    names = {}
    for action in parser._actions:
        if action.dest in dests:
            names[action.dest] = action.option_strings[-1] if action.option_strings else \
                (action.metavar if isinstance(action.metavar, str) else action.dest.upper())
    return tuple((d, names.get(d, f"--{d.replace('_', '-')}")) for d in dests)


def declare_outputs(parser: argparse.ArgumentParser, files: tuple[str, ...] = (), dirs: tuple[str, ...] = (),
                    inputs: tuple[str, ...] = ("sequence",)) -> None:
    """Name the options (argparse dests) that are output files or directories, and those that name inputs (files
    or directories; a list option names several). Before the command starts its work, ``main`` checks that each
    given output is writable, is not an input and is not another output (:func:`check_outputs`), and locks each
    output directory (:func:`output_locks`)."""
    parser.set_defaults(output_files=_option_names(parser, tuple(files)), output_dirs=_option_names(parser, tuple(dirs)),
                        input_paths=_option_names(parser, tuple(inputs)))


def _values(args: argparse.Namespace, dest: str) -> list[str]:
    value = getattr(args, dest, None)
    if value is None or value is False:
        return []
    return [str(v) for v in value] if isinstance(value, (list, tuple)) else [str(value)]


def _declared_outputs(args: argparse.Namespace) -> list:
    from pathlib import Path

    from ..io.outputs import PathArg

    return ([PathArg(option, Path(v)) for dest, option in getattr(args, "output_files", ()) for v in _values(args, dest)]
            + [PathArg(option, Path(v), is_dir=True) for dest, option in getattr(args, "output_dirs", ())
               for v in _values(args, dest)])


def check_outputs(args: argparse.Namespace) -> None:
    """Fail early (one line, exit code 2) when an output declared with :func:`declare_outputs` is not writable, is
    one of the command's inputs (or would replace a file inside an input directory), or is another output."""
    from ..io.atomic import ensure_writable
    from ..io.outputs import PathArg, check_no_clobber, input_path

    outputs = _declared_outputs(args)
    for out in outputs:
        ensure_writable(out.path, directory=out.is_dir)
    inputs = [PathArg(option, input_path(v)) for dest, option in getattr(args, "input_paths", ())
              for v in _values(args, dest)]
    check_no_clobber(inputs, outputs)


def output_locks(args: argparse.Namespace):
    """A context that holds the lock (:class:`sot_apps.io.lock.OutputLock`) of every declared output directory."""
    import contextlib

    from ..io.lock import OutputLock

    stack = contextlib.ExitStack()
    for out in _declared_outputs(args):
        if out.is_dir:
            stack.enter_context(OutputLock(out.path))
    return stack


# ------------------------------------------------------------------ numbers
# Every numeric option goes through one of these: a non-finite or out-of-range value is a usage error naming the
# option (exit code 2), before any work.

def finite_float(text: str) -> float:
    """A finite number (``nan``, ``inf`` refused)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def coordinate(text: str) -> float:
    """A finite coordinate in metres within the documented bound (|value| <= MAX_COORDINATE_M)."""
    from ..io.bounds import MAX_COORDINATE_M

    value = finite_float(text)
    if abs(value) > MAX_COORDINATE_M:
        raise argparse.ArgumentTypeError(f"{text} m is beyond the coordinate bound (|value| <= {MAX_COORDINATE_M:g} m)")
    return value


def _require(value, ok: bool, requirement: str, text: str):
    if not ok:
        raise argparse.ArgumentTypeError(f"must be {requirement}, got {text}")
    return value


def positive_float(text: str) -> float:
    value = finite_float(text)
    return _require(value, value > 0, "> 0", text)


def nonnegative_float(text: str) -> float:
    value = finite_float(text)
    return _require(value, value >= 0, ">= 0", text)


def probability(text: str) -> float:
    """A probability in [0, 1)."""
    value = finite_float(text)
    return _require(value, 0 <= value < 1, "a probability in [0, 1)", text)


def _integer(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None


def nonnegative_int(text: str) -> int:
    value = _integer(text)
    return _require(value, value >= 0, ">= 0", text)


def positive_int(text: str) -> int:
    value = _integer(text)
    return _require(value, value >= 1, ">= 1", text)
