"""Orchestration: for each image pair k -> k+1 of one camera, place the objects, compute and write flow.

Output layout (docs/flow.md), under ``OUT/<camera>/``, files named by k as six digits:
``flow_occ/``, ``flow_noc/`` (KITTI PNG), ``flo/`` (Middlebury, flow_occ), ``instances/`` (16-bit
PNG, 0 = none, object index + 1; mapping in ``instances.json``), ``vis/`` only when asked for
(``*_flow.png`` colour wheel, ``*_overlay.jpg``), ``pairs/`` (per-pair stats, written last) and ``stats.json``
(all finished pairs, data_schema/flow_stats.schema.json).

A pair's files are encoded and written on a small thread pool (:class:`PairWriter`) while the next pair is
computed; its ``pairs/`` record follows once all of them are in place. Every file is atomic (temporary file +
rename) but the pairs' files are not synced to the disk one by one (a file sync waits on the disk for ~10-30 ms):
a pair is finished when its record and its files are whole (:func:`pair_finished`), which a rerun checks, so a
pair whose files a power cut emptied is computed again. ``stats.json`` is synced.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from tracker import interpolate_pose, invert_transform, transform_points

from ..errors import InputError
from ..io.atomic import write_bytes, write_json
from ..io.sequence import Camera, Sequence
from .camera import CameraModel
from .dense import RayCache, dense_flow
from .flo_io import write_flo
from .kitti_io import write_kitti_flows
from .objects import MeshedObject
from .occlusion import ProjectedPoints, project_lidar
from .png import encode_png
from .scene import FlowObject, OcclusionParams, PairFlow, PairSetup, flow_magnitude

__all__ = ["FlowOptions", "camera_pose_at", "build_pair", "compute_pair", "annotate_camera", "write_pair_outputs",
           "pair_output_jobs", "pair_finished", "PairWriter", "STATS_VERSION"]

STATS_VERSION = 1
SUBDIRS = ("flow_occ", "flow_noc", "flo", "instances", "vis", "pairs")


@dataclass(frozen=True)
class FlowOptions:
    mode: str = "dense"
    occlusion: OcclusionParams = field(default_factory=OcclusionParams)
    use_lidar: bool = True
    write_vis: bool = False        # vis/ pictures (colour wheel PNG, overlay JPEG): off unless asked for
    exclusion_margin: float = 0.4
    writer_threads: int = 2        # threads encoding and writing finished pairs while the next one is computed


def camera_pose_at(seq: Sequence, camera: Camera, k: int) -> np.ndarray:
    """world_from_camera at camera frame k's own timestamp.

    A per-frame pose is used as given, except when it is just the LiDAR frame's ego pose times a
    rigid ``ego_from_camera`` (no pose of its own at the camera time): then the ego pose is
    interpolated to the camera timestamp.
    """
    frame = camera.frames[k]
    if camera.ego_from_camera is not None and len(seq.frames) > 1:
        derived = seq.frames[k].world_from_ego @ camera.ego_from_camera
        if np.allclose(derived, frame.world_from_camera, atol=1e-9):
            poses = np.stack([f.world_from_ego for f in seq.frames])
            return interpolate_pose(seq.timestamps_ns, poses, frame.timestamp_ns) @ camera.ego_from_camera
    return np.asarray(frame.world_from_camera, dtype=np.float64)


def _in_view(cam: np.ndarray, model: CameraModel, margin: float, min_depth: float, dtype: type) -> np.ndarray:
    """(N,) bool: the camera-frame points ``cam`` deeper than ``min_depth`` whose pinhole pixel (x / z * f + c, in
    ``dtype``, the array's own) lies within ``margin`` pixels of the image. One column at a time: the same
    operations per element as on the (N, 2) pixel array, at a third of the cost."""
    K = model.K
    z = cam[:, 2]
    inside = z > min_depth
    with np.errstate(divide="ignore", invalid="ignore"):
        for axis, size in ((0, model.width), (1, model.height)):
            pixel = cam[:, axis] / z
            pixel *= dtype(K[axis, axis])
            pixel += dtype(K[axis, 2])
            inside &= (pixel > -margin) & (pixel < size + margin)
    return inside


def _lidar_occluders(seq: Sequence, k: int, objects: list[MeshedObject], camera_from_world: np.ndarray,
                     model: CameraModel, margin: float) -> ProjectedPoints:
    """Frame k's points minus those in (or near) any tracked object during the sweep, projected."""
    if not 0 <= k < len(seq.frames):
        return ProjectedPoints.empty()
    # Only points the camera sees can occlude: cut to the view first (cheap), then remove object points.
    slack = 0.25 * max(model.width, model.height)  # generous: distortion may move points inwards
    xyz = seq.sweep(k).xyz
    if len(xyz) == 0:   # no sweep at this frame (or an empty one): no occluders
        return ProjectedPoints.empty()
    world_from_ego = seq.frames[k].world_from_ego
    # A float32 pass over the whole sweep keeps a superset of the view (margins far above float32 rounding);
    # the exact float64 test below then runs on that subset only, so the result is as if run on every point.
    cam32 = cv2.transform(np.ascontiguousarray(xyz, dtype=np.float32).reshape(1, -1, 3),
                          (camera_from_world @ world_from_ego)[:3]).reshape(-1, 3)
    near = slack + 16.0
    maybe = np.flatnonzero(_in_view(cam32, model, near, 0.45, np.float32))
    points = transform_points(world_from_ego, xyz[maybe])
    cam = transform_points(camera_from_world, points)
    points = points[_in_view(cam, model, slack, 0.5, np.float64)]
    keep = np.ones(len(points), dtype=bool)
    t_end = seq.frames[k].timestamp_ns
    for obj in objects:
        half = obj.extent() + margin
        for dt in (-100_000_000, -50_000_000, 0):
            pose = obj.trajectory.world_from_object_at(t_end + dt)
            if pose is None:
                continue
            # Cheap bounding-sphere test before the exact one.
            near = np.flatnonzero(keep & (np.sum((points - pose[:3, 3]) ** 2, axis=1) <= float(half @ half)))
            if len(near) == 0:
                continue
            local = transform_points(invert_transform(pose), points[near])
            keep[near[(np.abs(local) <= half).all(axis=1)]] = False
    return project_lidar(points[keep], camera_from_world, model)


def build_pair(seq: Sequence, camera: Camera, k: int, objects: list[MeshedObject], options: FlowOptions,
               lidar_cache: dict | None = None) -> tuple[PairSetup, list[FlowObject]]:
    """The pair's cameras, occluders and the objects present at camera k's time."""
    model = CameraModel.from_camera(camera)
    t0, t1 = camera.frames[k].timestamp_ns, camera.frames[k + 1].timestamp_ns
    pose_k, pose_k1 = camera_pose_at(seq, camera, k), camera_pose_at(seq, camera, k + 1)
    flow_objects = []
    for index, obj in enumerate(objects):
        wk = obj.trajectory.world_from_object_at(t0)
        if wk is None:
            continue
        flow_objects.append(FlowObject(index, obj.object_id, obj.mesh, wk, obj.trajectory.world_from_object_at(t1),
                                       obj.points, obj.label))
    lidar_k = lidar_k1 = None
    if options.use_lidar and flow_objects:
        cache = lidar_cache if lidar_cache is not None else {}

        def occluders(j: int, pose: np.ndarray) -> ProjectedPoints:
            if j not in cache:
                cache[j] = _lidar_occluders(seq, j, objects, invert_transform(pose), model, options.exclusion_margin)
                for old in [key for key in cache if key < j - 1]:
                    del cache[old]
            return cache[j]

        lidar_k, lidar_k1 = occluders(k, pose_k), occluders(k + 1, pose_k1)
    return PairSetup(model, pose_k, pose_k1, lidar_k, lidar_k1, options.occlusion), flow_objects


def compute_pair(setup: PairSetup, flow_objects: list[FlowObject], mode: str, ray_cache: RayCache | None = None) -> PairFlow:
    if mode == "dense":
        return dense_flow(setup, flow_objects, ray_cache)
    if mode == "sparse":
        from .sparse import sparse_flow  # imported by the mode that uses it (start-up of sot-apps flow)

        return sparse_flow(setup, flow_objects)
    raise ValueError(f"unknown mode {mode!r}")


def _write_encoded(path: Path, image: np.ndarray) -> None:
    """An image through ``cv2.imencode`` (format from the suffix) and a Python file write: any path works."""
    ok, data = cv2.imencode(path.suffix, image)
    if not ok:
        raise RuntimeError(f"cannot encode {path}")
    write_bytes(path, data.tobytes(), sync=False)


def _write_vis(root: Path, name: str, result: PairFlow, image: np.ndarray, image_path: Path) -> None:
    from .visualize import flow_to_color, overlay

    colour = flow_to_color(result.flow, result.valid_occ)   # RGB, black where there is no flow
    write_bytes(root / "vis" / f"{name}_flow.png", encode_png(colour, 0, result.valid_occ), sync=False)
    if image.shape[:2] != result.instance.shape:
        problem = (f"camera image is {image.shape[1]}x{image.shape[0]}, the camera model says "
                   f"{result.instance.shape[1]}x{result.instance.shape[0]}")
        sys.stderr.write(f"warning: {image_path}: {problem}; vis/{name}_overlay.jpg not written (the flow itself "
                         "does not use the image)\n")
    else:
        _write_encoded(root / "vis" / f"{name}_overlay.jpg", overlay(image, result.flow, result.valid_occ, result.instance))


def pair_output_jobs(root: Path, k: int, result: PairFlow, image_path: Path, write_vis: bool) -> list[Callable[[], None]]:
    """The independent file writes of pair k (each one atomic, none synced: :func:`pair_finished` checks them on a
    rerun), to run in any order or in parallel. With ``write_vis`` the camera image is decoded here, in the
    caller's thread: a damaged image is an error (InputError naming it) before any file of the pair is written,
    never drawn."""
    name = f"{k:06d}"
    image = None
    if write_vis:
        from ..io.images import read_color_image

        image = read_color_image(image_path)
    # flow_occ and flow_noc in one job: the non-occluded pixels are some of the valid ones, scaled once for both
    jobs = [lambda: write_kitti_flows(root / "flow_occ" / f"{name}.png", root / "flow_noc" / f"{name}.png",
                                      result.flow, result.valid_occ, result.valid_noc, sync=False),
            lambda: write_flo(root / "flo" / f"{name}.flo", result.flow, result.valid_occ, sync=False),
            lambda: write_bytes(root / "instances" / f"{name}.png", encode_png(result.instance, 0), sync=False)]
    if write_vis:
        jobs.append(lambda: _write_vis(root, name, result, image, image_path))
    return jobs


_PNG_END = b"\x00\x00\x00\x00IEND\xaeB`\x82"   # every PNG ends with this empty IEND chunk


def _png_whole(path: Path) -> bool:
    try:
        with open(path, "rb") as handle:
            handle.seek(-len(_PNG_END), os.SEEK_END)
            return handle.read() == _PNG_END
    except OSError:   # missing, or shorter than the chunk (an empty file)
        return False


def _read_record(path: Path, k: int) -> dict | None:
    """Pair k's record, or None when it is missing or not whole."""
    try:
        record = json.loads(path.read_bytes())
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) and record.get("frame") == k else None


