"""Every box of the 9 dev vehicles' tracks (examples/pipeline_dev_tracking.json) in the three tracking modes, run with
the code on PYTHONPATH, and the comparison of two such runs: a speed change must leave them bit-identical.

    PYTHONPATH=/work/main python scripts/compare_dev_tracks.py run A      # main's tracks: A/online, A/lag10, A/offline
    PYTHONPATH=$PWD      python scripts/compare_dev_tracks.py run B      # this checkout's
    python scripts/compare_dev_tracks.py compare A B                     # exit 1 on any difference

``run`` writes each mode with ``sot-apps run ... --workers 1 --quiet`` (the pipeline's one-pass tracking stage, preset
``full``) into DIR/<mode> (a new directory; DIR/<mode>.log keeps its output). ``compare`` reads every ``track.json``
of the two runs and compares, frame by frame, the state (x, y, z, heading: the float64 numbers as written, which
round-trip exactly), the size, the point count, the quality and the flags, and the bytes of each ``shape.ply``.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PIPELINE = REPO / "examples" / "pipeline_dev_tracking.json"
MODES = {"online": {"mode": "online"}, "lag10": {"mode": "lag", "lag": 10}, "offline": {"mode": "offline"}}


def run(out: Path) -> None:
    config = json.loads(PIPELINE.read_text())
    for sequence in config["sequences"]:   # absolute: the mode's pipeline file lives under ``out``
        sequence["path"] = str((PIPELINE.parent / sequence["path"]).resolve())
    out.mkdir(parents=True, exist_ok=True)
    for name, track in MODES.items():
        config["stages"]["track"].update(track)
        path = out / f"{name}.json"
        path.write_text(json.dumps(config, indent=1))
        cmd = [sys.executable, "-m", "sot_apps.cli.main", "run", str(path), "--out", str(out / name), "--workers", "1",
               "--quiet"]
        with open(out / f"{name}.log", "w") as log:
            code = subprocess.call(cmd, stdout=log, stderr=subprocess.STDOUT, env=os.environ.copy())
        print(f"{name}: exit {code} ({out / name})")


def _frames(track: Path) -> tuple[list, list]:
    data = json.loads(track.read_text())
    return data["size"], [(f["frame"], f["state"], f["num_points"], f.get("quality"), f["flags"]) for f in data["frames"]]


def compare(a: Path, b: Path) -> int:
    bad = boxes = 0
    for name in MODES:
        tracks_a = sorted(p.relative_to(a / name) for p in (a / name).rglob("track.json"))
        tracks_b = sorted(p.relative_to(b / name) for p in (b / name).rglob("track.json"))
        if not tracks_a or tracks_a != tracks_b:
            print(f"{name}: the tracks differ ({len(tracks_a)} against {len(tracks_b)})")
            bad += 1
            continue
        for rel in tracks_a:
            size_a, frames_a = _frames(a / name / rel)
            size_b, frames_b = _frames(b / name / rel)
            boxes += len(frames_a)
            if size_a != size_b or frames_a != frames_b:
                diff = [fa[0] for fa, fb in zip(frames_a, frames_b, strict=False) if fa != fb]
                print(f"{name}/{rel.parent.name}: differs (size {size_a == size_b}, frames {diff[:10]}, "
                      f"{len(frames_a)} against {len(frames_b)} frames)")
                bad += 1
            ply = rel.parent / "shape.ply"
            if (a / name / ply).read_bytes() != (b / name / ply).read_bytes():
                print(f"{name}/{ply}: the shape differs")
                bad += 1
        print(f"{name}: {len(tracks_a)} tracks compared")
    print(f"{boxes} boxes compared, {bad} differences")
    return 1 if bad else 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "run":
        run(Path(sys.argv[2]))
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(compare(Path(sys.argv[2]), Path(sys.argv[3])))
    else:
        sys.exit(__doc__)
