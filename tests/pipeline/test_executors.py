"""The local and Dask executors run the same tasks to the same outcomes; failures are reported, not fatal."""

from __future__ import annotations

import math

import pytest

from sot_apps.pipeline.executors import ExecutorSpec, Task, run_tasks


def _tasks() -> list[Task]:
    return [Task(f"sqrt/{v}", math.sqrt, (v,)) for v in (4.0, 9.0, -1.0, 16.0)]


def _summary(outcomes):
    return [(o.key, o.ok, o.result, (o.error or "").split(":")[0]) for o in outcomes]


@pytest.mark.parametrize("spec", [ExecutorSpec("inline"), ExecutorSpec("local", workers=2)])
def test_local_executor_reports_failures_and_keeps_order(spec):
    outcomes = run_tasks(_tasks(), spec, progress=False)
    assert _summary(outcomes) == [
        ("sqrt/4.0", True, 2.0, ""), ("sqrt/9.0", True, 3.0, ""),
        ("sqrt/-1.0", False, None, "ValueError"), ("sqrt/16.0", True, 4.0, ""),
    ]
    assert "math domain error" in outcomes[2].error


@pytest.mark.slow
def test_dask_local_cluster_matches_local():
    local = run_tasks(_tasks(), ExecutorSpec("local", workers=2), progress=False)
    dask = run_tasks(_tasks(), ExecutorSpec("dask", workers=2), progress=False)
    assert _summary(dask) == _summary(local)


@pytest.mark.slow
def test_dask_workers_open_each_sequence_once(tiny_worlds, tmp_path):
    """The worker-local cache: every Dask worker opens the sequence once, before the first batch, and the tracking
    tasks reuse it (nothing is re-opened between tasks or stages)."""
    from sot_apps.pipeline.config import PipelineConfig
    from sot_apps.pipeline.executors import ExecutorSession
    from sot_apps.pipeline.plan import worker_cache_info
    from sot_apps.pipeline.runner import run_pipeline

    doc = {"version": 1, "out": str(tmp_path / "out"),
           "sequences": [{"path": str(tiny_worlds[0]), "objects": {"from": "annotations",
                                                                   "track_ids": ["veh_000", "veh_001", "veh_002"]}}],
           "stages": {name: {"enabled": False} for name in ("bank", "motion", "flow", "scans")}}
    spec = ExecutorSpec("dask", workers=2)
    with ExecutorSession(spec) as session:
        result = run_pipeline(PipelineConfig.from_json(doc), spec, progress=False, session=session)
        assert len(result.by_stage("track")) == 3 and not result.failed
        infos = session.on_every_worker(worker_cache_info)
    assert len(infos) == 2 and len({i["pid"] for i in infos}) == 2
    for info in infos:
        assert info["opened"] == 1                      # opened once, when the runner filled the cache
    assert sum(info["reused"] for info in infos) >= 3   # every tracking task reused it


