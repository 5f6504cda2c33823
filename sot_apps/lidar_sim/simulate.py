"""``simulate-lidar`` as a library call: scene (+ optional background sweep) -> files in a directory."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tracker import invert_transform, transform_points

from ..io.atomic import write_json
from ..objects.bank import Bank
from ..sensor.preview import write_bev_png, write_object_gallery
from .export import write_bin, write_boxes, write_pcd, write_ply, write_scan_npz
from .scene import SceneSpec, SimResult, insert_into_background, simulate_scene

__all__ = ["SimulationOutputs", "run_simulation"]


@dataclass
class SimulationOutputs:
    result: SimResult
    files: list[Path]


def run_simulation(spec: SceneSpec, bank: Bank, out: Path, formats: tuple[str, ...] = (),
                   background=None, frame: int = 0, preview_extent: float = 50.0) -> SimulationOutputs:
    """Simulate and write DIR/scan.npz, boxes.json, labels_kitti.txt, preview.png, objects.png, scene.json (+ formats).

    ``background`` is a Sequence: its frame ``frame`` (in the LiDAR frame: ego points mapped through
    ``inv(ego_from_lidar)``) becomes the background sweep.
    """
    out = Path(out)
    if background is not None:
        sweep = background.sweep(frame)
        lidar_from_ego = invert_transform(background.ego_from_lidar)
        xyz = transform_points(lidar_from_ego, sweep.xyz)
        result = insert_into_background(spec, bank, xyz, sweep.intensity, sweep.time_offset_ns)
    else:
        result = simulate_scene(spec, bank)
    scan = result.scan
    files = [out / "scan.npz", out / "boxes.json", out / "labels_kitti.txt", out / "preview.png", out / "scene.json"]
    write_scan_npz(out / "scan.npz", scan)
    write_boxes(out, result.boxes, result.labels, [o.bank_id for o in result.objects], result.visibility)
    write_bev_png(out / "preview.png", scan.xyz, scan.instance, result.boxes, extent=preview_extent)
    if result.boxes:
        write_object_gallery(out / "objects.png", scan.xyz, scan.instance, result.boxes)
        files.append(out / "objects.png")
    doc = spec.to_json()
    doc["sensor"] = spec.sensor.name
    if background is not None:
        doc["background"] = {"sequence": str(background.root), "frame": int(frame),
                             "removed_background_points": result.removed_background,
                             "removed_vehicle_points": result.removed_vehicle}
    write_json(out / "scene.json", doc)
    writers = {"bin": (write_bin, "scan.bin"), "pcd": (write_pcd, "scan.pcd"), "ply": (write_ply, "scan.ply")}
    for fmt in formats:
        writer, name = writers[fmt]
        writer(out / name, scan)
        files.append(out / name)
    return SimulationOutputs(result, files)


def counts_table(result: SimResult) -> list[str]:
    lines = ["index  bank_id                          range_m  heading_deg  points  visible  occluded  truncated"]
    for i, (o, b, v) in enumerate(zip(result.objects, result.boxes, result.visibility, strict=True)):
        lines.append(f"{i:5d}  {o.bank_id:31s}  {np.hypot(b.x, b.y):7.1f}  {np.degrees(b.heading):11.1f}  "
                     f"{v.num_points:6d}  {100 * v.visible_share:6.0f}%  "
                     f"{v.occluded if v.visible else '-':>8}  {v.truncated:9.2f}")
    hidden = sum(not v.visible for v in result.visibility)
    if hidden:
        lines.append(f"{hidden} of {len(result.visibility)} vehicles got no return: left out of labels_kitti.txt, "
                     "kept in boxes.json with \"visible\": false")
    return lines
