"""Run independent tasks locally (processes) or on Dask, through one code path.

A task is a picklable :class:`Task` (a key naming its sequence/object, a top-level function and its
keyword arguments). :func:`run_tasks` runs them, shows a progress bar, and returns one
:class:`TaskOutcome` per task: a failure is recorded with its key and error and never stops the others.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
import traceback
import uuid
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Callable, Iterable, Iterator, Mapping

from ..interrupts import deferred_interrupt, sigint_ignored_in_children

if TYPE_CHECKING:
    from tqdm import tqdm

__all__ = ["Task", "TaskOutcome", "ExecutorSpec", "ExecutorSession", "run_tasks"]


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
    environment: bool = False   # failed because an output could not be written (full disk, read-only, ...)


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


_task_running = False   # in a worker process: whether a task is running (see _worker_sigint)
_stop_event = None      # in a worker process: set by the parent after Ctrl-C (see _worker_init)
_interrupted = False    # in a worker process: it received a Ctrl-C (see _worker_sigint)
_task_threads: set[int] = set()   # in a worker: the threads running a task (see _interrupt_running_tasks)
_other_unraisable_hook = sys.unraisablehook   # in a worker: the hook _worker_init replaced (every other exception)


def _call(task: Task) -> TaskOutcome:
    """Run a task, turning any exception into a failed outcome (runs in the worker)."""
    global _task_running
    start = time.perf_counter()
    if _interrupted or (_stop_event is not None and _stop_event.is_set()):
        raise KeyboardInterrupt   # handed to this worker before the Ctrl-C (or its signal was missed): not run
    try:
        _task_running = True
        _task_threads.add(threading.get_ident())
        try:
            result = task.fn(*task.args, **task.kwargs)
        finally:
            _task_running = False
            _task_threads.discard(threading.get_ident())
        return TaskOutcome(task.key, True, result=result, seconds=time.perf_counter() - start)
    except BaseException as exc:  # noqa: BLE001 - a worker must report, not die
        if isinstance(exc, KeyboardInterrupt):
            raise
        from ..errors import OutputError
        from ..io.atomic import is_environment_error

        seconds = time.perf_counter() - start
        if isinstance(exc, OutputError):
            return TaskOutcome(task.key, False, error=exc.one_line(), seconds=seconds, environment=True)
        message = " ".join(str(exc).split()) or type(exc).__name__
        detail = traceback.format_exc(limit=8) if os.environ.get("SOT_APPS_DEBUG") == "1" else ""
        return TaskOutcome(task.key, False, error=f"{type(exc).__name__}: {message}{detail}", seconds=seconds,
                           environment=is_environment_error(exc))


def _import_modules(modules: tuple[str, ...]) -> int:
    """A warm-up task (:meth:`ExecutorSession.prestart`): import ``modules`` in this worker."""
    import importlib

    for name in modules:
        importlib.import_module(name)
    return os.getpid()


def _worker_sigint(signum, frame) -> None:
    """Ctrl-C in a worker process: stop the running task (its atomic writes clean up; the pool hands the
    KeyboardInterrupt back to the parent, which reports the interrupt once); an idle worker only remembers it and
    starts no task any more (the parent is stopping)."""
    global _interrupted
    _interrupted = True
    if _task_running:
        raise KeyboardInterrupt


def _worker_redeliver_interrupt(unraisable) -> None:
    """``sys.unraisablehook`` in a pool worker. A Ctrl-C whose handler raised inside code where Python cannot raise
    (a weakref callback, a finalizer: seen once in CI, printed as "Exception ignored ..." and lost, the task going
    on) is printed as nothing and delivered again 10 ms later (SIGALRM -> :func:`_worker_sigint`), in ordinary
    code. Without timers (Windows) the worker has remembered it and starts no further task. Any other unraisable
    exception is printed as Python prints it."""
    if unraisable.exc_type is not None and issubclass(unraisable.exc_type, KeyboardInterrupt):
        if hasattr(signal, "setitimer"):
            signal.setitimer(signal.ITIMER_REAL, 0.01)
        return
    _other_unraisable_hook(unraisable)


class TaskInterrupted(Exception):
    """Raised inside a Dask worker's running task after the client's Ctrl-C (an Exception, not a
    KeyboardInterrupt: Dask logs a BaseException escaping a task as an unhandled error)."""


def _interrupt_running_tasks() -> int:
    """In a Dask worker (whose SIGINT is ignored), after the client's Ctrl-C: raise :class:`TaskInterrupted` in the
    threads running a task, so that the task stops at once and its atomic writes clean up (Dask cannot stop a
    running task; closing the cluster would wait for it, then kill the worker and leave its temporary files). The
    worker's Dask log is quietened: the cancellations that follow are expected."""
    import ctypes
    import sys

    _quieten_dask_logs()
    other_hook = sys.unraisablehook

    def hook(unraisable):   # landed in a finalizer or gc callback: dropped there; the caller sends it again
        if unraisable.exc_type is None or not issubclass(unraisable.exc_type, TaskInterrupted):
            other_hook(unraisable)

    sys.unraisablehook = hook
    for ident in list(_task_threads):
        ctypes.pythonapi.PyThreadState_SetAsyncExc(ctypes.c_ulong(ident), ctypes.py_object(TaskInterrupted))
    return len(_task_threads)


