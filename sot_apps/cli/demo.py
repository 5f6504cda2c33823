"""``sot-apps demo``: synthetic world with a camera (or a real sequence) -> whole pipeline -> HTML report."""

from __future__ import annotations

import argparse

from .common import add_subcommand, declare_outputs, positive_int


def register(subparsers) -> argparse.ArgumentParser:
    from .run import EXIT_RULE, add_executor_arguments

    parser = add_subcommand(
        subparsers, "demo",
        help="end-to-end demo: synthetic world (or --sequence), whole pipeline, MCAP and an HTML report",
        description="With no arguments: generate a small synthetic world (20 frames of a 64-beam LiDAR, a front "
                    "camera, moving vehicles with ground truth), run every pipeline stage on its moving vehicles "
                    "(tracking, vehicle bank, motion export to MCAP, optical flow, simulated scans at 20 m and 40 m) "
                    "and write OUT/report/index.html with the figures. With --sequence: the same on a real sequence "
                    "(objects = its moving vehicles; flow on the front camera, first 10 pairs). A rerun resumes. "
                    f"{EXIT_RULE}",
        examples=[
            "sot-apps demo --out demo_out   # then open demo_out/report/index.html",
            "sot-apps demo --out demo_pandaset --sequence ../shared/data/pandaset_002 --workers 2",
            "sot-apps demo --quick --out /tmp/demo_quick",
        ])
    parser.add_argument("--out", default="demo_out", metavar="DIR", help="output directory (default: demo_out)")
    parser.add_argument("--sequence", metavar="PATH", help="run on this sequence instead of a synthetic world")
    parser.add_argument("--quick", action="store_true",
                        help="a smaller synthetic world (6 frames, 16-beam LiDAR, 320x240 camera) for smoke tests")
    parser.add_argument("--flow-pairs", type=positive_int, metavar="N", default=None,
                        help="optical flow on the first N image pairs (default: all for the synthetic world, 10 for "
                             "--sequence)")
    add_executor_arguments(parser)
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.set_defaults(func=run)
    declare_outputs(parser, dirs=("out",))
    return parser


def run(args: argparse.Namespace) -> int:
    from ..demo import DEFAULT_SIZE, QUICK_SIZE, run_demo
    from ..errors import InputError
    from .run import executor_from_args

    if args.flow_pairs is not None and args.flow_pairs < 1:
        raise InputError(None, "--flow-pairs must be >= 1")
    if args.sequence and args.quick:
        raise InputError(None, "--quick sizes the synthetic world; it cannot be combined with --sequence")
    spec = executor_from_args(args)
    result = run_demo(args.out, args.sequence, QUICK_SIZE if args.quick else DEFAULT_SIZE, spec,
                      progress=not args.quiet, flow_pairs=args.flow_pairs)
    p = result.pipeline
    times = ", ".join(f"{k} {v:.1f} s" for k, v in result.seconds.items())
    print(f"demo: {len(p.plan.objects)} objects, {spec.describe()} ({times})")
    print(p.summary())
    for failure in p.failed:
        print(f"FAILED {failure.key}: {failure.error}")
    for s in p.plan.sequences:
        mcap = result.out / s.name / "motion.mcap"
        if mcap.is_file():
            print(f"MCAP: {mcap}")
    print(f"report: {result.report}")
    return p.exit_code()
