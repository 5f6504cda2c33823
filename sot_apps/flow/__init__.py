"""Optical-flow pseudo-ground-truth from tracked objects (``sot-apps flow``).

Modules: ``camera`` (projection with lens distortion, pixel rays), ``raycast`` (the meshes of a pair in one
:class:`sot_apps.raycast.RaycastScene`; shapes, meshes and trajectories come from :mod:`sot_apps.objects`), ``dense``
and ``sparse`` (flow of one image pair), ``occlusion`` (LiDAR depth maps), ``kitti_io``/``flo_io``
(file formats), ``visualize`` (colour wheel), ``annotate`` (orchestration per pair and object).
"""
