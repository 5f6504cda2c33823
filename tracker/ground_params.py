"""The ground remover's parameters, apart from its numpy code: the configuration (tracker/config.py) and
``sot-apps --help`` read them without loading numpy."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["GroundParams"]


@dataclass(frozen=True)
class GroundParams:
    lpr_count: int = 20
    seed_threshold: float = 1.2
    distance_threshold: float = 0.3
    iterations: int = 10
    segment_length: float = 8.0
    outlier_depth: float = 0.5
    min_cell_points: int = 30
    max_fit_points: int = 2000  # planes are fitted on at most this many points (an even subsample)
    bin_size: float = 2.0       # BEV bins of the robust first plane
    low_quantile: float = 0.1   # a bin's low point: this quantile of its heights
    max_slope_deg: float = 8.0
    low_plane_fallback: bool = False  # GPF found no road plane (a vehicle filled the seeds): use the first plane
