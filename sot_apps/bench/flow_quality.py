"""Flow quality measurements (``sot-apps bench flow``): they run the flow app, the tracker and OpenCV's
baselines and score the results with :mod:`sot_apps.evaluation.flow`.

(a) ``synthetic_quality``: a synthetic world with rendered camera images (``sot_apps.synth``).
    The exact flow comes from the ground-truth meshes and 1 ms trajectories, with the static world
    (walls, poles, ground) as occluders. Compared on vehicle pixels visible in both images: our
    annotation from ground-truth boxes (10 Hz, shapes from the simulated LiDAR points), from tracker
    states (SOTracker run from the first GT box), and OpenCV's DIS and Farneback flow on the rendered
    image pairs. Metrics: EPE (mean end-point error, px) and Fl (share of pixels with EPE > 3 px AND
    > 5 % of the true flow magnitude), plus coverage (share of the true object pixels that get a value).
(b) ``photometric_quality``: real image pairs. Image k+1 is warped into k with a flow over the
    annotated object pixels (cv2.remap); the mean absolute grey-level difference to image k is
    reported for our flow, zero flow and DIS flow on the same pixels.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:   # the module is imported by `sot-apps bench --help`: the libraries load when a measurement runs
    from ..flow.annotate import FlowOptions
    from ..flow.objects import MeshedObject
    from ..io.sequence import Sequence
    from ..objects.trajectory import Trajectory

__all__ = ["classical_flow", "synthetic_quality", "photometric_quality", "tracker_objects"]


def classical_flow(image_k: np.ndarray, image_k1: np.ndarray, method: str) -> np.ndarray:
    """(H, W, 2) float32 flow k -> k+1 by OpenCV's DIS (medium preset) or Farneback."""
    import cv2

    g0 = cv2.cvtColor(image_k, cv2.COLOR_BGR2GRAY) if image_k.ndim == 3 else image_k
    g1 = cv2.cvtColor(image_k1, cv2.COLOR_BGR2GRAY) if image_k1.ndim == 3 else image_k1
    if method == "dis":
        return cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM).calc(g0, g1, None)
    if method == "farneback":
        return cv2.calcOpticalFlowFarneback(g0, g1, None, 0.5, 5, 15, 3, 5, 1.2, 0)
    raise ValueError(method)


def _static(times: np.ndarray, state: np.ndarray) -> Trajectory:
    from ..objects.trajectory import CAMERA_EXTRAPOLATION_NS, Trajectory

    return Trajectory.from_samples([int(times.min()) - 10**9, int(times.max()) + 10**9], [state, state], "extrapolate",
                                   CAMERA_EXTRAPOLATION_NS)


def _gt_objects(world) -> tuple[list[MeshedObject], int]:
    """Exact vehicles (1 ms trajectories, GT meshes) followed by the static world as occluders."""
    from ..flow.objects import MeshedObject
    from ..objects.meshes import Mesh
    from ..objects.trajectory import Trajectory

    times = world.ego.times_ns
    out = []
    for o in world.objects:
        traj = o.trajectory
        trajectory = (_static(times, traj.states[0]) if traj.is_static
                      else Trajectory.from_samples(traj.times_ns, traj.states, "extrapolate", 0))
        mesh = Mesh(np.asarray(o.vertices, float), np.asarray(o.faces, np.int32))
        out.append(MeshedObject.from_trajectory(o.id, o.label, trajectory, mesh.vertices, mesh, np.asarray(o.size, float),
                                                "gt"))
    for i, b in enumerate(world.background):
        mesh = Mesh(np.asarray(b.vertices, float), np.asarray(b.faces, np.int32))
        state = b.trajectory.states[0]
        out.append(MeshedObject.from_trajectory(f"static_{b.name}_{i}", "static", _static(times, state), mesh.vertices,
                                                mesh, np.ptp(mesh.vertices, axis=0), "gt"))
    return out, len(world.objects)


