"""``sot-apps sensor fit``: estimate a LiDAR's beam table and azimuth resolution from real sweeps."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np

from ..errors import InputError
from .common import (
    add_action,
    add_sequence_argument,
    add_subcommand,
    coordinate,
    declare_outputs,
    load_sequence,
    nonnegative_float,
    positive_float,
)

MAX_PLAUSIBLE_BEAMS = 128   # the most beams of any spinning LiDAR on sale (e.g. Hesai OT128, Ouster OS-128)


def register(subparsers) -> argparse.ArgumentParser:
    parser = add_subcommand(
        subparsers, "sensor", help="fit a sensor model (beam elevations, azimuth step) to real sweeps",
        description="Fit a spinning-LiDAR model to sweeps of a sequence: beam elevations are the peaks of the "
                    "elevation histogram, the azimuth step is the median gap between a beam's consecutive returns, "
                    "spin rate and direction come from per-point times. Writes a sensor JSON (schema sensor) usable "
                    "by simulate-lidar and synth. See docs/lidar_sim.md for how it fares on PandaSet.",
        examples=["sot-apps sensor fit ../shared/data/pandaset_002 --align --out pandar64_fit.json --compare pandar64",
                  "sot-apps sensor fit out/world --frames 0,5 --out fitted.json"])
    sub = parser.add_subparsers(dest="sensor_command", metavar="ACTION")
    fit = add_action(sub, "fit", help="fit beam elevations and azimuth resolution",
                     description="Fit a sensor model to sweeps (points in the LiDAR frame) and print its summary "
                                 "(beams, elevations, azimuth step, spin rate); with --out, also write it as a sensor "
                                 "JSON for simulate-lidar, synth and benchmark make.",
                     examples=["sot-apps sensor fit ../shared/data/pandaset_002 --align --out pandar64_fit.json "
                               "--compare pandar64",
                               "sot-apps sensor fit out/world --frames 0,5 --out fitted.json",
                               "sot-apps sensor fit ../shared/data/pandaset_002 --align   # print only"])
    add_sequence_argument(fit)
    fit.add_argument("--frames", default="0,10,20", help="comma-separated frames to use (default 0,10,20)")
    fit.add_argument("--out", metavar="SENSOR.json",
                     help="write the fitted sensor JSON here (default: only print the summary)")
    fit.add_argument("--name", default=None, help="sensor name (default: fitted_<sequence id>)")
    fit.add_argument("--min-range", type=nonnegative_float, default=2.0, help="ignore points closer than this (m)")
    fit.add_argument("--min-separation", type=positive_float, default=0.09,
                     help="minimum angle between two beams in degrees (default 0.09)")
    fit.add_argument("--origin-z", type=coordinate, default=0.0,
                     help="height of the optical centre above the LiDAR frame origin (m, default 0; the PandaSet "
                          "reader already puts the LiDAR frame at the measured optical centre); --align searches the "
                          "full offset (docs/lidar_sim.md)")
    fit.add_argument("--align", action="store_true",
                     help="first search the optical centre (offset from the LiDAR frame origin) and roll, pitch that "
                          "sharpen the beams (for sweeps not given in the optical-centre frame, e.g. PandaSet)")
    fit.add_argument("--no-capture-poses", dest="capture_poses", action="store_false",
                     help="measure elevations from the frame's pose, not from the sensor pose at each point's capture "
                          "time (interpolated between frames; needs per-point times)")
    fit.add_argument("--compare", default=None, metavar="PRESET", help="print a comparison with a preset")
    fit.set_defaults(func=run_fit)
    declare_outputs(fit, files=("out",))
    parser.set_defaults(func=lambda args: (parser.print_help(), 2)[1])
    return parser


def run_fit(args: argparse.Namespace) -> int:
    from tracker import invert_transform, transform_points

    from ..io.atomic import write_json
    from ..sensor.fit import compare_to_preset, fit_sensor, points_at_capture_pose
    from ..sensor.model import preset

    seq = load_sequence(args)
    try:
        frames = [int(f) for f in args.frames.split(",") if f.strip()]
    except ValueError:
        raise InputError(None, f"--frames must be comma-separated integers, got {args.frames!r}") from None
    lidar_from_ego = invert_transform(seq.ego_from_lidar)

    def world_from_lidar(k: int) -> np.ndarray:
        return seq.frames[k].world_from_ego @ seq.ego_from_lidar

    sweeps, times = [], []
    for k in frames:
        seq.check_index(k)
        sweep = seq.sweep(k)
        xyz = transform_points(lidar_from_ego, sweep.xyz)
        if args.capture_poses and sweep.time_offset_ns is not None and len(seq) > 1:
            other = k - 1 if k > 0 else k + 1
            xyz = points_at_capture_pose(xyz, sweep.time_offset_ns, seq.frames[k].timestamp_ns, world_from_lidar(k),
                                         seq.frames[other].timestamp_ns, world_from_lidar(other))
        sweeps.append(xyz - [0.0, 0.0, args.origin_z])
        times.append(sweep.time_offset_ns)
    alignment = None
    if args.align:
        from ..sensor.fit import align_sensor_frame

        sensor_from_frame, alignment = align_sensor_frame(sweeps)
        sweeps = [transform_points(sensor_from_frame, s) for s in sweeps]
        print(f"alignment: {json.dumps(alignment)}")
    try:
        result = fit_sensor(sweeps, times, name=args.name or f"fitted_{seq.id}", min_range=args.min_range,
                            min_separation_deg=args.min_separation)
    except ValueError as exc:
        raise InputError(args.sequence, f"sensor fit failed: {exc}") from exc
    doc = result.to_json()
    if alignment is not None:
        doc["fit"]["alignment"] = alignment
    if args.compare:
        doc["fit"]["comparison"] = compare_to_preset(result.sensor, preset(args.compare))
    if args.out:
        write_json(Path(args.out), doc)
    s = result.sensor
    print(f"{s.beams} beams, elevations {max(s.elevations_deg):+.3f} ... {min(s.elevations_deg):+.3f} deg, "
          f"azimuth step {result.azimuth_step_deg:.4f} deg ({s.columns} columns), {s.rotation_hz:g} Hz, "
          f"direction {s.direction:+d}, max range {s.max_range:g} m")
    if args.compare:
        print(json.dumps(doc["fit"]["comparison"]))
    expected = preset(args.compare).beams if args.compare else None
    if (expected is not None and s.beams != expected) or s.beams > MAX_PLAUSIBLE_BEAMS:
        reason = f"{args.compare} has {expected}" if expected is not None else f"no spinning LiDAR has more than {MAX_PLAUSIBLE_BEAMS}"
        sys.stderr.write(f"warning: fitted {s.beams} beams but {reason}: the sweeps are probably not in the sensor's "
                         f"optical-centre frame{'' if args.align else ' (try --align)'}\n")
    print(f"wrote {args.out}" if args.out else "not written (give --out SENSOR.json to keep the fitted sensor)")
    return 0
