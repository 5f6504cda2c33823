"""The numpy convex hull (sot_apps.objects.convex_hull) against scipy's qhull and analytic solids."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from sot_apps.objects.convex_hull import canonical_faces, hull_faces
from sot_apps.objects.meshes import mesh_from_points


def _qhull_canonical(points: np.ndarray) -> np.ndarray:
    faces = ConvexHull(points).simplices.astype(np.int64)
    a, b, c = points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a - points.mean(axis=0)) < 0
    faces[inward] = faces[inward][:, ::-1]
    return canonical_faces(faces)


def _volume(points: np.ndarray, faces: np.ndarray) -> float:
    a, b, c = points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _check_closed_outward(points: np.ndarray, faces: np.ndarray) -> None:
    edges = {tuple(e) for e in np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]).tolist()}
    assert len(edges) == 3 * len(faces)                      # no directed edge twice
    assert all((b, a) in edges for a, b in edges)            # closed, consistently oriented
    a, b, c = points[faces[:, 0]], points[faces[:, 1]], points[faces[:, 2]]
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    assert (points @ normal.T - np.einsum("ij,ij->i", normal, a)).max() <= 1e-9   # every point inside


@pytest.mark.parametrize("shape", ["gauss", "box", "ellipsoid_surface", "car_like"])
def test_general_position_gives_qhulls_triangles(shape):
    rng = np.random.default_rng(len(shape))
    for n in (4, 5, 12, 200, 2500):
        if shape == "gauss":
            points = rng.normal(size=(n, 3))
        elif shape == "box":
            points = rng.uniform(-1, 1, (n, 3)) * [2.25, 0.95, 0.75]
        elif shape == "ellipsoid_surface":
            points = rng.normal(size=(n, 3))
            points = points / np.linalg.norm(points, axis=1, keepdims=True) * [2.3, 1.0, 0.8]
        else:   # LiDAR-like: points on a car's visible sides, 4.6 km from the origin
            points = rng.uniform(-1, 1, (n, 3)) * [2.3, 0.95, 0.75]
            points[: n // 2, 1] = 0.95 + rng.normal(scale=0.01, size=n // 2)
            points += [4600.0, -120.0, 30.0]
        faces = hull_faces(points)
        assert faces is not None
        assert np.array_equal(faces, _qhull_canonical(points)), (shape, n)
        _check_closed_outward(points, faces)


def test_grid_points_give_the_same_solid_as_qhull():
    """Voxel-grid shapes (tracker shapes) have many points on one face; both hulls triangulate those polygons in
    their own way but bound the same solid: same volume, same corner vertices, every point inside."""
    rng = np.random.default_rng(3)
    for _ in range(10):
        points = np.unique(np.round(rng.uniform(-1, 1, (1500, 3)) * [2.3, 0.95, 0.75] / 0.05) * 0.05, axis=0)
        points = points.astype(np.float32).astype(np.float64)
        faces = hull_faces(points)
        truth = ConvexHull(points)
        _check_closed_outward(points, faces)
        assert _volume(points, faces) == pytest.approx(truth.volume, rel=1e-12)
        assert set(np.unique(faces)) <= set(truth.coplanar[:, 0]) | set(np.unique(truth.simplices))


def test_cube_and_tetrahedron_exactly():
    cube = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
    inside = np.random.default_rng(0).uniform(0.1, 0.9, (50, 3))
    on_faces = np.array([[0.5, 0.5, 0.0], [0.5, 1.0, 0.5], [0.0, 0.2, 0.7]])
    points = np.concatenate([inside, cube, on_faces])
    faces = hull_faces(points)
    assert len(faces) == 12 and set(np.unique(faces)) == set(range(50, 58))
    assert _volume(points, faces) == pytest.approx(1.0, rel=1e-14)
    _check_closed_outward(points, faces)
    tetra = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    assert hull_faces(tetra).tolist() == [[0, 1, 3], [0, 2, 1], [0, 3, 2], [1, 2, 3]]


def test_flat_or_tiny_input_has_no_hull():
    rng = np.random.default_rng(1)
    plane = np.column_stack([rng.uniform(size=(40, 2)), np.zeros(40)])
    line = np.outer(rng.uniform(size=30), [1.0, 2.0, 3.0])
    assert hull_faces(plane) is None
    assert hull_faces(line) is None
    assert hull_faces(np.ones((10, 3))) is None
    assert hull_faces(np.eye(3)) is None
    assert hull_faces(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [np.nan, 0, 1]])) is None
    assert mesh_from_points(plane, "hull") is None


def test_mesh_from_points_hull_keeps_only_hull_vertices():
    rng = np.random.default_rng(5)
    points = rng.normal(size=(300, 3))
    mesh = mesh_from_points(points, "hull")
    truth = ConvexHull(points)
    assert np.array_equal(mesh.vertices, points[np.unique(truth.simplices)])
    _check_closed_outward(mesh.vertices, mesh.faces.astype(np.int64))


def test_a_failed_check_falls_back_to_qhull(monkeypatch):
    import sot_apps.objects.convex_hull as convex_hull

    points = np.random.default_rng(2).normal(size=(100, 3))
    expected = hull_faces(points)
    monkeypatch.setattr(convex_hull, "_closed_and_holding", lambda *args: False)
    assert np.array_equal(hull_faces(points), expected)


def test_flow_start_up_imports_no_scipy(pandaset_root):
    """The flow's modules, opening a PandaSet sequence and meshing a shape by its hull import no scipy (its
    spatial package costs ~0.35 s of start-up)."""
    import subprocess
    import sys
    from pathlib import Path

    code = ("import sys, numpy as np\n"
            "import sot_apps.flow.annotate, sot_apps.flow.objects\n"
            "from sot_apps.io import open_sequence\n"
            f"seq = open_sequence({str(pandaset_root)!r})\n"
            "from sot_apps.flow.objects import mesh_for\n"
            "mesh = mesh_for(np.random.default_rng(0).normal(size=(500, 3)), np.array([4.5, 1.9, 1.5]))\n"
            "assert len(mesh.faces) > 12\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[2])   # this checkout's sot_apps
    assert out.stdout.strip() == "[]"