def tracker_objects(seq: Sequence, vehicle_ids: list[str], frames: range | None = None,
                    mesh_method: str = "hull", box_time: str = "points") -> list[MeshedObject]:
    """SOTracker run on each vehicle from its first ground-truth box within ``frames``.

    Each estimate is stamped with the median capture time of the sweep points inside its box (the
    tracker fits the unmotion-compensated points, so its state describes the object when the beam
    passed it, as PandaSet's boxes do). The first estimate is the ground-truth start box: it keeps
    the boxes' own time convention ``box_time`` ("frame" for ``sot-apps synth``, "points" for PandaSet).
    """
    from tracker import points_in_box, track, transform_points

    from ..flow.objects import MeshedObject, mesh_for
    from ..objects.shapes import box_capture_time
    from ..objects.trajectory import CAMERA_EXTRAPOLATION_NS, Trajectory

    out = []
    tracks = seq.tracks()
    for vid in vehicle_ids:
        gt = tracks[vid]
        ks = [int(k) for k in gt.frames if frames is None or k in frames]
        if len(ks) < 2:
            continue
        result = track(seq, gt.box_at(ks[0]), start=ks[0], end=ks[-1])
        times, states = [], []
        for i, e in enumerate(result.estimates):
            stamp = seq.frames[e.frame].timestamp_ns
            sweep = seq.sweep(e.frame)
            if sweep.time_offset_ns is not None and (i > 0 or box_time == "points"):
                inside = points_in_box(transform_points(seq.frames[e.frame].world_from_ego, sweep.xyz), e.box)
                stamp = box_capture_time(stamp, sweep.time_offset_ns[inside], 3)
            times.append(stamp)
            states.append(e.state.to_array())
        size = np.asarray(result.size, float)
        trajectory = Trajectory.from_samples(times, states, "extrapolate", CAMERA_EXTRAPOLATION_NS)
        out.append(MeshedObject.from_trajectory(vid, gt.label, trajectory, result.shape,
                                                mesh_for(result.shape, size, mesh_method), size, "tracker"))
    return out


def synthetic_quality(world_dir: str | Path, frames: int = 8, vehicles: int = 4, seed: int = 0,
                      camera_size: tuple[int, int] = (960, 540), sensor: str = "pandar64", with_tracker: bool = True,
                      progress: bool = True) -> dict:
    """Build (or reuse) a synthetic world with camera images and score every method (see module doc)."""
    import cv2
    from tqdm import tqdm

    from ..evaluation.flow import flow_errors
    from ..flow.annotate import FlowOptions, build_pair, compute_pair
    from ..flow.dense import RayCache
    from ..flow.objects import objects_from_annotations
    from ..io import open_sequence
    from ..synth import make_world, write_world

    world_dir = Path(world_dir)
    world = make_world(frames=frames, vehicles=vehicles, sensor=sensor, seed=seed, cameras=True, camera_size=camera_size)
    if not (world_dir / "sequence.json").is_file():
        write_world(world_dir, world=world, progress=progress)
    seq = open_sequence(world_dir)
    camera = seq.cameras["front_camera"]
    gt_objects, n_vehicles = _gt_objects(world)
    vehicle_ids = [o.id for o in world.objects]
    methods: dict[str, list[MeshedObject]] = {
        "ours (GT boxes)": objects_from_annotations(seq, vehicle_ids, box_time="frame", progress=False)}
    if with_tracker:
        moving = [o.id for o in world.objects if o.moving]
        parked = [o for o in methods["ours (GT boxes)"] if o.object_id not in moving]
        methods["ours (tracker states)"] = tracker_objects(seq, moving, box_time="frame") + parked
    totals: dict[str, dict[str, dict[str, float]]] = {"all_vehicles": {}, "moving_vehicles": {}}
    cache = RayCache()
    pairs = []
    moving_values = [i + 1 for i, o in enumerate(world.objects) if o.moving]
    iterator = range(len(camera.frames) - 1)
    for k in tqdm(iterator, desc="flow quality (synthetic)", unit="pair", disable=not progress, leave=False):
        setup, fobjs = build_pair(seq, camera, k, gt_objects, FlowOptions(use_lidar=False))
        gt = compute_pair(setup, fobjs, "dense", cache)
        vehicle = (gt.instance >= 1) & (gt.instance <= n_vehicles)
        truth = {"all_vehicles": gt.valid_noc & vehicle,
                 "moving_vehicles": gt.valid_noc & vehicle & np.isin(gt.instance, moving_values)}
        estimates = {}
        for name, objs in methods.items():
            setup_o, fo = build_pair(seq, camera, k, objs, FlowOptions())
            res = compute_pair(setup_o, fo, "dense", cache)
            # Our instance values follow the objects' order; map them to GT values by object id.
            value_of = {o.object_id: i + 1 for i, o in enumerate(gt_objects)}
            lut = np.zeros(len(objs) + 1, np.int64)
            for i, o in enumerate(objs):
                lut[i + 1] = value_of[o.object_id]
            claimed = res.valid_occ
            wrong = claimed & (lut[res.instance] != gt.instance)
            estimates[name] = (res.flow, res.valid_occ, int(claimed.sum()), int(wrong.sum()))
        img0 = cv2.imread(str(camera.frames[k].image_path), cv2.IMREAD_COLOR)
        img1 = cv2.imread(str(camera.frames[k + 1].image_path), cv2.IMREAD_COLOR)
        everywhere = np.ones(vehicle.shape, bool)
        estimates["DIS (OpenCV)"] = (classical_flow(img0, img1, "dis"), everywhere, None, None)
        estimates["Farneback (OpenCV)"] = (classical_flow(img0, img1, "farneback"), everywhere, None, None)
        record = {"pair": k, "vehicle_pixels": int(truth["all_vehicles"].sum())}
        for name, (flow, valid, claimed, wrong) in estimates.items():
            for key, mask in truth.items():
                s = flow_errors(flow, valid, gt.flow, mask, name)
                acc = totals[key].setdefault(name, {"epe_sum": 0.0, "fl_sum": 0.0, "pixels": 0, "truth": 0,
                                                    "claimed": 0, "wrong": 0, "has_claims": claimed is not None})
                acc["epe_sum"] += s.epe * s.pixels
                acc["fl_sum"] += s.fl * s.pixels
                acc["pixels"] += s.pixels
                acc["truth"] += int(mask.sum())
                if claimed is not None and key == "all_vehicles":
                    acc["claimed"] += claimed
                    acc["wrong"] += wrong
                if key == "all_vehicles":
                    record[name] = {"epe": round(s.epe, 4), "fl": round(s.fl, 5), "coverage": round(s.coverage, 4)}
        pairs.append(record)

    def rows(table: dict) -> list[dict]:
        out = []
        for name, a in table.items():
            n = max(a["pixels"], 1)
            out.append({"method": name, "epe": round(a["epe_sum"] / n, 3), "fl_percent": round(100 * a["fl_sum"] / n, 2),
                        "coverage_percent": round(100 * a["pixels"] / max(a["truth"], 1), 1), "pixels": a["pixels"],
                        "wrong_percent": (round(100 * a["wrong"] / max(a["claimed"], 1), 1)
                                          if a["has_claims"] and a["claimed"] else None)})
        return out

    return {"world": str(world_dir), "frames": frames, "vehicles": vehicles, "seed": seed,
            "camera_size": list(camera_size), "pairs": len(pairs), "all_vehicles": rows(totals["all_vehicles"]),
            "moving_vehicles": rows(totals["moving_vehicles"]), "per_pair": pairs}


