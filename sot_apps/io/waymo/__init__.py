"""Waymo Open Dataset readers (v1 TFRecord ``Frame`` files and v2 component parquet tables).

``open_sequence`` picks them automatically; :func:`find_waymo_segment` maps a LiDAR-SOT
``segment_name`` to the path to open. See docs/data-formats.md.
"""

from __future__ import annotations

from .common import PointSelection
from .segments import find_waymo_segment
from .v1 import is_waymo_v1, read_waymo_v1
from .v2 import is_waymo_v2, read_waymo_v2

__all__ = ["read_waymo_v1", "read_waymo_v2", "is_waymo_v1", "is_waymo_v2", "find_waymo_segment", "PointSelection"]
