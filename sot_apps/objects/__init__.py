"""What is known about one object over time, shared by every app (the floor under flow, motion_export, lidar_sim).

Modules: ``selection`` (which annotated objects are vehicles / moving: one rule, documented thresholds),
``trajectory`` (timed states, interpolation, ``world_from_object``), ``meshes`` (box, hull, surfels, the one
voxel downsampler), ``smoother`` (the CTRV RTS smoother and kinematics), ``motion_profiles`` (vehicle motions with bounded acceleration
and jerk, shared by the synthetic world and the generated benchmark).
"""
