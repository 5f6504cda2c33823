"""``sot-apps bench frames``: where a tracker variant wins or loses on a benchmark's tracklets, frame by frame.

Every tracklet of a ``benchmark make`` list (or its ``--tracklets``) is tracked from its first ground-truth box with
each preset and each variant (``NAME:PATH=VALUE,PATH=VALUE``: ``full`` with those settings) and one seed. Per
tracklet: Acc (mean 3D IoU over frames 1..n-1, as ``sot-apps eval``), the median and last-frame absolute heading
error (degrees) and the mean height error (m); with ``--frames`` each frame's errors in the ground-truth box's frame
(along, across, z; m), the heading error (deg), the object points and flags (``C`` yaw capped, ``P`` prior only,
``c`` coasting, ``r`` re-locked, ``b`` from a backward pass). ``--offline``: each run's offline refinement
(:func:`tracker.offline.refine_offline`, as ``sot-apps eval --offline``) instead of its online states. It diagnoses
on CHOOSING sets: a list whose tracklets come from the bank's confirming part (``split: confirm``) is refused unless
``--allow-confirm`` (the confirming part never influences a choice; docs/benchmark.md).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Sequence

if TYPE_CHECKING:   # imported by `sot-apps bench --help` (module discovery): the libraries load when a run starts
    import numpy as np

    from tracker import Box, FrameEstimate

__all__ = ["FrameErrors", "frame_errors", "parse_variant", "register"]


@dataclass(frozen=True)
class FrameErrors:
    """Per-frame errors of estimated boxes against ground truth, in the ground-truth box's frame."""

    along: np.ndarray      # (n,) m, along the ground-truth heading
    across: np.ndarray     # (n,) m, to its left
    dz: np.ndarray         # (n,) m
    heading_deg: np.ndarray  # (n,) estimated - true, wrapped to [-180, 180)
    iou: np.ndarray        # (n,) 3D IoU


def frame_errors(boxes: Sequence[Box], truth: Sequence[Box]) -> FrameErrors:
    """The errors of ``boxes`` against ``truth`` frame by frame (equal lengths)."""
    import numpy as np

    from tracker import iou_3d_batch

    est = np.array([[b.x, b.y, b.z, b.heading] for b in boxes], dtype=np.float64).reshape(-1, 4)
    gt = np.array([[b.x, b.y, b.z, b.heading] for b in truth], dtype=np.float64).reshape(-1, 4)
    if est.shape != gt.shape:
        raise ValueError(f"{len(est)} boxes against {len(gt)} ground-truth boxes")
    d = est[:, :2] - gt[:, :2]
    c, s = np.cos(gt[:, 3]), np.sin(gt[:, 3])
    heading = np.degrees(np.angle(np.exp(1j * (est[:, 3] - gt[:, 3]))))
    iou = iou_3d_batch(list(boxes), list(truth)) if len(est) else np.zeros(0)
    return FrameErrors(c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], est[:, 2] - gt[:, 2], heading, iou)


def parse_variant(text: str) -> tuple[str, dict[str, Any]]:
    """``NAME:PATH=VALUE,PATH=VALUE`` as (name, {dotted path: typed value}) (``NAME:`` alone: no change)."""
    from tracker import parse_overrides

    from ..errors import InputError

    name, sep, sets = text.partition(":")
    if not sep or not name:
        raise InputError(None, f"--variant {text!r}: expected NAME:PATH=VALUE[,PATH=VALUE...]")
    try:
        return name, parse_overrides([item for item in sets.split(",") if item]) if sets else {}
    except ValueError as exc:
        raise InputError(None, f"--variant {name}: {exc} (settings: docs/tracker.md)") from None


