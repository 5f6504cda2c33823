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
