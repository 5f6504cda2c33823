"""``sot-apps bench rear-view``: a straight drive seen only from behind, over many scenes and tracker seeds.

A box drives straight at 10 m/s, seen only by its rear face from a sensor following 15 m behind (150 face points
and flat ground per frame, 2 cm noise; :func:`rear_view_sequence`). Printed per preset: the heading error over
40 frames (how many runs go above 2 degrees, at which frames, the worst, the worst from frame 15, the mean), the
worst sideways error of the box, and how frame 1's sideways error goes with the worst heading error; then the
position error after a gap of four frames at 12 m/s (along the track and in all). The tests run a few scenes
(tests/tracker/test_motion_filter.py); this runs scenes 0..N-1 x tracker seeds 0..S-1.
"""

from __future__ import annotations

import argparse
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:   # numpy and the tracker load when a run starts (`sot-apps --help` imports this module)
    from tracker import Box, LidarFrame

__all__ = ["rear_view_sequence", "rear_view_figures", "frame_gap_figures", "register"]


def rear_view_sequence(n: int, speed: float = 10.0, heading: float = 0.4, seed: int = 0
                       ) -> tuple[list[LidarFrame], list[Box]]:
    """``n`` frames (10 Hz) of a box driving straight along ``heading``, seen only from behind (its rear face,
    from a sensor following it), with the true boxes."""
    import numpy as np

    from tracker import Box, LidarFrame, invert_transform, make_transform, rotation_z, transform_points

    rng = np.random.default_rng(seed)
    frames, boxes = [], []
    direction = np.array([np.cos(heading), np.sin(heading)])
    for k in range(n):
        centre = np.array([20.0, 5.0]) + speed * 0.1 * k * direction
        box = Box(centre[0], centre[1], 0.0, heading, 4.5, 1.8, 1.5)
        face = np.column_stack([np.full(150, -2.25), rng.uniform(-0.9, 0.9, 150), rng.uniform(-0.6, 0.75, 150)])
        world = transform_points(box.world_from_object(), face)
        sensor_xy = centre - 15.0 * direction
        ground_xy = centre + rng.uniform(-10.0, 10.0, (3200, 2))       # 8 points per m² over 20 m x 20 m
        ground = np.column_stack([ground_xy, -0.75 + rng.normal(0.0, 0.02, 3200)])
        pts = np.vstack([world, ground]) + rng.normal(0.0, 0.02, (150 + 3200, 3))
        world_from_ego = make_transform(rotation_z(heading), np.array([sensor_xy[0], sensor_xy[1], 1.0]))
        ego = transform_points(invert_transform(world_from_ego), pts).astype(np.float32)
        frames.append(LidarFrame(k, 1_000_000_000 + 100_000_000 * k, ego, world_from_ego))
        boxes.append(box)
    return frames, boxes


def rear_view_figures(preset: str, scenes: int, seeds: int, overrides: dict[str, Any]) -> str:
    """Heading error of a 40-frame straight drive seen only from behind, and the sideways error of the box."""
    import numpy as np

    from tracker import Tracker, get_preset, wrap_angle

    heading, sideways, first_sideways = [], [], []
    for scene in range(scenes):
        frames, boxes = rear_view_sequence(40, seed=scene)
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
    r = np.corrcoef(f, worst)[0, 1] if len(f) > 1 else float("nan")
    return (f"rear view, {len(h)} runs: heading error above 2 deg in {above.sum()} runs (frames "
            f"{sorted(set((np.nonzero(h > 2.0)[1] + 1).tolist()))}), worst {h.max():.2f} deg, worst from frame 15 "
            f"{h[:, 14:].max():.2f}, mean {h.mean():.2f}; sideways error worst {a.max():.2f} m; frame-1 sideways error "
            f"vs worst heading error r = {r:.2f}"
            + (f" ({f[above].mean():.3f} m in the runs above 2 deg, {f[~above].mean():.3f} m in the others)"
               if above.any() and (~above).any() else ""))


def frame_gap_figures(preset: str, scenes: int, seeds: int, overrides: dict[str, Any]) -> str:
    """Position error after a 4-frame gap (12 m/s): along the track and in all."""
    import numpy as np

    from tracker import Tracker, get_preset

    along, total = [], []
    for scene in range(scenes):
        frames, boxes = rear_view_sequence(20, speed=12.0, seed=scene)
        for seed in range(seeds):
            tracker = Tracker(get_preset(preset, seed=seed, **overrides))
            tracker.start(frames[0], boxes[0])
            for frame in frames[1:8]:
                tracker.step(frame)
            est = tracker.step(frames[12])
            offset = est.box.center[:2] - boxes[12].center[:2]
            along.append(abs(offset @ [np.cos(boxes[12].heading), np.sin(boxes[12].heading)]))
            total.append(float(np.hypot(*offset)))
    return (f"frame gap, {len(total)} runs: along-track error at most {max(along):.3f} m, in all at most "
            f"{max(total):.3f} m")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--preset", nargs="+", default=["full"], metavar="NAME", help="tracker presets (default: full)")
    parser.add_argument("--scenes", type=int, default=12, help="scenes 0..N-1 (default 12)")
    parser.add_argument("--seeds", type=int, default=3, help="tracker seeds 0..S-1 (default 3)")
    parser.add_argument("--set", dest="overrides", action="append", default=[], metavar="PATH=VALUE",
                        help="replace a tracker setting in every preset (e.g. motion.alpha=0.6); repeatable")


def run(args: argparse.Namespace) -> int:
    from ..errors import InputError
    from .sequence_eval import checked_overrides, resolve_presets

    if args.scenes < 1 or args.seeds < 1:
        raise InputError(None, f"--scenes and --seeds must be at least 1, not {args.scenes} and {args.seeds}")
    presets = resolve_presets(args.preset)
    overrides = checked_overrides(args.overrides, presets)
    for preset in presets:
        print(f"{preset}: {rear_view_figures(preset, args.scenes, args.seeds, overrides)}")
        print(f"{preset}: {frame_gap_figures(preset, args.scenes, args.seeds, overrides)}")
    return 0


def register(registry) -> None:
    """Hook for the ``sot-apps bench`` registry (sot_apps/cli/bench.py)."""
    from . import module_docstring

    registry.add("rear-view", help="a straight drive seen only from behind: heading and gap errors over many scenes",
                 add_arguments=add_arguments, run=run, description=module_docstring("sot_apps.bench.rear_view"))
