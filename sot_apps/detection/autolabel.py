"""Auto-labels: full, consistent tracks of every vehicle of a sequence from per-frame detections.

1. :func:`associate_tracks`: tracking-by-detection. Every live track predicts its box with a constant-velocity
   Kalman filter (:class:`tracker.det_baseline.ConstantVelocityFilter`); detections with score >=
   ``min_score`` are assigned to predictions by the Hungarian method on 1 - BEV IoU (IoU >= ``min_iou``, or
   centres within ``max_centre_distance`` for small fast boxes); an unassigned detection with score >=
   ``birth_score`` starts a track; a track missed ``max_misses`` frames in a row ends. Tracks with fewer
   than ``min_detections`` detections are dropped (clutter).
   A track needs ``confirm_detections`` detections scored >= ``birth_score`` (a confirmed birth).
2. :func:`track_both_ways`: SOT (``det_sot`` with re-acquisition, :func:`label_config_tracker`) from each track's
   most reliable detection (highest score; its size is the median size of the track's detections), forward to
   ``LabelConfig.extend`` frames past the track's last detection and backward to as many before its first, with
   the Detection term on the track's own detections; all tracks in ONE forward and ONE backward pass over the
   sweeps (:func:`sot_apps.tracking.track_objects`, ``chunk`` tracks at a time). The frames past the
   detections are kept up to the first one without support (:func:`_trimmed`).
3. :func:`merge_duplicates`: tracks whose boxes overlap on most shared frames are one object (the one with the
   most supported frames keeps the others' detections); tracks with fewer than ``min_supported_frames``
   supported frames are dropped.
4. :func:`label_from_result`: the offline refinement (:mod:`tracker.offline`) over the whole span, and the whole
   track is moved by the median offset of its detections (:func:`anchor_to_detections`: SOT is exact relative
   to its seed box, the detections fix where the box sits); finally the box is fitted to the points the track
   gathered over all its frames (:func:`fit_to_points`): on every axis whose two faces the points show, the
   points give the extent (the detector's size and offset errors are correlated over time, so their median
   keeps a bias); on an axis seen from one side only, the box keeps its size and moves just enough to hold the
   points. Each axis weighs the points' estimate against the detections' median by their errors
   (:func:`detection_sigma`). Each label box carries its track's mean detection score.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.optimize import linear_sum_assignment

from tracker import (
    Box,
    ConstantVelocityFilter,
    FrameDetections,
    FrameSource,
    LidarFrame,
    TrackerConfig,
    TrackResult,
    align_heading,
    get_preset,
    iou_bev_batch,
    points_in_box,
    voxel_downsample_centres,
    wrap_angle,
)

from ..io.object_track import ObjectTrack

__all__ = ["AssociationConfig", "AutoLabel", "associate_tracks", "LabelConfig", "track_both_ways",
           "merge_duplicates", "label_from_result", "label_config_tracker", "anchor_to_detections",
           "PointFit", "fit_to_points", "detection_sigma", "autolabel", "per_frame_detections", "labels_as_detections", "tracks_as_detections",
           "write_autolabels"]


@dataclass(frozen=True)
class AssociationConfig:
    min_score: float = 0.3
    birth_score: float = 0.5
    min_iou: float = 0.1
    max_centre_distance: float = 1.5
    max_misses: int = 3
    min_detections: int = 3
    confirm_detections: int = 2    # detections scored >= birth_score a track needs (a confirmed birth)


def _detections_by_frame(detection_track: ObjectTrack) -> dict[int, np.ndarray]:
    """A detection track's (7,) boxes by frame (a detection track: an ObjectTrack with a ``scores`` column)."""
    return dict(zip(detection_track.frames.tolist(), detection_track.boxes, strict=True))


def _scores_by_frame(detection_track: ObjectTrack) -> dict[int, float]:
    return dict(zip(detection_track.frames.tolist(), np.asarray(detection_track.scores).tolist(), strict=True))