def _flags(estimate: FrameEstimate) -> str:
    return "".join(mark if flag in estimate.flags else "." for flag, mark in
                   (("yaw_clamped", "C"), ("prior_only", "P"), ("coasting", "c"), ("searching", "s"),
                    ("reacquired", "r"), ("backward", "b"), ("bridged", "B")))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("benchmark", metavar="LIST", help="a choosing benchmark.json (sot-apps benchmark make)")
    parser.add_argument("--preset", nargs="+", default=["faithful", "full"], help="presets (default faithful full)")
    parser.add_argument("--variant", nargs="+", action="extend", default=[], metavar="NAME:PATH=VALUE,...",
                        help="full with these settings, e.g. ft:motion.first_turn_points=200")
    parser.add_argument("--tracklets", default=None, metavar="ID,...", help="only these tracklet ids")
    parser.add_argument("--seed", type=int, default=0, help="tracker seed (default 0)")
    parser.add_argument("--frames", action="store_true", help="print per-frame rows")
    parser.add_argument("--offline", action="store_true", help="the runs' offline refinement (as eval --offline)")
    parser.add_argument("--allow-confirm", action="store_true",
                        help="also diagnose tracklets of the bank's confirming part (not for choosing)")


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from tracker import get_preset, refine_offline, track

    from ..errors import InputError
    from ..io import open_sequence
    from ..io.cached_source import CachedSource
    from .benchmark_eval import open_benchmark
    from .sequence_eval import resolve_presets

    configs = {name: get_preset(name, seed=args.seed) for name in resolve_presets(args.preset)}
    for text in args.variant:
        name, overrides = parse_variant(text)
        try:
            configs[name] = get_preset("full", seed=args.seed, **overrides)
        except ValueError as exc:
            raise InputError(None, f"--variant {name}: {exc}") from None
    bench = open_benchmark(args.benchmark)
    tracklets = bench.tracklets
    if args.tracklets:
        wanted = args.tracklets.split(",")
        tracklets = [t for t in tracklets if t.id in wanted]
        if len(tracklets) != len(wanted):
            raise InputError(bench.source, f"no tracklet {sorted(set(wanted) - {t.id for t in tracklets})[0]}")
    confirming = [t.id for t in tracklets if t.extra.get("split") == "confirm"]
    if confirming and not args.allow_confirm:
        raise InputError(bench.source, f"{len(confirming)} tracklets come from the bank's confirming part "
                                       "(never used to choose; --allow-confirm to diagnose them anyway)")
    sources: dict[str, tuple] = {}
    pooled: dict[str, list] = {name: [] for name in configs}
    for t in tracklets:
        path = str(bench.resolve(t))
        if path not in sources:
            sequence = open_sequence(path)
            sources[path] = (sequence, CachedSource(sequence))
        sequence, source = sources[path]
        a, b = t.frame_range
        truth = [sequence.tracks()[t.id].box_at(k) for k in range(a, b + 1)]
        runs = {}
        for name, config in configs.items():
            result = track(source, truth[0], a, b, config)
            if args.offline:
                result = refine_offline(source, result, config)
            runs[name] = (result.estimates, frame_errors([e.box for e in result.estimates], truth))
            pooled[name].append(runs[name][1].iou[1:])
        head = f"{t.id} {t.profile or '-':12s} {t.difficulty or '-':6s}"
        print(head + "".join(f" | {n} {100 * e.iou[1:].mean():5.1f} h {np.median(np.abs(e.heading_deg)):5.1f}"
                             f"/{abs(e.heading_deg[-1]):5.1f} z {e.dz.mean():+.2f}" for n, (_, e) in runs.items()))
        if args.frames:
            print("   k  v(m/s)  dyaw | " + " | ".join(f"{n + ': along across z hdg pts':^36}" for n in runs))
            for k in range(len(truth)):
                v = float(np.hypot(truth[k].x - truth[k - 1].x, truth[k].y - truth[k - 1].y)) / 0.1 if k else 0.0
                dyaw = float(np.degrees(truth[k].heading - truth[k - 1].heading)) if k else 0.0
                cells = [f"{e.along[k]:6.2f}{e.across[k]:6.2f}{e.dz[k]:6.2f}{e.heading_deg[k]:7.1f}"
                         f"{est[k].num_points:5d} {_flags(est[k])}" for est, e in runs.values()]
                print(f"  {k:2d} {v:6.1f} {dyaw:6.1f} | " + " | ".join(cells))
    print("all " + "  ".join(f"{n} {100 * np.concatenate(v).mean():5.1f}" for n, v in pooled.items() if v))
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry (sot_apps/cli/bench.py)."""
    from . import module_docstring

    registry.add("frames", help="per-tracklet and per-frame errors (heading, along, across, z) of presets and "
                                "variants on a choosing benchmark",
                 add_arguments=add_arguments, run=run, description=module_docstring("sot_apps.bench.frames"))
