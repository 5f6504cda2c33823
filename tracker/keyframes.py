"""Keyframe-assisted tracks: boxes given at some frames (an annotator's keyframes), the frames between from the points.

Given boxes at keyframes k_0 < k_1 < ... (world frame):

1. passes (:func:`keyframe_passes`): every gap [a, b] is tracked twice with the online tracker, forward from the
   box at a (a keyframe re-initialises the tracker) through b, and backward from the box at b through a (the sweeps
   in reverse order on a reversed clock, the box turned by pi so the vehicle drives forward again, as the motion
   model expects; turned back afterwards). Each pass ends on the other keyframe: its closure error there is known.
   Frames before the first keyframe are tracked backward from it, frames after the last forward from it;
2. candidates (:func:`_candidates`) per frame between keyframes: the CTRV interpolation (``interpolation``, the
   default), the two passes corrected by their closure errors spread evenly over the gap and blended by time and
   drift, the raw passes blended by time, each pass corrected and raw. :func:`_select` keeps the first candidate
   unless another one's box explains clearly more of the frame's points (points within ``_INLIER_M`` of the
   shape the keyframes see in their exact boxes);
3. the offline solve (:func:`tracker.offline.refine_states`, ``refine``) re-estimates all states jointly against
   the shape aggregated from every frame (voxel means, in the box grown by ``solve_margin``), pulled toward the
   chosen states, with the keyframes as :class:`~tracker.offline.Anchors`: held exactly (default) or, with
   ``sigma_xyz`` > 0, pulled with weight 1 / sigma^2. The pull (:func:`_arc_pull`) is firm on the frames where the
   arc was kept and few points pin the frame, weak where many do and where a tracked state was chosen;
4. the size comes from the keyframes: a frame between two keyframes gets their sizes (and roll, pitch)
   interpolated linearly; the solve uses the median keyframe size. A keyframe's own box is returned unchanged
   (bit for bit).

Baselines on the same keyframes: :func:`interpolate_linear` (what annotation tools do: centre, heading, size
linear between keyframes) and :func:`interpolate_ctrv` (constant turn rate and speed: the arc from the first
keyframe whose heading turns evenly to the second's; the part of the displacement an arc cannot explain is
spread linearly, so both keyframes are met exactly). Frames outside the keyframes keep the nearest keyframe's box.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from .config import OfflineParams, TrackerConfig
from .frames import FrameSource, LidarFrame
from .geometry import Box, State, lerp_box, points_in_box, wrap_angle
from .offline import Anchors, _rebuild_shape, frame_region_points, refine_states
from .sotracker import FrameEstimate, Tracker, TrackResult

__all__ = ["KeyframeParams", "KeyframePasses", "keyframe_passes", "keyframe_schedule", "interpolate_linear", "interpolate_ctrv", "track_keyframes"]


@dataclass(frozen=True)
class KeyframeParams:
    """How :func:`track_keyframes` uses the keyframes (metres, radians)."""

    backward: bool = True       # also track every gap backward from its closing keyframe, and blend
    refine: bool = True         # the offline solve with the keyframes as anchors (False: the blended passes)
    sigma_xyz: float = 0.0      # 0: keyframes held exactly; > 0: pulled with weight 1 / sigma^2 (x, y, z)
    sigma_heading: float = 0.0  # the heading's sigma of a soft keyframe (0 with sigma_xyz > 0: 0.02 rad)
    interpolation: bool = True  # the CTRV interpolation is the default candidate between keyframes: a tracked
                                # state replaces it only where it explains clearly more points (see _select)
    arc_sigma_xyz: float = 0.02       # the solve's pull toward the arc where the choice kept it, on a frame with
    arc_sigma_heading: float = 0.005  # at most arc_points points in its box; the sigmas grow in proportion to the
    arc_points: int = 50              # points beyond (the points pin the frame), up to refinement.offline's
                                      # anchor_sigma_* (the weak pull toward a tracked state); arc_sigma_xyz 0: none
    shape_voxel: str = "means"        # the solve's fold shapes (refinement.offline.shape_voxel): a voxel's points'
                                      # mean, not its centre (centres pull the frames between the keyframes, which
                                      # are held, by up to half a voxel onto the grid's layers)
    solve_margin: float = 0.05        # m: the solve's box grown by this on every side (a face's points that lie
                                      # just outside a tight box would be cut off the shape, moving its face inward)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.sigma_xyz) and np.isfinite(self.sigma_heading)) or min(self.sigma_xyz,
                                                                                         self.sigma_heading) < 0:
            raise ValueError(f"keyframe sigmas must be finite and >= 0, not {self.sigma_xyz}, {self.sigma_heading}")

    def anchor_sigma(self) -> np.ndarray | None:
        """The (4,) sigma of soft keyframes, None for hard ones."""
        if self.sigma_xyz <= 0 and self.sigma_heading <= 0:
            return None
        xyz = self.sigma_xyz if self.sigma_xyz > 0 else 0.01
        return np.array([xyz, xyz, xyz, self.sigma_heading if self.sigma_heading > 0 else 0.02])


def keyframe_schedule(start: int, end: int, every: int) -> list[int]:
    """Frames start, start + every, ... and always ``end`` (an annotator closes the track with a keyframe)."""
    if every < 1:
        raise ValueError(f"the keyframe interval must be at least 1, not {every}")
    return sorted(set(range(start, end + 1, every)) | {end})


# ----------------------------------------------------------------------------------------- interpolation

def _gaps(frames: list[int], keyframes: Mapping[int, Box]):
    """(frame, box a, box b, t) for every frame: between keyframes a and b at fraction t; outside them the
    nearest keyframe (a = b); at a keyframe None (its box is used as given)."""
    keys = sorted(keyframes)
    if not keys:
        raise ValueError("no keyframe")
    for k in frames:
        if k in keyframes:
            yield k, None, None, 0.0
        elif k < keys[0] or k > keys[-1]:
            near = keyframes[keys[0] if k < keys[0] else keys[-1]]
            yield k, near, near, 0.0
        else:
            i = int(np.searchsorted(keys, k))
            a, b = keys[i - 1], keys[i]
            yield k, keyframes[a], keyframes[b], (k - a) / (b - a)


def interpolate_linear(frames: list[int], keyframes: Mapping[int, Box]) -> dict[int, Box]:
    """Boxes at ``frames`` linear between the keyframes (see the module docstring)."""
    return {k: keyframes[k] if a is None else lerp_box(a, b, t) for k, a, b, t in _gaps(frames, keyframes)}


def _ctrv_centre(a: Box, b: Box, t: float) -> np.ndarray:
    """The centre at fraction ``t`` along the constant-turn-rate arc from ``a`` toward ``b`` (see the module
    docstring)."""
    turn = float(wrap_angle(b.heading - a.heading))

    def arc(s: float) -> np.ndarray:  # displacement after fraction s of the gap at unit path length
        if abs(turn) < 1e-6:
            return np.array([np.cos(a.heading), np.sin(a.heading)]) * s
        return np.array([np.sin(a.heading + turn * s) - np.sin(a.heading),
                         np.cos(a.heading) - np.cos(a.heading + turn * s)]) / turn

    full = arc(1.0)
    chord = b.center[:2] - a.center[:2]
    length = float(chord @ full) / max(float(full @ full), 1e-12)   # least-squares path length (signed)
    residual = chord - length * full
    xy = a.center[:2] + length * arc(t) + t * residual
    return np.array([xy[0], xy[1], (1.0 - t) * a.z + t * b.z])


def interpolate_ctrv(frames: list[int], keyframes: Mapping[int, Box]) -> dict[int, Box]:
    """Boxes at ``frames`` on constant-turn-rate arcs between the keyframes (see the module docstring)."""
    return {k: keyframes[k] if a is None else lerp_box(a, b, t, centre=_ctrv_centre(a, b, t) if a is not b else None)
            for k, a, b, t in _gaps(frames, keyframes)}


# ------------------------------------------------------------------------------------------------ tracking

def _turned(box: Box) -> Box:
    """The same box with its length axis pointing the other way."""
    return dataclasses.replace(box, heading=float(wrap_angle(box.heading + np.pi)), roll=-box.roll, pitch=-box.pitch)


def _reversed_frame(frame: LidarFrame) -> LidarFrame:
    """The frame on a reversed clock (time and per-point offsets negated), so that frames run forward in time."""
    offsets = None if frame.point_time_offset_ns is None else -np.asarray(frame.point_time_offset_ns)
    return dataclasses.replace(frame, timestamp_ns=-int(frame.timestamp_ns), point_time_offset_ns=offsets)


def _pass(source: FrameSource, box: Box, frames: list[int], config: TrackerConfig) -> list[FrameEstimate]:
    """The online tracker from ``box`` at ``frames[0]`` through ``frames`` in the order given (descending frames:
    backward in time on the turned box; the estimates come back turned again)."""
    backward = len(frames) > 1 and frames[1] < frames[0]
    tracker = Tracker(config)
    get = (lambda k: _reversed_frame(source.lidar_frame(k))) if backward else source.lidar_frame
    out = [tracker.start(get(frames[0]), _turned(box) if backward else box)]
    out += [tracker.step(get(k)) for k in frames[1:]]
    if backward:
        out = [dataclasses.replace(e, box=_turned(e.box), state=_turned(e.box).state) for e in out]
    return out


def _blend(forward: np.ndarray, backward: np.ndarray, w_backward: np.ndarray) -> np.ndarray:
    """States (n, 4) blended with weights ``w_backward`` (n,) on the backward ones (headings the short way)."""
    out = forward + w_backward[:, None] * (backward - forward)
    out[:, 3] = forward[:, 3] + w_backward * wrap_angle(backward[:, 3] - forward[:, 3])
    return out


@dataclass(frozen=True)
class KeyframePasses:
    """The online passes of :func:`track_keyframes`, by frame: ``forward`` for every frame that is not a keyframe
    (between keyframes and after the last: the pass from the keyframe before; before the first keyframe: the
    backward pass from it), ``backward`` for the frames between two keyframes (the pass from the one after).
    ``arrivals``: per gap (a, b), the states (4,) the forward pass reached at b and the backward pass at a (None
    without backward passes): how far each pass drifted from the keyframe it ran into."""

    forward: dict[int, FrameEstimate]
    backward: dict[int, FrameEstimate]
    arrivals: dict[tuple[int, int], tuple[np.ndarray, np.ndarray | None]]


def keyframe_passes(source: FrameSource, keyframes: Mapping[int, Box], start: int, end: int, config: TrackerConfig,
                    backward: bool = True) -> KeyframePasses:
    """The online passes over ``start``..``end`` (see :class:`KeyframePasses`; ``backward=False``: no backward
    passes between keyframes)."""
    keys = sorted(keyframes)
    forward_estimates: dict[int, FrameEstimate] = {}
    backward_estimates: dict[int, FrameEstimate] = {}
    arrivals: dict[tuple[int, int], tuple[np.ndarray, np.ndarray | None]] = {}
    if start < keys[0]:
        forward_estimates.update((e.frame, e) for e in _pass(source, keyframes[keys[0]],
                                                              list(range(keys[0], start - 1, -1)), config)[1:])
    for a, b in zip(keys[:-1], keys[1:], strict=True):
        if b - a < 2:
            continue
        forward = _pass(source, keyframes[a], list(range(a, b + 1)), config)
        forward_estimates.update((e.frame, e) for e in forward[1:-1])
        back_arrival = None
        if backward:
            back = _pass(source, keyframes[b], list(range(b, a - 1, -1)), config)
            backward_estimates.update((e.frame, e) for e in back[1:-1])
            back_arrival = back[-1].state.to_array()
        arrivals[(a, b)] = (forward[-1].state.to_array(), back_arrival)
    if end > keys[-1]:
        forward_estimates.update((e.frame, e) for e in _pass(source, keyframes[keys[-1]],
                                                              list(range(keys[-1], end + 1)), config)[1:])
    return KeyframePasses(forward_estimates, backward_estimates, arrivals)


_CLOSURE_FLOOR = 0.05   # m: closure errors below this weigh as this (two good passes: the blend by time alone)


def _closure(keyframe: Box, arrival: np.ndarray) -> tuple[np.ndarray, float]:
    """The correction (4,) from a pass's arrival to the keyframe it ran into, and its size in metres (centre shift
    plus the heading error times half the length: how far a corner moved)."""
    delta = keyframe.state.to_array() - arrival
    delta[3] = wrap_angle(delta[3])
    return delta, float(np.linalg.norm(delta[:3]) + 0.5 * keyframe.length * abs(delta[3]))


def _candidates(passes: KeyframePasses, keyframes: Mapping[int, Box], both_ways: bool) -> dict[int, np.ndarray]:
    """Each frame's candidate states (m, 4) from the passes, the default first. Between keyframes a < k < b,
    t = (k - a) / (b - a): the forward pass corrected by t x its closure error at b (the drift spread evenly over
    the gap, as a loop closure does), the backward one by (1 - t) x its closure error at a; the default blends the
    two with weights (1 - t) / e_forward and t / e_backward (e: the closure error's size, at least
    ``_CLOSURE_FLOOR``: each pass is trusted near the keyframe it started from, and less the more it drifted);
    then the raw passes blended by time alone, the corrected and the raw passes (a pass that lost the object
    abruptly is right before it did, and its correction is then wrong there). Elsewhere the forward pass's state."""
    out = {k: e.state.to_array()[None] for k, e in passes.forward.items()}
    for (a, b), (forward_arrival, backward_arrival) in passes.arrivals.items():
        frames = np.arange(a + 1, b)
        t = (frames - a) / (b - a)
        raw_f = np.array([passes.forward[int(k)].state.to_array() for k in frames])
        fix, error_f = _closure(keyframes[b], forward_arrival)
        fixed_f = raw_f + t[:, None] * fix
        rows = [fixed_f, raw_f]
        if both_ways and backward_arrival is not None:
            raw_b = np.array([passes.backward[int(k)].state.to_array() for k in frames])
            fix, error_b = _closure(keyframes[a], backward_arrival)
            fixed_b = raw_b + (1.0 - t)[:, None] * fix
            w_f, w_b = (1.0 - t) / max(error_f, _CLOSURE_FLOOR), t / max(error_b, _CLOSURE_FLOOR)
            rows = [_blend(fixed_f, fixed_b, w_b / (w_f + w_b)), _blend(raw_f, raw_b, t), fixed_f, fixed_b, raw_f, raw_b]
        stacked = np.stack(rows, axis=1)   # (frames, m, 4)
        out.update(zip(frames.tolist(), stacked, strict=True))
    return out


