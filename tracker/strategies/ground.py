"""Ground removal strategies (``ground.remover``) and the road points the height model reads (``height.road``).

A remover marks the ground among a frame's local points: :class:`SweepGround` (upstream) takes one plane per
sweep in the ego frame (tracker/sweep_ground.py, cached per sweep), :class:`LocalGround` fits per-cell planes on
the local region (tracker/ground.py), :class:`NoGround` keeps every point. The road under the box is the removed
ground (:class:`RemovedGround`), nothing (:class:`NoRoad`) or, under a sweep plane, local planes fitted for the
height (:class:`LocalRoadPlanes`: one plane per sweep can miss a far road's grade and camber by more than 5 cm).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..config import TrackerConfig
from ..ground import GroundParams, ground_mask
from ..sweep_ground import cached_sweep_ground_mask

__all__ = ["GroundRemover", "RoadPoints", "NoGround", "LocalGround", "SweepGround", "RemovedGround", "NoRoad",
           "LocalRoadPlanes", "choose_ground", "choose_road"]


class GroundRemover(Protocol):
    label: str  # LocalCrop.ground: "none", "local" or "sweep"

    def candidates(self, points_ego: np.ndarray, idx: np.ndarray) -> np.ndarray | None:
        """Ground mask of the sweep's points ``idx`` known before they are moved to the world, or None."""

    def mask(self, world: np.ndarray, known: np.ndarray | None) -> np.ndarray | None:
        """Ground mask of the region's world points (``known``: :meth:`candidates` kept to the region), or None
        when nothing is removed."""


class NoGround:
    label = "none"

    def candidates(self, points_ego: np.ndarray, idx: np.ndarray) -> np.ndarray | None:
        return None

    def mask(self, world: np.ndarray, known: np.ndarray | None) -> np.ndarray | None:
        return None


class LocalGround:
    """Per-cell planes fitted on the region the search can reach."""

    label = "local"

    def __init__(self, params: GroundParams) -> None:
        self.params = params

    def candidates(self, points_ego: np.ndarray, idx: np.ndarray) -> np.ndarray | None:
        return None

    def mask(self, world: np.ndarray, known: np.ndarray | None) -> np.ndarray | None:
        return ground_mask(world, self.params) if len(world) >= 3 else None


class SweepGround:
    """Upstream: one plane for the whole sweep in the sensor frame, its mask cached per sweep."""

    label = "sweep"

    def __init__(self, args: tuple[int, float, float, int]) -> None:
        self.args = args

    def candidates(self, points_ego: np.ndarray, idx: np.ndarray) -> np.ndarray | None:
        return cached_sweep_ground_mask(points_ego, *self.args)[idx]

    def mask(self, world: np.ndarray, known: np.ndarray | None) -> np.ndarray | None:
        return known


class RoadPoints(Protocol):
    def road(self, world: np.ndarray, is_ground: np.ndarray) -> np.ndarray:
        """Mask of the road points among ``world`` given the removed ground ``is_ground``."""


class RemovedGround:
    def road(self, world: np.ndarray, is_ground: np.ndarray) -> np.ndarray:
        return is_ground


class NoRoad:
    def road(self, world: np.ndarray, is_ground: np.ndarray) -> np.ndarray:
        return np.zeros(len(world), dtype=bool)


class LocalRoadPlanes:
    def __init__(self, params: GroundParams) -> None:
        self.params = params

    def road(self, world: np.ndarray, is_ground: np.ndarray) -> np.ndarray:
        return ground_mask(world, self.params) if len(world) >= 3 else is_ground


def choose_ground(config: TrackerConfig) -> GroundRemover:
    g = config.ground
    removers: dict[str, GroundRemover] = {"none": NoGround(), "local": LocalGround(g.params()),
                                          "sweep": SweepGround(g.sweep_args())}
    return removers[g.remover]


def choose_road(config: TrackerConfig) -> RoadPoints:
    if config.height.road == "none":
        return NoRoad()
    if (config.ground.remover == "sweep" and config.height.road == "local"
            and config.height.model in ("filter", "ground")):
        return LocalRoadPlanes(config.ground.params())
    return RemovedGround()