def pair_finished(root: Path, k: int, width: int, height: int) -> dict | None:
    """Pair k's record when the pair is finished: its record and its default files (flow_occ, flow_noc, instances
    PNGs ending with their IEND chunk, the .flo of a ``width`` x ``height`` image at its full size) are whole. The
    files are written without a file sync, so a power cut may leave some empty; such a pair is computed again."""
    name = f"{k:06d}"
    record = _read_record(root / "pairs" / f"{name}.json", k)
    if record is None or not all(_png_whole(root / sub / f"{name}.png") for sub in ("flow_occ", "flow_noc", "instances")):
        return None
    try:
        return record if os.stat(root / "flo" / f"{name}.flo").st_size == 12 + 8 * width * height else None
    except OSError:
        return None


def write_pair_outputs(root: Path, k: int, result: PairFlow, image_path: Path, write_vis: bool) -> None:
    """The files of pair k under ``root``: KITTI flow_occ / flow_noc PNGs, .flo, the instance PNG, vis/."""
    for job in pair_output_jobs(root, k, result, image_path, write_vis):
        job()


class PairWriter:
    """Writes pairs' files on ``workers`` threads while the caller computes the next pair.

    zlib, numpy's copies and the file writes release the GIL (the PNG encoder's row loop does not). At most ``max_pending`` pairs wait (each holds
    its flow arrays, ~25 MB at 1080p). A pair's ``on_done`` (its ``pairs/`` record) runs in the caller's thread,
    in submission order, once all its files are in place. On an error or Ctrl-C, files not started are dropped
    and no record is written for an unfinished pair (each file is atomic, so nothing half-written remains).
    """

    def __init__(self, workers: int = 2, max_pending: int = 2):
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="flow-writer")
        self._pending: deque[tuple[list[Future], Callable[[], None]]] = deque()
        self._max_pending = max_pending

    def submit(self, jobs: list[Callable[[], None]], on_done: Callable[[], None]) -> None:
        self._pending.append(([self._pool.submit(job) for job in jobs], on_done))
        self._finish(block_until=self._max_pending)

    def _finish(self, block_until: int) -> None:
        while self._pending and (len(self._pending) > block_until or all(f.done() for f in self._pending[0][0])):
            futures, on_done = self._pending.popleft()
            wait(futures)
            for future in futures:
                future.result()   # the first error propagates
            on_done()

    def close(self) -> None:
        """Wait for every pair and run its ``on_done``."""
        self._finish(block_until=0)

    def __enter__(self) -> "PairWriter":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            try:
                self.close()
            finally:
                self._pool.shutdown(wait=True)
        else:
            self._pending.clear()
            self._pool.shutdown(wait=True, cancel_futures=True)


