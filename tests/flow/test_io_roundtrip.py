"""KITTI PNG and Middlebury .flo files round-trip exactly through OpenCV's own readers."""

from __future__ import annotations

import cv2
import numpy as np

from sot_apps.flow.flo_io import read_flo, write_flo
from sot_apps.flow.kitti_io import read_kitti_flow, write_kitti_flow
from sot_apps.flow.visualize import color_wheel, flow_to_color


def random_flow(rng, h=37, w=53):
    flow = rng.uniform(-300, 300, size=(h, w, 2)).astype(np.float32)
    valid = rng.random((h, w)) < 0.6
    return flow, valid


def test_kitti_png_roundtrip_through_cv2(tmp_path):
    rng = np.random.default_rng(1)
    flow, valid = random_flow(rng)
    flow = np.round(flow * 64) / 64  # exactly representable values
    path = tmp_path / "000000.png"
    write_kitti_flow(path, flow, valid)
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert raw.dtype == np.uint16 and raw.shape == (37, 53, 3)
    # KITTI's layout read back as RGB: R = u, G = v, B = valid.
    rgb = raw[..., ::-1].astype(np.int64)
    np.testing.assert_array_equal(rgb[..., 2], valid.astype(np.int64))
    np.testing.assert_array_equal(rgb[..., 0][valid], (flow[..., 0][valid] * 64 + 2 ** 15).astype(np.int64))
    np.testing.assert_array_equal(rgb[..., 1][valid], (flow[..., 1][valid] * 64 + 2 ** 15).astype(np.int64))
    back, back_valid = read_kitti_flow(path)
    np.testing.assert_array_equal(back_valid, valid)
    np.testing.assert_array_equal(back[valid], flow[valid])


def test_kitti_png_quantises_to_one_64th_pixel(tmp_path):
    rng = np.random.default_rng(2)
    flow, valid = random_flow(rng)
    write_kitti_flow(tmp_path / "a.png", flow, valid)
    back, _ = read_kitti_flow(tmp_path / "a.png")
    assert np.abs(back[valid] - flow[valid]).max() <= 0.5 / 64 + 1e-6


def test_flo_roundtrip_through_cv2(tmp_path):
    rng = np.random.default_rng(3)
    flow, valid = random_flow(rng)
    path = tmp_path / "000000.flo"
    write_flo(path, flow, valid)
    raw = cv2.readOpticalFlow(str(path))
    assert raw.dtype == np.float32 and raw.shape == (37, 53, 2)
    np.testing.assert_array_equal(raw[valid], flow[valid])
    assert (raw[~valid] > 1e9).all()
    back, known = read_flo(path)
    np.testing.assert_array_equal(known, valid)
    np.testing.assert_array_equal(back[valid], flow[valid])


def test_colour_wheel_matches_middlebury_layout():
    wheel = color_wheel()
    assert wheel.shape == (55, 3)
    np.testing.assert_array_equal(wheel[0], [255, 0, 0])
    np.testing.assert_array_equal(wheel[15], [255, 255, 0])
    np.testing.assert_array_equal(wheel[21], [0, 255, 0])
    # Middlebury: flow pointing left (-u) is cyan-ish blue side, right (+u) red side; zero flow is white.
    colours = flow_to_color(np.array([[[1.0, 0.0], [-1.0, 0.0], [0.0, 0.0]]]), max_flow=1.0)
    assert colours[0, 2].tolist() == [255, 255, 255]
    assert colours[0, 0, 0] > 200 and colours[0, 0, 2] < 60   # +u: red
    assert colours[0, 1, 2] > 200 and colours[0, 1, 0] < 60   # -u: cyan
