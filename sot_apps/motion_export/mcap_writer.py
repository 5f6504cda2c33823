"""Write smoothed object kinematics to an MCAP file that Foxglove opens directly.

One ``foxglove.Context`` per file; every message carries an explicit ``log_time`` (the frame's
timestamp in integer ns) and a header timestamp equal to it. Topics (docs/motion-export.md):

- ``/tf`` (foxglove.FrameTransforms), one per frame: world -> ego, world -> object/<id> for each
  object valid at that frame;
- ``/markers/objects`` (foxglove.SceneUpdate), one per frame: first a delete-all, then one entity
  per valid object (a CubePrimitive box coloured per id, a TextPrimitive label, a LinePrimitive
  trajectory of the smoothed centres up to this frame; metadata id, class, speed, yaw_rate);
- ``/objects/<id>/pose`` (foxglove.Odometry) per valid frame: pose in world, velocity and yaw rate
  in the object frame, covariances from the smoother;
- ``/objects/<id>/kinematics`` (JSON, schema data_schema/kinematics.schema.json) per frame of the
  track, invalid frames included (valid=false, null values);
- ``/objects/<id>/shape`` (foxglove.PointCloud, frame object/<id>) per valid frame when the object
  has a shape (Foxglove places a point cloud with the transform at its own timestamp, so a shape
  logged once would stay behind where the object was);
- ``/lidar/points`` (foxglove.PointCloud, frame ego) per frame, only with ``with_points``;
- a metadata record ``sot_apps.motion_export`` (source, sequence, config, objects).
"""

from __future__ import annotations

import colorsys
import contextlib
import json
import os
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from tracker import rotation_z, rotation_zyx

from ..io.atomic import atomic_path
from ..io.object_track import ObjectTrack
from ..io.sequence import Sequence
from ..schemas import load_schema, validate

__all__ = ["write_motion_mcap", "McapSummary", "object_color", "METADATA_NAME", "WORLD_FRAME", "EGO_FRAME",
           "object_frame", "KINEMATICS_SCHEMA_NAME", "kinematics_sample"]

METADATA_NAME = "sot_apps.motion_export"
WORLD_FRAME = "world"
EGO_FRAME = "ego"
KINEMATICS_SCHEMA_NAME = "sot_apps.Kinematics"


def object_frame(object_id: str) -> str:
    return f"object/{object_id}"


@dataclass
class McapSummary:
    path: Path
    frames: int
    objects: int
    message_counts: dict[str, int] = field(default_factory=dict)

    @property
    def messages(self) -> int:
        return sum(self.message_counts.values())


def object_color(object_id: str) -> tuple[float, float, float]:
    """A stable, saturated RGB colour (0..1) for an id."""
    hue = (zlib.crc32(object_id.encode("utf-8")) % 360) / 360.0
    return colorsys.hsv_to_rgb(hue, 0.85, 0.95)


def _timestamp(m, t_ns: int):
    return m.Timestamp(int(t_ns) // 1_000_000_000, int(t_ns) % 1_000_000_000)


def _quat_z(m, heading: float):
    return m.Quaternion(x=0.0, y=0.0, z=float(np.sin(heading / 2.0)), w=float(np.cos(heading / 2.0)))


def _quat_matrix(m, rotation: np.ndarray):
    x, y, z, w = Rotation.from_matrix(rotation).as_quat()
    return m.Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))


def _point_cloud(m, t_ns: int, frame_id: str, xyz: np.ndarray, intensity: np.ndarray | None = None):
    F = m.PackedElementFieldNumericType.Float32
    names = ["x", "y", "z"] + (["intensity"] if intensity is not None else [])
    columns = [np.asarray(xyz, dtype=np.float32).reshape(-1, 3)]
    if intensity is not None:
        columns.append(np.asarray(intensity, dtype=np.float32).reshape(-1, 1))
    data = np.ascontiguousarray(np.concatenate(columns, axis=1), dtype="<f4")
    fields = [m.PackedElementField(name=n, offset=4 * i, type=F) for i, n in enumerate(names)]
    return m.PointCloud(timestamp=_timestamp(m, t_ns), frame_id=frame_id,
                        pose=m.Pose(position=m.Vector3(x=0.0, y=0.0, z=0.0), orientation=m.Quaternion(w=1.0)),
                        point_stride=4 * len(names), fields=fields, data=data.tobytes())


