"""Issue 16, defect 5: two pipeline runs into one output directory at once: the second is refused."""

from __future__ import annotations

import json
import subprocess
import sys

from sot_apps.cli.main import main

HOLD = ("import sys, time; from sot_apps.pipeline.lock import RunLock\n"
        "with RunLock(sys.argv[1]):\n    print('held', flush=True); time.sleep(60)\n")


def _doc(world, out) -> dict:
    return {"out": str(out), "sequences": [{"path": str(world), "objects": {"from": "annotations",
                                                                              "track_ids": ["veh_000"]}}],
            "stages": {s: {"enabled": False} for s in ("bank", "motion", "flow", "scans")}}


def test_second_run_into_the_same_output_is_refused(tiny_worlds, tmp_path, capsys):
    out = tmp_path / "out"
    path = tmp_path / "pipeline.json"
    path.write_text(json.dumps(_doc(tiny_worlds[0], out)))
    holder = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == "held"
        code = main(["run", str(path), "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and len(err.strip().splitlines()) == 1
        assert "another sot-apps command" in err and ".sot-apps.lock" in err and f"pid {holder.pid}" in err
        assert not (out / "manifest.json").exists() and not (out / "synth_s4").exists()
    finally:
        holder.kill()
        holder.wait()
    # the holder is gone (killed, not cleaned up): its lock went with it and the run goes ahead
    assert main(["run", str(path), "--quiet"]) == 0
    assert (out / "synth_s4" / "tracks" / "veh_000" / "track.json").is_file()


def test_the_lock_is_reentrant_in_one_process(tmp_path):
    from sot_apps.pipeline.lock import LOCK_NAME, RunLock

    with RunLock(tmp_path), RunLock(tmp_path):
        assert "pid" in (tmp_path / LOCK_NAME).read_text()
    assert not (tmp_path / LOCK_NAME).exists()   # removed once released: nothing is left behind
