"""Helpers shared by subcommand modules."""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING

from ..io import FORMATS

if TYPE_CHECKING:
    from ..io.sequence import Sequence


def add_sequence_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("sequence", metavar="SEQUENCE", help="sequence: canonical or PandaSet directory, Waymo v1 .tfrecord or v2 directory/component .parquet, Argoverse 2 log, nuScenes root (DIR#scene), KITTI tracking (label_02/SSSS.txt or DIR#SSSS), KITTI object / View-of-Delft folder")
    parser.add_argument("--format", choices=FORMATS, default=None, help="force the reader (default: auto-detect)")


def load_sequence(args: argparse.Namespace) -> Sequence:
    from ..io import open_sequence

    return open_sequence(args.sequence, format=getattr(args, "format", None))


def example_epilog(*examples: str) -> str:
    return "Examples:\n" + "\n".join(f"  {e}" for e in examples)


def add_subcommand(subparsers, name: str, help: str, description: str, examples: list[str]) -> argparse.ArgumentParser:
    return subparsers.add_parser(name, help=help, description=description, epilog=example_epilog(*examples),
                                 formatter_class=argparse.RawDescriptionHelpFormatter)


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
