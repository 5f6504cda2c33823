"""``sot-apps run PIPELINE.json``: the data-generation pipeline (tracking -> bank -> motion -> flow -> scans)."""

from __future__ import annotations

import argparse

from .common import add_subcommand, declare_outputs, positive_int

EXIT_RULE = ("Exit code 1 when any unit failed, except annotated objects the tracker could not start or follow for "
             "lack of LiDAR points (listed as FAILED; far or hidden vehicles are a normal outcome on real data); "
             "0 otherwise. Tracks that look lost are reported, not counted as failures.")


def add_executor_arguments(parser: argparse.ArgumentParser) -> None:
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--workers", type=positive_int, default=None, metavar="N",
                       help="local worker processes (default 1: run in this process)")
    group.add_argument("--dask", metavar="tcp://HOST:PORT", help="run the tasks on this Dask scheduler")
    group.add_argument("--dask-local", type=positive_int, metavar="N", help="run the tasks on a Dask LocalCluster of N workers")


def executor_from_args(args: argparse.Namespace):
    from ..errors import InputError
    from ..pipeline.executors import ExecutorSpec

    if args.dask:
        return ExecutorSpec("dask", address=args.dask)
    if args.dask_local is not None:
        if args.dask_local < 1:
            raise InputError(None, "--dask-local needs at least 1 worker")
        return ExecutorSpec("dask", workers=args.dask_local)
    workers = 1 if args.workers is None else args.workers
    if workers < 1:
        raise InputError(None, "--workers needs at least 1")
    return ExecutorSpec("local", workers=workers)


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "run",
        help="run a data-generation pipeline (tracking, bank, motion export, flow, simulated scans)",
        description="Run the stages of PIPELINE.json (schema: data_schema/pipeline.schema.json) over its sequences "
                    "and objects: tracking (one task per object), vehicle bank, motion export (MCAP + tables), optical "
                    "flow, and simulated scans of bank vehicles. Finished units are skipped on a rerun (resume after a "
                    "crash or Ctrl-C); a failed unit is listed in OUT/failures.json and does not stop the run. "
                    f"{EXIT_RULE} Only one run at a time may write into an output directory (a lock in OUT; a "
                    "second run is refused with exit code 2). "
                    "See docs/pipeline.md for the output tree.",
        examples=[
            "sot-apps run examples/pipeline.json",
            "sot-apps run examples/pipeline.json --workers 2 --out /tmp/pipeline_out",
            "sot-apps run examples/pipeline.json --dask-local 2 --report",
            "sot-apps run examples/pipeline.json --dask tcp://10.0.0.5:8786",
        ])
    parser.add_argument("pipeline", metavar="PIPELINE.json", help="pipeline file")
    parser.add_argument("--out", metavar="DIR", help="output directory (overrides the file's 'out')")
    add_executor_arguments(parser)
    parser.add_argument("--detections", metavar="FILE",
                        help="per-frame detections of the (single) sequence, for stages.track.preset det / det_sot")
    parser.add_argument("--report", action="store_true",
                        help="also write OUT/report/index.html (figures of the first sequences, as `sot-apps demo`)")
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.set_defaults(func=run)
    declare_outputs(parser, dirs=("out",), inputs=("pipeline", "detections"))
    return parser


def run(args: argparse.Namespace) -> int:
    from ..pipeline import WORKER_MODULES
    from ..pipeline.executors import ExecutorSession
    from ..pipeline.warm import pipeline_sequences, warm_environment

    spec = executor_from_args(args)
    # the workers' fork server imports the toolkit and opens the file's sequences on the other core while this
    # process imports and plans (docs/pipeline.md, "Worker start-up"); a Dask LocalCluster is created once the
    # pipeline file is read, on a thread, while this process plans
    warm = warm_environment(pipeline_sequences(args.pipeline))
    with ExecutorSession(spec) as session:
        session.prestart(WORKER_MODULES, cluster=False, environ=warm)
        from ..io.atomic import ensure_writable
        from ..pipeline.config import load_config
        from ..pipeline.runner import run_pipeline

        config = load_config(args.pipeline, out=args.out, detections=args.detections)
        ensure_writable(config.out, directory=True)
        session.prestart(WORKER_MODULES, environ=warm)
        result = run_pipeline(config, spec, progress=not args.quiet, session=session)
    print(f"{len(result.plan.objects)} objects in {len(result.plan.sequences)} sequences, {spec.describe()}, "
          f"{result.seconds:.1f} s")
    print(result.summary())
    for failure in result.failed:
        print(f"FAILED {failure.key}: {failure.error}")
    print(f"manifest: {result.manifest}")
    if args.report:
        from ..report import build_report

        print(f"report: {build_report(result, config.description or 'sot-apps pipeline report')}")
    if result.failed:
        print(f"failures: {result.failures}")
    return result.exit_code()