def _quieten_dask_logs() -> None:
    """After Ctrl-C, Dask logs the cancellations and the closing connections it causes: expected, not news."""
    import logging

    for name in ["distributed", *logging.root.manager.loggerDict]:
        if name.startswith("distributed"):
            logging.getLogger(name).setLevel(logging.CRITICAL)


def _worker_init(stop_event=None) -> None:
    global _stop_event, _other_unraisable_hook
    _single_threaded_env()
    _stop_event = stop_event
    signal.signal(signal.SIGINT, _worker_sigint)
    if hasattr(signal, "SIGALRM"):
        signal.signal(signal.SIGALRM, _worker_sigint)
    if sys.unraisablehook is not _worker_redeliver_interrupt:
        _other_unraisable_hook, sys.unraisablehook = sys.unraisablehook, _worker_redeliver_interrupt


_THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


@contextlib.contextmanager
def _children_environment(environ: Mapping[str, str] | None = None) -> Iterator[None]:
    """Processes started in the block get the thread variables of :func:`_single_threaded_env` (unless this
    process sets them) and ``environ``: this process's own environment is left as it was afterwards."""
    environ = dict(environ or {})
    saved = {var: os.environ.get(var) for var in (*_THREAD_VARIABLES, *environ)}
    _single_threaded_env()
    os.environ.update(environ)
    try:
        yield
    finally:
        for var, value in saved.items():
            if value is None:
                os.environ.pop(var, None)
            else:
                os.environ[var] = value


# when this process started its fork server: (its CPU seconds, unix time) then (pipeline.accounting: start-up path)
forkserver_started: tuple[float, float] | None = None


def _start_forkserver(modules: Iterable[str] = (), environ: Mapping[str, str] | None = None) -> bool:
    """Start multiprocessing's fork server (once per process) importing ``modules`` besides its own preload list,
    with SIGINT ignored (inherited by every process it forks: a Ctrl-C while a worker starts prints nothing),
    single-threaded BLAS/OpenMP and ``environ`` in its environment (read by the modules it imports, e.g.
    :mod:`sot_apps.pipeline.warm`). Returns immediately: the server imports in the background, and the processes
    forked from it start with those modules loaded (no interpreter start-up, no imports). False without fork
    servers (Windows). A server already running keeps the preload list and environment it was started with."""
    import multiprocessing
    import multiprocessing.forkserver

    global forkserver_started
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return False
    server = multiprocessing.forkserver._forkserver
    if not getattr(server, "_forkserver_pid", None):
        forkserver_started = time.process_time(), time.time()
        preload = list(getattr(server, "_preload_modules", None) or ["__main__"])
        preload += [m for m in modules if m not in preload]
        server.set_forkserver_preload(preload)
        with sigint_ignored_in_children(), _children_environment(environ):
            multiprocessing.forkserver.ensure_running()
    return True