@dataclass(frozen=True)
class AutoLabel:
    """One auto-labelled object: ``track`` its box per frame of its span (an ObjectTrack with the refinement's
    shape as ``shape_points``; ``boxes`` is a view of it), its score, and the detections associated over time."""

    track: ObjectTrack
    score: float
    detections: ObjectTrack    # the detections associated over time (boxes and their scores)

    @classmethod
    def of(cls, track_id: str, boxes: dict[int, Box], score: float, shape: np.ndarray,
           detections: ObjectTrack) -> "AutoLabel":
        """The label of ``boxes`` by frame with its ``score`` and ``shape`` (object frame)."""
        return cls(ObjectTrack.from_boxes(track_id, "", boxes, shape_points=shape), score, detections)

    @property
    def track_id(self) -> str:
        return self.track.object_id

    @property
    def shape(self) -> np.ndarray:
        return self.track.shape_points

    @cached_property
    def boxes(self) -> dict[int, Box]:
        """Box by frame, in frame order."""
        return self.track.boxes_by_frame()


def associate_tracks(detections: dict[int, FrameDetections], n_frames: int,
                     config: AssociationConfig = AssociationConfig()) -> list[ObjectTrack]:
    """Detection tracks (see the module docstring; ObjectTracks with a ``scores`` column), ids ``t0000``,
    ``t0001``, ... in order of birth."""
    live: list[dict] = []
    finished: list[dict] = []
    next_id = 0
    for k in range(n_frames):
        det = detections.get(k, FrameDetections.empty())
        keep = det.scores >= config.min_score
        boxes, scores = det.boxes[keep], det.scores[keep]
        predicted = np.array([np.r_[t["kf"].predict(), t["size"]] for t in live]).reshape(-1, 7)
        cost = np.ones((len(live), len(boxes)))
        if len(live) and len(boxes):
            a = np.repeat(predicted, len(boxes), axis=0)
            b = np.tile(boxes, (len(live), 1))
            iou = iou_bev_batch(a, b).reshape(len(live), len(boxes))
            dist = np.hypot(a[:, 0] - b[:, 0], a[:, 1] - b[:, 1]).reshape(len(live), len(boxes))
            ok = (iou >= config.min_iou) | (dist <= config.max_centre_distance)
            cost = np.where(ok, 1.0 - iou + 0.1 * np.minimum(dist, 10.0), 1e6)
        assigned_tracks, assigned_dets = set(), set()
        if cost.size:
            rows, cols = linear_sum_assignment(cost)
            for r, c in zip(rows, cols, strict=True):
                if cost[r, c] < 1e6:
                    t = live[r]
                    t["kf"].update(boxes[c])
                    t["boxes"][k] = boxes[c].copy()
                    t["scores"][k] = float(scores[c])
                    t["misses"] = 0
                    assigned_tracks.add(r)
                    assigned_dets.add(c)
        still = []
        for i, t in enumerate(live):
            if i not in assigned_tracks:
                t["misses"] += 1
            (still if t["misses"] <= config.max_misses else finished).append(t)
        live = still
        for c in range(len(boxes)):
            if c not in assigned_dets and scores[c] >= config.birth_score:
                box = Box(*boxes[c])
                live.append({"id": next_id, "kf": ConstantVelocityFilter(box), "size": boxes[c][4:7].copy(),
                             "boxes": {k: boxes[c].copy()}, "scores": {k: float(scores[c])}, "misses": 0})
                next_id += 1
    finished += live
    finished.sort(key=lambda t: t["id"])
    return [ObjectTrack(f"t{t['id']:04d}", "", list(t["boxes"]), list(t["boxes"].values()),
                        scores=list(t["scores"].values())) for t in finished
            if len(t["boxes"]) >= config.min_detections
            and sum(v >= config.birth_score for v in t["scores"].values()) >= config.confirm_detections]


class _Reversed:
    """A FrameSource over frames ``last`` .. 0 in reverse order (frame indices stay the original ones)."""

    def __init__(self, source: FrameSource, last: int) -> None:
        self.source, self.last = source, last

    def __len__(self) -> int:
        return self.last + 1

    def lidar_frame(self, index: int) -> LidarFrame:
        return self.source.lidar_frame(self.last - index)


def _turned(box: Box) -> Box:
    return Box(box.x, box.y, box.z, float(wrap_angle(box.heading + np.pi)), box.length, box.width, box.height)


def _merge(backward: TrackResult | None, forward: TrackResult) -> TrackResult:
    """One result in frame order; the backward pass ran on the turned box (see :func:`label_track`)."""
    estimates = list(forward.estimates)
    if backward is not None:
        back = [dataclasses.replace(e, box=_turned(e.box), state=_turned(e.box).state) for e in backward.estimates[1:]]
        estimates = list(reversed(back)) + estimates
    return TrackResult(estimates, forward.size, forward.shape, forward.config)


