"""Association strategies (``search.association``): how the moved source points are paired with the frame's points.

:class:`GlobalAssociation`: one kd-tree over all local points; pairs whose target lies outside the crop are
dropped; the source and shape subsets (<= ``max_points``, without replacement) are drawn once per frame.
:class:`CropAssociation` (upstream): each outer iteration resamples the crop, the source and the shape
(<= ``max_points``, with replacement) and pairs each source point with its nearest crop point.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..association import NearestNeighbors, random_subset
from ..finder import resample
from ..terms import apply_motion

__all__ = ["Association", "Pairs", "GlobalAssociation", "CropAssociation"]

# (source, local-point index or -1, distance, moved source, target point)
Pairs = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


class Association(Protocol):
    def per_frame(self, points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The subset of a source (or shape) set used for the whole frame."""

    def crop(self, local: np.ndarray, mask: np.ndarray, rng: np.random.Generator) -> NearestNeighbors | None:
        """This outer iteration's target among the local points inside the crop ``mask`` (None: all of them)."""

    def pairs(self, x: np.ndarray, source: np.ndarray, pivot: np.ndarray, tree: NearestNeighbors,
              mask: np.ndarray, crop: NearestNeighbors | None, rng: np.random.Generator) -> Pairs:
        """1-NN pairs of ``source`` moved by ``x`` (rotation about ``pivot``)."""


class GlobalAssociation:
    def __init__(self, max_points: int) -> None:
        self.max_points = max_points

    def per_frame(self, points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return random_subset(points, self.max_points, rng)

    def crop(self, local: np.ndarray, mask: np.ndarray, rng: np.random.Generator) -> NearestNeighbors | None:
        return None

    def pairs(self, x: np.ndarray, source: np.ndarray, pivot: np.ndarray, tree: NearestNeighbors,
              mask: np.ndarray, crop: NearestNeighbors | None, rng: np.random.Generator) -> Pairs:
        moved = apply_motion(x, source, pivot)
        dist, idx = tree.query(moved)
        keep = mask[idx]
        idx = idx[keep]
        return source[keep], idx, dist[keep], moved[keep], tree.target[idx]


class CropAssociation:
    def __init__(self, max_points: int) -> None:
        self.max_points = max_points

    def per_frame(self, points: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        return points

    def crop(self, local: np.ndarray, mask: np.ndarray, rng: np.random.Generator) -> NearestNeighbors | None:
        return NearestNeighbors(resample(local[mask], self.max_points, rng))

    def pairs(self, x: np.ndarray, source: np.ndarray, pivot: np.ndarray, tree: NearestNeighbors,
              mask: np.ndarray, crop: NearestNeighbors | None, rng: np.random.Generator) -> Pairs:
        assert crop is not None
        source = resample(source, self.max_points, rng)
        moved = apply_motion(x, source, pivot)
        dist, idx = crop.query(moved)
        return source, np.full(len(source), -1), dist, moved, crop.target[idx]