def _pair_record(k: int, camera: Camera, result: PairFlow, elapsed_ms: float) -> dict:
    objects = [s.to_dict() for s in result.objects]
    rows = np.flatnonzero(result.valid_occ.any(axis=1))
    if len(rows):   # the valid pixels in image order, found within the rows that hold them
        first, width = rows[0], result.valid_occ.shape[1]
        valid = np.flatnonzero(result.valid_occ[first:rows[-1] + 1]) + first * width
    else:
        valid = np.zeros(0, dtype=np.int64)
    mag = flow_magnitude(result.flow.reshape(-1, 2)[valid])
    pixels = len(valid)
    noc = int(np.count_nonzero(result.valid_noc))
    return {"frame": k, "frame_next": k + 1, "timestamp_ns": int(camera.frames[k].timestamp_ns),
            "timestamp_next_ns": int(camera.frames[k + 1].timestamp_ns), "pixels": pixels, "pixels_noc": noc,
            "mean_flow_px": round(float(mag.mean()), 4) if pixels else 0.0,
            "occluded_share": round(1.0 - noc / pixels, 6) if pixels else 0.0,
            "time_ms": round(elapsed_ms, 1), "objects": [o for o in objects if o["pixels"] > 0]}


def _check_instances(root: Path, mapping: list[dict]) -> None:
    path = root / "instances.json"
    doc = {"schema_version": STATS_VERSION, "instances": mapping}
    if path.is_file():
        try:
            existing = json.loads(path.read_bytes())
        except ValueError:
            existing = None
        if existing == doc:
            return
        if isinstance(existing, dict) and existing.get("instances") != mapping and any((root / "pairs").glob("*.json")):
            raise InputError(path, "this output directory holds pairs annotated with different objects; use a new --out")
    write_json(path, doc)