def _detection_velocity(detection_track: ObjectTrack, frame: int, window: int = 5) -> np.ndarray:
    """Per-frame motion [dx, dy, dz, 0] near ``frame`` from the track's detections: a least-squares line through
    the detection centres of the ``window`` frames either side (zero with fewer than 2 detections)."""
    near = [k for k in detection_track.frames.tolist() if abs(k - frame) <= window]
    if len(near) < 2:
        return np.zeros(4)
    t = np.array(near, dtype=np.float64)
    by_frame = _detections_by_frame(detection_track)
    centres = np.array([by_frame[k][:3] for k in near])
    slope = np.polyfit(t - t.mean(), centres, 1)[0]
    return np.array([slope[0], slope[1], slope[2], 0.0])


@dataclass(frozen=True)
class PointFit:
    """How :func:`fit_to_points` gathers a track's points and reads its box from them (metres)."""

    margin: float = 0.3              # points up to this far outside the box footprint may grow it
    ground_ring: float = 1.0         # the ground height of a frame: median height of the points in this ring
    ground_clearance: float = 0.2    # points less than this above the ground are ground, not vehicle
    min_ground_points: int = 10      # fewer ring points below the box centre: no ground estimate that frame
    voxel: float = 0.05              # pooled points are thinned to one per voxel (dense frames do not dominate)
    trim: float = 0.002              # share of the thinned points ignored at each end of an axis (stray returns)
    both_faces: float = 0.9          # the points span >= this share of the size: both faces seen
    min_points: int = 50             # fewer gathered points: the boxes are left as they are
    point_sigma: float = 0.1         # error of a box read from the points (registration, labelling convention)


def fit_to_points(source: FrameSource, boxes: dict[int, Box], fit: PointFit = PointFit(),
                  detection_track: ObjectTrack | None = None) -> dict[int, Box]:
    """The track's boxes moved and resized by one object-frame correction read from the points of all its frames.

    Each frame's points in the box footprint grown by ``margin`` and above that frame's ground (median height
    of the points in the surrounding ring below the box centre, + ``ground_clearance``) go to the object
    frame and are pooled (one per ``voxel``). Per axis (length, width, height), with trimmed extremes lo..hi:
    if hi - lo >= ``both_faces`` x size, both faces are seen and the box spans lo..hi; otherwise the size
    stays and the centre moves the least that puts lo..hi inside the box. Where the ground is seen, the
    height spans the ground to the highest point (a vehicle stands on the ground; LiDAR sees it from above).

    With ``detection_track`` (the detections the boxes were anchored on, :func:`anchor_to_detections`), the
    correction is weighed against the anchor by their errors: per axis, the points' estimate gets the weight
    sigma_det^2 / (sigma_det^2 + ``point_sigma``^2), with sigma_det the error of the detections' median
    (:func:`detection_sigma`). Many detections with uncorrelated errors: the anchor stays; a few, or errors
    repeated from frame to frame: the points decide."""
    pooled, bottoms = [], []
    for k, box in boxes.items():
        points = source.lidar_frame(k).points_world()
        near = points[points_in_box(points, _grown(box, fit.ground_ring, 1.0))]
        if len(near) == 0:
            continue
        local = _object_frame(near, box)
        half = np.array([box.length, box.width]) / 2.0
        inside = np.all(np.abs(local[:, :2]) <= half + fit.margin, axis=1)
        ring = ~np.all(np.abs(local[:, :2]) <= half + fit.margin + 0.2, axis=1) & (local[:, 2] < 0.0)
        ground = -box.height / 2.0
        if ring.sum() >= fit.min_ground_points:
            ground = float(np.median(local[ring, 2]))
            bottoms.append(ground)
        keep = inside & (local[:, 2] > ground + fit.ground_clearance) & (local[:, 2] <= box.height / 2.0 + fit.margin)
        pooled.append(local[keep])
    points = voxel_downsample_centres(np.vstack(pooled), fit.voxel) if pooled else np.zeros((0, 3))
    if len(points) < fit.min_points:
        return boxes
    first = next(iter(boxes.values()))
    size = np.array([first.length, first.width, first.height])
    cut = max(1, int(fit.trim * len(points)))
    ordered = np.sort(points, axis=0)
    lo, hi = ordered[cut], ordered[-cut - 1]
    both = hi - lo >= fit.both_faces * size
    if bottoms:  # a vehicle stands on the ground and LiDAR sees it from above: ground to the highest point
        lo[2] = float(np.median(bottoms))
        both[2] = True
    new_size = np.where(both, hi - lo, size)
    centre = np.where(both, (lo + hi) / 2.0, np.clip(0.0, hi - size / 2.0, lo + size / 2.0))
    if detection_track is not None:
        sigma_centre, sigma_size = detection_sigma(boxes, detection_track)
        centre = centre * _weight(sigma_centre, fit.point_sigma)
        new_size = size + (new_size - size) * _weight(sigma_size, fit.point_sigma)
    du, dv, dz = centre
    out = {}
    for k, box in boxes.items():
        c, s = np.cos(box.heading), np.sin(box.heading)
        out[k] = Box(box.x + c * du - s * dv, box.y + s * du + c * dv, box.z + dz, box.heading, *new_size)
    return out


