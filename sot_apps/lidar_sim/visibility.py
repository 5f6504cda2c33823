"""What the sensor saw of each placed vehicle: points, visible share, KITTI truncation and occlusion levels.

- ``expected_points``: the returns the vehicle would give ALONE (its mesh is the only thing in the
  scene; the sensor's full ray grid, its range limits, no noise). ``visible_share`` = the returns it got
  in the scene / that number (clipped to 1): other vehicles and, with a background sweep, real objects
  in front of it lower it. A vehicle with no return is ``visible = False``.
- ``truncated``: the share of the box (a 6 x 6 x 6 grid of its volume) outside the sensor's field of
  view (between the lowest and highest beam, within min..max range); KITTI's "leaving image
  boundaries" for a spinning LiDAR without an image.
- ``occluded`` (KITTI levels): 0 fully visible (share >= 0.8), 1 partly occluded (>= 0.4), 2 largely
  occluded (> 0); invisible vehicles get no KITTI label (3 = unknown is never written).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tracker import Box

from ..raycast import RaycastScene
from ..sensor.model import Sensor
from ..sensor.scan import SimObject

__all__ = ["Visibility", "vehicle_visibility", "occlusion_level", "FULLY_VISIBLE_SHARE", "PARTLY_VISIBLE_SHARE"]

FULLY_VISIBLE_SHARE = 0.8
PARTLY_VISIBLE_SHARE = 0.4


@dataclass(frozen=True)
class Visibility:
    num_points: int
    expected_points: int
    visible_share: float
    truncated: float
    occluded: int          # KITTI level 0/1/2 (meaningless when not visible)

    @property
    def visible(self) -> bool:
        return self.num_points > 0

    def to_json(self) -> dict:
        return {"num_points": self.num_points, "expected_points": self.expected_points, "visible": self.visible,
                "visible_share": self.visible_share, "truncated": self.truncated, "occluded": self.occluded}


def occlusion_level(visible_share: float) -> int:
    """KITTI occlusion level of a vehicle that got ``visible_share`` of its unoccluded returns."""
    if visible_share >= FULLY_VISIBLE_SHARE:
        return 0
    return 1 if visible_share >= PARTLY_VISIBLE_SHARE else 2


def placed_vertices(obj: SimObject) -> np.ndarray:
    """The vertices of a static object at its pose (heading, roll and pitch)."""
    world_from_object = obj.trajectory.poses_at(int(obj.trajectory.times_ns[0]))
    return np.asarray(obj.vertices, dtype=np.float64) @ world_from_object[:3, :3].T + world_from_object[:3, 3]


def _expected_points(sensor: Sensor, obj: SimObject) -> int:
    dirs, _, _ = sensor.ray_grid()
    vertices = placed_vertices(obj)
    centre = vertices.mean(axis=0)
    radius = float(np.linalg.norm(vertices - centre, axis=1).max())
    t = dirs @ centre
    near = (np.einsum("i,i->", centre, centre) - t * t <= radius * radius) & (t >= -radius)
    if not near.any():
        return 0
    scene = RaycastScene()
    scene.add_mesh(vertices, obj.faces)
    hits = scene.cast(np.zeros(3), np.ascontiguousarray(dirs[near]))
    return int((hits.hit & (hits.distance >= sensor.min_range) & (hits.distance <= sensor.max_range)).sum())


def _truncated(sensor: Sensor, box: Box) -> float:
    g = (np.arange(6) + 0.5) / 6 - 0.5
    local = np.stack(np.meshgrid(g * box.length, g * box.width, g * box.height, indexing="ij"), -1).reshape(-1, 3)
    pts = local @ box.rotation().T + box.center
    rng = np.linalg.norm(pts, axis=1)
    elevation = np.degrees(np.arcsin(np.clip(pts[:, 2] / np.maximum(rng, 1e-9), -1.0, 1.0)))
    el = np.asarray(sensor.elevations_deg, dtype=np.float64)
    inside = (elevation >= el.min()) & (elevation <= el.max()) & (rng >= sensor.min_range) & (rng <= sensor.max_range)
    return round(float(1.0 - inside.mean()), 2)


def vehicle_visibility(sensor: Sensor, vehicles: list[SimObject], boxes: list[Box],
                       instance: np.ndarray) -> list[Visibility]:
    """Visibility of each vehicle (``vehicles[i]`` has instance id ``i`` in the scan's ``instance``)."""
    counts = np.bincount(instance[instance >= 0], minlength=len(vehicles)) if len(instance) else \
        np.zeros(len(vehicles), np.int64)
    out = []
    for i, (obj, box) in enumerate(zip(vehicles, boxes, strict=True)):
        n = int(counts[i])
        expected = _expected_points(sensor, obj)
        share = 0.0 if n == 0 else (1.0 if expected == 0 else min(1.0, n / expected))
        out.append(Visibility(n, expected, round(share, 3), _truncated(sensor, box), occlusion_level(share)))
    return out
