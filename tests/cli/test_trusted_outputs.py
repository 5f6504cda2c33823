"""Issue 26 items 6, 7 and 12: an output never overwrites an input or another output; special files are written
through and symbolic links followed; one command at a time writes into an output directory.

The refusals happen before any work, so most cases run the CLI in-process on a tiny synthetic world."""

from __future__ import annotations

import hashlib
import os
import stat
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from sot_apps.cli.main import main

CLI = [sys.executable, "-m", "sot_apps.cli.main"]
ROOT = Path(__file__).resolve().parents[2]   # the CLI subprocesses run this checkout's code


# Never replace a real device node or /dev/stdout, whatever the code under test does: a rename onto anything under
# /dev or /proc fails the test instead (the tests run as root; an atomic replace of /dev/null would break the machine)
_GUARD = """
import os
def _guarded(rename):
    def call(src, dst, *args, **kwargs):
        if os.path.abspath(dst).startswith(("/dev/", "/proc/")):
            raise AssertionError(f"refusing to rename onto {dst}")
        return rename(src, dst, *args, **kwargs)
    return call
os.replace, os.rename = _guarded(os.replace), _guarded(os.rename)
"""


@pytest.fixture(autouse=True)
def no_rename_into_dev(monkeypatch):
    original = os.replace, os.rename
    exec(_GUARD, {})   # wraps os.replace and os.rename in place: hand them to monkeypatch, which undoes it
    guarded = os.replace, os.rename
    os.replace, os.rename = original
    monkeypatch.setattr(os, "replace", guarded[0])
    monkeypatch.setattr(os, "rename", guarded[1])


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture
def refused(capsys):
    """Run the CLI in-process; assert exit code 2 and one line naming both paths; return the line."""

    def check(argv: list, *names: str) -> str:
        code = main([str(a) for a in argv])
        err = capsys.readouterr().err.strip()
        assert code == 2, err
        assert len(err.splitlines()) == 1 and err.startswith("error: "), err
        for name in names:
            assert name in err, (name, err)
        return err

    return check


# ------------------------------------------------------------------ item 6: an output is never an input

def test_outputs_that_would_replace_an_input_file_are_refused(tiny_copy, tmp_path, refused):
    seq = tiny_copy
    before = _digest(seq / "sequence.json")
    refused(["eval", seq, "--tracks", "x", "--json", seq / "sequence.json"], "--json", "sequence.json", str(seq))
    refused(["detect", seq, "--simulate", "learned", "--out", seq / "sequence.json"], "--out", "SEQUENCE")
    # the same file under another name: a symbolic link, a hard link
    (tmp_path / "link.json").symlink_to(seq / "sequence.json")
    refused(["eval", seq, "--tracks", "x", "--json", tmp_path / "link.json"], "--json", "SEQUENCE")
    os.link(seq / "sequence.json", tmp_path / "hard.json")
    refused(["detect", tmp_path / "hard.json", "--simulate", "clean", "--out", seq / "sequence.json"], "--out")
    assert _digest(seq / "sequence.json") == before


def test_outputs_over_track_benchmark_and_list_inputs_are_refused(tiny_dir, tmp_path, refused):
    tracks = tmp_path / "T"
    tracks.mkdir()
    (tracks / "track.json").write_text("{}")
    refused(["motion-export", tiny_dir, "--tracks", tracks, "--out", tracks / "track.json"], "--tracks", "track.json")
    bench = tmp_path / "B"
    bench.mkdir()
    (bench / "benchmark.json").write_text("[]")
    (bench / "make.json").write_text("{}")
    refused(["eval", "--benchmark", bench / "benchmark.json", "--json", bench / "benchmark.json"], "--benchmark")
    refused(["benchmark", "realism", bench, "--json", bench / "make.json"], "make.json", "DIR")
    refused(["track", tiny_dir, "--track-id", "x", "--out", tiny_dir], "--out", "SEQUENCE")
    assert (tracks / "track.json").read_text() == "{}" and (bench / "make.json").read_text() == "{}"


def test_a_benchmarks_json_never_replaces_its_input_files(tmp_path, refused):
    """`sot-apps bench`: each benchmark names its input options (pipeline file, reports, sources)."""
    pipeline = tmp_path / "pipeline.json"
    pipeline.write_text("{}")
    refused(["bench", "pipeline", "--pipeline", pipeline, "--json", pipeline], "--json", "--pipeline")
    refused(["bench", "rule", "--baseline", pipeline, "--candidate", tmp_path / "b.json", "--json", pipeline],
            "--json", "--baseline")
    refused(["bench", "keyframes", pipeline, "--json", pipeline], "--json", "SOURCE")
    assert pipeline.read_text() == "{}"


def test_two_outputs_of_one_command_may_not_be_the_same_file(tiny_dir, tmp_path, refused):
    out = tmp_path / "X.mcap"
    refused(["motion-export", tiny_dir, "--from-annotations", "--out", out, "--parquet", out], "--parquet", "--out")
    refused(["motion-export", tiny_dir, "--from-annotations", "--out", out, "--csv", tmp_path / "." / "X.mcap"],
            "--csv")
    assert not out.exists()


def test_a_new_file_inside_an_input_directory_is_allowed(tiny_copy, capsys):
    """Only replacing an existing file is refused: a new name inside the sequence directory is fine."""
    assert main(["detect", str(tiny_copy), "--simulate", "clean", "--out", str(tiny_copy / "dets.json")]) == 0
    assert (tiny_copy / "dets.json").is_file()


# ------------------------------------------------------------------ item 7: special files and symbolic links

