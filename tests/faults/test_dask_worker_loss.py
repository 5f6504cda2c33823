"""Faults to survive: a real distributed run (``dask scheduler`` + two ``dask worker`` processes on 127.0.0.1)
loses a worker (SIGKILL) mid-run. The run finishes (Dask reruns the lost tasks on the other worker) or reports
exactly the lost units; a rerun completes them; the outputs equal a clean local run; nothing half-written."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from .conftest import run_cli
from .interrupt_driver import checksums, pipeline_file

DASK = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
WORKER = [sys.executable, "-m", "distributed.cli.dask_worker"]


def _start(argv: list[str], log: Path) -> subprocess.Popen:
    handle = open(log, "wb")
    return subprocess.Popen(argv, stdout=handle, stderr=subprocess.STDOUT, start_new_session=True)


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)


def _wait_for(condition, timeout: float, what: str) -> None:
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.1)


@pytest.fixture
def cluster(tmp_path):
    """A scheduler and two single-threaded workers (no nanny: a killed worker stays dead), all on 127.0.0.1."""
    pytest.importorskip("distributed", reason="the 'dist' extra (dask) is part of the test environment")
    sched_file = tmp_path / "scheduler.json"
    procs = [_start([*DASK, "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file",
                     str(sched_file)], tmp_path / "scheduler.log")]
    try:
        _wait_for(lambda: sched_file.is_file() and sched_file.stat().st_size > 0, 60, "the scheduler")
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:"), address
        for name in ("wa", "wb"):
            procs.append(_start([*WORKER, address, "--name", name, "--host", "127.0.0.1", "--nthreads", "1",
                                 "--no-nanny", "--no-dashboard"], tmp_path / f"worker_{name}.log"))
        from distributed import Client

        with Client(address, timeout=60) as client:
            client.wait_for_workers(2, timeout=120)
        yield address, {"wa": procs[1], "wb": procs[2]}   # without a nanny, each process is its worker
    finally:
        for proc in procs:
            _stop(proc)


def test_killed_worker_mid_run(cluster, world, tmp_path):
    from sot_apps.pipeline.config import PipelineConfig
    from sot_apps.pipeline.executors import ExecutorSpec
    from sot_apps.pipeline.runner import run_pipeline

    address, workers = cluster
    pipeline = pipeline_file(world, tmp_path)
    clean = tmp_path / "clean"
    config = PipelineConfig.from_json({**json.loads(pipeline.read_text()), "out": str(clean)})
    assert not run_pipeline(config, ExecutorSpec("inline"), progress=False).failed
    reference = checksums(clean)

    out = tmp_path / "dist"
    argv = [*(sys.executable, "-m", "sot_apps.cli.main"), "run", str(pipeline), "--dask", address, "--quiet",
            "--out", str(out)]
    run = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        # kill worker "wa" as soon as the first unit is finished: the others are queued or running
        _wait_for(lambda: (out / ".done").is_dir() and any((out / ".done").rglob("*.json")) or run.poll() is not None,
                  240, "the first finished unit")
        assert run.poll() is None, "the run ended before a worker could be killed"
        os.kill(workers["wa"].pid, signal.SIGKILL)
        workers["wa"].wait(timeout=30)
        stdout, stderr = run.communicate(timeout=300)
    finally:
        if run.poll() is None:
            os.killpg(run.pid, signal.SIGKILL)
    assert "Traceback" not in stderr, stderr
    failures = json.loads((out / "failures.json").read_text())["failures"]
    print(f"after losing worker wa: exit {run.returncode}, failed units {[f['key'] for f in failures]}")
    if run.returncode == 0:
        assert failures == []          # Dask ran the lost tasks again on the other worker
    else:                              # or the run names exactly the lost units
        assert run.returncode == 1, stderr
        assert failures and all("Killed" in f["error"] or "lost" in f["error"].lower() for f in failures), failures
        assert {f"FAILED {f['key']}" for f in failures} <= set(stdout.splitlines()), stdout
    rerun = run_cli(["run", pipeline, "--dask", address, "--quiet", "--out", out], timeout=300)
    assert rerun.returncode == 0, rerun.stderr
    assert json.loads((out / "failures.json").read_text()) == {"failures": []}
    assert not list(out.rglob("*.tmp")), "temporary files left behind"
    assert checksums(out) == reference
