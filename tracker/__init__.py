"""SOTracker core: model-free single-object tracking of vehicles in LiDAR sequences.

numpy and scipy only; this package never imports ``sot_apps``.
"""

from .frames import FrameSource, LidarFrame
from .geometry import Box, State, points_in_box, transform_points, wrap_angle

__all__ = ["Box", "State", "LidarFrame", "FrameSource", "points_in_box", "transform_points", "wrap_angle"]
