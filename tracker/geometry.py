"""Boxes, states and rigid transforms.

Conventions (docs/conventions.md): right-handed, z up, metres, radians. A box is its centre
(x, y, z), its heading (angle of the LENGTH axis from +x, counter-clockwise about +z), and its
length, width, height; optionally roll and pitch (default 0: a level box). The object frame has x
forward along the length, y to the left, z up, and its origin at the box centre; its rotation is
Rz(heading) @ Ry(pitch) @ Rx(roll), so the heading stays the yaw of the length axis and a positive
pitch lowers the front. A transform is a 4x4 matrix named ``target_from_source``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = [
    "Box",
    "State",
    "wrap_angle",
    "lerp_box",
    "rotation_z",
    "rotation_zyx",
    "zyx_angles",
    "make_transform",
    "interpolate_pose",
    "invert_transform",
    "transform_points",
    "points_in_box",
    "yaw_of_transform",
]


def wrap_angle(angle: float | np.ndarray) -> float | np.ndarray:
    """Wrap an angle (radians) into [-pi, pi)."""
    wrapped = (np.asarray(angle) + np.pi) % (2.0 * np.pi) - np.pi
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


def rotation_z(theta: float) -> np.ndarray:
    """3x3 rotation by ``theta`` radians counter-clockwise about +z."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_zyx(heading: float | np.ndarray, pitch: float | np.ndarray = 0.0,
                 roll: float | np.ndarray = 0.0) -> np.ndarray:
    """3x3 rotation Rz(heading) @ Ry(pitch) @ Rx(roll); exactly :func:`rotation_z` when pitch = roll = 0.
    Arrays of angles (broadcast together) give (..., 3, 3) rotations."""
    if np.ndim(heading) == np.ndim(pitch) == np.ndim(roll) == 0 and pitch == 0.0 and roll == 0.0:
        return rotation_z(float(heading))
    cy, sy, cp, sp, cr, sr = np.cos(heading), np.sin(heading), np.cos(pitch), np.sin(pitch), np.cos(roll), np.sin(roll)
    cy, sy, cp, sp, cr, sr = np.broadcast_arrays(cy, sy, cp, sp, cr, sr)
    return np.stack([np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], axis=-1),
                     np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], axis=-1),
                     np.stack([-sp, cp * sr, cp * cr], axis=-1)], axis=-2)


def zyx_angles(rotation: np.ndarray) -> tuple[float, float, float]:
    """(heading, pitch, roll) of a 3x3 rotation R = Rz(heading) @ Ry(pitch) @ Rx(roll); heading is the yaw
    of R's x axis, pitch in [-pi/2, pi/2]."""
    r = np.asarray(rotation, dtype=np.float64)
    heading = float(np.arctan2(r[1, 0], r[0, 0]))
    pitch = float(np.arcsin(np.clip(-r[2, 0], -1.0, 1.0)))
    roll = float(np.arctan2(r[2, 1], r[2, 2]))
    return heading, pitch, roll