def test_prestart_workers_start_with_the_named_modules_loaded():
    """``ExecutorSession.prestart``: the local workers (forked from multiprocessing's fork server, which prestart
    starts importing the named modules) have those modules loaded before their first task, without importing
    them; the batch runs on them. In a fresh process: the fork server is one per process."""
    import json
    import multiprocessing
    import os
    import subprocess
    import sys
    from pathlib import Path

    # the local executor forks its workers from this server on the platforms the project installs on (Linux)
    assert "forkserver" in multiprocessing.get_all_start_methods()
    script = """
import json, os, sys
from sot_apps.pipeline.executors import ExecutorSession, ExecutorSpec, Task
from tests.pipeline.preload_probe import loaded
with ExecutorSession(ExecutorSpec("local", workers=2)) as session:
    session.prestart(("colorsys",))
    outcomes = session.run([Task(f"probe/{i}", loaded, ("colorsys",)) for i in range(4)], progress=False)
print(json.dumps({"main": os.getpid(), "main_loaded": "colorsys" in sys.modules,
                  "results": [o.result for o in outcomes]}))
"""
    root = Path(__file__).resolve().parents[2]
    run = subprocess.run([sys.executable, "-c", script], cwd=root, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONPATH": str(root)})
    assert run.returncode == 0, run.stderr
    doc = json.loads(run.stdout.strip().splitlines()[-1])
    assert not doc["main_loaded"]                                  # the run itself never imported it
    results = doc["results"]
    assert len(results) == 4 and all(r[0] for r in results)      # every worker had it before its task
    assert 1 <= len({r[1] for r in results}) <= 2                  # at most the 2 workers ran the batch
    assert all(r[1] != doc["main"] and r[2] != doc["main"] for r in results)   # forked from the server


def test_a_warmed_fork_server_hands_its_workers_the_opened_sequences(tiny_worlds):
    """``prestart(..., environ=warm_environment(sources))`` (as ``sot-apps run``): the fork server opens the
    sequences once and freezes its objects out of the garbage collector (:mod:`sot_apps.pipeline.warm`); every
    worker forked from it finds them in its sequence cache (its first opening is a cache hit), and the variable is
    consumed by the server. Without the variable nothing is opened. In a fresh process: one server per process."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    script = """
import json, sys
from sot_apps.pipeline.executors import ExecutorSession, ExecutorSpec, Task
from sot_apps.pipeline.warm import warm_environment
from tests.pipeline.preload_probe import sequence_cache
path, warm = sys.argv[1], sys.argv[2] == "warm"
with ExecutorSession(ExecutorSpec("local", workers=2)) as session:
    session.prestart(("sot_apps.pipeline.warm",), environ=warm_environment([(path, None)]) if warm else None)
    outcomes = session.run([Task(f"probe/{i}", sequence_cache, (path,)) for i in range(4)], progress=False)
print(json.dumps([o.result for o in outcomes]))
"""
    root = Path(__file__).resolve().parents[2]
    for warm in ("warm", "cold"):
        run = subprocess.run([sys.executable, "-c", script, str(tiny_worlds[0]), warm], cwd=root, capture_output=True,
                             text=True, timeout=300, env={**os.environ, "PYTHONPATH": str(root)})
        assert run.returncode == 0, run.stderr
        results = json.loads(run.stdout.strip().splitlines()[-1])
        first = {}
        for r in results:   # each worker's first task
            first.setdefault(r["pid"], r)
        assert all(r["variable"] is None for r in results)
        if warm == "warm":
            assert all(r["held"] == 1 and r["hit"] and r["frozen"] > 0 for r in first.values())
        else:
            assert all(r["held"] == 0 and not r["hit"] and r["frozen"] == 0 for r in first.values())


def test_pipeline_sequences_reads_the_sequences_load_config_reads():
    """The warm-up's reading of a pipeline file (json only) names the sequences, paths resolved as
    :func:`~sot_apps.pipeline.config.load_config` resolves them, for every example pipeline; an unreadable file
    names none."""
    from pathlib import Path

    from sot_apps.pipeline.config import load_config
    from sot_apps.pipeline.warm import pipeline_sequences

    examples = sorted((Path(__file__).resolve().parents[2] / "examples").glob("pipeline*.json"))
    assert examples
    for example in examples:
        expected = [(s.path, s.format) for s in load_config(example).sequences]
        assert pipeline_sequences(example) == expected and expected
    assert pipeline_sequences(examples[0].parent / "missing.json") == []


def test_the_server_opens_only_the_sequences_of_a_run_of_few():
    """More sequences than ``WARM_MAX_SEQUENCES``: the server opens none (each worker opens its own tasks' ones),
    and still freezes its objects."""
    import json

    from sot_apps.pipeline.warm import WARM_MAX_SEQUENCES, WARM_VARIABLE, warm_environment

    few = [(f"/data/s{i}", None) for i in range(WARM_MAX_SEQUENCES)]
    assert json.loads(warm_environment(few)[WARM_VARIABLE]) == [[p, f] for p, f in few]
    assert json.loads(warm_environment(few + [("/data/more", "kitti")])[WARM_VARIABLE]) == []


def test_prestart_starts_nothing_inline():
    import multiprocessing

    from sot_apps.pipeline.executors import ExecutorSession

    before = set(multiprocessing.active_children())
    with ExecutorSession(ExecutorSpec("inline")) as session:
        session.prestart(("json",))   # nothing to start
        assert set(multiprocessing.active_children()) == before


@pytest.mark.slow
def test_dask_prestart_creates_the_cluster_the_first_batch_runs_on(monkeypatch):
    """``prestart`` with a Dask LocalCluster spec creates the cluster on a thread while this process goes on; the
    first batch runs on that cluster (no second one is created), and it is closed with the session. A session
    closed before any batch closes the cluster prestart created (nothing left running)."""
    from distributed.core import Status
    from distributed.deploy.spec import SpecCluster

    from sot_apps.pipeline.executors import ExecutorSession

    monkeypatch.setattr(SpecCluster, "_instances", set(SpecCluster._instances))   # kept after they are closed
    before = set(SpecCluster._instances)
    with ExecutorSession(ExecutorSpec("dask", workers=1)) as session:
        session.prestart(())
        outcomes = session.run(_tasks(), progress=False)
        created = set(SpecCluster._instances) - before
        assert len(created) == 1
        (cluster,) = created
        assert len(cluster.workers) == 1
    assert _summary(outcomes) == _summary(run_tasks(_tasks(), ExecutorSpec("inline"), progress=False))
    assert cluster.status == Status.closed

    before = set(SpecCluster._instances)
    with ExecutorSession(ExecutorSpec("dask", workers=1)) as session:
        session.prestart(())
    unused = set(SpecCluster._instances) - before
    assert len(unused) == 1 and all(c.status == Status.closed for c in unused)


def test_a_session_closed_by_ctrl_c_during_the_cluster_start_logs_nothing_more():
    """Seen in CI: ``sot-apps run --dask-local 2`` interrupted while prestart's thread created the LocalCluster; the
    scheduler logged 'Registering Worker plugin shuffle' (INFO) after the command's 'interrupted' line."""
    import logging

    from sot_apps.pipeline.executors import ExecutorSession

    names = ["distributed", *(n for n in logging.root.manager.loggerDict if n.startswith("distributed"))]
    levels = {name: logging.getLogger(name).level for name in names}
    try:
        session = ExecutorSession(ExecutorSpec("dask", workers=1))
        session.prestart(())
        session.close(wait=False)   # as after a Ctrl-C: the start may still be under way
        for name in [*names, "distributed.scheduler", "distributed.nanny", "distributed.core"]:
            assert not logging.getLogger(name).isEnabledFor(logging.WARNING), name
    finally:
        for name, level in levels.items():
            logging.getLogger(name).setLevel(level)


_WORKER_CTRL_C_IN_A_CALLBACK = """
import signal, sys, time, weakref
from sot_apps.pipeline import executors

executors._worker_init()
executors._task_running = True      # as inside _call

class Key:
    pass

class Broken:
    def __del__(self):
        raise ValueError("not an interrupt")

table = weakref.WeakKeyDictionary()
key = Key()
table[key] = 1
weakref.finalize(key, signal.raise_signal, signal.SIGINT)   # Ctrl-C while a weakref callback runs
try:
    Broken()        # an ordinary unraisable error: still printed as Python prints it
    del key         # the callback runs here: Python cannot raise in it
    print("callback done", flush=True)
    time.sleep(2.0)
    print("the task went on")
except KeyboardInterrupt:
    print("task interrupted")
"""


def test_a_worker_ctrl_c_landing_in_a_weakref_callback_is_delivered_again(tmp_path):
    """A pool worker's Ctrl-C handler raising inside a weakref callback (seen once in CI: "Exception ignored in
    ... WeakKeyDictionary ... remove", printed by the worker, and the task went on) is printed as nothing and
    delivered again in ordinary code: the running task stops."""
    import subprocess
    import sys

    script = tmp_path / "worker_ctrl_c.py"
    script.write_text(_WORKER_CTRL_C_IN_A_CALLBACK)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    assert done.stdout.split("\n")[:2] == ["callback done", "task interrupted"], done.stdout + done.stderr
    assert "KeyboardInterrupt" not in done.stderr
    assert "ValueError: not an interrupt" in done.stderr
