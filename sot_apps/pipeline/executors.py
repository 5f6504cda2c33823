"""Run independent tasks locally (processes) or on Dask, through one code path.

A task is a picklable :class:`Task` (a key naming its sequence/object, a top-level function and its
keyword arguments). :func:`run_tasks` runs them, shows a progress bar, and returns one
:class:`TaskOutcome` per task: a failure is recorded with its key and error and never stops the others.
"""

from __future__ import annotations

import os
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

from tqdm import tqdm

__all__ = ["Task", "TaskOutcome", "ExecutorSpec", "run_tasks"]


@dataclass(frozen=True)
class Task:
    """One unit of work. ``key`` names it in reports, e.g. ``"track/pandaset_002/8ac00bad"``."""

    key: str
    fn: Callable[..., Any]
    args: tuple = ()
    kwargs: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class TaskOutcome:
    key: str
    ok: bool
    result: Any = None
    error: str | None = None
    seconds: float = 0.0


@dataclass(frozen=True)
class ExecutorSpec:
    """Where tasks run: ``kind`` is "inline" (this process), "local" (processes) or "dask".

    For Dask, ``address`` is a scheduler (``tcp://HOST:PORT``) or None with ``workers`` for a LocalCluster.
    """

    kind: str = "local"
    workers: int = 1
    address: str | None = None

    def describe(self) -> str:
        if self.kind == "dask":
            return f"dask {self.address}" if self.address else f"dask LocalCluster({self.workers})"
        return f"{self.kind} ({self.workers} worker{'s' if self.workers != 1 else ''})"


def _single_threaded_env() -> None:
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")


def _call(task: Task) -> TaskOutcome:
    """Run a task, turning any exception into a failed outcome (runs in the worker)."""
    start = time.perf_counter()
    try:
        result = task.fn(*task.args, **task.kwargs)
        return TaskOutcome(task.key, True, result=result, seconds=time.perf_counter() - start)
    except BaseException as exc:  # noqa: BLE001 - a worker must report, not die
        if isinstance(exc, KeyboardInterrupt):
            raise
        message = " ".join(str(exc).split()) or type(exc).__name__
        detail = traceback.format_exc(limit=8) if os.environ.get("SOT_APPS_DEBUG") == "1" else ""
        return TaskOutcome(task.key, False, error=f"{type(exc).__name__}: {message}{detail}",
                           seconds=time.perf_counter() - start)


def _worker_init() -> None:
    _single_threaded_env()


def _progress(total: int, desc: str, enabled: bool) -> tqdm:
    return tqdm(total=total, desc=desc, unit="task", disable=not enabled, dynamic_ncols=True, leave=False)


def run_tasks(tasks: Iterable[Task], spec: ExecutorSpec = ExecutorSpec(), desc: str = "tasks",
              progress: bool = True) -> list[TaskOutcome]:
    """Run ``tasks``; outcomes come back in the order of ``tasks``."""
    tasks = list(tasks)
    if not tasks:
        return []
    if spec.kind == "inline" or (spec.kind == "local" and spec.workers <= 1):
        outcomes = []
        with _progress(len(tasks), desc, progress) as bar:
            for task in tasks:
                outcomes.append(_call(task))
                bar.update(1)
        return outcomes
    if spec.kind == "local":
        return _run_processes(tasks, spec.workers, desc, progress)
    if spec.kind == "dask":
        return _run_dask(tasks, spec, desc, progress)
    raise ValueError(f"unknown executor kind {spec.kind!r}")


def _run_processes(tasks: list[Task], workers: int, desc: str, progress: bool) -> list[TaskOutcome]:
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    outcomes: dict[str, TaskOutcome] = {}
    with ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_worker_init) as pool:
        pending: dict[Future, Task] = {pool.submit(_call, task): task for task in tasks}
        with _progress(len(tasks), desc, progress) as bar:
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    task = pending.pop(future)
                    try:
                        outcomes[task.key] = future.result()
                    except BaseException as exc:  # noqa: BLE001 - e.g. a worker process died
                        outcomes[task.key] = TaskOutcome(task.key, False, error=f"{type(exc).__name__}: {exc}")
                    bar.update(1)
    return [outcomes[t.key] for t in tasks]


def _run_dask(tasks: list[Task], spec: ExecutorSpec, desc: str, progress: bool) -> list[TaskOutcome]:
    try:
        from distributed import Client, LocalCluster, as_completed
    except ImportError as exc:  # pragma: no cover - depends on the optional extra
        raise RuntimeError("the Dask executor needs the 'dist' extra: pip install 'sot-apps[dist]'") from exc
    cluster = None
    if spec.address:
        client = Client(spec.address)
    else:
        cluster = LocalCluster(n_workers=max(1, spec.workers), threads_per_worker=1, processes=True,
                               dashboard_address=None)
        client = Client(cluster)
    try:
        client.run(_single_threaded_env)
        futures = client.map(_call, tasks, key=[f"{t.key}-{i}" for i, t in enumerate(tasks)], pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        outcomes: list[TaskOutcome | None] = [None] * len(tasks)
        with _progress(len(tasks), desc, progress) as bar:
            for future in as_completed(futures):
                i = index[future.key]
                try:
                    outcomes[i] = future.result()
                except BaseException as exc:  # noqa: BLE001 - a lost worker
                    outcomes[i] = TaskOutcome(tasks[i].key, False, error=f"{type(exc).__name__}: {exc}")
                bar.update(1)
        return [o for o in outcomes if o is not None]
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