def test_dev_null_and_dev_full_are_written_through_never_replaced(tmp_path):
    from sot_apps.errors import OutputError
    from sot_apps.io.atomic import ensure_writable, write_json, write_text

    before = os.stat("/dev/null")
    ensure_writable("/dev/null")
    write_json("/dev/null", {"a": 1})
    after = os.stat("/dev/null")
    assert stat.S_ISCHR(after.st_mode) and (after.st_ino, after.st_rdev) == (before.st_ino, before.st_rdev)
    assert not [p for p in os.listdir("/dev") if p.startswith(".sot-apps") or p.endswith(".tmp")]
    with pytest.raises(OutputError, match="No space left"):
        write_text("/dev/full", "x")
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def test_a_fifo_output_is_written_through(tmp_path):
    """As the CLI would for ``--json FIFO``: the reader gets the bytes; the FIFO stays a FIFO."""
    from sot_apps.io.atomic import write_json

    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    received: list[bytes] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()
    write_json(fifo, {"frames": [1, 2]})
    reader.join(10)
    assert received == [b'{\n "frames": [\n  1,\n  2\n ]\n}\n']
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and os.listdir(tmp_path) == ["pipe"]


def test_cli_output_into_a_fifo(tiny_dir, tmp_path):
    fifo = tmp_path / "dets.fifo"
    os.mkfifo(fifo)
    received: list[bytes] = []
    reader = threading.Thread(target=lambda: received.append(fifo.read_bytes()), daemon=True)
    reader.start()
    done = subprocess.run([*CLI, "detect", str(tiny_dir), "--simulate", "clean", "--out", str(fifo)],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    reader.join(10)
    assert done.returncode == 0, done.stderr
    assert b'"frames"' in received[0] and stat.S_ISFIFO(os.lstat(fifo).st_mode)
    assert os.listdir(tmp_path) == ["dets.fifo"]


def test_dev_stdout_continues_the_redirected_file(tmp_path):
    out = tmp_path / "out.txt"
    script = _GUARD + ("from sot_apps.io.atomic import write_text\nprint('before')\n"
                       "write_text('/dev/stdout', 'middle\\n')\nprint('after')\n")
    with open(out, "w") as handle:
        subprocess.run([sys.executable, "-c", script], stdout=handle, check=True, timeout=60, cwd=ROOT)
    assert out.read_text() == "before\nmiddle\nafter\n"


def test_symbolic_links_are_followed_and_stay(tmp_path):
    from sot_apps.io.atomic import write_text

    target = tmp_path / "real.json"
    target.write_text("old")
    link = tmp_path / "link.json"
    link.symlink_to("real.json")
    write_text(link, "new")
    assert link.is_symlink() and os.readlink(link) == "real.json" and target.read_text() == "new"
    dangling = tmp_path / "dangling.json"
    dangling.symlink_to("sub/made.json")
    (tmp_path / "sub").mkdir()
    write_text(dangling, "made")
    assert dangling.is_symlink() and (tmp_path / "sub" / "made.json").read_text() == "made"
    assert not list(tmp_path.rglob("*.tmp"))


# ------------------------------------------------------------------ item 12: one command per output directory

HOLD = ("import sys, time; from sot_apps.io.lock import OutputLock\n"
        "with OutputLock(sys.argv[1]):\n    print('held', flush=True); time.sleep(60)\n")


@pytest.fixture
def held_out(tmp_path):
    out = tmp_path / "out"
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdout=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        assert holder.stdout.readline().strip() == "held"
        yield out, holder.pid
    finally:
        holder.kill()
        holder.wait()


def test_a_second_command_into_a_locked_directory_is_refused(held_out, tiny_dir, tmp_path, refused):
    out, pid = held_out
    for argv in (["track", tiny_dir, "--track-id", "veh", "--quiet", "--out", out],
                 ["convert", tiny_dir, "--out", out],
                 ["benchmark", "make", "--background", tiny_dir, "--bank", tmp_path / "bank", "--out", out],
                 ["benchmark", "build", tiny_dir, "--out", out],
                 ["simulate-lidar", "--bank", tmp_path / "bank", "--random", "1", "--out", out],
                 ["synth", "--frames", "1", "--out", out],
                 ["flow", tiny_dir, "--from-annotations", "--camera", "front", "--out", out],
                 ["autolabel", tiny_dir, "--simulate", "clean", "--out", out],
                 ["bank", "build", "--from-annotations", tiny_dir, "--all", "--out", out]):
        err = refused(argv, ".sot-apps.lock", f"pid {pid}")
        assert "another sot-apps command" in err
    assert sorted(os.listdir(out)) == [".sot-apps.lock"]   # the holder's, untouched


def test_a_finished_or_rejected_command_leaves_no_lock(tiny_dir, tmp_path, capsys):
    out = tmp_path / "t"
    assert main(["track", str(tiny_dir), "--track-id", "car-move", "--end-frame", "2", "--quiet", "--out", str(out)]) == 0
    assert (out / "track.json").is_file() and not (out / ".sot-apps.lock").exists()
    # rejected after the lock was taken (no such track): neither the lock nor the directory it created stays
    rejected = tmp_path / "deep" / "r"
    assert main(["track", str(tiny_dir), "--track-id", "no_such", "--out", str(rejected)]) == 2
    assert not (tmp_path / "deep").exists()
    pipeline = tmp_path / "p.json"
    pipeline.write_text('{"version": 1, "out": "%s", "sequences": [{"path": "%s", "objects": {"from": "annotations", '
                        '"track_ids": ["no_such_track"]}}]}' % (tmp_path / "run_out", tiny_dir))
    assert main(["run", str(pipeline), "--quiet"]) == 2
    assert not (tmp_path / "run_out").exists()   # neither a lock file (of any name) nor the directory it needed
    capsys.readouterr()
