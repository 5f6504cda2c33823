"""``sot-apps synth``: write a synthetic world as a canonical sequence with exact ground truth."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError
from .common import add_subcommand, declare_outputs, nonnegative_int, positive_int


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "synth", help="synthesise a driving world (canonical sequence + ground truth)",
        description="Simulate a small world (ground, walls, poles, parked cars, moving procedural vehicles that "
                    "turn, stop and accelerate; a moving ego) with a spinning LiDAR and write it as a canonical "
                    "sequence with ground-truth boxes, meshes, trajectories and per-point instance labels (DIR/gt/). "
                    "The same arguments give byte-identical output except the camera PNGs (--cameras): those come "
                    "from Mesa's software OpenGL (pyrender), which resolves some depth ties at triangle edges "
                    "differently from run to run, so an image may differ in a few single edge pixels (measured: "
                    "1 pixel in 3 of 20 images). LiDAR sweeps, labels, ground truth and the sequence file are "
                    "byte-identical; never hash camera images to compare runs.",
        examples=["sot-apps synth --out out/world --frames 20 --vehicles 3 --sensor pandar64 --seed 0",
                  "sot-apps synth --out /tmp/world_cam --frames 10 --vehicles 4 --cameras --camera-size 640x360",
                  "sot-apps synth --out out/world_profiles --frames 40 --vehicles 7 --profiles"])
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument("--frames", type=positive_int, default=20, help="number of frames (default 20)")
    parser.add_argument("--vehicles", type=nonnegative_int, default=3, help="number of moving vehicles (default 3)")
    parser.add_argument("--sensor", default="pandar64", help="sensor preset or sensor JSON (default pandar64)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--cameras", action="store_true", help="also render a front pinhole camera (pyrender, EGL)")
    parser.add_argument("--camera-size", default="640x360", metavar="WxH", help="camera image size (default 640x360)")
    parser.add_argument("--open-road", action="store_true",
                        help="no walls and no poles: open ground all round (a background for the benchmark's "
                             "far_approach, passing and oblique profiles; docs/benchmark.md)")
    parser.add_argument("--clutter", action="store_true",
                        help="unannotated roadside clutter: bushes, hedges, trees, building corners, kiosks, "
                             "pedestrians (what a model-free detector must not call a vehicle; docs/detection.md)")
    parser.add_argument("--parked", type=nonnegative_int, default=None, metavar="N",
                        help="number of parked cars, alternating sides, >= 7 m apart (default: 4-8 drawn from the "
                             "seed); 24 gives rows of parked cars that hide each other, as on a city street")
    parser.add_argument("--profiles", action="store_true",
                        help="moving vehicles follow the benchmark's motion profiles (kinematic bicycle, bounded "
                             "acceleration and jerk: constant speed, hard braking, strong acceleration, stop-and-go, "
                             "lane change, turn, U-turn) instead of random piecewise motion")
    parser.set_defaults(func=run)
    declare_outputs(parser, dirs=("out",), inputs=("sensor",))
    return parser


def _size(text: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(None, f"--camera-size must look like 640x360, got {text!r}") from None
    if w < 8 or h < 8:
        raise InputError(None, "--camera-size must be at least 8x8")
    return w, h


def run(args: argparse.Namespace) -> int:
    from ..synth import write_world

    if args.frames < 1 or args.vehicles < 0:
        raise InputError(None, "--frames must be >= 1 and --vehicles >= 0")
    out = write_world(Path(args.out), frames=args.frames, vehicles=args.vehicles, sensor=args.sensor,
                      seed=args.seed, cameras=args.cameras, camera_size=_size(args.camera_size), progress=True,
                      profiles=args.profiles, open_road=args.open_road, clutter=args.clutter,
                      parked=args.parked)
    print(f"wrote {out / 'sequence.json'} ({args.frames} frames, {args.vehicles} moving vehicles; ground truth in {out / 'gt'})")
    return 0
