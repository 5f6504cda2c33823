"""Optical-flow pseudo-ground-truth from tracked objects (``sot-apps flow``).

Modules: ``camera`` (projection with lens distortion, pixel rays), ``states`` (object states and
camera poses at camera timestamps), ``raycast``/``meshing`` (shape -> mesh, embree scene), ``dense``
and ``sparse`` (flow of one image pair), ``occlusion`` (LiDAR depth maps), ``kitti_io``/``flo_io``
(file formats), ``visualize`` (colour wheel), ``annotate`` (orchestration per pair and object).
"""
