"""SOTracker core: model-free single-object tracking of vehicles in LiDAR sequences.

numpy and scipy only; this package never imports ``sot_apps``.
"""

from .association import NearestNeighbors, RansacResult, fit_rigid_2d, ransac_rigid_2d
from .config import DETECTION_PRESETS, PRESETS, TrackerConfig, get_preset, parse_overrides, preset_names
from .det_baseline import ConstantVelocityFilter
from .detection import Detections, FrameDetections, align_heading
from .fixed_lag import FixedLagSmoother, FixedLagTracker, refine_fixed_lag, track_fixed_lag
from .frames import FrameSource, LidarFrame
from .geometry import Box, State, invert_transform, make_transform, points_in_box, rotation_z, transform_points, wrap_angle
from .ground import GroundParams, fit_plane, ground_mask, remove_ground
from .metrics import (DIFFICULTIES, DIFFICULTY_THRESHOLDS, PRECISION_THRESHOLDS, ROB_THRESHOLDS, SUCCESS_THRESHOLDS,
                      PooledMetrics, TrackletScores, accuracy, centre_errors_batch, iou_bev_batch, chamfer_distance, difficulty, iou_3d_batch,
                      pool_metrics, robustness, score_tracklet, tracklet_metrics, voxel_downsample_centres)
from .motion import MotionPrior
from .offline import frame_region_points, refine_offline
from .pseudo_gt import mean_points_in_boxes, pseudo_gt_shape
from .shape import ShapeModel, SubShape, voxel_downsample
from .solver import SolverResult, solve
from .sotracker import FrameEstimate, Tracker, TrackResult, deskew_points, track
from .sweep_ground import cached_sweep_ground_mask, remember_sweep_ground_mask, sweep_ground_mask
from .geometry import rotation_zyx

__all__ = [
    "Box", "State", "LidarFrame", "FrameSource", "points_in_box", "transform_points", "wrap_angle",
    "invert_transform", "make_transform", "rotation_z",
    "TrackerConfig", "PRESETS", "get_preset", "parse_overrides", "preset_names",
    "Tracker", "FrameEstimate", "TrackResult", "track", "deskew_points",
    "GroundParams", "ground_mask", "remove_ground", "fit_plane", "sweep_ground_mask", "cached_sweep_ground_mask",
    "NearestNeighbors", "RansacResult", "fit_rigid_2d", "ransac_rigid_2d",
    "MotionPrior", "ShapeModel", "SubShape", "voxel_downsample", "SolverResult", "solve",
    "refine_offline", "mean_points_in_boxes", "pseudo_gt_shape", "voxel_downsample_centres", "chamfer_distance",
    "DIFFICULTIES", "DIFFICULTY_THRESHOLDS", "PRECISION_THRESHOLDS", "ROB_THRESHOLDS", "SUCCESS_THRESHOLDS",
    "PooledMetrics", "TrackletScores", "centre_errors_batch", "iou_3d_batch", "difficulty", "pool_metrics",
    "score_tracklet", "tracklet_metrics", "accuracy", "robustness",
    "DETECTION_PRESETS", "Detections", "FrameDetections", "align_heading", "ConstantVelocityFilter", "iou_bev_batch",
    "FixedLagTracker", "refine_fixed_lag", "track_fixed_lag",
    "rotation_zyx",
    # the multi-object pass of sot_apps.tracking feeds the refinements from the sweeps it reads
    "FixedLagSmoother", "frame_region_points", "remember_sweep_ground_mask",
]
