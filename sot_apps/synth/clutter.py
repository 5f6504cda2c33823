"""Roadside clutter for the synthetic worlds: what a model-free detector must learn NOT to call a vehicle.

Real streets put vehicle-sized, vehicle-high things next to the parked cars: bushes and hedges (round,
porous, returns all through the footprint), trees (a trunk and a canopy that reaches down into the
vehicles' height band), building corners (two walls at a right angle: an L-shape like a car's), kiosks and
utility boxes (box-shaped but small or too tall), pedestrians. None of them is annotated: they are
background (instance -1). All lie on the sidewalk band ``|y|`` in [``inner``, ``outer``] (beyond the parked
cars at ~10 m, before the walls at 13.5-15 m), or, for building corners, reach from it through the walls'
line. Meshes are static and closed; sizes are drawn per object.
"""

from __future__ import annotations

import numpy as np

from ..interrupts import import_trimesh
from ..objects.meshes import box_mesh
from ..objects.trajectory import Trajectory
from ..sensor.scan import SimObject

__all__ = ["CLUTTER_KINDS", "clutter_objects"]

CLUTTER_KINDS = ("bush", "hedge", "tree", "corner", "kiosk", "pedestrian")


def _static(vertices: np.ndarray, faces: np.ndarray, name: str, reflectivity: float) -> SimObject:
    return SimObject(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64),
                     Trajectory.static(0, 0, 0, 0), -1, reflectivity, name)


def _blob(rng: np.random.Generator, size: np.ndarray, centre: np.ndarray, roughness: float = 0.15):
    """An ellipsoid of the given full ``size`` (3,) with its vertices pushed in and out (foliage)."""
    trimesh = import_trimesh()
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    v = np.asarray(sphere.vertices) * (1.0 + rng.uniform(-roughness, roughness, (len(sphere.vertices), 1)))
    return v * (0.5 * size) + centre, np.asarray(sphere.faces)


def _box(extents, centre) -> tuple[np.ndarray, np.ndarray]:
    mesh = box_mesh(*(float(e) for e in extents))
    return mesh.vertices + np.asarray(centre, dtype=np.float64), mesh.faces


def _merge(parts: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    vertices, faces, offset = [], [], 0
    for v, f in parts:
        vertices.append(v)
        faces.append(f + offset)
        offset += len(v)
    return np.vstack(vertices), np.vstack(faces)


def _item(rng: np.random.Generator, kind: str, x: float, side: float, inner: float, outer: float) -> SimObject:
    y = side * rng.uniform(inner, outer)
    if kind == "bush":
        size = np.array([rng.uniform(1.2, 4.5), rng.uniform(0.8, 1.6), rng.uniform(0.9, 2.2)])
        v, f = _blob(rng, size, np.array([x, y, 0.45 * size[2]]))
        return _static(v, f, kind, 0.25)
    if kind == "hedge":   # a long, uneven box: many small blobs in a row
        length = rng.uniform(3.0, 9.0)
        width, height = rng.uniform(0.6, 1.3), rng.uniform(1.0, 2.0)
        n = max(2, int(length / 1.2))
        parts = [_blob(rng, np.array([1.6 * length / n, width, height]) * rng.uniform(0.85, 1.15, 3),
                       np.array([x - 0.5 * length + (i + 0.5) * length / n, y, 0.45 * height]), 0.1)
                 for i in range(n)]
        return _static(*_merge(parts), kind, 0.25)
    if kind == "tree":
        trimesh = import_trimesh()
        trunk_h = rng.uniform(1.8, 3.2)
        trunk = trimesh.creation.cylinder(radius=rng.uniform(0.12, 0.3), height=trunk_h, sections=10)
        crown = np.array([rng.uniform(2.5, 5.0), rng.uniform(2.5, 5.0), rng.uniform(2.0, 4.0)])
        canopy = _blob(rng, crown, np.array([x, y, trunk_h + 0.35 * crown[2]]), 0.2)
        return _static(*_merge([(np.asarray(trunk.vertices) + [x, y, 0.5 * trunk_h], np.asarray(trunk.faces)),
                                canopy]), kind, 0.3)
    if kind == "corner":   # a building corner: a wall along the street and one going away from it
        along, away = rng.uniform(2.0, 7.0), rng.uniform(1.5, 4.0)
        height, t = rng.uniform(2.5, 5.0), 0.3
        sign = rng.choice([-1.0, 1.0])
        front = _box([along, t, height], [x, y, 0.5 * height])
        back = _box([t, away, height], [x + sign * 0.5 * (along - t), y + side * 0.5 * (away - t), 0.5 * height])
        return _static(*_merge([front, back]), kind, 0.4)
    if kind == "kiosk":    # utility boxes, kiosks, bins: box-shaped, small or too tall for a car
        size = np.array([rng.uniform(0.6, 2.5), rng.uniform(0.5, 1.6), rng.uniform(1.0, 2.8)])
        v, f = _box(size, [x, y, 0.5 * size[2]])
        yaw = rng.uniform(-0.2, 0.2)
        c, s = np.cos(yaw), np.sin(yaw)
        v[:, :2] = (v[:, :2] - [x, y]) @ np.array([[c, s], [-s, c]]) + [x, y]
        return _static(v, f, kind, 0.5)
    # pedestrian: a body and a head
    trimesh = import_trimesh()
    h = rng.uniform(1.5, 1.9)
    body = trimesh.creation.cylinder(radius=0.2, height=0.8 * h, sections=8)
    head = _blob(rng, np.full(3, 0.22), np.array([x, y, 0.9 * h]), 0.0)
    return _static(*_merge([(np.asarray(body.vertices) + [x, y, 0.4 * h], np.asarray(body.faces)), head]), kind, 0.4)


def clutter_objects(rng: np.random.Generator, x_min: float, x_max: float, spacing: float = 8.0,
                    inner: float = 12.0, outer: float = 13.0) -> list[SimObject]:
    """Clutter along both sides of the road between ``x_min`` and ``x_max``, one item every ``spacing`` metres
    on average per side (a random kind of :data:`CLUTTER_KINDS`, bushes and hedges most often)."""
    weights = np.array([0.25, 0.2, 0.2, 0.15, 0.12, 0.08])
    out = []
    for side in (1.0, -1.0):
        x = x_min + rng.uniform(0.0, spacing)
        while x < x_max:
            kind = str(rng.choice(CLUTTER_KINDS, p=weights / weights.sum()))
            out.append(_item(rng, kind, x, side, inner, outer))
            x += rng.uniform(0.5, 1.5) * spacing
    return out
