"""The per-pair shortcuts of the flow computation give exactly what the plain formulas give (bit for bit)."""

from __future__ import annotations

import numpy as np

from sot_apps.flow.camera import CameraModel, grid_pixels, pixel_rays
from sot_apps.flow.dense import RayCache
from sot_apps.flow.occlusion import NO_DEPTH, lookup_depth
from sot_apps.flow.scene import flow_magnitude


def test_flow_magnitude_is_numpys_norm():
    rng = np.random.default_rng(0)
    for dtype in (np.float32, np.float64):
        flow = (rng.normal(0, 30, (50_000, 2)) * rng.choice([1.0, 1e-20, 1e20], (50_000, 2))).astype(dtype)
        flow[:4] = [[0.0, -0.0], [np.inf, 1.0], [np.nan, 1.0], [1e-45, 1e-45]]
        with np.errstate(over="ignore", under="ignore"):
            expected = np.linalg.norm(flow, axis=1)
            got = flow_magnitude(flow)
        assert got.dtype == expected.dtype
        np.testing.assert_array_equal(got, expected)


def test_ray_cache_gives_pixel_rays():
    """Per-column/per-row tables (pinhole) and the whole-image map (distortion) against pixel_rays per pixel."""
    K = np.array([[1970.3, 0.0, 970.1], [0.0, 1969.7, 483.9], [0.0, 0.0, 1.0]])
    pixels = grid_pixels(0, 0, 64, 48)[::7]
    for distortion in (np.zeros(5), np.array([-0.2, 0.05, 0.001, -0.002, 0.0])):
        model = CameraModel(K, distortion, 64, 48)
        cache = RayCache()
        for _ in range(2):   # set up, then from the tables
            np.testing.assert_array_equal(cache.rays(model, pixels), pixel_rays(pixels, model))
    skewed = CameraModel(K + [[0.0, 0.7, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], np.zeros(5), 64, 48)
    np.testing.assert_array_equal(RayCache().rays(skewed, pixels), pixel_rays(pixels, skewed))


def test_lookup_depth_integer_and_float_pixels_agree():
    rng = np.random.default_rng(1)
    roi = (10, 20, 50, 45)
    depth = rng.uniform(1, 80, (25, 40)).astype(np.float32)
    uv = rng.uniform(0, 60, (5_000, 2))
    uv[:3] = [[np.nan, 30.0], [np.inf, 30.0], [30.0, -np.inf]]
    got = lookup_depth(depth, roi, uv)
    pix = np.rint(np.nan_to_num(uv, nan=-1e6, posinf=-1e6, neginf=-1e6)).astype(np.int64)
    inside = (pix[:, 0] >= 10) & (pix[:, 0] < 50) & (pix[:, 1] >= 20) & (pix[:, 1] < 45)
    expected = np.full(len(uv), NO_DEPTH, np.float32)
    expected[inside] = depth[pix[inside, 1] - 20, pix[inside, 0] - 10]
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(lookup_depth(depth, roi, pix[3:]), expected[3:])   # integer pixels as they are