def _object_frame(points: np.ndarray, state: np.ndarray) -> np.ndarray:
    c, s = np.cos(state[3]), np.sin(state[3])
    d = points - state[:3]
    return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]], axis=1)


def _select(source: FrameSource, keyframes: Mapping[int, Box], candidates: dict[int, np.ndarray],
            config: TrackerConfig, size: np.ndarray) -> tuple[dict[int, np.ndarray], set[int]]:
    """Per frame, the candidate whose box explains the most of the frame's points: points inside it (x 1.1) within
    ``_INLIER_M`` of the shape seen at the keyframes (their points in their exact boxes, object frame). The default
    (first) candidate is kept unless another explains ``_SELECT_MARGIN`` times as many points."""
    from scipy.spatial import cKDTree

    from .metrics import voxel_downsample_centres

    offline = config.refinement.offline
    seen = []
    for k, box in keyframes.items():
        pts = frame_region_points(source.lidar_frame(k), box, config, offline)
        seen.append(_object_frame(pts[points_in_box(pts, box, 1.0)], box.state.to_array()))
    shape = voxel_downsample_centres(np.vstack(seen), offline.voxel) if seen else np.zeros((0, 3))
    chosen = {k: c[0] for k, c in candidates.items()}
    replaced: set[int] = set()
    if len(shape) < _MIN_SHAPE_POINTS:
        return chosen, replaced
    tree = cKDTree(shape)
    half = 0.55 * np.asarray(size, dtype=np.float64)
    for k, cands in candidates.items():
        if len(cands) < 2:
            continue
        spread = float(np.max(np.linalg.norm(cands[:, :2] - cands[0, :2], axis=1)))
        x, y, z, heading = (float(v) for v in cands[0])
        reach = Box(x, y, z, heading, float(size[0]) + 2 * spread + 1.0, float(size[1]) + 2 * spread + 1.0,
                    float(size[2]))
        pts = frame_region_points(source.lidar_frame(k), reach, config, offline)
        counts = []
        for state in cands:
            local = _object_frame(pts, state)
            local = local[np.all(np.abs(local) <= half, axis=1)]
            counts.append(int(np.sum(tree.query(local, distance_upper_bound=_INLIER_M)[0] <= _INLIER_M))
                          if len(local) else 0)
        best = int(np.argmax(counts))
        if counts[best] >= max(_SELECT_MARGIN * counts[0], counts[0] + _SELECT_MIN_GAIN):
            chosen[k] = cands[best]
            replaced.add(k)
    return chosen, replaced


