"""ICP metric strategies (``registration.metric``): point-to-point pairs carry no normals; point-to-plane pairs
carry the target points' normals (PCA of their neighbours, computed on demand and cached per frame)."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..association import NearestNeighbors

__all__ = ["FrameTarget", "Metric", "PointMetric", "PlaneMetric"]


class FrameTarget:
    """A frame's local (non-ground) points with one kd-tree and lazily computed normals."""

    def __init__(self, points: np.ndarray) -> None:
        self.nn = NearestNeighbors(points)
        self.normals = np.zeros((len(points), 3))
        self.has_normal = np.zeros(len(points), dtype=bool)


class Metric(Protocol):
    def normals(self, target: FrameTarget, idx: np.ndarray) -> np.ndarray | None:
        """Normals of local points ``idx`` (None: point-to-point)."""


class PointMetric:
    def normals(self, target: FrameTarget, idx: np.ndarray) -> np.ndarray | None:
        return None


class PlaneMetric:
    def __init__(self, neighbors: int, radius: float) -> None:
        self.neighbors, self.radius = neighbors, radius

    def normals(self, target: FrameTarget, idx: np.ndarray) -> np.ndarray | None:
        """Unit normals (zeros where undefined) of local points ``idx``, computed on demand and cached."""
        missing = np.unique(idx[~target.has_normal[idx]])
        if len(missing):
            k = min(self.neighbors, len(target.nn))
            assert target.nn.tree is not None
            dist, nbr = target.nn.tree.query(target.nn.target[missing], k=k, distance_upper_bound=self.radius)
            dist = dist.reshape(len(missing), k)
            nbr = nbr.reshape(len(missing), k)
            valid = np.isfinite(dist)
            nbr = np.where(valid, nbr, 0)
            pts = target.nn.target[nbr]                                   # (m, k, 3)
            w = valid[..., None].astype(np.float64)
            count = w.sum(axis=1)                                         # (m, 1)
            mean = (pts * w).sum(axis=1) / np.maximum(count, 1.0)
            d = (pts - mean[:, None]) * w
            cov = np.einsum("mki,mkj->mij", d, d)
            evals, evecs = np.linalg.eigh(cov)
            normal = evecs[:, :, 0]
            # a normal needs enough neighbours and a flat neighbourhood (smallest eigenvalue well below the next)
            ok = (count[:, 0] >= 4) & (evals[:, 0] < 0.3 * evals[:, 1])
            target.normals[missing] = np.where(ok[:, None], normal, 0.0)
            target.has_normal[missing] = True
        return target.normals[idx]