def _weight(sigma_det: np.ndarray, sigma_points: float) -> np.ndarray:
    """Inverse-variance weight of the points' estimate against the detections' (1 where sigma_det is inf)."""
    with np.errstate(invalid="ignore"):
        w = sigma_det ** 2 / (sigma_det ** 2 + sigma_points ** 2)
    return np.where(np.isfinite(sigma_det), w, 1.0)


def detection_sigma(boxes: dict[int, Box], detection_track: ObjectTrack) -> tuple[np.ndarray, np.ndarray]:
    """Errors (3,) of the median centre offset (length, width, up; object frame) and of the median size of the
    track's detections relative to ``boxes``: robust spread (1.4826 MAD) / sqrt(effective count), the count
    shrunk by the lag-1 autocorrelation rho of the series, n (1 - rho) / (1 + rho). Inf with < 3 detections."""
    detections = _detections_by_frame(detection_track)
    frames = sorted(k for k in detections if k in boxes)
    if len(frames) < 3:
        return np.full(3, np.inf), np.full(3, np.inf)
    offsets, sizes = [], []
    for k in frames:
        det, box = detections[k], boxes[k]
        offsets.append(_object_frame(det[None, :3], box)[0])
        sizes.append(det[4:7])
    return _median_sigma(np.array(offsets)), _median_sigma(np.array(sizes))


def _median_sigma(series: np.ndarray) -> np.ndarray:
    deviation = series - np.median(series, axis=0)
    spread = 1.4826 * np.median(np.abs(deviation), axis=0)
    a, b = deviation[:-1], deviation[1:]
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = np.nan_to_num((a * b).sum(axis=0) / (deviation ** 2).sum(axis=0))
    rho = np.clip(rho, 0.0, 0.95)
    n_eff = np.maximum(len(series) * (1.0 - rho) / (1.0 + rho), 1.0)
    return spread / np.sqrt(n_eff)


def _grown(box: Box, margin: float, z_margin: float) -> Box:
    return Box(box.x, box.y, box.z, box.heading, box.length + 2 * margin, box.width + 2 * margin,
               box.height + 2 * z_margin)


def _object_frame(points: np.ndarray, box: Box) -> np.ndarray:
    c, s = np.cos(box.heading), np.sin(box.heading)
    d = points - box.center
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], d[:, 2]])


@dataclass(frozen=True)
class LabelConfig:
    """How detection tracks become labels (:func:`autolabel`).

    ``extend``: frames SOT follows a track past its first / last detection (backward / forward; the extension is
    cut at its first frame without support). ``support_points``: an estimate supports its track when its box holds
    at least this many object points and it neither coasted nor continued on the prior; a label needs
    ``min_supported_frames`` such frames. Duplicates: two tracks whose boxes overlap at BEV IoU >=
    ``duplicate_iou`` on >= ``duplicate_share`` of their >= ``min_shared_frames`` shared frames are one object.
    ``reacquire``: SOT runs with re-acquisition (``reacquire.mode="clusters"``, docs/tracker.md).
    ``chunk``: objects per pass over the sweeps (None: all; bounds memory, the labels do not depend on it)."""

    extend: int = 30
    support_points: int = 5
    min_supported_frames: int = 3
    duplicate_iou: float = 0.3
    duplicate_share: float = 0.5
    min_shared_frames: int = 3
    reacquire: bool = True
    chunk: int | None = None


_UNSUPPORTED = frozenset({"no_points", "prior_only", "coasting", "det_only", "no_sweep"})