_INLIER_M = 0.1            # a frame point within this of the keyframes' shape is explained by the box
_SELECT_MARGIN = 1.1       # another candidate replaces the default when it explains this many times the points ...
_SELECT_MIN_GAIN = 5       # ... and at least this many more
_MIN_SHAPE_POINTS = 30     # fewer keyframe shape points: no selection (the default candidates)


def _arc_pull(arc: np.ndarray, counts: np.ndarray, params: KeyframeParams, offline: OfflineParams) -> np.ndarray:
    """Each frame's sigma (K, 4) of the solve's pull toward its chosen state: on the arc (``arc``, where the choice
    kept the CTRV interpolation) ``arc_sigma_*`` times max(1, points in its box / ``arc_points``), at most the weak
    pull of ``offline.anchor_sigma_*``, which every other frame gets (a tracked state is the points' already). Few
    points pin no frame (a sparse or oblique view: the solve would turn and shift it by the shape's errors), many
    do (a lane change the choice did not see: the solve follows them)."""
    weak = np.array([offline.anchor_sigma_xyz] * 3 + [offline.anchor_sigma_heading])
    if offline.anchor_sigma_z > 0:
        weak[2] = offline.anchor_sigma_z
    firm = np.array([params.arc_sigma_xyz] * 3 + [params.arc_sigma_heading])
    scale = np.maximum(1.0, np.asarray(counts, dtype=np.float64) / max(params.arc_points, 1))
    return np.where(np.asarray(arc)[:, None], np.minimum(firm[None] * scale[:, None], weak[None]), weak[None])


