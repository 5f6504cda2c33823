"""Height strategies (``height.model``): how the box's dz is set after the registration.

:class:`IcpHeight`: dz from the loss like dx, dy. :class:`FixedHeight`: dz = 0. :class:`GroundHeight`: the box keeps
its start height above the road under it. :class:`FilterHeight`: a slow filter of the registration's z with the
road as a prior (tracker/motion_filter.py; with ``height.road_points`` the prior's sigma grows as the plane's
ground points fall below that count). The road is a plane through the road points around the box.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from ..config import HeightConfig
from ..geometry import Box
from ..motion_filter import HeightFilter

__all__ = ["HeightModel", "IcpHeight", "FixedHeight", "GroundHeight", "FilterHeight", "road_height",
           "road_plane", "choose_height"]


def road_height(ground: np.ndarray, centre_xy: np.ndarray, box: Box, min_points: int = 20) -> float | None:
    """Height of the road under ``centre_xy``: a plane z = a x + b y + c through the ground points around the
    box (outside its footprint, within 3 m), refitted without outliers; None with too few points."""
    plane = road_plane(ground, centre_xy, box, min_points)
    return None if plane is None else plane[0]


def road_plane(ground: np.ndarray, centre_xy: np.ndarray, box: Box, min_points: int = 20
               ) -> tuple[float, int] | None:
    """:func:`road_height` and the number of ground points the plane was fitted through."""
    if len(ground) < min_points:
        return None
    d = ground[:, :2] - centre_xy
    ca, sa = np.cos(box.heading), np.sin(box.heading)
    u = np.abs(d @ np.array([ca, sa])) - 0.5 * box.length
    v = np.abs(d @ np.array([-sa, ca])) - 0.5 * box.width
    near = ground[(u <= 3.0) & (v <= 3.0)]
    if len(near) < min_points:
        return None
    keep = np.abs(near[:, 2] - np.median(near[:, 2])) < 0.5  # sub-ground noise is classified ground too
    for _ in range(2):
        if keep.sum() < min_points:
            return None
        a = np.column_stack([near[keep, 0] - centre_xy[0], near[keep, 1] - centre_xy[1], np.ones(keep.sum())])
        coef, *_ = np.linalg.lstsq(a, near[keep, 2], rcond=None)
        residual = near[:, 0:2] - centre_xy
        pred = residual @ coef[:2] + coef[2]
        keep = np.abs(near[:, 2] - pred) < 0.15
    return float(coef[2]), int(keep.sum())


class HeightModel(Protocol):
    def start(self, box: Box, road: np.ndarray) -> None:
        """Begin at the start ``box`` with the road points around it."""

    def motion(self, x: np.ndarray, prev: Box, road: np.ndarray, fit: bool) -> np.ndarray:
        """A copy of the motion ``x`` from ``prev`` with dz set (``fit``: x[2] is a registration's)."""


class IcpHeight:
    def start(self, box: Box, road: np.ndarray) -> None:
        pass

    def motion(self, x: np.ndarray, prev: Box, road: np.ndarray, fit: bool) -> np.ndarray:
        return x.copy()


class FixedHeight(IcpHeight):
    def motion(self, x: np.ndarray, prev: Box, road: np.ndarray, fit: bool) -> np.ndarray:
        x = x.copy()
        x[2] = 0.0
        return x


class GroundHeight(IcpHeight):
    offset: float | None = None

    def start(self, box: Box, road: np.ndarray) -> None:
        height = road_height(road, box.center[:2], box)
        self.offset = None if height is None else box.z - height

    def motion(self, x: np.ndarray, prev: Box, road: np.ndarray, fit: bool) -> np.ndarray:
        x = x.copy()
        if self.offset is not None:
            height = road_height(road, prev.center[:2] + x[:2], prev)
            if height is not None:
                x[2] = height + self.offset - prev.z
        return x


class FilterHeight:
    def __init__(self, params: HeightConfig) -> None:
        self.params = params

    def start(self, box: Box, road: np.ndarray) -> None:
        p = self.params
        road_z = road_height(road, box.center[:2], box)
        self.filter = HeightFilter(box.z, road_z, p.drift_sigma, p.fit_sigma, p.road_sigma, p.offset_gain,
                                   p.offset_fit_gain)

    def motion(self, x: np.ndarray, prev: Box, road: np.ndarray, fit: bool) -> np.ndarray:
        x = x.copy()
        plane = road_plane(road, prev.center[:2] + x[:2], prev)
        height, sigma = None, None
        if plane is not None:
            height = plane[0]
            if self.params.road_points > 0:  # a plane through few ground points (a far road) holds z weakly
                sigma = self.params.road_sigma * float(np.sqrt(max(1.0, self.params.road_points / max(plane[1], 1))))
        # a road through few ground points (far out) is seen with a bias that changes as the box moves: there the
        # height above it is learned from the registration's z (height.offset_fit_gain, height.offset_fit_points)
        from_fit = plane is not None and (self.params.offset_fit_points == 0 or plane[1] < self.params.offset_fit_points)
        x[2] = self.filter.update(prev.z + x[2] if fit else None, height, sigma, from_fit) - prev.z
        return x


def choose_height(params: HeightConfig) -> HeightModel:
    models: dict[str, type] = {"icp": IcpHeight, "fixed": FixedHeight, "ground": GroundHeight}
    return FilterHeight(params) if params.model == "filter" else models[params.model]()
