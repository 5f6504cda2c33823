"""SOTracker core: model-free single-object tracking of vehicles in LiDAR sequences.

numpy and scipy only; this package never imports ``sot_apps``.
"""

from .association import NearestNeighbors, RansacResult, fit_rigid_2d, ransac_rigid_2d
from .config import PRESETS, TrackerConfig, get_preset, preset_names
from .frames import FrameSource, LidarFrame
from .geometry import Box, State, points_in_box, transform_points, wrap_angle
from .ground import GroundParams, fit_plane, ground_mask, remove_ground
from .motion import MotionPrior
from .shape import ShapeModel, SubShape, voxel_downsample
from .solver import SolverResult, solve
from .sotracker import FrameEstimate, Tracker, TrackResult, deskew_points, track

__all__ = [
    "Box", "State", "LidarFrame", "FrameSource", "points_in_box", "transform_points", "wrap_angle",
    "TrackerConfig", "PRESETS", "get_preset", "preset_names",
    "Tracker", "FrameEstimate", "TrackResult", "track", "deskew_points",
    "GroundParams", "ground_mask", "remove_ground", "fit_plane",
    "NearestNeighbors", "RansacResult", "fit_rigid_2d", "ransac_rigid_2d",
    "MotionPrior", "ShapeModel", "SubShape", "voxel_downsample", "SolverResult", "solve",
]
