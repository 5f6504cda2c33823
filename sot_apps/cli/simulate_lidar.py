"""``sot-apps simulate-lidar``: raycast bank vehicles (optionally into a real sweep)."""

from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError
from .common import add_subcommand, coordinate, declare_outputs, nonnegative_int, positive_float, positive_int


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "simulate-lidar", help="simulate a LiDAR scan of bank vehicles (optionally inserted into a real sweep)",
        description="Raycast (Embree) the vehicles of a scene file, or of a random scene, with a sensor preset or "
                    "sensor JSON. Writes DIR/scan.npz (xyz, instance, intensity, time_offset_ns, beam, column, range, "
                    "range_image), boxes.json, labels_kitti.txt, preview.png (bird's-eye view) and optional "
                    "scan.bin/.pcd/.ply. With --background the vehicles are inserted into a real sweep: background "
                    "returns behind a vehicle are removed and vehicle returns behind real objects are dropped.",
        examples=["sot-apps simulate-lidar --bank bank --scene examples/scenes/paper_figure.json --out out/paper_figure",
                  "sot-apps simulate-lidar --bank bank --random 8 --seed 1 --sensor pandar64 --out out/random --format bin,pcd,ply",
                  "sot-apps simulate-lidar --bank bank --scene scene.json --background ../shared/data/pandaset_002 "
                  "--frame 10 --out out/inserted"])
    parser.add_argument("--bank", required=True, metavar="BANK", help="vehicle bank directory (sot-apps bank build)")
    parser.add_argument("--scene", metavar="SCENE.json", help="scene file (schema scene)")
    parser.add_argument("--random", type=positive_int, metavar="N", help="sample a scene of N random bank vehicles instead")
    parser.add_argument("--seed", type=int, default=0, help="seed for --random and the noise (default 0)")
    parser.add_argument("--sensor", default=None,
                        help="sensor preset or JSON (with --random; overrides the scene's sensor). Default pandar64")
    parser.add_argument("--ground-z", type=coordinate, default=None,
                        help="ground height for --random without background (default -1.8)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument("--background", metavar="SEQUENCE", help="insert into a sweep of this sequence")
    parser.add_argument("--frame", type=nonnegative_int, default=0, help="background frame (default 0)")
    parser.add_argument("--format", default="", help="extra point formats, comma-separated: bin,pcd,ply")
    parser.add_argument("--extent", type=positive_float, default=50.0, help="preview half-size in metres (default 50)")
    parser.set_defaults(func=run)
    declare_outputs(parser, dirs=("out",), inputs=("bank", "scene", "background", "sensor"))
    return parser


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from ..io import open_sequence
    from ..lidar_sim.export import FORMATS
    from ..lidar_sim.scene import load_scene, overlapping_objects, random_scene
    from ..lidar_sim.simulate import counts_table, run_simulation
    from ..objects.bank import read_bank
    from ..sensor.model import load_sensor

    if (args.scene is None) == (args.random is None):
        raise InputError(None, "simulate-lidar: give exactly one of --scene SCENE.json or --random N")
    formats = tuple(f.strip() for f in args.format.split(",") if f.strip())
    bad = [f for f in formats if f not in FORMATS]
    if bad:
        raise InputError(None, f"--format: unknown {bad}; choose from {', '.join(FORMATS)}")
    bank = read_bank(args.bank)
    background = open_sequence(args.background) if args.background else None
    if background is not None:
        background.check_index(args.frame)
    if args.scene:
        spec = load_scene(args.scene)
        overlaps = overlapping_objects(spec, bank)
        if overlaps:
            pairs = ", ".join(f"{a} and {b}" for a, b in overlaps[:5])
            raise InputError(args.scene, f"objects {pairs} overlap (their footprints intersect); vehicles cannot "
                                         "share space: move them apart")
        if args.sensor:
            spec = replace(spec, sensor=load_sensor(args.sensor))
    else:
        if args.random < 1:
            raise InputError(None, "--random must be >= 1")
        ground = args.ground_z if args.ground_z is not None else (None if background is not None else -1.8)
        bg_xyz = None
        if background is not None:
            from tracker import invert_transform, transform_points

            bg_xyz = transform_points(invert_transform(background.ego_from_lidar), background.sweep(args.frame).xyz)
        spec = random_scene(bank, args.random, args.seed, load_sensor(args.sensor or "pandar64"), ground_z=ground,
                            background_xyz=bg_xyz)
    outputs = run_simulation(spec, bank, Path(args.out), formats, background, args.frame, args.extent)
    result = outputs.result
    print("\n".join(counts_table(result)))
    if background is not None:
        print(f"background: removed {result.removed_background} occluded returns; dropped {result.removed_vehicle} "
              "vehicle returns hidden behind real objects")
    print(f"{len(result.scan)} points -> " + ", ".join(str(p) for p in outputs.files))
    return 0
