"""objects.shapes: points in annotated boxes into the object frame, undoing the rolling-scan smear."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sot_apps.io.object_track import ObjectTrack
from sot_apps.io.sequence import Sweep
from sot_apps.objects.shapes import BoxMargin, ShapeParams, box_capture_time, in_box, object_points_by_frame
from tracker import Box

SPEED = 10.0                 # m/s along +x
SIZE = (4.0, 2.0, 1.5)
DT = 100_000_000


@dataclass
class _Frame:
    timestamp_ns: int
    world_from_ego: np.ndarray


class _RollingWorld:
    """A box driving at SPEED; every point is on its surface AT THE POINT'S OWN capture time (a sweep spans the
    100 ms before the frame time). The annotation is the box at the median capture time, as PandaSet's."""

    def __init__(self, frames: int = 4):
        self.frames = [_Frame(k * DT, np.eye(4)) for k in range(frames)]
        self._rng = np.random.default_rng(0)

    @staticmethod
    def box_at(t_ns: np.ndarray | int) -> np.ndarray:
        return 10.0 + SPEED * np.asarray(t_ns, dtype=np.float64) * 1e-9

    def sweep(self, k: int) -> Sweep:
        n = 800
        u = self._rng.uniform(-0.5, 0.5, (n, 2))
        local = np.stack([u[:, 0] * SIZE[0], np.full(n, -SIZE[1] / 2), u[:, 1] * SIZE[2]], axis=1)  # the near side
        offsets = -self._rng.integers(0, DT, n)
        world = local.copy()
        world[:, 0] += self.box_at(self.frames[k].timestamp_ns + offsets)
        world[:, 2] += SIZE[2] / 2
        return Sweep(xyz=world.astype(np.float64), intensity=np.zeros(n, np.float32), time_offset_ns=offsets)

    def annotation(self, k: int) -> Box:
        return Box(float(self.box_at(self.frames[k].timestamp_ns - DT // 2)), 0.0, SIZE[2] / 2, 0.0, *SIZE)


def test_box_capture_time_is_the_median_offset_or_the_frame_time():
    assert box_capture_time(1000, np.array([-30, -10, -20])) == 980
    assert box_capture_time(1000, np.array([-30, -10]), min_points=3) == 1000


def test_in_box_margins_scale_then_pad():
    local = np.array([[2.05, 0, 0], [2.2, 0, 0], [0, 1.25, 0]])
    assert in_box(local, np.array(SIZE), BoxMargin(pad=(0.1, 0.3, 0))).tolist() == [True, False, True]
    assert in_box(local, np.array(SIZE), BoxMargin(scale=(1.1, 1.0, 1.0))).tolist() == [True, True, False]


def test_per_point_capture_time_undoes_the_rolling_scan_smear():
    world = _RollingWorld()
    frames = tuple(range(len(world.frames)))
    tracks = {"car": ObjectTrack.from_boxes("car", "Car", {k: world.annotation(k) for k in frames})}
    wide = BoxMargin(pad=(1.0, 0.3, 0.0))
    # extrapolate: the first sweep's early points were captured before the first box's capture time
    params = ShapeParams(near=wide, stamp=BoxMargin(pad=(0.6, 0.1, 0.0)), keep=wide, ground_clearance=None,
                         end="extrapolate")
    points, stamped = object_points_by_frame(world, tracks, params)
    # the boxes are stamped at their capture time (the median point time, 50 ms before the frame)
    np.testing.assert_allclose(stamped["car"].timestamps_ns - np.array([f.timestamp_ns for f in world.frames]),
                               -DT // 2, atol=8_000_000)
    sharp = np.concatenate(list(points["car"].values()))
    assert len(sharp) > 2000
    assert np.abs(sharp[:, 0]).max() < SIZE[0] / 2 + 0.08   # on the box up to the stamp noise (~5 ms at 10 m/s)
    frame_boxes = ShapeParams(near=wide, stamp=wide, keep=wide, ground_clearance=None, per_point_time=False)
    smeared = np.concatenate(list(object_points_by_frame(world, tracks, frame_boxes)[0]["car"].values()))
    assert np.abs(smeared[:, 0]).max() > SIZE[0] / 2 + 0.4         # half a sweep at 10 m/s: 0.5 m of smear
