"""Issue 16, defect 8: `synth --help` promised byte-identical output, but camera PNGs (Mesa's software
OpenGL through pyrender) differ run to run in single edge pixels. The help now says exactly what is
byte-identical (everything but the camera PNGs) and the bound on the images, which this test checks."""

from __future__ import annotations

import hashlib

import cv2
import numpy as np

from sot_apps.cli.main import build_parser
from sot_apps.synth import make_world, write_world
from sot_apps.synth.render import render_camera_images


def test_help_states_exactly_what_is_deterministic():
    sub = build_parser()._subparsers._group_actions[0].choices["synth"]
    text = " ".join(sub.format_help().split())
    assert "byte-identical" in text and "except the camera PNGs" in text


def test_everything_but_camera_images_is_byte_identical(tmp_path):
    def digests(out):
        write_world(out, frames=3, vehicles=2, sensor="vlp16", seed=2, cameras=True, camera_size=(160, 120))
        return {p.relative_to(out).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
                for p in sorted(out.rglob("*")) if p.is_file() and p.suffix != ".png" or p.name == "preview.png"}
    assert digests(tmp_path / "a") == digests(tmp_path / "b")


def test_camera_images_differ_in_at_most_a_few_edge_pixels(tmp_path):
    world = make_world(frames=6, vehicles=3, seed=0, cameras=True)
    cam = world.cameras[0]
    times = world.frame_times_ns + cam.time_offset_ns
    first = render_camera_images(world, cam, times, tmp_path / "a")
    second = render_camera_images(world, cam, times, tmp_path / "b")
    for a, b in zip(first, second, strict=True):
        diff = np.abs(cv2.imread(str(a)).astype(int) - cv2.imread(str(b)).astype(int)).max(axis=2)
        assert (diff > 0).sum() <= 4 and diff.max() <= 32