def annotate_camera(seq: Sequence, camera_name: str, objects: list[MeshedObject], out: str | Path,
                    pairs: tuple[int, int] | None = None, options: FlowOptions | None = None,
                    progress: bool = True, source: str = "") -> dict:
    """Annotate pairs k -> k+1 for A <= k < B of one camera; returns the stats document."""
    options = options or FlowOptions()
    if camera_name not in seq.cameras:
        raise InputError(seq.root, f"no camera {camera_name!r}; cameras: {', '.join(seq.cameras) or 'none'}")
    camera = seq.cameras[camera_name]
    last = len(camera.frames) - 1
    a, b = pairs if pairs is not None else (0, last)
    if not (0 <= a < b <= last):
        raise InputError(seq.root, f"--pairs {a}:{b} is out of range: camera {camera_name} has pairs 0..{last}"
                                   f" (A:B with 0 <= A < B <= {last})")
    root = Path(out) / camera_name
    model = CameraModel.from_camera(camera)
    mapping = [{"value": i + 1, "object_id": o.object_id, "label": o.label, "source": o.source}
               for i, o in enumerate(objects)]
    _check_instances(root, mapping)
    ray_cache, lidar_cache = RayCache(), {}
    with PairWriter(workers=options.writer_threads) as writer:
        if progress:   # tqdm only when it shows something (its import costs ~45 ms of start-up)
            from tqdm import tqdm

            steps = tqdm(range(a, b), desc=f"flow {camera_name}", unit="pair")
        else:
            steps = range(a, b)
        for k in steps:
            if pair_finished(root, k, model.width, model.height) is not None:
                continue
            start = time.perf_counter()
            setup, flow_objects = build_pair(seq, camera, k, objects, options, lidar_cache)
            result = compute_pair(setup, flow_objects, options.mode, ray_cache)
            elapsed = (time.perf_counter() - start) * 1e3
            record = _pair_record(k, camera, result, elapsed)
            missing = [j for j in (k, k + 1) if j < len(seq.frames) and not seq.frames[j].has_sweep]
            if missing:  # no sweep: no lidar occluders at that frame (the flow itself comes from the object states)
                record["no_lidar_sweep"] = missing
            writer.submit(pair_output_jobs(root, k, result, camera.frames[k].image_path, options.write_vis),
                          lambda path=root / "pairs" / f"{k:06d}.json", record=record: write_json(path, record,
                                                                                                 sync=False))
    return write_stats(root, seq.id, camera_name, options.mode, source, mapping, (model.width, model.height))


