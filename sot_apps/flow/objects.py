"""The objects to annotate (:class:`MeshedObject`: an ObjectTrack of states at known times, and a mesh), from
tracks or GT boxes.

- ``objects_from_tracks``: the tracker's ``track.json`` + ``shape.ply`` (states at each frame's
  ``timestamp_ns``, shape points in the object frame).
- ``objects_from_annotations``: ground-truth boxes. Each box is stamped with the median capture
  time of the LiDAR points inside it (sweeps are not motion-compensated, so a box describes the
  object when the beam passed it, not at the frame timestamp); the shape is the ground-removed
  points inside the boxes, aggregated in the object frame.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import Iterable

import numpy as np

from tracker import Box, invert_transform, points_in_box, transform_points

from ..errors import InputError
from ..io.object_track import ObjectTrack
from ..io.sequence import Sequence
from ..objects.meshes import Mesh, box_mesh, mesh_from_points, voxel_downsample_means
from ..objects.shapes import ShapeParams, box_capture_time, object_points_by_frame
from ..objects.trajectory import CAMERA_EXTRAPOLATION_NS, EndMode, Trajectory

__all__ = ["MeshedObject", "objects_from_tracks", "objects_from_annotations", "mesh_for", "smoothed"]


@dataclass(frozen=True, eq=False)
class MeshedObject:
    """One object flow places in the images: its :class:`ObjectTrack` and its mesh (object frame).

    The track holds the object's id, label, size, source and shape points (object frame), and the WORLD states
    flow interpolates, at the times its boxes describe (``timestamps_ns``: the capture time of the box's points,
    or the frame time); its ``frames`` are the sequence frames of those states (sample indices for states that do
    not come from a sequence, :meth:`from_trajectory`). :attr:`trajectory` interpolates them (``end``,
    ``max_extrapolation_ns``), made on first use."""

    track: ObjectTrack
    mesh: Mesh
    end: EndMode = "extrapolate"
    max_extrapolation_ns: int | None = CAMERA_EXTRAPOLATION_NS

    @classmethod
    def from_trajectory(cls, object_id: str, label: str, trajectory: Trajectory, points: np.ndarray, mesh: Mesh,
                        size: Iterable[float], source: str) -> "MeshedObject":
        """An object whose states are the samples of ``trajectory`` (frames 0..N-1), with its end mode."""
        n = len(trajectory.times_ns)
        track = ObjectTrack.from_states(object_id, label, size, np.arange(n), trajectory.times_ns, trajectory.states,
                                        np.ones(n, dtype=bool), tilts=trajectory.tilts, source=source,
                                        shape_points=np.asarray(points, dtype=np.float64).reshape(-1, 3))
        return cls(track, mesh, trajectory.end, trajectory.max_extrapolation_ns)

    @cached_property
    def trajectory(self) -> Trajectory:
        return Trajectory.from_track(self.track, self.end, self.max_extrapolation_ns)

    @property
    def object_id(self) -> str:
        return self.track.object_id

    @property
    def label(self) -> str:
        return self.track.label

    @property
    def source(self) -> str:
        return self.track.source

    @property
    def points(self) -> np.ndarray:
        """(M, 3) shape points, object frame."""
        return self.track.shape_points if self.track.shape_points is not None else np.zeros((0, 3))

    @property
    def size(self) -> np.ndarray:
        return np.asarray(self.track.size, dtype=np.float64)

    def extent(self) -> np.ndarray:
        """Half extents of the object (box size and mesh bounds, whichever is larger), object frame."""
        mesh_half = np.abs(self.mesh.vertices).max(axis=0) if len(self.mesh.vertices) else np.zeros(3)
        return np.maximum(self.size / 2.0, mesh_half)


def mesh_for(points: np.ndarray, size: np.ndarray, method: str = "hull", extend_to_ground: bool = False) -> Mesh:
    """Mesh of an object's shape points; the box itself when the points cannot span a volume.

    ``extend_to_ground``: copies of the lower-body points are dropped to the box bottom, so the
    hull reaches the road (ground removal cuts the lowest ~0.2 m away). Off by default: on the
    synthetic benchmark it covered 4 % more object pixels but tripled the pixels wrongly claimed
    (the road under the body between the wheels).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if extend_to_ground and len(points):
        bottom = -float(size[2]) / 2.0
        low = points[points[:, 2] < bottom + 0.6]
        if len(low):
            dropped = low.copy()
            dropped[:, 2] = bottom
            points = np.concatenate([points, dropped])
    mesh = mesh_from_points(points, method) if len(points) >= 4 else None
    return mesh if mesh is not None else box_mesh(*(float(v) for v in size))


