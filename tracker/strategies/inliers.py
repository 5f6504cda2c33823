"""Shape-pair selection strategies (``shape.ransac.mode``): which of the shape term's pairs are kept.

:class:`FixedRansac`: the same hypotheses (a per-frame seed) every outer iteration so the loop can settle; fewer
than ``min_inliers`` inliers: no pairs. :class:`UpstreamRansac`: new draws from the tracker's generator each call,
the current estimate (identity on the moved points) the first hypothesis; too few inliers: all pairs.
:class:`AllPairs`: no RANSAC.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..association import RansacDraws, ransac_rigid_2d
from ..config import RansacConfig

__all__ = ["ShapeInliers", "AllPairs", "FixedRansac", "UpstreamRansac"]

Triple = tuple[np.ndarray, np.ndarray, np.ndarray]


class ShapeInliers(Protocol):
    def select(self, src: np.ndarray, idx: np.ndarray, tgt: np.ndarray, moved: np.ndarray, seed: int,
               rng: np.random.Generator) -> Triple:
        """The kept (source, local index, target) pairs; ``seed``: the frame's RANSAC seed."""


class AllPairs:
    def select(self, src: np.ndarray, idx: np.ndarray, tgt: np.ndarray, moved: np.ndarray, seed: int,
               rng: np.random.Generator) -> Triple:
        return src, idx, tgt


class _Ransac:
    upstream = False

    def __init__(self, params: RansacConfig) -> None:
        self.params = params

    def _inliers(self, moved: np.ndarray, tgt: np.ndarray, rng: np.random.Generator,
                 draws: RansacDraws | None = None) -> np.ndarray:
        p = self.params
        if len(moved) < p.min_inliers:
            return np.zeros(len(moved), dtype=bool)
        return ransac_rigid_2d(moved[:, :2], tgt[:, :2], rng, max_iterations=p.max_iterations,
                               confidence=p.confidence, sample_size=p.sample_size, threshold=p.inlier_threshold,
                               max_score_pairs=p.score_pairs, identity_first=self.upstream, draws=draws).inliers


class FixedRansac(_Ransac):
    """The draws of a (seed, number of pairs) are made once and replayed (:class:`~tracker.association.RansacDraws`:
    the same as drawing them again from ``default_rng(seed)``); those of the previous seed are forgotten."""

    def __init__(self, params: RansacConfig) -> None:
        super().__init__(params)
        self._seed: int | None = None
        self._draws: dict[int, RansacDraws] = {}

    def _draws_for(self, seed: int, n: int) -> RansacDraws:
        if seed != self._seed:
            self._seed, self._draws = seed, {}
        if n not in self._draws:
            p = self.params
            self._draws[n] = RansacDraws(np.random.default_rng(seed), n, p.score_pairs, p.sample_size)
        return self._draws[n]

    def select(self, src: np.ndarray, idx: np.ndarray, tgt: np.ndarray, moved: np.ndarray, seed: int,
               rng: np.random.Generator) -> Triple:
        p = self.params
        draws = self._draws_for(seed, len(moved)) if len(moved) >= max(p.min_inliers, p.sample_size) else None
        keep = self._inliers(moved, tgt, np.random.default_rng(seed) if draws is None else draws.rng, draws)
        if keep.sum() >= self.params.min_inliers:
            return src[keep], idx[keep], tgt[keep]
        return src[:0], idx[:0], tgt[:0]


class UpstreamRansac(_Ransac):
    upstream = True

    def select(self, src: np.ndarray, idx: np.ndarray, tgt: np.ndarray, moved: np.ndarray, seed: int,
               rng: np.random.Generator) -> Triple:
        keep = self._inliers(moved, tgt, rng)
        if keep.sum() >= self.params.min_inliers:
            return src[keep], idx[keep], tgt[keep]
        return src, idx, tgt
