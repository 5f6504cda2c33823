"""Records shared by the dense and sparse flow computations of one image pair k -> k+1."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from tracker import invert_transform

from ..objects.meshes import Mesh
from .camera import CameraModel, apply_transform, project
from .occlusion import ProjectedPoints

__all__ = ["FlowObject", "OcclusionParams", "PairSetup", "ObjectPairStats", "PairFlow", "image_roi", "flow_magnitude"]


@dataclass(frozen=True)
class FlowObject:
    """One object in one pair: its mesh and shape points (object frame) and poses at both camera times.

    ``world_from_object_k1`` is None when the object's state at camera k+1's time is unknown: it
    then still occludes in image k but gets no flow.
    """

    index: int
    object_id: str
    mesh: Mesh
    world_from_object_k: np.ndarray
    world_from_object_k1: np.ndarray | None
    points: np.ndarray | None = None
    label: str = ""

    def bottom_z(self, world_from_object: np.ndarray) -> float:
        """World height of the mesh's lowest vertex."""
        return float(apply_transform(world_from_object, self.mesh.vertices)[:, 2].min())


@dataclass(frozen=True)
class OcclusionParams:
    """Depth tests. A surface occludes a point at depth z when it is nearer by more than
    ``abs_margin + rel_margin * z`` metres. ``dilate_px``: min-filter size densifying LiDAR depth;
    ``ground_clearance``: LiDAR points lower than the object's bottom + this are ignored (ground)."""

    abs_margin: float = 0.3
    rel_margin: float = 0.02
    dilate_px: int = 7
    ground_clearance: float = 0.3

    def margin(self, depth: np.ndarray) -> np.ndarray:
        return self.abs_margin + self.rel_margin * depth


@dataclass(frozen=True)
class PairSetup:
    """Camera intrinsics and the two camera poses; LiDAR occluders already projected into each image."""

    model: CameraModel
    world_from_camera_k: np.ndarray
    world_from_camera_k1: np.ndarray
    lidar_k: ProjectedPoints | None = None
    lidar_k1: ProjectedPoints | None = None
    params: OcclusionParams = field(default_factory=OcclusionParams)

    @property
    def camera_k_from_world(self) -> np.ndarray:
        return invert_transform(self.world_from_camera_k)

    @property
    def camera_k1_from_world(self) -> np.ndarray:
        return invert_transform(self.world_from_camera_k1)

    def motion(self, obj: FlowObject) -> np.ndarray:
        """camera_k1_from_camera_k for points fixed on ``obj`` (object frame coordinates kept)."""
        return (self.camera_k1_from_world @ obj.world_from_object_k1 @ invert_transform(obj.world_from_object_k)
                @ self.world_from_camera_k)


@dataclass(frozen=True)
class ObjectPairStats:
    """Per object and pair: ``pixels`` visible in image k (the instance mask), ``pixels_noc`` also
    visible in k+1, ``hidden_k`` pixels of its silhouette behind LiDAR occluders in k."""

    index: int
    object_id: str
    pixels: int
    pixels_noc: int
    hidden_k: int
    mean_flow: float
    mean_flow_noc: float
    has_flow: bool

    @staticmethod
    def fields_before_flow(obj: "FlowObject", pixels: int = 0, hidden_k: int = 0) -> dict:
        """The record's fields for an object seen on ``pixels`` pixels in image k, before its flow is known."""
        return dict(index=obj.index, object_id=obj.object_id, pixels=int(pixels), pixels_noc=0,
                    hidden_k=int(hidden_k), mean_flow=0.0, mean_flow_noc=0.0, has_flow=False)

    @property
    def occluded_share(self) -> float:
        return 0.0 if self.pixels == 0 else 1.0 - self.pixels_noc / self.pixels

    def to_dict(self) -> dict:
        return {"index": self.index, "object_id": self.object_id, "pixels": self.pixels, "pixels_noc": self.pixels_noc,
                "hidden_by_lidar_k": self.hidden_k, "mean_flow_px": round(self.mean_flow, 4),
                "mean_flow_noc_px": round(self.mean_flow_noc, 4), "occluded_share": round(self.occluded_share, 6),
                "has_flow": self.has_flow}


@dataclass
class PairFlow:
    """Flow of one pair: ``flow`` (H, W, 2) float32 (u, v), ``valid_occ``/``valid_noc`` (H, W) bool,
    ``instance`` (H, W) uint16 (0 = no object, else object index + 1), per-object stats."""

    flow: np.ndarray
    valid_occ: np.ndarray
    valid_noc: np.ndarray
    instance: np.ndarray
    objects: list[ObjectPairStats]

    @classmethod
    def empty(cls, width: int, height: int) -> "PairFlow":
        return cls(np.zeros((height, width, 2), np.float32), np.zeros((height, width), bool),
                   np.zeros((height, width), bool), np.zeros((height, width), np.uint16), [])


def flow_magnitude(flow: np.ndarray) -> np.ndarray:
    """(N,) length of each (N, 2) flow vector: ``np.linalg.norm(flow, axis=1)`` to the bit (the same squares,
    their sum, its square root, in the flow's dtype), without the axis reduction's cost."""
    u, v = flow[:, 0], flow[:, 1]
    out = u * u
    out += v * v
    return np.sqrt(out, out=out)


def image_roi(uv: np.ndarray, model: CameraModel, margin: int = 2) -> tuple[int, int, int, int] | None:
    """Pixel rectangle (x0, y0, x1, y1) covering ``uv`` (NaN = behind the camera -> whole image)."""
    if len(uv) == 0:
        return None
    if np.isnan(uv).any():
        finite = uv[np.isfinite(uv).all(axis=1)]
        return (0, 0, model.width, model.height) if len(finite) else None
    x0 = max(int(np.floor(uv[:, 0].min())) - margin, 0)
    y0 = max(int(np.floor(uv[:, 1].min())) - margin, 0)
    x1 = min(int(np.ceil(uv[:, 0].max())) + margin + 1, model.width)
    y1 = min(int(np.ceil(uv[:, 1].max())) + margin + 1, model.height)
    if x1 <= x0 or y1 <= y0:
        return None
    return x0, y0, x1, y1


def project_vertices(mesh: Mesh, camera_from_object: np.ndarray, model: CameraModel) -> np.ndarray:
    cam = apply_transform(camera_from_object, mesh.vertices)
    uv, z = project(cam, model)
    uv[z <= 0.05] = np.nan
    return uv