def _near_box(points_ego: np.ndarray, world_from_ego: np.ndarray, box: Box) -> np.ndarray:
    """Indices of the ego-frame points within the box's bounding sphere + 1 m: a float32 pass over the sweep whose
    result holds every point inside the box (the margin is far above float32 rounding), so the exact float64 test
    needs to run on these only."""
    centre = transform_points(invert_transform(world_from_ego), box.center.reshape(1, 3))[0].astype(np.float32)
    radius = np.float32(np.linalg.norm(box.size) / 2.0 + 1.0)
    d = np.asarray(points_ego, dtype=np.float32) - centre
    return np.flatnonzero(np.einsum("ij,ij->i", d, d) <= radius * radius)


def objects_from_tracks(track_dirs: Iterable[str | Path], mesh_method: str = "hull", seq: Sequence | None = None,
                        box_time: str = "points", frames: Iterable[int] | None = None) -> list[MeshedObject]:
    """Objects from track directories (track.json + shape.ply).

    ``box_time="points"`` (needs ``seq``) restamps the states of ``frames`` (default: all) with the median
    capture time of the sweep points inside the track's box: the tracker fits sweeps whose object
    motion is not compensated, so its state at frame k describes the object when the beam passed it,
    while track.json records the frame timestamp. ``"frame"`` keeps track.json's ``timestamp_ns``.
    """
    from ..io.tracks import check_track_belongs, read_track

    if box_time not in ("points", "frame"):
        raise ValueError(f"box_time must be 'points' or 'frame', not {box_time!r}")
    wanted = None if frames is None else set(frames)
    out = []
    for directory in track_dirs:
        header, rows = read_track(directory)
        if not len(rows):
            raise InputError(directory, "track has no frames")
        if seq is not None:
            check_track_belongs(header, rows, seq, Path(directory) / "track.json")
        rows = replace(rows, source=f"track ({header.mode}):{Path(directory)}")
        shape = rows.shape_points
        times = rows.timestamps_ns.copy()
        if box_time == "points" and seq is not None:
            for i, frame in enumerate(int(k) for k in rows.frames):
                if (wanted is not None and frame not in wanted) or not 0 <= frame < len(seq.frames):
                    continue
                sweep = seq.sweep(frame)
                if sweep.time_offset_ns is None:
                    continue
                box = rows.box(i)
                near = _near_box(sweep.xyz, seq.frames[frame].world_from_ego, box)
                world = transform_points(seq.frames[frame].world_from_ego, sweep.xyz[near])
                inside = near[points_in_box(world, box)]
                times[i] = box_capture_time(seq.frames[frame].timestamp_ns, sweep.time_offset_ns[inside], 3)
        out.append(MeshedObject(rows.restamped(times), mesh_for(shape, np.asarray(rows.size), mesh_method)))
    return out


def objects_for_pairs(seq: Sequence, track_dirs: Iterable[str | Path], pairs: tuple[int, int] | None,
                      mesh_method: str = "hull", box_time: str = "points") -> list[MeshedObject]:
    """Objects from track directories for the flow of image ``pairs`` (inclusive; None = every frame): the
    states of the sweeps around the pairs (2 frames of margin) re-stamped as ``box_time`` says. ``sot-apps
    flow --tracks`` and the pipeline's flow stage both call this, so they give the same flow."""
    a, b = pairs if pairs is not None else (0, len(seq.frames) - 1)
    return objects_from_tracks(track_dirs, mesh_method=mesh_method, seq=seq, box_time=box_time,
                               frames=range(max(a - 2, 0), b + 3))


