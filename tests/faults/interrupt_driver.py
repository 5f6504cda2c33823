"""Interrupt trials: SIGINT into the process group of a CLI command at random times, then rerun.

For each command (``run`` with 2 local worker processes, ``run_dask`` with a Dask LocalCluster of 2, ``benchmark``:
``benchmark make --workers 2``, ``demo``, ``convert``, ``flow``, ``synth``): a clean run gives the reference outputs; then ``trials`` runs on one output directory are each
sent SIGINT at a random time (each resumes what the previous left; one that finishes before the signal is compared
with the clean run and the directory starts afresh), and a last run completes and is compared. Checked:
an interrupted run exits 130 with the one line "interrupted: ..." and nothing else on stderr (no worker's line, no
Dask log, no leaked-semaphore warning; or 0 when it finished before the signal, or dies of the signal without
output when it lands before Python installed its handler or after it removed it), no run prints a traceback, no
temporary file and no lock file is left, and the completed outputs equal the clean run byte for byte (files that
record run times or absolute paths aside). The seconds from the signal to the exit are recorded (printed, not
asserted: the machine may be loaded).

The test suite runs a few trials per command (tests/faults/test_interrupts.py); the issue's 20 trials per command:

    python tests/faults/interrupt_driver.py --trials 20 [--commands run demo convert flow synth] [--seed 0]
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

CLI = [sys.executable, "-m", "sot_apps.cli.main"]
_PROGRESS = re.compile(r"\d+%\||\d+/\d+ \[")   # tqdm redraws
COMMANDS = ("run", "run_dask", "benchmark", "demo", "convert", "flow", "synth")


def _argv(command: str, world: Path, out: Path, pipeline: Path) -> list[str]:
    return {
        "run": ["run", pipeline, "--workers", "2", "--quiet", "--out", out],
        "run_dask": ["run", pipeline, "--dask-local", "2", "--quiet", "--out", out],
        "benchmark": ["benchmark", "make", "--background", world, "--bank", world.parent / "bank", "--frames", "0:3",
                      "--tracklets", "4", "--per-copy", "1", "--workers", "2", "--sensor", "vlp16", "--range", "5:30",
                      "--bands", "15", "--quiet", "--out", out],
        "demo": ["demo", "--quick", "--quiet", "--out", out],
        "convert": ["convert", world, "--out", out],
        "flow": ["flow", world, "--from-annotations", "--camera", "front_camera", "--quiet", "--out", out],
        "synth": ["synth", "--frames", "3", "--vehicles", "2", "--sensor", "vlp16", "--cameras",
                  "--camera-size", "320x240", "--seed", "4", "--out", out],
    }[command]


def _timing_or_path_record(rel: str) -> bool:
    """Files that record run times or absolute paths (manifest, completion markers, report, flow stats/pairs)."""
    name = rel.rsplit("/", 1)[-1]
    return (rel.startswith((".done/", "report/")) or rel in ("manifest.json", "make.json")
            or name == "stats.json" or "/pairs/" in f"/{rel}")


def checksums(out: Path) -> dict[str, str]:
    return {p.relative_to(out).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(out.rglob("*")) if p.is_file() and not _timing_or_path_record(p.relative_to(out).as_posix())}


def pipeline_file(world: Path, root: Path) -> Path:
    path = root / "pipeline.json"
    path.write_text(json.dumps({
        "version": 1, "out": str(root / "unused"),
        "sequences": [{"path": str(world), "objects": {"from": "annotations", "track_ids": ["veh_000", "veh_001"]}}],
        "stages": {"bank": {"min_points": 0}, "flow": {"max_pairs": 2},
                   "scans": {"sensor": "vlp16", "max_entries": 1, "ranges_m": [20], "headings_deg": [0, 90]}}}))
    return path


@dataclass
class CommandResult:
    command: str
    clean_seconds: float
    delays: list[float] = field(default_factory=list)
    exit_codes: list[int] = field(default_factory=list)
    exit_seconds: list[float] = field(default_factory=list)   # from the signal to the exit, interrupted trials
    problems: list[str] = field(default_factory=list)
    handled: int = 0   # trials whose command caught the signal and printed its 'interrupted' line


    def line(self) -> str:
        interrupted = sum(c in (130, -signal.SIGINT) for c in self.exit_codes)
        status = "ok" if not self.problems else f"{len(self.problems)} problems"
        exits = (f"; exit {min(self.exit_seconds):.2f}-{max(self.exit_seconds):.2f} s after the signal"
                 if self.exit_seconds else "")
        return (f"{self.command:9s} clean {self.clean_seconds:5.1f} s, {len(self.exit_codes)} trials "
                f"({interrupted} interrupted, {len(self.exit_codes) - interrupted} finished first{exits}): {status}")


def _run(argv: list, delay: float | None, timeout: float) -> tuple[int, str, float, float | None]:
    env = {k: v for k, v in os.environ.items() if k != "SOT_APPS_DEBUG"}
    start = time.perf_counter()
    signalled = None
    proc = subprocess.Popen([*CLI, *map(str, argv)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=env)   # its own process group, as a terminal's Ctrl-C
    try:
        if delay is not None:
            try:
                proc.wait(delay)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGINT)
                signalled = time.perf_counter()
        stdout, stderr = proc.communicate(timeout=timeout)
        ended = time.perf_counter()
    except BaseException:
        with __import__("contextlib").suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        raise
    if proc.returncode not in (0, 130, -signal.SIGINT):   # e.g. a failed unit: its FAILED line is on stdout
        stderr += f"\n[stdout]\n{stdout[-1500:]}"
    return proc.returncode, stderr, ended - start, None if signalled is None else ended - signalled


def _temporaries(out: Path) -> list[str]:
    return sorted(p.name for p in [*out.rglob("*.tmp"), *out.rglob(".sot-apps.lock")]) if out.exists() else []


def trials_for(command: str, trials: int, rng: random.Random, world: Path, root: Path,
               timeout: float = 300) -> CommandResult:
    pipeline = pipeline_file(world, root)
    clean_out, out = root / f"{command}_clean", root / f"{command}_trials"
    for d in (clean_out, out):
        shutil.rmtree(d, ignore_errors=True)
    # the clean run writes where the trials will (outputs may record their own absolute paths), then moves away
    rc, stderr, seconds, _ = _run(_argv(command, world, out, pipeline), None, timeout)
    result = CommandResult(command, seconds)
    if rc != 0:
        result.problems.append(f"clean run exit {rc}: {stderr[-500:]}")
        return result
    out.rename(clean_out)
    reference = checksums(clean_out)
    i = 0
    # a trial whose command finishes first, or whose signal comes before Python's handler is installed, exercises
    # nothing: a few extra trials, earlier into the run (a command that takes 0.3 s on a fast machine finishes
    # before any signal at 0.3 s or later), until one interrupt was handled
    while i < trials or (result.handled == 0 and i < trials + 6):
        low, high = (0.3, max(0.6, seconds)) if i < trials else (min(0.3, 0.3 * seconds), max(0.35, 0.7 * seconds))
        delay = rng.uniform(low, high)
        rc, stderr, _, exit_seconds = _run(_argv(command, world, out, pipeline), delay, timeout)
        result.delays.append(round(delay, 2))
        result.exit_codes.append(rc)
        if rc == 130 and exit_seconds is not None:
            result.exit_seconds.append(round(exit_seconds, 2))
        lines = [s.strip() for s in stderr.replace("\r", "\n").splitlines()
                 if s.strip() and not _PROGRESS.search(s)]
        if "Traceback" in stderr or "KeyboardInterrupt" in stderr:
            result.problems.append(f"trial {i} (SIGINT at {delay:.2f} s) printed a traceback:\n{stderr[-3000:]}")
        if rc == -signal.SIGINT and not lines:
            # killed by the signal itself before the command printed anything: it came while Python's SIGINT
            # handler was not installed yet (interpreter start-up); a shell reports this as exit 130
            pass
        elif rc in (130, -signal.SIGINT):
            # -SIGINT with the line: the command handled the signal and returned 130, but the signal had landed
            # inside a string exec (dataclass creation during a lazy import), which makes CPython 3.11 end the
            # process by re-raising SIGINT after finalisation; a shell reports it as exit 130 as well
            if not lines or not lines[-1].startswith("interrupted"):
                result.problems.append(f"trial {i}: exit {rc} without the 'interrupted' line: {stderr[-500:]}")
            elif len(lines) != 1:   # a worker's own line, a Dask log record, a leaked-semaphore warning
                result.problems.append(f"trial {i} (SIGINT at {delay:.2f} s): more than the one line:\n{stderr[-1500:]}")
            else:
                result.handled += 1
        elif rc != 0:
            result.problems.append(f"trial {i} (SIGINT at {delay:.2f} s): exit {rc}: {stderr[-1500:]}")
        if _temporaries(out):
            result.problems.append(f"trial {i}: temporary files left: {_temporaries(out)}")
        if rc == 0:   # this resume finished before the signal: check it, then start the next trial afresh
            _compare(out, reference, f"trial {i} (finished first)", result)
            shutil.rmtree(out)
        i += 1
    rc, stderr, _, _ = _run(_argv(command, world, out, pipeline), None, timeout)
    if rc != 0:
        result.problems.append(f"completing rerun exit {rc}: {stderr[-1500:]}")
    else:
        _compare(out, reference, "completing rerun", result)
    return result


def _compare(out: Path, reference: dict[str, str], what: str, result: CommandResult) -> None:
    got = checksums(out)
    if got != reference:
        diff = sorted(k for k in set(got) | set(reference) if got.get(k) != reference.get(k))
        result.problems.append(f"{what}: outputs differ from a clean run: {diff[:20]}")


def tiny_world(root: Path) -> Path:
    from sot_apps.synth import write_world

    world = write_world(root / "world", frames=3, vehicles=2, sensor="vlp16", seed=4, cameras=True,
                        camera_size=(320, 240))
    from sot_apps.io import open_sequence
    from sot_apps.objects.bank import entries_from_annotations, read_bank, write_bank_index

    bank = read_bank(root / "bank", must_exist=False)   # for `benchmark make`
    entries, _ = entries_from_annotations(root / "bank", open_sequence(world), ["veh_000", "veh_001"], min_points=20)
    for entry in entries:
        bank.upsert(entry)
    write_bank_index(bank)
    return world


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--commands", nargs="+", choices=COMMANDS, default=list(COMMANDS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--root", default=None, help="work directory (default: a new temporary one)")
    args = parser.parse_args()
    import tempfile

    root = Path(args.root or tempfile.mkdtemp(prefix="sot_interrupts_"))
    root.mkdir(parents=True, exist_ok=True)
    world = tiny_world(root)
    rng = random.Random(args.seed)
    failed = False
    for command in args.commands:
        result = trials_for(command, args.trials, rng, world, root)
        print(result.line(), flush=True)
        for problem in result.problems:
            failed = True
            print("   ", problem.replace("\n", "\n    "), flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
