"""Parametric vehicle meshes (sedan, SUV, van, truck) built from trimesh primitives.

Each mesh is in the object frame (x forward along the length, y left, z up) and centred so that its
axis-aligned bounds are exactly ``[-L/2, L/2] x [-W/2, W/2] x [-H/2, H/2]``: the ground-truth box is the
mesh's bounding box. Parts overlap (no boolean union is needed for ray casting).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

__all__ = ["VEHICLE_KINDS", "VehicleMesh", "make_vehicle", "random_vehicle"]

# (length, width, height) ranges in metres and the label written to annotations.
VEHICLE_KINDS: dict[str, dict] = {
    "sedan": {"length": (4.2, 4.9), "width": (1.75, 1.9), "height": (1.38, 1.5), "label": "Car"},
    "suv": {"length": (4.4, 5.0), "width": (1.85, 2.0), "height": (1.65, 1.85), "label": "Car"},
    "van": {"length": (4.8, 5.6), "width": (1.9, 2.05), "height": (1.95, 2.3), "label": "Van"},
    "truck": {"length": (6.5, 8.5), "width": (2.3, 2.5), "height": (2.8, 3.3), "label": "Truck"},
}


@dataclass(frozen=True)
class VehicleMesh:
    kind: str
    label: str
    vertices: np.ndarray  # (V, 3) float64, object frame
    faces: np.ndarray     # (F, 3) int64
    size: tuple[float, float, float]  # length, width, height (= mesh bounds)


def _box(extents, centre) -> trimesh.Trimesh:
    return trimesh.creation.box(extents=extents, transform=trimesh.transformations.translation_matrix(centre))


def _wheel(radius: float, width: float, centre) -> trimesh.Trimesh:
    wheel = trimesh.creation.cylinder(radius=radius, height=width, sections=16)
    wheel.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    wheel.apply_translation(centre)
    return wheel


def make_vehicle(kind: str, length: float, width: float, height: float) -> VehicleMesh:
    """A vehicle of the given kind whose bounding box is exactly (length, width, height)."""
    if kind not in VEHICLE_KINDS:
        raise ValueError(f"unknown vehicle kind {kind!r}; choose one of {', '.join(VEHICLE_KINDS)}")
    L, W, H = float(length), float(width), float(height)
    wheel_r = min(0.45, 0.16 * H + 0.1) if kind == "truck" else 0.32
    clearance = 0.6 * wheel_r
    body_w = W * 0.96
    parts: list[trimesh.Trimesh] = []
    if kind == "truck":
        cab_len = 0.28 * L
        parts.append(_box([cab_len, body_w, 0.78 * H - clearance], [L / 2 - cab_len / 2, 0, clearance + (0.78 * H - clearance) / 2]))
        cargo_len = L - cab_len - 0.15
        parts.append(_box([cargo_len, W, H - clearance - 0.1], [-L / 2 + cargo_len / 2, 0, clearance + 0.1 + (H - clearance - 0.1) / 2]))
        axles = [L / 2 - 0.6 * cab_len, -L / 2 + 0.2 * cargo_len, -L / 2 + 0.35 * cargo_len]
    else:
        if kind == "van":
            body_h, cabin_len, cabin_off, cabin_w = 0.45 * H, 0.78 * L, -0.08 * L, 0.95 * W
        elif kind == "suv":
            body_h, cabin_len, cabin_off, cabin_w = 0.5 * H, 0.62 * L, -0.1 * L, 0.88 * W
        else:
            body_h, cabin_len, cabin_off, cabin_w = 0.45 * H, 0.5 * L, -0.05 * L, 0.84 * W
        parts.append(_box([L, body_w, body_h - clearance], [0, 0, clearance + (body_h - clearance) / 2]))
        parts.append(_box([0.12 * L, W, 0.12], [0.3 * L, 0, body_h - 0.1]))  # mirrors / fender line: full width
        cabin_h = H - body_h
        parts.append(_box([cabin_len, cabin_w, cabin_h], [cabin_off, 0, body_h + cabin_h / 2]))
        if kind != "van":  # sloped windscreen and rear window as a narrower step
            parts.append(_box([0.15 * L, cabin_w * 0.95, cabin_h * 0.6],
                              [cabin_off + cabin_len / 2 + 0.07 * L, 0, body_h + cabin_h * 0.3]))
        axles = [0.33 * L, -0.32 * L]
    for ax in axles:
        for side in (1, -1):
            parts.append(_wheel(wheel_r, 0.24, [ax, side * (W / 2 - 0.16), wheel_r]))
    mesh = trimesh.util.concatenate(parts)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    # Stretch to the exact requested bounds (parts were laid out to nearly fit) and centre.
    vertices = (vertices - lo) / (hi - lo) * np.array([L, W, H]) - np.array([L, W, H]) / 2.0
    return VehicleMesh(kind, VEHICLE_KINDS[kind]["label"], vertices, np.asarray(mesh.faces, dtype=np.int64), (L, W, H))


def random_vehicle(rng: np.random.Generator, kind: str | None = None,
                   weights: tuple[float, ...] = (0.4, 0.3, 0.2, 0.1)) -> VehicleMesh:
    kinds = list(VEHICLE_KINDS)
    if kind is None:
        kind = kinds[int(rng.choice(len(kinds), p=np.asarray(weights) / np.sum(weights)))]
    spec = VEHICLE_KINDS[kind]
    size = [round(float(rng.uniform(*spec[k])), 3) for k in ("length", "width", "height")]
    return make_vehicle(kind, *size)