@contextlib.contextmanager
def _forkserver_method(modules: Iterable[str] = (), environ: Mapping[str, str] | None = None) -> Iterator[None]:
    """Dask's workers forked from multiprocessing's fork server, started with SIGINT ignored.

    Spawned workers (Dask's default) start a fresh interpreter that installs Python's KeyboardInterrupt handler:
    a Ctrl-C in their first ~0.1-1 s (start-up, before they import sot_apps.cli.main, which ignores it) printed a
    traceback, or "Fatal Python error: init_import_site". An ignored signal stays ignored across fork and exec:
    the fork server is started here (this process ignores Ctrl-C only during that fork and exec) and forks every
    worker with SIGINT ignored from its first instruction. Without fork servers (Windows), Dask spawns as before;
    if this process already runs a fork server started otherwise, its workers keep its handler."""
    import multiprocessing

    if "forkserver" not in multiprocessing.get_all_start_methods():
        yield
        return
    import dask
    from distributed.utils import get_mp_context

    with dask.config.set({"distributed.worker.multiprocessing-method": "forkserver"}):
        if _start_forkserver(("distributed", *modules), environ):   # distributed and the toolkit preloaded (prestart)
            import distributed.utils

            # Dask's own preload list (get_mp_context) would import pandas and lz4 into this process at the first
            # worker's start, ~0.5 s of CPU the tasks do not need; the server runs already, so that list is moot
            if hasattr(distributed.utils, "_forkserver_preload_set"):
                distributed.utils._forkserver_preload_set = True
        get_mp_context()
        yield


def _in_thread(fn: Callable[[], Any], name: str) -> Future:
    """``fn()`` on a daemon thread; its result (or exception) in the returned future."""
    future: Future = Future()

    def target() -> None:
        try:
            future.set_result(fn())
        except BaseException as exc:  # noqa: BLE001 - handed to whoever takes the result
            future.set_exception(exc)

    threading.Thread(target=target, name=name, daemon=True).start()
    return future


# Our LocalCluster's settings (its nannies hand them to the workers): Dask's statistical profiler samples the running
# task's stack every 10 ms (it took the GIL from the task: +16 % task CPU measured with 2 workers), and the event
# loops' latency tick (every 20 ms) and memory monitors (every 100 ms) wake the scheduler, the nannies (all in this
# process) and every worker many times a second beside the tasks. A cluster given by address keeps its own settings.
LOCAL_DASK_CONFIG = {"distributed.worker.profile.enabled": False, "distributed.admin.tick.interval": "1s",
                     "distributed.worker.memory.monitor-interval": "1s",
                     "distributed.admin.system-monitor.interval": "2s"}


def _progress(total: int, desc: str, enabled: bool) -> tqdm:
    from tqdm import tqdm  # imported when a batch runs: `sot-apps run` starts its fork server before this import

    return tqdm(total=total, desc=desc, unit="task", disable=not enabled, dynamic_ncols=True, leave=False)


