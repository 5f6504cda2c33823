"""Track one vehicle with the tracker API and write its track directory (track.json + shape.ply).

    python examples/track_one_vehicle.py [SEQUENCE] [TRACK_ID] [OUT]

Without arguments it makes a small synthetic world and tracks its vehicle veh_001. With PandaSet:
    python examples/track_one_vehicle.py ../shared/data/pandaset_002 8ac00bad out/8ac00bad
Prints the centre error against the annotation per frame.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from sot_apps.io import open_sequence
from sot_apps.tracking import track_sequence, write_track_result
from tracker.config import get_preset


def main() -> None:
    if len(sys.argv) > 1:
        sequence_path, prefix = sys.argv[1], sys.argv[2]
        out = Path(sys.argv[3] if len(sys.argv) > 3 else f"out/{prefix}")
    else:
        from sot_apps.synth import write_world

        sequence_path = write_world(Path(tempfile.mkdtemp()) / "world", frames=10, vehicles=3, sensor="vlp16", seed=4)
        prefix, out = "veh_001", Path("out/track_one_vehicle")
    seq = open_sequence(sequence_path)
    track_id = seq.resolve_track_id(prefix)
    annotated = seq.tracks()[track_id]
    start, end = int(annotated.frames[0]), int(annotated.frames[-1])
    init_box = annotated.box_at(start)                      # WORLD frame box at the start frame
    result = track_sequence(seq, init_box, start, end, get_preset("full"))
    path = write_track_result(out, seq, result, track_id, init_box, annotated.label)
    for estimate in result.estimates:
        truth = annotated.box_at(estimate.frame)
        error = np.linalg.norm(estimate.box.center - truth.center) if truth is not None else float("nan")
        print(f"frame {estimate.frame:3d}  points {estimate.num_points:5d}  centre error {100 * error:6.1f} cm  "
              f"{','.join(estimate.flags)}")
    print(f"wrote {path} and {path.parent / 'shape.ply'} ({len(result.shape)} shape points)")


if __name__ == "__main__":
    main()
