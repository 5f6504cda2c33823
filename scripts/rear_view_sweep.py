"""The rear-view and frame-gap checks of tests/tracker/test_motion_filter.py over many scenes and seeds.

The tests run a few scenes; this runs scenes 0..N-1 x tracker seeds 0..S-1 and prints the figures quoted in
docs/tracker.md ("A rear view, and frame 1's sideways motion"):

    python scripts/rear_view_sweep.py --preset full --scenes 12 --seeds 3
    python scripts/rear_view_sweep.py --preset full --scenes 12 --seeds 3 --set motion.first_motion_along_heading=false
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "tracker"))

from test_motion_filter import _rear_view_sequence  # noqa: E402  (the tests' scene builder)

from tracker import Tracker, get_preset, parse_overrides  # noqa: E402
from tracker.geometry import wrap_angle  # noqa: E402


def rear_view(preset: str, scenes: int, seeds: int, overrides: dict) -> str:
    """Heading error of a 40-frame straight drive seen only from behind, and the sideways error of the box."""
    heading, sideways, first_sideways = [], [], []
    for scene in range(scenes):
        frames, boxes = _rear_view_sequence(40, seed=scene)
        for seed in range(seeds):
            tracker = Tracker(get_preset(preset, seed=seed, **overrides))
            tracker.start(frames[0], boxes[0])
            h, a = [], []
            for frame, box in zip(frames[1:], boxes[1:], strict=True):
                est = tracker.step(frame)
                h.append(abs(np.degrees(wrap_angle(est.box.heading - box.heading))))
                a.append((est.box.center[:2] - box.center[:2]) @ [-np.sin(box.heading), np.cos(box.heading)])
            heading.append(h)
            sideways.append(np.abs(a))
            first_sideways.append(abs(a[0]))
    h, a, f = np.array(heading), np.array(sideways), np.array(first_sideways)
    worst = h.max(axis=1)
    above = worst > 2.0
    return (f"rear view, {len(h)} runs: heading error above 2 deg in {above.sum()} runs (frames "
            f"{sorted(set((np.nonzero(h > 2.0)[1] + 1).tolist()))}), worst {h.max():.2f} deg, worst from frame 15 "
            f"{h[:, 14:].max():.2f}, mean {h.mean():.2f}; sideways error worst {a.max():.2f} m; frame-1 sideways error "
            f"vs worst heading error r = {np.corrcoef(f, worst)[0, 1]:.2f}"
            + (f" ({f[above].mean():.3f} m in the runs above 2 deg, {f[~above].mean():.3f} m in the others)"
               if above.any() and (~above).any() else ""))


def frame_gap(preset: str, scenes: int, seeds: int, overrides: dict) -> str:
    """Position error after a 4-frame gap (12 m/s): along the track and in all."""
    along, total = [], []
    for scene in range(scenes):
        frames, boxes = _rear_view_sequence(20, speed=12.0, seed=scene)
        for seed in range(seeds):
            tracker = Tracker(get_preset(preset, seed=seed, **overrides))
            tracker.start(frames[0], boxes[0])
            for frame in frames[1:8]:
                tracker.step(frame)
            est = tracker.step(frames[12])
            offset = est.box.center[:2] - boxes[12].center[:2]
            along.append(abs(offset @ [np.cos(boxes[12].heading), np.sin(boxes[12].heading)]))
            total.append(float(np.hypot(*offset)))
    return f"frame gap, {len(total)} runs: along-track error at most {max(along):.3f} m, in all at most {max(total):.3f} m"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", nargs="+", default=["full"])
    parser.add_argument("--scenes", type=int, default=12)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--set", action="append", default=[], metavar="PATH=VALUE",
                        help="replace a tracker setting in every preset (e.g. motion.alpha=0.6); repeatable")
    args = parser.parse_args()
    overrides = parse_overrides(args.set)
    for preset in args.preset:
        print(f"{preset}: {rear_view(preset, args.scenes, args.seeds, overrides)}")
        print(f"{preset}: {frame_gap(preset, args.scenes, args.seeds, overrides)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