def kinematics_sample(k: ObjectTrack, i: int) -> dict[str, Any]:
    """Sample ``i`` of a smoothed track (:func:`sot_apps.objects.smoother.smooth_track`) as plain Python values
    (None for NaN): the ``/objects/<id>/kinematics`` message (data_schema/kinematics.schema.json)."""
    def f(value: float) -> float | None:
        value = float(value)
        return value if np.isfinite(value) else None

    x, y, z, heading = k.boxes[i, :4]
    return {
        "object_id": k.object_id, "label": k.label, "frame": int(k.frames[i]),
        "timestamp_ns": int(k.timestamps_ns[i]), "valid": bool(k.valid[i]), "flags": list(k.flags[i]),
        "position": {"x": f(x), "y": f(y), "z": f(z)},
        "heading": f(heading),
        "velocity": {"x": f(k.velocity[i, 0]), "y": f(k.velocity[i, 1])},
        "speed": f(k.speed[i]), "acceleration": f(k.acceleration[i]), "yaw_rate": f(k.yaw_rate[i]),
        "std": {"position": f(k.position_std[i]), "heading": f(k.heading_std[i]),
                "speed": f(k.speed_std[i]), "yaw_rate": f(k.yaw_rate_std[i])},
        "size": {"length": float(k.size[0]), "width": float(k.size[1]), "height": float(k.size[2])},
    }


def _fmt(value: float, digits: int = 3) -> str:
    return "nan" if not np.isfinite(value) else f"{value:.{digits}f}"


