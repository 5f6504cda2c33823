"""SOTracker core: model-free single-object tracking of vehicles in LiDAR sequences.

numpy and scipy only; this package never imports ``sot_apps``. The names below are imported from their
submodules on first use (``from tracker import Tracker`` works as usual; ``import tracker`` alone loads nothing).
"""

from __future__ import annotations

_EXPORTS = {  # name -> submodule: imported on first use, so `import tracker` stays cheap (CLI start-up)
    "NearestNeighbors": "association", "RansacResult": "association", "fit_rigid_2d": "association",
    "ransac_rigid_2d": "association",
    "DETECTION_PRESETS": "config", "PRESETS": "config", "TrackerConfig": "config", "get_preset": "config",
    "preset_names": "config", "parse_overrides": "config",
    "ConstantVelocityFilter": "det_baseline",
    "Detections": "detection", "FrameDetections": "detection", "align_heading": "detection",
    "FixedLagSmoother": "fixed_lag", "FixedLagTracker": "fixed_lag", "refine_fixed_lag": "fixed_lag", "track_fixed_lag": "fixed_lag",
    "FrameSource": "frames", "LidarFrame": "frames",
    "Box": "geometry", "State": "geometry", "invert_transform": "geometry", "make_transform": "geometry",
    "interpolate_pose": "geometry", "ctrv_arc": "motion_filter",
    "points_in_box": "geometry", "rotation_z": "geometry", "rotation_zyx": "geometry", "transform_points": "geometry", "wrap_angle": "geometry",
    "GroundParams": "ground_params", "fit_plane": "ground", "ground_mask": "ground", "remove_ground": "ground",
    "DIFFICULTIES": "metrics", "DIFFICULTY_THRESHOLDS": "metrics", "PRECISION_THRESHOLDS": "metrics",
    "PooledMetrics": "metrics", "ROB_THRESHOLDS": "metrics", "SUCCESS_THRESHOLDS": "metrics",
    "TrackletScores": "metrics", "accuracy": "metrics", "centre_errors_batch": "metrics",
    "chamfer_distance": "metrics", "difficulty": "metrics", "iou_3d_batch": "metrics", "iou_bev_batch": "metrics",
    "pool_metrics": "metrics", "robustness": "metrics", "score_tracklet": "metrics", "tracklet_metrics": "metrics",
    "voxel_downsample_centres": "metrics", "voxel_downsample_means": "metrics",
    "KeyframeParams": "keyframes", "interpolate_ctrv": "keyframes", "interpolate_linear": "keyframes",
    "keyframe_passes": "keyframes", "keyframe_schedule": "keyframes", "track_keyframes": "keyframes",
    "MotionPrior": "motion",
    "refine_offline": "offline", "frame_region_points": "offline", "frame_region_points_timed": "offline",
    "mean_points_in_boxes": "pseudo_gt", "pseudo_gt_shape": "pseudo_gt",
    "ShapeModel": "shape", "SubShape": "shape",
    "SolverResult": "solver", "solve": "solver",
    "FrameEstimate": "sotracker", "TrackResult": "sotracker", "Tracker": "sotracker", "deskew_points": "sotracker",
    "track": "sotracker",
    "cached_sweep_ground_mask": "sweep_ground", "sweep_ground_mask": "sweep_ground",
    "remember_sweep_ground_mask": "sweep_ground",
}


__all__ = [
    "Box", "State", "LidarFrame", "FrameSource", "points_in_box", "transform_points", "wrap_angle",
    "invert_transform", "make_transform", "rotation_z",
    "TrackerConfig", "PRESETS", "get_preset", "preset_names",
    "Tracker", "FrameEstimate", "TrackResult", "track", "deskew_points",
    "GroundParams", "ground_mask", "remove_ground", "fit_plane", "sweep_ground_mask", "cached_sweep_ground_mask",
    "NearestNeighbors", "RansacResult", "fit_rigid_2d", "ransac_rigid_2d",
    "MotionPrior", "ShapeModel", "SubShape", "SolverResult", "solve",
    "refine_offline", "mean_points_in_boxes", "pseudo_gt_shape", "voxel_downsample_centres", "voxel_downsample_means",
    "chamfer_distance",
    "DIFFICULTIES", "DIFFICULTY_THRESHOLDS", "PRECISION_THRESHOLDS", "ROB_THRESHOLDS", "SUCCESS_THRESHOLDS",
    "PooledMetrics", "TrackletScores", "centre_errors_batch", "iou_3d_batch", "difficulty", "pool_metrics",
    "score_tracklet", "tracklet_metrics", "accuracy", "robustness",
    "DETECTION_PRESETS", "Detections", "FrameDetections", "align_heading", "ConstantVelocityFilter", "iou_bev_batch",
    "FixedLagTracker", "refine_fixed_lag", "track_fixed_lag",
    "rotation_zyx", "parse_overrides", "interpolate_pose", "ctrv_arc",
    # the multi-object pass of sot_apps.tracking feeds the refinements from the sweeps it reads
    "FixedLagSmoother", "frame_region_points", "frame_region_points_timed", "remember_sweep_ground_mask",
    "KeyframeParams", "track_keyframes", "keyframe_passes", "keyframe_schedule", "interpolate_linear",
    "interpolate_ctrv",
]


def __getattr__(name: str):
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'tracker' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(f".{module}", __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