def photometric_quality(seq: Sequence, camera_name: str, objects: list[MeshedObject], pairs: range,
                        options: FlowOptions | None = None) -> dict:
    """Mean |I_k - warp(I_k+1)| (grey levels) over annotated non-occluded object pixels, per flow."""
    import cv2

    from ..evaluation.flow import warp_abs_difference
    from ..flow.annotate import FlowOptions, build_pair, compute_pair
    from ..flow.dense import RayCache

    options = options or FlowOptions(write_vis=False)
    camera = seq.cameras[camera_name]
    cache = RayCache()
    names = ("ours", "zero flow", "DIS (OpenCV)")
    regions = ("all", "interior")
    sums = {(r, n): 0.0 for r in regions for n in names}
    counts = {r: 0 for r in regions}
    per_pair = []
    for k in pairs:
        setup, fobjs = build_pair(seq, camera, k, objects, options)
        res = compute_pair(setup, fobjs, options.mode, cache)
        masks = {"all": res.valid_noc,
                 # 5 px away from any mask boundary: separates silhouette errors from motion errors.
                 "interior": res.valid_noc & (cv2.erode(res.valid_noc.astype(np.uint8), np.ones((11, 11), np.uint8)) > 0)}
        if not masks["all"].any():
            continue
        g0 = cv2.imread(str(camera.frames[k].image_path), cv2.IMREAD_GRAYSCALE)
        g1 = cv2.imread(str(camera.frames[k + 1].image_path), cv2.IMREAD_GRAYSCALE)
        dis = classical_flow(g0, g1, "dis")
        flows = {"ours": res.flow, "zero flow": np.zeros_like(res.flow), "DIS (OpenCV)": dis}
        rec = {"pair": k, "pixels": int(masks["all"].sum()), "interior_pixels": int(masks["interior"].sum())}
        for name, flow in flows.items():
            diff = warp_abs_difference(g0, g1, flow)
            for region, mask in masks.items():
                if mask.any():
                    sums[(region, name)] += float(diff[mask].sum())
            rec[name] = round(float(diff[masks["all"]].mean()), 3)
        for region, mask in masks.items():
            counts[region] += int(mask.sum())
        per_pair.append(rec)
    return {"camera": camera_name, "pairs": len(per_pair), "pixels": counts["all"], "interior_pixels": counts["interior"],
            "mean_abs_error": {n: round(sums[("all", n)] / max(counts["all"], 1), 3) for n in names},
            "mean_abs_error_interior": {n: round(sums[("interior", n)] / max(counts["interior"], 1), 3) for n in names},
            "per_pair": per_pair}
