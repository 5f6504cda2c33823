"""Issue 16 defect 4: Ctrl-C while a local worker pool has an idle worker printed that worker's
``KeyboardInterrupt`` traceback. Workers now leave SIGINT to the parent (which prints one line, exit 130)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

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
                            start_new_session=True)
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