def write_stats(root: Path, sequence_id: str, camera_name: str, mode: str, source: str, mapping: list[dict],
                size: tuple[int, int]) -> dict:
    """Gather the records of the finished pairs (:func:`pair_finished`; ``size``: the images' width and height)
    into ``stats.json`` (validated against its schema, synced)."""
    records = []
    for path in sorted((root / "pairs").glob("*.json")):
        k = int(path.stem) if path.stem.isdigit() else -1
        record = pair_finished(root, k, *size) if k >= 0 else None
        if record is not None:
            records.append(record)
    totals: dict[str, dict] = {}
    for rec in records:
        for o in rec["objects"]:
            t = totals.setdefault(o["object_id"], {"object_id": o["object_id"], "index": o["index"], "pairs": 0,
                                                    "pixels": 0, "pixels_noc": 0, "_flow_sum": 0.0})
            t["pairs"] += 1
            t["pixels"] += o["pixels"]
            t["pixels_noc"] += o["pixels_noc"]
            t["_flow_sum"] += o["mean_flow_px"] * o["pixels"]
    objects = []
    for t in sorted(totals.values(), key=lambda d: d["index"]):
        flow_sum = t.pop("_flow_sum")
        t["mean_flow_px"] = round(flow_sum / t["pixels"], 4) if t["pixels"] else 0.0
        t["occluded_share"] = round(1.0 - t["pixels_noc"] / t["pixels"], 6) if t["pixels"] else 0.0
        objects.append(t)
    doc = {"schema_version": STATS_VERSION, "sequence": sequence_id, "camera": camera_name, "mode": mode, "source": source,
           "instances": mapping, "pairs": records, "objects": objects}
    from ..schemas import validate

    validate("flow_stats", doc, root / "stats.json")
    write_json(root / "stats.json", doc)
    return doc