def objects_from_annotations(seq: Sequence, track_ids: list[str] | None = None, frames: Iterable[int] | None = None,
                             moving_only: bool = False, mesh_method: str = "hull", ground_clearance: float = 0.2,
                             voxel: float = 0.05, box_time: str = "points", extend_to_ground: bool = False,
                             progress: bool = True) -> list[MeshedObject]:
    """Objects from the ground-truth boxes (see module doc). ``frames``: sweeps used for shapes and timing.

    ``box_time``: "points" stamps each box with the median capture time of its points (PandaSet: boxes
    are fitted to the unmotion-compensated points); "frame" uses the frame timestamp (datasets whose
    boxes are the object state at the frame time, e.g. ``sot-apps synth``).
    """
    if box_time not in ("points", "frame"):
        raise ValueError(f"box_time must be 'points' or 'frame', not {box_time!r}")
    tracks = seq.tracks()
    if not tracks:
        raise InputError(seq.root, "the sequence has no annotations (needed by --from-annotations)")
    ids = [seq.resolve_track_id(t) for t in track_ids] if track_ids else sorted(tracks)
    frame_list = set(range(len(seq.frames)) if frames is None else frames)
    boxes = {tid: ObjectTrack.from_boxes(tid, tracks[tid].label, {k: b for k, b in tracks[tid].boxes_by_frame().items()
                                                                 if k in frame_list})
             for tid in ids}
    boxes = {tid: tb for tid, tb in boxes.items() if len(tb)}
    if moving_only:
        from ..objects.selection import DEFAULT_SELECTION

        boxes = {tid: tb for tid, tb in boxes.items()
                 if DEFAULT_SELECTION.track_motion(tracks[tid], seq.timestamps_ns).moving}
    params = ShapeParams(ground_clearance=ground_clearance, capture_time=box_time == "points", end="extrapolate",
                         max_extrapolation_ns=CAMERA_EXTRAPOLATION_NS)
    points, stamped = object_points_by_frame(seq, boxes, params, progress=progress)
    out = []
    for tid, tb in boxes.items():
        size = np.median(tb.boxes[:, 4:7], axis=0)
        parts = [points[tid][k] for k in sorted(points[tid])]
        shape = voxel_downsample_means(np.concatenate(parts) if parts else np.zeros((0, 3)), voxel)
        track = replace(stamped[tid], shape_points=shape, size=tuple(float(v) for v in size), source="annotations")
        out.append(MeshedObject(track, mesh_for(shape, size, mesh_method, extend_to_ground), params.end,
                                params.max_extrapolation_ns))
    return out


def smoothed(objects: list[MeshedObject], source: str = "annotations") -> list[MeshedObject]:
    """The objects with their states replaced by the motion export's CTRV smoother (EKF + RTS).

    Per-frame box jitter of a few centimetres is several pixels of flow for a car 10 m away; the
    smoother keeps the states on a physically plausible path. ``source``: "annotations" or "tracks"
    (selects the smoother's measurement noise).
    """
    from ..objects.smoother import ANNOTATION_SMOOTHER, TRACKER_SMOOTHER, smooth_track

    config = ANNOTATION_SMOOTHER if source == "annotations" else TRACKER_SMOOTHER
    out = []
    for obj in objects:
        traj = obj.trajectory
        if len(traj.times_ns) < 3:
            out.append(obj)
            continue
        track = ObjectTrack.from_states(obj.object_id, obj.label, tuple(float(v) for v in obj.size),
                                        np.arange(len(traj.times_ns)),
                            traj.times_ns, traj.states, np.ones(len(traj.times_ns), bool))
        kin = smooth_track(track, config)
        states = kin.states
        if not np.isfinite(states).all():
            out.append(obj)
            continue
        boxes = obj.track.boxes.copy()
        boxes[:, :4] = states
        out.append(MeshedObject(replace(obj.track, boxes=boxes), obj.mesh, obj.end, obj.max_extrapolation_ns))
    return out
