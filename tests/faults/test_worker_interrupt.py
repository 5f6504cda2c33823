"""Issue 16 defect 4: Ctrl-C while a local worker pool has an idle worker printed that worker's
``KeyboardInterrupt`` traceback. Workers now leave SIGINT to the parent (which prints one line, exit 130)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

# the scripts below run from a temporary directory: they import this checkout's code
ENV = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}

SCRIPT = textwrap.dedent("""
    import sys, time
    from sot_apps.pipeline.executors import ExecutorSession, ExecutorSpec, Task

    def main():
        with ExecutorSession(ExecutorSpec("local", workers=2)) as session:
            session.run([Task("warm/0", time.sleep, (0.1,)), Task("warm/1", time.sleep, (0.1,))], progress=False)
            print("ready", flush=True)
            session.run([Task("slow", time.sleep, (30,))], progress=False)   # one worker busy, one idle

    if __name__ == "__main__":
        try:
            main()
        except KeyboardInterrupt:
            sys.stderr.write("interrupted\\n")
            sys.exit(130)
""")


def test_sigint_to_the_group_with_an_idle_worker_prints_no_traceback(tmp_path):
    script = tmp_path / "pool.py"
    script.write_text(SCRIPT)
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=ENV)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(1.0)
        os.killpg(proc.pid, signal.SIGINT)
        start = time.perf_counter()
        _, stderr = proc.communicate(timeout=60)
        waited = time.perf_counter() - start
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr
    assert stderr.strip() == "interrupted", stderr
    assert waited < 20, f"the busy worker was not stopped ({waited:.1f} s)"


QUEUED = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from sot_apps.pipeline.executors import ExecutorSession, ExecutorSpec, Task

    def touch(path):
        Path(path).write_text("ran")

    def main(marker):
        with ExecutorSession(ExecutorSpec("local", workers=2)) as session:
            session.run([Task("warm/0", time.sleep, (0.1,)), Task("warm/1", time.sleep, (0.1,))], progress=False)
            print("ready", flush=True)
            # both workers busy; the third task is already handed to the pool's call queue
            session.run([Task("slow/0", time.sleep, (30,)), Task("slow/1", time.sleep, (30,)),
                         Task("after", touch, (marker,))], progress=False)

    if __name__ == "__main__":
        try:
            main(sys.argv[1])
        except KeyboardInterrupt:
            sys.stderr.write("interrupted\\n")
            sys.exit(130)
""")


def test_a_task_queued_before_ctrl_c_is_not_run(tmp_path):
    """Issue 26 item 11: after Ctrl-C a worker picked up the task already queued for it and ran it to the end
    (the exit waited seconds for it); now a worker that got the Ctrl-C, or was told by the parent, starts none."""
    script = tmp_path / "queued.py"
    script.write_text(QUEUED)
    marker = tmp_path / "after.txt"
    proc = subprocess.Popen([sys.executable, str(script), str(marker)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, env=ENV)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(1.5)
        os.killpg(proc.pid, signal.SIGINT)
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130 and stderr.strip() == "interrupted", stderr
    time.sleep(0.5)
    assert not marker.exists()


SPAWNED = textwrap.dedent("""
    import multiprocessing, signal, sys
    from sot_apps.cli import main as cli

    def probe(queue):
        queue.put((cli._AS_PROGRAM, signal.getsignal(signal.SIGINT) is cli._interrupted_while_starting))

    if __name__ == "__main__":
        context = multiprocessing.get_context("spawn")
        queue = context.Queue()
        child = context.Process(target=probe, args=(queue,))
        child.start()
        print(cli._AS_PROGRAM, queue.get(timeout=60))
        child.join()
""")


def test_spawned_workers_of_the_console_script_are_not_the_program(tmp_path):
    """Issue 26 item 11: worker processes spawned by the ``sot-apps`` console script import it again (as
    ``__mp_main__``, with the parent's argv); they installed the CLI's start-up Ctrl-C handler and each printed its
    own "interrupted" line."""
    script = tmp_path / "sot-apps"
    script.write_text(SPAWNED)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120, env=ENV)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "True (False, False)"


DASK_WORKERS = textwrap.dedent("""
    import os, signal, sys
    from sot_apps.pipeline.executors import ExecutorSession, ExecutorSpec

    def ignored(pid):   # SIGINT in the process's ignored-signal mask (/proc/PID/status SigIgn)
        line = next(l for l in open(f"/proc/{pid}/status") if l.startswith("SigIgn:"))
        return bool(int(line.split()[1], 16) & (1 << (signal.SIGINT - 1)))

    def probe():
        parent = open(f"/proc/{os.getppid()}/cmdline", "rb").read()
        return ignored(os.getpid()), b"forkserver" in parent, ignored(os.getppid())

    if __name__ == "__main__":
        with ExecutorSession(ExecutorSpec("dask", workers=2)) as session:
            print(sorted(session.on_every_worker(probe)), ignored(os.getpid()))
""")


def test_dask_workers_ignore_sigint_from_their_first_instruction(tmp_path):
    """Issue 26 gap: a Ctrl-C in a Dask worker's first ~0.1-1 s (interpreter start-up, before it imported
    sot_apps.cli.main) printed a KeyboardInterrupt traceback or "Fatal Python error: init_import_site". The
    workers are now forked by a fork server that was started with SIGINT ignored, so they ignore it from the
    start; the command itself still handles Ctrl-C."""
    script = tmp_path / "dask_workers.py"
    script.write_text(DASK_WORKERS)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, env=ENV,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[(True, True, True), (True, True, True)] False", done.stdout
