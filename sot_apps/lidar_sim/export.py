"""Writers for simulated scans: npz, KITTI ``.bin``, PCD, PLY, boxes JSON and KITTI labels.

KITTI label convention (``labels_kitti.txt``), one line per object::

    type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y

in KITTI's rectified CAMERA frame (x right, y down, z forward) with the camera at the LiDAR origin and no
rectification: ``x_cam = -y_lidar``, ``y_cam = -z_lidar``, ``z_cam = x_lidar``. ``(x, y, z)`` is the centre
of the box's BOTTOM face (``y_cam = -(z_centre - h/2)``), ``rotation_y = -heading - pi/2`` (wrapped; the
rotation about the camera's y axis, 0 = facing camera x), ``alpha = rotation_y - atan2(x, z)``. No image
exists, so the 2D box is written as ``-1 -1 -1 -1``. KITTI labels have no roll or pitch: a tilted vehicle's
label is its level box (``boxes.json`` keeps ``roll`` and ``pitch``). ``truncated`` and ``occluded`` say what
the LiDAR saw (``sot_apps.lidar_sim.visibility``: share of the box outside the field of view; KITTI occlusion
level from the share of its unoccluded returns it got); a vehicle with no return is left out of the labels
(``boxes.json`` keeps it with ``"visible": false``). ``.bin`` is KITTI's Velodyne layout: float32 x, y, z, intensity (intensity in [0, 1]).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from tracker import Box, wrap_angle

from ..io.atomic import write_bytes, write_json, write_npz, write_text
from ..io.ply import write_ply_points
from ..sensor.scan import Scan
from .visibility import Visibility

__all__ = ["write_scan_npz", "write_bin", "write_pcd", "write_ply", "kitti_label_lines", "write_boxes",
           "FORMATS"]

FORMATS = ("bin", "pcd", "ply")


def write_scan_npz(path: Path, scan: Scan, organised: bool = True) -> None:
    arrays = {"xyz": scan.xyz.astype(np.float32), "instance": scan.instance.astype(np.int32),
              "intensity": scan.intensity.astype(np.float32), "time_offset_ns": scan.time_offset_ns.astype(np.int64),
              "beam": scan.beam.astype(np.int32), "column": scan.column.astype(np.int32),
              "range": scan.distance.astype(np.float32)}
    if organised and scan.num_beams and (scan.beam >= 0).any():
        sim = scan.beam >= 0
        image = np.zeros((scan.num_beams, scan.num_columns), np.float32)
        inst = np.full((scan.num_beams, scan.num_columns), -1, np.int32)
        image[scan.beam[sim], scan.column[sim]] = scan.distance[sim]
        inst[scan.beam[sim], scan.column[sim]] = scan.instance[sim]
        arrays["range_image"] = image
        arrays["instance_image"] = inst
    write_npz(path, level=1, **arrays)   # deflate level 1: about half the default level's time, 6 % larger


def write_bin(path: Path, scan: Scan) -> None:
    table = np.column_stack([scan.xyz.astype(np.float32), scan.intensity.astype(np.float32)])
    write_bytes(path, np.ascontiguousarray(table, dtype="<f4").tobytes())


def write_pcd(path: Path, scan: Scan) -> None:
    """Binary PCD v0.7: x y z intensity (float32), instance (int32)."""
    n = len(scan)
    table = np.empty(n, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4"), ("instance", "<i4")])
    table["x"], table["y"], table["z"] = scan.xyz[:, 0], scan.xyz[:, 1], scan.xyz[:, 2]
    table["intensity"] = scan.intensity
    table["instance"] = scan.instance
    header = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z intensity instance\n"
              "SIZE 4 4 4 4 4\nTYPE F F F F I\nCOUNT 1 1 1 1 1\n"
              f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary\n")
    write_bytes(path, header.encode("ascii") + table.tobytes())


def write_ply(path: Path, scan: Scan) -> None:
    write_ply_points(path, scan.xyz, intensity=scan.intensity.astype(np.float32),
                     instance=scan.instance.astype(np.int32))


def kitti_label_lines(boxes: list[Box], labels: list[str], visibility: list[Visibility] | None = None) -> list[str]:
    """KITTI label lines; with ``visibility``, invisible vehicles are left out and the others carry their
    truncation and occlusion level (without: truncated 0, occluded 0)."""
    lines = []
    for i, (box, label) in enumerate(zip(boxes, labels, strict=True)):
        truncated, occluded = 0.0, 0
        if visibility is not None:
            if not visibility[i].visible:
                continue
            truncated, occluded = visibility[i].truncated, visibility[i].occluded
        x_cam, y_cam, z_cam = -box.y, -(box.z - box.height / 2.0), box.x
        rot_y = float(wrap_angle(-box.heading - math.pi / 2.0))
        alpha = float(wrap_angle(rot_y - math.atan2(x_cam, z_cam)))
        kitti_type = label if label in ("Car", "Van", "Truck", "Pedestrian", "Cyclist", "Tram", "Misc") else "Car"
        lines.append(f"{kitti_type} {truncated:.2f} {occluded:d} {alpha:.4f} -1 -1 -1 -1 {box.height:.4f} {box.width:.4f} {box.length:.4f} "
                     f"{x_cam:.4f} {y_cam:.4f} {z_cam:.4f} {rot_y:.4f}")
    return lines


def write_boxes(out_dir: Path, boxes: list[Box], labels: list[str], bank_ids: list[str],
                visibility: list[Visibility]) -> None:
    """``boxes.json`` (every placed vehicle, with what the sensor saw of it) and ``labels_kitti.txt``
    (the vehicles that got returns)."""
    doc = {"version": 1, "frame": "sensor", "boxes": [
        {"index": i, "bank_id": b_id, "label": lab, "x": b.x, "y": b.y, "z": b.z, "heading": b.heading,
         "length": b.length, "width": b.width, "height": b.height, "roll": b.roll, "pitch": b.pitch, **v.to_json()}
        for i, (b, lab, b_id, v) in enumerate(zip(boxes, labels, bank_ids, visibility, strict=True))]}
    write_json(out_dir / "boxes.json", doc)
    lines = kitti_label_lines(boxes, labels, visibility)
    write_text(out_dir / "labels_kitti.txt", "\n".join(lines) + ("\n" if lines else ""))