def track_keyframes(source: FrameSource, keyframes: Mapping[int, Box], start: int | None = None,
                    end: int | None = None, config: TrackerConfig | None = None,
                    params: KeyframeParams = KeyframeParams(), passes: KeyframePasses | None = None) -> TrackResult:
    """A track over ``start``..``end`` (default: the first to the last keyframe) through the keyframe boxes
    (world frame, by frame index; see the module docstring). The result's mode is ``offline``; keyframe
    estimates carry the flag ``keyframe``, the others ``keyframes`` (and ``offline`` when refined). ``passes``: the
    online passes when the caller has them (:func:`keyframe_passes` over the same frames and keyframes)."""
    config = config or TrackerConfig()
    keys = sorted(int(k) for k in keyframes)
    if not keys:
        raise ValueError("no keyframe")
    start = keys[0] if start is None else int(start)
    end = keys[-1] if end is None else int(end)
    keyframes = {k: keyframes[k] for k in keys if start <= k <= end}
    if not keyframes:
        raise ValueError(f"no keyframe in frames {start}..{end}")
    keys = sorted(keyframes)
    frames = list(range(start, end + 1))
    if passes is None:
        passes = keyframe_passes(source, keyframes, start, end, config, params.backward)
    size = np.median(np.array([keyframes[k].size for k in keys]), axis=0)
    candidates = _candidates(passes, keyframes, params.backward)
    if params.interpolation:   # the CTRV arc first: the default, kept unless a tracked state explains more points
        arcs = interpolate_ctrv(sorted(candidates), keyframes)
        inside = [k for k in candidates if keys[0] < k < keys[-1]]
        candidates.update({k: np.vstack([arcs[k].state.to_array()[None], candidates[k]]) for k in inside})
    states, replaced = _select(source, keyframes, candidates, config, size)
    estimates = {k: e if k not in passes.backward or not params.backward
                 else dataclasses.replace(e, time_ms=e.time_ms + passes.backward[k].time_ms)
                 for k, e in passes.forward.items()}
    sizes = interpolate_linear(frames, keyframes)   # each frame's size (and tilt) from its keyframes
    online = np.array([keyframes[k].state.to_array() if k in keyframes else states[k] for k in frames])
    flags: dict[int, tuple[str, ...]] = {k: ("keyframe",) if k in keyframes else ("keyframes",) for k in frames}
    extra_ms = 0.0   # the solve's time, spread over the frames
    points: list[np.ndarray] | None = None
    if params.refine and len(frames) > 2:
        t0 = time.perf_counter()
        # voxel means on the offline grid: the dense tracks' finer centre grid (dense_voxel) is the centres' remedy
        offline = dataclasses.replace(config.refinement.offline, shape_voxel=params.shape_voxel, dense_voxel=0.0)
        points, previous = [], None
        for k, state in zip(frames, online, strict=True):
            frame = source.lidar_frame(k)
            points.append(frame_region_points(frame, Box(*state, *size), config, offline, previous))
            previous = (int(frame.timestamp_ns), np.asarray(frame.world_from_ego, dtype=np.float64))
        pull = None
        if params.interpolation and params.arc_sigma_xyz > 0:
            arc = np.array([keys[0] < k < keys[-1] and k not in replaced for k in frames])
            counts = np.array([points_in_box(p, Box(*state, *size), 1.0).sum() if len(p) else 0
                               for p, state in zip(points, online, strict=True)])
            pull = _arc_pull(arc, counts, params, offline)
        anchors = Anchors(np.array([frames.index(k) for k in keys]), np.array([online[frames.index(k)] for k in keys]),
                          params.anchor_sigma(), pull)
        online, shape = refine_states(points, online, size + 2.0 * params.solve_margin, offline, seed=config.seed,
                                      anchors=anchors)
        flags = {k: f if k in keyframes else f + ("offline",) for k, f in flags.items()}
        extra_ms = (time.perf_counter() - t0) * 1e3 / len(frames)
    out: list[FrameEstimate] = []
    for i, k in enumerate(frames):
        box = keyframes[k] if k in keyframes else sizes[k].with_state(State.from_array(online[i]))
        pts = points[i] if points is not None else np.zeros((0, 3))
        obj = pts[points_in_box(pts, box, 1.0)] if len(pts) else pts
        est = estimates.get(k)
        out.append(FrameEstimate(k, box.state, box, len(obj) if points is not None else (est.num_points if est else 0),
                                 est.quality if est else 1.0, flags[k],
                                 (est.time_ms if est else 0.0) + extra_ms, obj))
    if points is None:
        shape = _rebuild_shape([e.points for e in estimates.values()],
                               np.array([e.state.to_array() for e in estimates.values()]), size,
                               config.refinement.offline.voxel) if estimates else np.zeros((0, 3))
    return TrackResult(out, size, shape if shape is not None else np.zeros((0, 3)), config, mode="offline")