def _supported(estimate, config: LabelConfig) -> bool:
    return estimate.num_points >= config.support_points and not _UNSUPPORTED.intersection(estimate.flags)


@dataclass(frozen=True)
class _Seed:
    """Where SOT starts on a detection track: its most reliable detection with the track's median size."""

    frame: int
    box: Box
    velocity: np.ndarray


def _seed(detection_track: ObjectTrack) -> _Seed:
    frames = detection_track.frames.tolist()
    scores, detections = _scores_by_frame(detection_track), _detections_by_frame(detection_track)
    frame = max(frames, key=lambda k: (scores[k], -abs(k - frames[len(frames) // 2])))
    sizes = np.array([detections[k][4:7] for k in frames])
    box = Box(*detections[frame][:4], *np.median(sizes, axis=0))
    return _Seed(frame, box, _detection_velocity(detection_track, frame))


def _own_detections(detection_track: ObjectTrack) -> dict[int, FrameDetections]:
    scores = _scores_by_frame(detection_track)
    return {k: FrameDetections(b[None], np.array([scores[k]]))
            for k, b in _detections_by_frame(detection_track).items()}


def track_both_ways(source: FrameSource, tracks: list[ObjectTrack], config: TrackerConfig,
                    label_config: LabelConfig = LabelConfig(), progress=None) -> list[TrackResult]:
    """SOT of every detection track from its seed (:func:`_seed`) forward to ``extend`` frames past its last
    detection and backward (on the box turned by pi, in reversed time: the vehicle drives forward, as the motion
    term expects) to ``extend`` frames before its first, with its own detections in the Detection term. All
    tracks (or ``chunk`` of them at a time) in ONE forward and ONE backward pass over the sweeps
    (:func:`sot_apps.tracking.track_objects`). One online result per track, in frame order."""
    from ..tracking import ObjectRequest, track_objects

    n = len(source)
    last = n - 1
    reverse = _Reversed(source, last)
    chunk = label_config.chunk or max(len(tracks), 1)
    results: list[TrackResult] = []
    for at in range(0, len(tracks), chunk):
        part = tracks[at:at + chunk]
        seeds = [_seed(t) for t in part]
        forward, backward = [], []
        for t, seed in zip(part, seeds, strict=True):
            own = _own_detections(t)
            forward.append(ObjectRequest(t.object_id, seed.box, seed.frame,
                                         min(int(t.frames[-1]) + label_config.extend, last),
                                         detections=own, initial_motion=seed.velocity))
            first = max(int(t.frames[0]) - label_config.extend, 0)
            if seed.frame > first:
                backward.append(ObjectRequest(t.object_id, _turned(seed.box), last - seed.frame, last - first,
                                              detections={last - k: d for k, d in own.items() if k <= seed.frame},
                                              initial_motion=-seed.velocity))
        ahead, _ = track_objects(source, forward, config, detections=None, min_points=None,
                                 progress=(lambda f: progress(f, "forward")) if progress else None)
        behind, _ = track_objects(reverse, backward, config, detections=None, min_points=None,
                                  progress=(lambda f: progress(f, "backward")) if progress else None)
        back = {o.object_id: o for o in behind}
        for out in ahead:
            if out.result is None:
                raise RuntimeError(f"auto-label track {out.object_id}: {out.error}")
            b = back.get(out.object_id)
            if b is not None and b.result is None:
                raise RuntimeError(f"auto-label track {out.object_id} (backward): {b.error}")
            results.append(_merge(None if b is None else b.result, out.result))
    return results


def _trimmed(result: TrackResult, detection_track: ObjectTrack, config: LabelConfig) -> TrackResult:
    """``result`` without the frames past the detections beyond the first unsupported one (either way)."""
    frames = [e.frame for e in result.estimates]
    first, last = int(detection_track.frames[0]), int(detection_track.frames[-1])
    keep = np.array([first <= k <= last for k in frames])
    ok = np.array([_supported(e, config) for e in result.estimates])
    i = frames.index(last) if last in frames else len(frames) - 1
    while i + 1 < len(frames) and ok[i + 1]:
        i += 1
        keep[i] = True
    i = frames.index(first) if first in frames else 0
    while i - 1 >= 0 and ok[i - 1]:
        i -= 1
        keep[i] = True
    estimates = [e for e, kept in zip(result.estimates, keep, strict=True) if kept]
    return dataclasses.replace(result, estimates=estimates)


def merge_duplicates(results: list[TrackResult], tracks: list[ObjectTrack], config: LabelConfig = LabelConfig()
                     ) -> tuple[list[TrackResult], list[ObjectTrack]]:
    """One track per object: a track whose boxes overlap a kept track's (BEV IoU >= ``duplicate_iou``) on >=
    ``duplicate_share`` of their (>= ``min_shared_frames``) shared frames is folded into it (its detections
    join the kept track's on the frames that have none). Tracks are kept in order of supported frames, then
    detections; the survivors come back in their original order."""
    support = [sum(_supported(e, config) for e in r.estimates) for r in results]
    order = sorted(range(len(results)), key=lambda i: (-support[i], -len(tracks[i]), i))
    boxes = [{e.frame: e.box.to_array() for e in r.estimates} for r in results]
    kept: list[int] = []
    folded: dict[int, list[int]] = {}
    for i in order:
        into = None
        for j in kept:
            shared = sorted(set(boxes[i]) & set(boxes[j]))
            if len(shared) < config.min_shared_frames:
                continue
            iou = iou_bev_batch(np.array([boxes[i][k] for k in shared]), np.array([boxes[j][k] for k in shared]))
            if np.mean(iou >= config.duplicate_iou) >= config.duplicate_share:
                into = j
                break
        if into is None:
            kept.append(i)
        else:
            folded.setdefault(into, []).append(i)
    out_results, out_tracks = [], []
    for i in sorted(kept):
        joined = tracks[i]
        for j in folded.get(i, []):
            boxes_j, scores_j = _detections_by_frame(tracks[j]), _scores_by_frame(tracks[j])
            extra = [k for k in boxes_j if joined.box_at(k) is None]
            detections = {**_detections_by_frame(joined), **{k: boxes_j[k] for k in extra}}
            scores = {**_scores_by_frame(joined), **{k: scores_j[k] for k in extra}}
            frames = sorted(detections)
            joined = ObjectTrack(joined.object_id, joined.label, frames, [detections[k] for k in frames],
                                 scores=[scores[k] for k in frames])
        out_results.append(results[i])
        out_tracks.append(joined)
    return out_results, out_tracks


def label_from_result(source: FrameSource, result: TrackResult, detection_track: ObjectTrack,
                      config: TrackerConfig, offline: bool = True, fit: PointFit | None = PointFit()) -> AutoLabel:
    """The offline refinement of a track's online result, anchored on its detections and fitted to its points."""
    if offline and len(result.estimates) > 2:
        from tracker import refine_offline

        result = refine_offline(source, result, config)
    boxes = anchor_to_detections({e.frame: e.box for e in result.estimates}, detection_track)
    if fit is not None:
        boxes = fit_to_points(source, boxes, fit, detection_track)
    return AutoLabel.of(detection_track.object_id, boxes, detection_track.mean_score, result.shape, detection_track)


def label_config_tracker(config: TrackerConfig, label_config: LabelConfig) -> TrackerConfig:
    """The tracker config of the auto-labeller: ``config`` with re-acquisition when ``label_config`` asks."""
    if not label_config.reacquire:
        return config
    return dataclasses.replace(config, reacquire=dataclasses.replace(config.reacquire, mode="clusters"))


def anchor_to_detections(boxes: dict[int, Box], detection_track: ObjectTrack) -> dict[int, Box]:
    """The track moved by one constant correction in the object frame (heading, then centre): the median,
    over the track's detections, of how the detection sits relative to the tracked box (headings modulo
    pi). SOT fixes the motion relative to the seed box, so the seed detection's error would otherwise stay
    in every frame; the median over all detections averages the detector's errors and ignores outliers."""
    detections = _detections_by_frame(detection_track)
    frames = [k for k in detections if k in boxes]
    if not frames:
        return boxes
    turn = float(np.median([wrap_angle(align_heading(detections[k][3], boxes[k].heading)
                                       - boxes[k].heading) for k in frames]))
    offsets = []
    for k in frames:
        det, box = detections[k], boxes[k]
        c, s = np.cos(box.heading + turn), np.sin(box.heading + turn)
        d = det[:3] - box.center
        offsets.append([c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2]])
    du, dv, dz = np.median(np.array(offsets), axis=0)
    out = {}
    for k, box in boxes.items():
        heading = float(wrap_angle(box.heading + turn))
        c, s = np.cos(heading), np.sin(heading)
        out[k] = Box(box.x + c * du - s * dv, box.y + s * du + c * dv, box.z + dz, heading,
                     box.length, box.width, box.height)
    return out


def autolabel(source: FrameSource, detections: dict[int, FrameDetections], config: TrackerConfig | None = None,
              association: AssociationConfig = AssociationConfig(), offline: bool = True,
              progress=None, label_config: LabelConfig = LabelConfig()) -> tuple[list[AutoLabel], list[ObjectTrack]]:
    """Auto-labels of every vehicle of ``source`` (and the detection tracks they came from): detection tracks
    (:func:`associate_tracks`), SOT both ways in one pass each (:func:`track_both_ways`), extensions cut where
    support ends, duplicates merged (:func:`merge_duplicates`), tracks with fewer than ``min_supported_frames``
    supported frames dropped, then each refined offline, anchored and fitted (:func:`label_from_result`)."""
    config = label_config_tracker(config or get_preset("det_sot"), label_config)
    tracks = associate_tracks(detections, len(source), association)
    results = track_both_ways(source, tracks, config, label_config, progress)
    results = [_trimmed(r, t, label_config) for r, t in zip(results, tracks, strict=True)]
    results, merged = merge_duplicates(results, tracks, label_config)
    pairs = [(r, t) for r, t in zip(results, merged, strict=True)
             if sum(_supported(e, label_config) for e in r.estimates) >= label_config.min_supported_frames]
    labels = [label_from_result(source, r, t, config, offline)
              for r, t in (progress(pairs, "refine") if progress else pairs)]
    return labels, tracks


def per_frame_detections(entries) -> dict[int, FrameDetections]:
    """(frame, box (7,), score) triples grouped into FrameDetections per frame."""
    per_frame: dict[int, list[tuple[np.ndarray, float]]] = {}
    for k, box, score in entries:
        per_frame.setdefault(k, []).append((np.asarray(box, dtype=np.float64), float(score)))
    return {k: FrameDetections(np.array([b for b, _ in items]), np.array([s for _, s in items]))
            for k, items in per_frame.items()}


def labels_as_detections(labels: list[AutoLabel]) -> dict[int, FrameDetections]:
    """The auto-label boxes per frame, each scored with its track's score (for AP)."""
    return per_frame_detections((k, box.to_array(), label.score) for label in labels for k, box in label.boxes.items())


def tracks_as_detections(tracks: list[ObjectTrack]) -> dict[int, FrameDetections]:
    """The detections kept in detection tracks, per frame, with their own scores."""
    return per_frame_detections((k, box, score) for t in tracks
                                for k, box, score in zip(t.frames.tolist(), t.boxes, t.scores, strict=True))


def write_autolabels(out_dir, sequence, labels: list[AutoLabel], category: str = "Car",
                     with_sequence: bool = True) -> list[str]:
    """Write the labels under ``out_dir``: ``kitti/label_02/0000.txt`` (+ calib; only with a camera, KITTI's 2D
    boxes need one), ``av2/annotations.feather`` and ``av2/submission.feather`` (with the track scores), and
    the canonical ``sequence`` (its boxes = the labels). The writers are the ones of ``convert --labels``
    (:mod:`sot_apps.io.labels`). Returns one report line per output."""
    from pathlib import Path

    from ..io.canonical import write_sequence
    from ..io.label_export import export_labels
    from ..io.labels import kitti_camera
    from ..io.sequence import BoxAnnotation

    out_dir = Path(out_dir)
    tracks = [dataclasses.replace(label.track, label=category, scores=np.full(len(label.track), label.score),
                                  shape_points=None) for label in labels]
    lines = []
    if kitti_camera(sequence) is not None:
        lines += export_labels(sequence, "kitti", out_dir / "kitti", tracks)
    else:
        lines.append("kitti: not written (the sequence has no camera, and KITTI's 2D boxes need one)")
    lines += export_labels(sequence, "av2", out_dir / "av2", tracks, submission=True)
    if with_sequence:
        annotations = [[] for _ in sequence.frames]
        for label in labels:
            for k, box in label.boxes.items():
                annotations[k].append(BoxAnnotation(label.track_id, category, box))
        labelled = dataclasses.replace(sequence, annotations=annotations, _cache=sequence._cache)
        lines.append(f"wrote sequence: {write_sequence(labelled, out_dir / 'sequence', progress=False)}")
    return lines
