"""Camera images of the synthetic world, rendered offscreen by pyrender (EGL, Mesa software rendering).

pyrender cameras use OpenGL axes (x right, y up, looking down -z); the project's cameras use OpenCV
axes (x right, y down, z forward): ``world_from_glcam = world_from_cvcam @ diag(1, -1, -1, 1)``.
Each image shows the scene at the camera's own timestamp (vehicles and ego at that time).
Needs system packages libegl1, libgl1-mesa-dri, libegl-mesa0.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..interrupts import deferred_interrupt, import_pyrender, import_trimesh
from ..io.atomic import atomic_path

__all__ = ["render_camera_images", "CV_FROM_GL"]

CV_FROM_GL = np.diag([1.0, -1.0, -1.0, 1.0])


def _pyrender():
    os.environ.setdefault("PYOPENGL_PLATFORM", "egl")
    pyrender = import_pyrender()

    return pyrender


def render_camera_images(world, cam, times_ns: np.ndarray, out_dir: Path) -> list[Path]:
    """Render one PNG per time into ``out_dir/NNNNNN.png``; returns the paths."""
    import cv2
    trimesh = import_trimesh()

    from ..objects.trajectory import world_from_object

    pyrender = _pyrender()
    scene = pyrender.Scene(bg_color=[0.62, 0.75, 0.9, 1.0], ambient_light=[0.35, 0.35, 0.35])
    ground_color = {"ground": (0.35, 0.35, 0.33), "wall": (0.7, 0.62, 0.5), "pole": (0.3, 0.3, 0.32)}
    for obj in world.background:
        mesh = trimesh.Trimesh(obj.vertices, obj.faces, process=False)
        material = pyrender.MetallicRoughnessMaterial(baseColorFactor=(*ground_color.get(obj.name, (0.5, 0.5, 0.5)), 1.0),
                                                      metallicFactor=0.0, roughnessFactor=1.0)
        scene.add(pyrender.Mesh.from_trimesh(mesh, material=material, smooth=False))
    nodes = []
    for o in world.objects:
        mesh = trimesh.Trimesh(o.vertices, o.faces, process=False)
        material = pyrender.MetallicRoughnessMaterial(baseColorFactor=(*o.color, 1.0), metallicFactor=0.1,
                                                      roughnessFactor=0.7)
        nodes.append(scene.add(pyrender.Mesh.from_trimesh(mesh, material=material, smooth=False)))
    light = pyrender.DirectionalLight(color=np.ones(3), intensity=3.0)
    light_pose = np.eye(4)
    light_pose[:3, :3] = trimesh.transformations.rotation_matrix(-0.9, [1, 0.3, 0])[:3, :3]
    scene.add(light, pose=light_pose)
    fx, fy, cx, cy = cam.K[0, 0], cam.K[1, 1], cam.K[0, 2], cam.K[1, 2]
    camera = pyrender.IntrinsicsCamera(fx, fy, cx, cy, znear=0.1, zfar=500.0)
    cam_node = scene.add(camera, pose=np.eye(4))
    # PyOpenGL turns a KeyboardInterrupt raised inside its calls into a TypeError: Ctrl-C waits for each GL call
    with deferred_interrupt():
        renderer = pyrender.OffscreenRenderer(cam.width, cam.height)
    paths = []
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        for k, t in enumerate(times_ns):
            t = int(t)
            for node, o in zip(nodes, world.objects, strict=True):
                scene.set_pose(node, world_from_object(o.trajectory.states_at(t)))
            world_from_camera = world.world_from_ego(t) @ cam.ego_from_camera
            scene.set_pose(cam_node, world_from_camera @ CV_FROM_GL)
            with deferred_interrupt():
                color, _ = renderer.render(scene)
            path = out_dir / f"{k:06d}.png"
            ok, data = cv2.imencode(".png", cv2.cvtColor(color, cv2.COLOR_RGB2BGR))
            if not ok:
                raise RuntimeError("PNG encoding failed")
            with atomic_path(path) as tmp:
                tmp.write_bytes(data.tobytes())
            paths.append(path)
    finally:
        with deferred_interrupt():
            renderer.delete()
    return paths