def make_transform(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform from a 3x3 rotation and a translation."""
    out = np.eye(4)
    out[:3, :3] = rotation
    out[:3, 3] = translation
    return out


def interpolate_pose(times_ns: np.ndarray, target_from_source: np.ndarray, time_ns: int) -> np.ndarray:
    """SE(3) pose at ``time_ns`` from (N, 4, 4) poses at increasing ``times_ns`` (clamped at the ends): spherical
    linear interpolation of the rotation and linear interpolation of the translation between the two neighbours."""
    from scipy.spatial.transform import Rotation, Slerp

    times = np.asarray(times_ns, dtype=np.int64)
    poses = np.asarray(target_from_source, dtype=np.float64)
    if len(times) == 1:
        return poses[0].copy()
    i = int(np.clip(np.searchsorted(times, time_ns) - 1, 0, len(times) - 2))
    t0, t1 = int(times[i]), int(times[i + 1])
    alpha = float(np.clip((time_ns - t0) / float(t1 - t0), 0.0, 1.0))
    slerp = Slerp([0.0, 1.0], Rotation.from_matrix(poses[i:i + 2, :3, :3]))
    rotation = slerp([alpha]).as_matrix()[0]
    translation = (1.0 - alpha) * poses[i, :3, 3] + alpha * poses[i + 1, :3, 3]
    return make_transform(rotation, translation)


def invert_transform(target_from_source: np.ndarray) -> np.ndarray:
    """Inverse of a rigid 4x4 transform: returns ``source_from_target``."""
    rotation = target_from_source[:3, :3]
    translation = target_from_source[:3, 3]
    out = np.eye(4)
    out[:3, :3] = rotation.T
    out[:3, 3] = -rotation.T @ translation
    return out


def transform_points(target_from_source: np.ndarray, points_source: np.ndarray) -> np.ndarray:
    """Apply a 4x4 transform to (N, 3) points; returns (N, 3) float64 points."""
    points_source = np.asarray(points_source, dtype=np.float64).reshape(-1, 3)
    rotation = target_from_source[:3, :3]
    # Three broadcast multiply-adds instead of a (N,3)@(3,3) BLAS call: no thread start-up, and no
    # contention with other processes for the BLAS pool (it was 15-25x slower on a loaded 2-core machine).
    out = points_source[:, 0:1] * rotation[:, 0]
    out += points_source[:, 1:2] * rotation[:, 1]
    out += points_source[:, 2:3] * rotation[:, 2]
    out += target_from_source[:3, 3]
    return out


def yaw_of_transform(target_from_source: np.ndarray) -> float:
    """Rotation about +z of a transform's x axis (radians)."""
    return float(np.arctan2(target_from_source[1, 0], target_from_source[0, 0]))


@dataclass(frozen=True)
class State:
    """A vehicle's 4-DOF state in the world frame: centre (x, y, z) and heading."""

    x: float
    y: float
    z: float
    heading: float

    def to_array(self) -> np.ndarray:
        return np.array([self.x, self.y, self.z, self.heading], dtype=np.float64)

    @classmethod
    def from_array(cls, values: np.ndarray) -> "State":
        x, y, z, heading = (float(v) for v in np.asarray(values, dtype=np.float64).reshape(4))
        return cls(x, y, z, heading)


@dataclass(frozen=True)
class Box:
    """A 3D box: centre, heading of the length axis, size, and optional roll and pitch (see module docstring).

    ``to_array``/``from_array``/``state`` carry the 7 upright values only (the tracker estimates x, y, z and
    heading); roll and pitch are kept by ``with_state``, ``scaled`` and ``transformed(..., keep_tilt=True)``.
    """

    x: float
    y: float
    z: float
    heading: float
    length: float
    width: float
    height: float
    roll: float = 0.0
    pitch: float = 0.0

    @property
    def is_level(self) -> bool:
        return self.roll == 0.0 and self.pitch == 0.0

    def rotation(self) -> np.ndarray:
        """3x3 rotation of the object frame: Rz(heading) @ Ry(pitch) @ Rx(roll)."""
        return rotation_zyx(self.heading, self.pitch, self.roll)

    @property
    def center(self) -> np.ndarray:
        return np.array([self.x, self.y, self.z], dtype=np.float64)

    @property
    def size(self) -> np.ndarray:
        """(length, width, height)."""
        return np.array([self.length, self.width, self.height], dtype=np.float64)

    @property
    def state(self) -> State:
        return State(self.x, self.y, self.z, self.heading)

    def with_state(self, state: State) -> "Box":
        return Box(state.x, state.y, state.z, state.heading, self.length, self.width, self.height, self.roll, self.pitch)

    def scaled(self, factor: float) -> "Box":
        """The same box with length, width and height multiplied by ``factor``."""
        return Box(self.x, self.y, self.z, self.heading,
                   self.length * factor, self.width * factor, self.height * factor, self.roll, self.pitch)

    def to_array(self) -> np.ndarray:
        """[x, y, z, heading, length, width, height]."""
        return np.array([self.x, self.y, self.z, self.heading, self.length, self.width, self.height],
                        dtype=np.float64)

    @classmethod
    def from_array(cls, values: np.ndarray) -> "Box":
        vals = [float(v) for v in np.asarray(values, dtype=np.float64).reshape(7)]
        return cls(*vals)

    def world_from_object(self) -> np.ndarray:
        """4x4 transform taking object-frame points (x along the length) to the box's frame of reference."""
        return make_transform(self.rotation(), self.center)

    def object_from_world(self) -> np.ndarray:
        return invert_transform(self.world_from_object())

    def corners(self) -> np.ndarray:
        """(8, 3) corners: bottom face first (counter-clockwise from front-left), then top face."""
        l, w, h = self.length / 2.0, self.width / 2.0, self.height / 2.0
        corners_object = np.array([
            [l, w, -h], [-l, w, -h], [-l, -w, -h], [l, -w, -h],
            [l, w, h], [-l, w, h], [-l, -w, h], [l, -w, h],
        ])
        return transform_points(self.world_from_object(), corners_object)

    def bev_corners(self) -> np.ndarray:
        """(4, 2) bird's-eye-view corners, counter-clockwise."""
        return self.corners()[:4, :2]

    def transformed(self, target_from_source: np.ndarray, keep_tilt: bool = False) -> "Box":
        """This box (expressed in ``source``) expressed in ``target``.

        ``keep_tilt=False``: an upright box whose heading gains only the yaw of the transform (roll and pitch
        are dropped). ``keep_tilt=True``: the same solid in ``target`` (its full rotation, as roll and pitch).
        """
        center = transform_points(target_from_source, self.center[None])[0]
        if keep_tilt:
            heading, pitch, roll = zyx_angles(np.asarray(target_from_source)[:3, :3] @ self.rotation())
            return Box(float(center[0]), float(center[1]), float(center[2]), heading,
                       self.length, self.width, self.height, roll, pitch)
        yaw = wrap_angle(self.heading + yaw_of_transform(target_from_source))
        return Box(float(center[0]), float(center[1]), float(center[2]), float(yaw),
                   self.length, self.width, self.height)


def points_in_box(points: np.ndarray, box: Box, scale: float | tuple[float, float, float] = 1.0) -> np.ndarray:
    """Boolean mask of the (N, 3) points inside ``box`` with its size scaled by ``scale``."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if isinstance(scale, (int, float)):   # the common case, without broadcast_to's overhead (same values)
        half = box.size * float(scale) / 2.0
    else:
        half = box.size * np.broadcast_to(np.asarray(scale, dtype=np.float64), (3,)) / 2.0
    d = points - box.center
    if not box.is_level:  # tilted box: object-frame coordinates R^T d
        r = box.rotation()
        local = d[:, 0:1] * r[0] + d[:, 1:2] * r[1] + d[:, 2:3] * r[2]
        return np.all(np.abs(local) <= half, axis=1)
    c, s = np.cos(box.heading), np.sin(box.heading)
    local_x = c * d[:, 0] + s * d[:, 1]
    local_y = -s * d[:, 0] + c * d[:, 1]
    return (np.abs(local_x) <= half[0]) & (np.abs(local_y) <= half[1]) & (np.abs(d[:, 2]) <= half[2])


def lerp_box(a: Box, b: Box, t: float, centre: np.ndarray | None = None, heading: float | None = None) -> Box:
    """The box a fraction ``t`` of the way from ``a`` to ``b``: everything linear (heading the short way round),
    unless ``centre`` / ``heading`` are given."""
    if centre is None:
        centre = (1.0 - t) * a.center + t * b.center
    if heading is None:
        heading = a.heading + t * float(wrap_angle(b.heading - a.heading))
    size = (1.0 - t) * a.size + t * b.size
    return Box(float(centre[0]), float(centre[1]), float(centre[2]), float(wrap_angle(heading)), float(size[0]),
               float(size[1]), float(size[2]), roll=(1.0 - t) * a.roll + t * b.roll,
               pitch=(1.0 - t) * a.pitch + t * b.pitch)