class _Writer:
    def __init__(self, ctx, m, channels, kinematics: list[ObjectTrack], sequence: Sequence):
        self.ctx, self.m = ctx, m
        self.counts: dict[str, int] = {}
        self.kin = kinematics
        self.sequence = sequence
        self.tf = channels.FrameTransformsChannel("/tf", context=ctx)
        self.markers = channels.SceneUpdateChannel("/markers/objects", context=ctx)
        schema = load_schema("kinematics")
        import foxglove

        self.pose = {k.object_id: channels.OdometryChannel(f"/objects/{k.object_id}/pose", context=ctx)
                     for k in kinematics}
        self.kin_channels = {k.object_id: foxglove.Channel(f"/objects/{k.object_id}/kinematics", schema=schema,
                                                           context=ctx) for k in kinematics}
        self.shape = {k.object_id: channels.PointCloudChannel(f"/objects/{k.object_id}/shape", context=ctx)
                      for k in kinematics if k.shape_points is not None and len(k.shape_points) > 0}
        self.points = None
        self.checked: set[tuple[str, bool]] = set()  # (object, valid) pairs whose message was schema-checked
        # frame index -> sample index per object
        self.index = [{int(f): i for i, f in enumerate(k.frames)} for k in kinematics]

    def _log(self, channel, topic: str, msg, t_ns: int) -> None:
        channel.log(msg, log_time=int(t_ns))
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def frame(self, frame: int, with_points: bool) -> None:
        m = self.m
        info = self.sequence.frames[frame]
        t_ns = int(info.timestamp_ns)
        ts = _timestamp(m, t_ns)
        w_e = info.world_from_ego
        transforms = [m.FrameTransform(timestamp=ts, parent_frame_id=WORLD_FRAME, child_frame_id=EGO_FRAME,
                                       translation=m.Vector3(x=float(w_e[0, 3]), y=float(w_e[1, 3]), z=float(w_e[2, 3])),
                                       rotation=_quat_matrix(m, w_e[:3, :3]))]
        entities = []
        for j, k in enumerate(self.kin):
            i = self.index[j].get(frame)
            if i is None:
                continue
            oid = k.object_id
            sample = kinematics_sample(k, i)
            if (oid, bool(k.valid[i])) not in self.checked:  # guard the contract once per object and validity
                validate("kinematics", sample, f"/objects/{oid}/kinematics")
                self.checked.add((oid, bool(k.valid[i])))
            self._log(self.kin_channels[oid], f"/objects/{oid}/kinematics", sample, t_ns)
            if not k.valid[i]:
                continue
            position = m.Vector3(x=float(k.boxes[i, 0]), y=float(k.boxes[i, 1]), z=float(k.boxes[i, 2]))
            if k.tilts is None:
                orientation = _quat_z(m, float(k.boxes[i, 3]))
                rotation = rotation_z(float(k.boxes[i, 3]))
            else:   # a box that is not level in the world keeps its roll and pitch
                rotation = rotation_zyx(float(k.boxes[i, 3]), float(k.tilts[i, 1]), float(k.tilts[i, 0]))
                orientation = _quat_matrix(m, rotation)
            pose = m.Pose(position=position, orientation=orientation)
            transforms.append(m.FrameTransform(timestamp=ts, parent_frame_id=WORLD_FRAME,
                                               child_frame_id=object_frame(oid), translation=position,
                                               rotation=orientation))
            # velocity (world x, y; no vertical component) and yaw rate (about world z) in the object frame
            body_v = rotation.T @ [float(k.velocity[i, 0]), float(k.velocity[i, 1]), 0.0]
            body_w = rotation.T @ [0.0, 0.0, float(k.yaw_rate[i])]
            pos_var = float(k.position_std[i]) ** 2 / 2.0
            pose_cov = [0.0] * 36
            pose_cov[0] = pose_cov[7] = pos_var
            pose_cov[35] = float(k.heading_std[i]) ** 2
            vel_cov = [0.0] * 36
            vel_cov[0] = float(k.speed_std[i]) ** 2
            vel_cov[35] = float(k.yaw_rate_std[i]) ** 2
            odom = m.Odometry(timestamp=ts, frame_id=WORLD_FRAME, body_frame_id=object_frame(oid), pose=pose,
                              linear_velocity=m.Vector3(x=float(body_v[0]), y=float(body_v[1]), z=float(body_v[2])),
                              angular_velocity=m.Vector3(x=float(body_w[0]), y=float(body_w[1]), z=float(body_w[2])),
                              pose_covariance=pose_cov, velocity_covariance=vel_cov)
            self._log(self.pose[oid], f"/objects/{oid}/pose", odom, t_ns)
            entities.append(self._entity(k, i, ts, pose))
            if oid in self.shape:
                self._log(self.shape[oid], f"/objects/{oid}/shape",
                          _point_cloud(m, t_ns, object_frame(oid), k.shape_points), t_ns)
        self._log(self.tf, "/tf", m.FrameTransforms(transforms=transforms), t_ns)
        deletion = m.SceneEntityDeletion(timestamp=ts, type=m.SceneEntityDeletionType.All, id="")
        self._log(self.markers, "/markers/objects", m.SceneUpdate(deletions=[deletion], entities=entities), t_ns)
        if with_points and self.sequence.frames[frame].has_sweep:  # a frame without a sweep logs no cloud
            if self.points is None:
                from foxglove import channels

                self.points = channels.PointCloudChannel("/lidar/points", context=self.ctx)
            sweep = self.sequence.sweep(frame)
            self._log(self.points, "/lidar/points", _point_cloud(m, t_ns, EGO_FRAME, sweep.xyz, sweep.intensity), t_ns)

    def _entity(self, k: ObjectTrack, i: int, ts, pose):
        m = self.m
        r, g, b = object_color(k.object_id)
        color = m.Color(r=r, g=g, b=b, a=0.6)
        cube = m.CubePrimitive(pose=pose, size=m.Vector3(x=k.size[0], y=k.size[1], z=k.size[2]), color=color)
        label_pose = m.Pose(position=m.Vector3(x=float(k.boxes[i, 0]), y=float(k.boxes[i, 1]), z=float(k.boxes[i, 2]) + k.size[2] / 2 + 0.5),
                            orientation=m.Quaternion(w=1.0))
        text = m.TextPrimitive(pose=label_pose, billboard=True, font_size=14.0, scale_invariant=True,
                               color=m.Color(r=1.0, g=1.0, b=1.0, a=1.0),
                               text=f"{k.object_id[:8]} {k.label} {float(k.speed[i]):.1f} m/s")
        # trajectory so far: segments between consecutive valid samples only (no bridging of gaps)
        upto = np.arange(i + 1)
        ok = k.valid[upto]
        seg = np.flatnonzero(ok[:-1] & ok[1:])
        points = []
        for s in seg:
            points.append(m.Point3(x=float(k.boxes[s, 0]), y=float(k.boxes[s, 1]), z=float(k.boxes[s, 2])))
            points.append(m.Point3(x=float(k.boxes[s + 1, 0]), y=float(k.boxes[s + 1, 1]), z=float(k.boxes[s + 1, 2])))
        lines = [m.LinePrimitive(type=m.LinePrimitiveLineType.LineList, pose=m.Pose(orientation=m.Quaternion(w=1.0)),
                                 thickness=0.15, scale_invariant=False, points=points,
                                 color=m.Color(r=r, g=g, b=b, a=1.0))] if points else []
        metadata = [m.KeyValuePair(key="id", value=k.object_id), m.KeyValuePair(key="class", value=k.label),
                    m.KeyValuePair(key="speed", value=_fmt(float(k.speed[i]))),
                    m.KeyValuePair(key="yaw_rate", value=_fmt(float(k.yaw_rate[i]), 4)),
                    m.KeyValuePair(key="frame", value=str(int(k.frames[i])))]
        return m.SceneEntity(timestamp=ts, frame_id=WORLD_FRAME, id=k.object_id, frame_locked=False,
                             metadata=metadata, cubes=[cube], texts=[text], lines=lines)