class ExecutorSession:
    """A pool (processes or a Dask client) kept open for several batches of tasks.

    ``with ExecutorSession(spec) as session: session.run(tasks, desc)``; :func:`run_tasks` is a one-batch session.
    Starting worker processes costs seconds (each imports the toolkit), so a pipeline opens one session for
    all its stages.
    """

    def __init__(self, spec: ExecutorSpec = ExecutorSpec()) -> None:
        self.spec = spec
        self._pool: ProcessPoolExecutor | None = None
        self._preload: tuple[str, ...] = ()   # modules the workers import before their first task (prestart)
        self._environ: dict[str, str] = {}     # ... and the fork server's environment variables (prestart)
        self._stop_event = None
        self._client = None
        self._cluster = None
        self._cluster_start: Future | None = None   # a LocalCluster being created on a thread (prestart)

    def __enter__(self) -> "ExecutorSession":
        return self

    def __exit__(self, exc_type, *exc) -> None:
        self.close(wait=exc_type is None)

    def close(self, wait: bool = True) -> None:
        """Shut the pool down; ``wait=False`` (after Ctrl-C) cancels queued tasks, tells the workers not to start the
        ones already handed to them, and stops the workers (:func:`sot_apps.interrupts.stop_process_pool`)."""
        if not wait and (self._client is not None or self._cluster is not None or self._cluster_start is not None):
            # Ctrl-C: what Dask logs while it stops (cancellations, closing connections, a cluster start still
            # registering its workers) is expected, and must not follow the command's last line
            _quieten_dask_logs()
        if self._pool is not None:
            if wait:
                self._pool.shutdown(wait=True, cancel_futures=True)
            else:
                from ..interrupts import stop_process_pool

                if self._stop_event is not None:
                    self._stop_event.set()
                stop_process_pool(self._pool)
            self._pool = None
        if self._client is not None:
            if not wait and self._cluster is not None:   # Ctrl-C: stop our own workers' running tasks, quietly
                self._interrupt_dask_tasks()
            self._client.close()
            self._client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None
        if self._cluster_start is not None:   # started by prestart, never used (the run stopped before its tasks)
            start, self._cluster_start = self._cluster_start, None
            # after a Ctrl-C, a start that does not end within a minute is left to its daemon thread: exiting beats
            # waiting for ever on a thread that cannot go on
            with deferred_interrupt(), contextlib.suppress(Exception):
                start.result(timeout=None if wait else 60.0).close()

    def _interrupt_dask_tasks(self) -> None:
        with contextlib.suppress(Exception):
            for _ in range(20):   # again while a task still runs (the exception can land where it is dropped)
                if not sum(self._client.run(_interrupt_running_tasks).values()):
                    break
                time.sleep(0.1)

    def run(self, tasks: Iterable[Task], desc: str = "tasks", progress: bool = True) -> list[TaskOutcome]:
        """Run ``tasks``; outcomes come back in the order of ``tasks``."""
        tasks = list(tasks)
        if not tasks:
            return []
        spec = self.spec
        if spec.kind == "inline" or (spec.kind == "local" and spec.workers <= 1):
            outcomes = []
            with _progress(len(tasks), desc, progress) as bar:
                for task in tasks:
                    outcomes.append(_call(task))
                    bar.update(1)
            return outcomes
        if spec.kind == "local":
            return self._run_processes(tasks, desc, progress)
        if spec.kind == "dask":
            return self._run_dask(tasks, desc, progress)
        raise ValueError(f"unknown executor kind {spec.kind!r}")

    def prestart(self, modules: Iterable[str] = (), cluster: bool = True,
                 environ: Mapping[str, str] | None = None) -> None:
        """Prepare the workers now, without waiting for them, so that their start-up overlaps with what this
        process does before its first batch (planning). Local processes: where the platform has fork servers,
        start multiprocessing's fork server importing ``modules`` (once; every worker is then forked from it with
        them loaded, in milliseconds, instead of a fresh interpreter importing the toolkit, ~0.6-1 s of CPU
        each); else start the spawned workers now, each importing ``modules``. A Dask LocalCluster forks its
        workers from the same server (``modules`` preloaded); with ``cluster`` it is created now on a thread of
        this process (its scheduler and nannies live here) while this process goes on planning, and the first
        batch takes it (``cluster=False``: only the fork server; ``sot-apps run`` starts the cluster once its
        pipeline file is read, so that a bad file is reported at once). ``environ``: variables set in the fork
        server's environment (``sot-apps run`` names its sequences there, for :mod:`sot_apps.pipeline.warm`).
        Nothing for inline runs."""
        spec = self.spec
        self._preload = tuple(modules)
        self._environ = dict(environ or {})
        if spec.kind == "dask" and not spec.address:
            # the cluster's workers are forked from this fork server, which imports Dask's worker and ``modules``
            _start_forkserver(("distributed", *self._preload), self._environ)
            if cluster and self._cluster is None and self._cluster_start is None:
                self._cluster_start = _in_thread(self._start_local_cluster, "dask-cluster-start")
            return
        if spec.kind != "local" or spec.workers <= 1 or self._pool is not None:
            return
        if _start_forkserver(self._preload, self._environ):
            return   # the pool forks its workers from the server at the first batch
        with sigint_ignored_in_children():   # submit() starts the worker processes
            pool = self._process_pool()
            for _ in range(spec.workers):
                pool.submit(_import_modules, tuple(modules))

    def worker_count(self) -> int:
        """How many tasks can run at once: the local workers, or the Dask cluster's workers now."""
        spec = self.spec
        if spec.kind == "dask":
            return max(1, len(self._dask_client().scheduler_info().get("workers", {})))
        return 1 if spec.kind == "inline" else max(1, spec.workers)

    def on_every_worker(self, fn: Callable[..., Any], *args: Any) -> list[Any]:
        """Run ``fn(*args)`` once in every worker, e.g. to fill its worker-local caches before a batch; returns
        one result per worker reached. Dask: every worker of the client (``Client.run``); inline: this process;
        local process pools cannot address their workers (none: each fills its cache at its first task)."""
        spec = self.spec
        if spec.kind == "inline" or (spec.kind == "local" and spec.workers <= 1):
            return [fn(*args)]
        if spec.kind == "dask":
            return list(self._dask_client().run(fn, *args).values())
        return []

    # ------------------------------------------------------------------ local processes
    def _process_pool(self) -> ProcessPoolExecutor:
        if self._pool is None:
            import multiprocessing

            # forked from the fork server (started by prestart, else here) with the toolkit loaded; else spawned
            method = "forkserver" if _start_forkserver(self._preload, self._environ) else "spawn"
            context = multiprocessing.get_context(method)
            self._stop_event = context.Event()
            self._pool = ProcessPoolExecutor(max_workers=self.spec.workers, mp_context=context,
                                             initializer=_worker_init, initargs=(self._stop_event,))
        return self._pool

    def _run_processes(self, tasks: list[Task], desc: str, progress: bool) -> list[TaskOutcome]:
        from concurrent.futures.process import BrokenProcessPool

        outcomes: dict[int, TaskOutcome] = {}
        broken = False
        try:
            with sigint_ignored_in_children():   # submit() starts the worker processes
                pool = self._process_pool()
                pending: dict[Future, int] = {pool.submit(_call, task): i for i, task in enumerate(tasks)}
            with _progress(len(tasks), desc, progress) as bar:
                while pending:
                    done, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for future in done:
                        i = pending.pop(future)
                        try:
                            outcomes[i] = future.result()
                        except BrokenProcessPool as exc:
                            broken = True
                            outcomes[i] = TaskOutcome(tasks[i].key, False, error=f"{type(exc).__name__}: {exc}")
                        except KeyboardInterrupt:
                            raise   # the Ctrl-C reached the worker first: the run is interrupted, not the task failed
                        except BaseException as exc:  # noqa: BLE001 - e.g. an unpicklable result
                            outcomes[i] = TaskOutcome(tasks[i].key, False, error=f"{type(exc).__name__}: {exc}")
                        bar.update(1)
        except BaseException:
            self.close(wait=False)   # Ctrl-C: cancel what is queued; workers get the same SIGINT, stop their task
            raise
        if broken:   # a worker died (e.g. killed): the next batch gets a fresh pool
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        return [outcomes[i] for i in range(len(tasks))]

    # ------------------------------------------------------------------ dask
    def _dask_client(self):
        if self._client is None:
            try:
                from distributed import Client
            except ImportError as exc:  # pragma: no cover - depends on the optional extra
                raise RuntimeError("the Dask executor needs the 'dist' extra: pip install 'sot-apps[dist]'") from exc
            if self.spec.address:
                self._client = Client(self.spec.address)
            else:
                # a Ctrl-C while the cluster starts is held and delivered once it stands (the session's close
                # then stops it; ignoring it lost the Ctrl-C for seconds); the workers ignore SIGINT from their
                # first instruction on (_forkserver_method) and keep it so (asyncio installs no handler over an
                # ignored signal), so they print nothing of their own
                with deferred_interrupt():
                    if self._cluster_start is not None:   # prestart's, created meanwhile
                        start, self._cluster_start = self._cluster_start, None
                        self._cluster = start.result()
                    else:
                        self._cluster = self._start_local_cluster()
                self._client = Client(self._cluster)
            self._client.run(_single_threaded_env)
        return self._client

    def _start_local_cluster(self):
        import dask
        from distributed import LocalCluster

        with _forkserver_method(self._preload, self._environ), dask.config.set(LOCAL_DASK_CONFIG):
            return LocalCluster(n_workers=max(1, self.spec.workers), threads_per_worker=1, processes=True,
                                dashboard_address=None, worker_dashboard_address=None,
                                # no dashboard; its HTTP server (health, metrics) on a free port instead of 8787,
                                # which another cluster may hold (a warning)
                                scheduler_kwargs={"dashboard_address": ":0"})

    def _run_dask(self, tasks: list[Task], desc: str, progress: bool) -> list[TaskOutcome]:
        from distributed import as_completed

        client = self._dask_client()
        # Dynamic scheduling in the given order (the tracking chunks come costliest first): as many tasks in flight as
        # the cluster has threads, the next one submitted as one finishes. Submitting all at once let the scheduler
        # hand each single-threaded worker 2 tasks (worker-saturation 1.1), and a worker that finished early then
        # idled while another still held a queued task (its duration unknown, Dask does not steal it).
        slots = max(1, sum(int(w.get("nthreads", 1)) for w in client.scheduler_info().get("workers", {}).values()))
        pending = iter(enumerate(tasks))
        futures: list = []
        index: dict[str, int] = {}
        running = as_completed()

        def submit_next() -> None:
            for i, task in pending:
                future = client.submit(_call, task, key=f"{task.key}-{uuid.uuid4().hex[:8]}", pure=False,
                                       priority=len(tasks) - i)
                index[future.key] = i
                futures.append(future)
                running.add(future)
                return

        outcomes: list[TaskOutcome | None] = [None] * len(tasks)
        try:
            for _ in range(slots):
                submit_next()
            with _progress(len(tasks), desc, progress) as bar:
                for future in running:
                    submit_next()
                    i = index[future.key]
                    try:
                        outcomes[i] = future.result()
                    except KeyboardInterrupt:
                        raise   # Ctrl-C while this process waited for the result: the run is interrupted
                    except BaseException as exc:  # noqa: BLE001 - a lost worker
                        outcomes[i] = TaskOutcome(tasks[i].key, False, error=f"{type(exc).__name__}: {exc}")
                    bar.update(1)
        except BaseException:
            with contextlib.suppress(Exception):
                client.cancel(futures)
            self.close(wait=False)
            raise
        return [o for o in outcomes if o is not None]


def run_tasks(tasks: Iterable[Task], spec: ExecutorSpec = ExecutorSpec(), desc: str = "tasks",
              progress: bool = True) -> list[TaskOutcome]:
    """Run ``tasks`` in a one-batch :class:`ExecutorSession`; outcomes come back in the order of ``tasks``."""
    with ExecutorSession(spec) as session:
        return session.run(tasks, desc, progress)