class _FirstErrorSink:
    """The file the MCAP writer writes through: the first exception (an OSError such as a full disk, or a
    Ctrl-C that lands in this Python callback, which the writer would otherwise turn into an I/O error and lose)
    is kept and every later write is dropped (positions still advance as if written, as the writer checks them),
    so the writer does not log one failure per message; the caller raises it once, after each frame."""

    def __init__(self, handle) -> None:
        self._handle = handle
        self.error: BaseException | None = None
        self._position = 0   # after an error: where the file would be
        self._end = 0

    def write(self, data) -> int:
        if self.error is None:
            try:
                return self._handle.write(data)
            except BaseException as exc:  # noqa: BLE001 - kept and raised by raise_error
                self._fail(exc)
        self._position += len(data)
        self._end = max(self._end, self._position)
        return len(data)

    def seek(self, offset: int, whence: int = 0) -> int:
        if self.error is None:
            try:
                return self._handle.seek(offset, whence)
            except BaseException as exc:  # noqa: BLE001 - kept and raised by raise_error
                self._fail(exc)
        self._position = (offset, self._position + offset, self._end + offset)[whence]
        return self._position

    def tell(self) -> int:
        if self.error is None:
            try:
                return self._handle.tell()
            except BaseException as exc:  # noqa: BLE001 - kept and raised by raise_error
                self._fail(exc)
        return self._position

    def flush(self) -> None:
        if self.error is None:
            try:
                self._handle.flush()
            except BaseException as exc:  # noqa: BLE001 - kept and raised by raise_error
                self._fail(exc)

    def _fail(self, exc: BaseException) -> None:
        self.error = exc
        with contextlib.suppress(OSError, ValueError):
            self._position = self._handle.tell()
            self._end = max(self._position, os.fstat(self._handle.fileno()).st_size)

    def raise_error(self) -> None:
        if self.error is not None:
            raise self.error


def _write_options():
    """zstd level 1 on this thread: half the CPU of the default (level 3 on a thread per core) for ~12 % more bytes
    with the LiDAR points; no extra threads competing with pipeline workers."""
    from foxglove.mcap import MCAPWriteOptions

    return MCAPWriteOptions(compression_level=1, compression_threads=0)


def write_motion_mcap(path: str | Path, sequence: Sequence, kinematics: list[ObjectTrack], metadata: dict[str, Any],
                      with_points: bool = False, progress: bool = True) -> McapSummary:
    """Write the MCAP atomically (temporary file, then rename); returns per-topic message counts.

    Frames written: every sequence frame from the first to the last frame of any object.
    """
    import foxglove
    from foxglove import channels
    from foxglove import messages as m
    from tqdm import tqdm

    path = Path(path)
    if kinematics:
        lo = min(int(k.frames[0]) for k in kinematics)
        hi = max(int(k.frames[-1]) for k in kinematics)
    else:
        lo, hi = 0, len(sequence.frames) - 1
    frames = range(lo, hi + 1)
    record = {key: value if isinstance(value, str) else json.dumps(value, sort_keys=True, default=str)
              for key, value in metadata.items()}
    record["objects"] = json.dumps([{"id": k.object_id, "label": k.label, "frames": [int(k.frames[0]), int(k.frames[-1])],
                                     "valid_frames": int(k.valid.sum()), "source": k.source} for k in kinematics])
    record["frames"] = json.dumps([lo, hi])
    with atomic_path(path) as tmp, open(tmp, "wb", buffering=0) as handle:   # the writer buffers
        sink = _FirstErrorSink(handle)
        ctx = foxglove.Context()
        writer = foxglove.open_mcap(sink, context=ctx, writer_options=_write_options())
        try:
            state = _Writer(ctx, m, channels, kinematics, sequence)
            for frame in tqdm(frames, desc="mcap", unit="frame", disable=not progress, leave=False):
                state.frame(frame, with_points)
                sink.raise_error()
            writer.write_metadata(METADATA_NAME, record)
        except BaseException:
            with contextlib.suppress(Exception):
                writer.close()
            raise
        writer.close()  # finishes the summary section; errors here must surface
        sink.raise_error()
    return McapSummary(path=path, frames=len(frames), objects=len(kinematics), message_counts=state.counts)
