"""Accuracy of the motion export against ground truth (the paper's "motion generation" figure).

For every evaluated track (tracker output of an annotated object, started at frame s):

- centre error at k = 1..horizon frames after the start: distance between the EXPORTED (smoothed)
  centre at frame s+k and the annotated box centre, in 3D and in bird's-eye view; the same for the
  raw tracker states (no smoothing) for comparison;
- velocity error |v_export - v_gt| (vector norm, m/s) and yaw-rate error |omega_export - omega_gt|
  over all valid frames, against two references derived from the annotations: the SAME smoother
  applied to the ground-truth boxes (``gt-smoothed``) and central differences of the ground-truth
  boxes (``gt-central``, np.gradient over the true frame times).

Invalid (flagged) frames are excluded; ``n`` counts the samples that entered each mean.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from itertools import pairwise
from pathlib import Path
from typing import Sequence as Seq

import numpy as np

from ..errors import InputError
from ..io.object_track import ObjectTrack
from ..io.sequence import Sequence
from ..objects.smoother import (
    ANNOTATION_SMOOTHER,
    TRACKER_SMOOTHER,
    SmootherConfig,
    central_difference_kinematics,
    smooth_track,
)

__all__ = ["TrackMotionErrors", "MotionAccuracy", "evaluate_motion", "format_table", "plot_accuracy",
           "find_track_dirs"]


@dataclass
class TrackMotionErrors:
    object_id: str
    start_frame: int
    frames: int
    valid_frames: int
    centre_3d: list[float | None]      # index k-1: error at k frames after the start (None: no sample)
    centre_bev: list[float | None]
    raw_centre_3d: list[float | None]
    mean_centre_3d: float              # over all valid frames after the start
    raw_mean_centre_3d: float
    velocity_vs_gt_smoothed: float     # mean |dv| (m/s)
    velocity_vs_gt_central: float
    raw_velocity_vs_gt_central: float  # tracker states by central differences, no smoothing
    yaw_rate_vs_gt_smoothed: float     # mean |d omega| (rad/s)
    yaw_rate_vs_gt_central: float
    raw_yaw_rate_vs_gt_central: float
    speed: float                       # mean ground-truth speed (m/s)


@dataclass
class MotionAccuracy:
    horizon: int
    source: str
    tracks: list[TrackMotionErrors] = field(default_factory=list)

    def _per_k(self, attr: str) -> tuple[np.ndarray, np.ndarray]:
        values = np.full((len(self.tracks), self.horizon), np.nan)
        for i, t in enumerate(self.tracks):
            row = getattr(t, attr)
            values[i, : len(row)] = [np.nan if v is None else v for v in row]
        n = np.isfinite(values).sum(axis=0)
        with np.errstate(invalid="ignore"):
            mean = np.where(n > 0, np.nansum(values, axis=0) / np.maximum(n, 1), np.nan)
        return mean, n

    def curve(self, attr: str = "centre_3d") -> tuple[np.ndarray, np.ndarray]:
        """(mean over tracks at k = 1..horizon, number of tracks contributing)."""
        return self._per_k(attr)

    def median_curve(self, attr: str = "centre_3d") -> np.ndarray:
        """Median over tracks at k = 1..horizon (NaN where no track has a valid sample)."""
        values = np.full((max(len(self.tracks), 1), self.horizon), np.nan)
        for i, t in enumerate(self.tracks):
            row = getattr(t, attr)
            values[i, : len(row)] = [np.nan if v is None else v for v in row]
        out = np.full(self.horizon, np.nan)
        ok = np.isfinite(values).any(axis=0)
        out[ok] = np.nanmedian(values[:, ok], axis=0)
        return out

    def pooled(self, attr: str) -> float:
        vals = np.array([getattr(t, attr) for t in self.tracks], dtype=float)
        w = np.array([t.valid_frames for t in self.tracks], dtype=float)
        ok = np.isfinite(vals)
        return float(np.sum(vals[ok] * w[ok]) / np.sum(w[ok])) if ok.any() else float("nan")

    def to_json(self) -> dict:
        out = {"horizon": self.horizon, "source": self.source, "tracks": [asdict(t) for t in self.tracks]}
        for attr in ("centre_3d", "centre_bev", "raw_centre_3d"):
            mean, n = self.curve(attr)
            out[f"mean_{attr}_by_k"] = [None if not np.isfinite(v) else float(v) for v in mean]
            out[f"median_{attr}_by_k"] = [None if not np.isfinite(v) else float(v) for v in self.median_curve(attr)]
            out[f"n_{attr}_by_k"] = [int(v) for v in n]
        return out


def _nanmean(values: np.ndarray) -> float:
    values = np.asarray(values, dtype=float)
    ok = np.isfinite(values)
    return float(values[ok].mean()) if ok.any() else float("nan")


def _gt_track(sequence: Sequence, object_id: str, frames: np.ndarray) -> ObjectTrack:
    gt = sequence.tracks().get(object_id)
    if gt is None:
        raise InputError(sequence.root, f"object {object_id!r} has no annotations to compare with")
    states = np.full((len(frames), 4), np.nan)
    valid = np.zeros(len(frames), dtype=bool)
    for i, k in enumerate(frames):
        box = gt.box_at(int(k))
        if box is not None:
            states[i] = [box.x, box.y, box.z, box.heading]
            valid[i] = True
    return ObjectTrack.from_states(object_id=object_id, label=gt.label, size=(1.0, 1.0, 1.0), frames=frames,
                       timestamps_ns=sequence.timestamps_ns[frames], states=states, valid=valid)


def _velocity_error(a: ObjectTrack, b: ObjectTrack) -> np.ndarray:
    return np.hypot(*(a.velocity - b.velocity).T)


def evaluate_track(sequence: Sequence, track: ObjectTrack, horizon: int = 30,
                   smoother: SmootherConfig = TRACKER_SMOOTHER) -> TrackMotionErrors:
    """Errors of one exported track against the annotations (see the module docstring)."""
    exported = smooth_track(track, smoother)
    raw = central_difference_kinematics(track)
    gt_track = _gt_track(sequence, track.object_id, track.frames)
    gt_smooth = smooth_track(gt_track, ANNOTATION_SMOOTHER)
    gt_central = central_difference_kinematics(gt_track)
    truth = gt_track.states
    both = exported.valid & gt_track.valid
    d3 = np.where(both, np.sqrt((exported.boxes[:, 0] - truth[:, 0]) ** 2 + (exported.boxes[:, 1] - truth[:, 1]) ** 2
                                + (exported.boxes[:, 2] - truth[:, 2]) ** 2), np.nan)
    dbev = np.where(both, np.hypot(exported.boxes[:, 0] - truth[:, 0], exported.boxes[:, 1] - truth[:, 1]), np.nan)
    raw_d3 = np.where(both, np.linalg.norm(track.states[:, :3] - truth[:, :3], axis=1), np.nan)
    start = int(track.frames[0])
    steps = track.frames - start

    def by_k(values: np.ndarray) -> list[float | None]:
        out: list[float | None] = []
        for k in range(1, horizon + 1):
            hit = np.flatnonzero(steps == k)
            out.append(float(values[hit[0]]) if len(hit) and np.isfinite(values[hit[0]]) else None)
        return out

    after = steps >= 1
    return TrackMotionErrors(
        object_id=track.object_id, start_frame=start, frames=len(track.frames), valid_frames=int(both.sum()),
        centre_3d=by_k(d3), centre_bev=by_k(dbev), raw_centre_3d=by_k(raw_d3),
        mean_centre_3d=_nanmean(d3[after]), raw_mean_centre_3d=_nanmean(raw_d3[after]),
        velocity_vs_gt_smoothed=_nanmean(np.where(both, _velocity_error(exported, gt_smooth), np.nan)),
        velocity_vs_gt_central=_nanmean(np.where(both, _velocity_error(exported, gt_central), np.nan)),
        raw_velocity_vs_gt_central=_nanmean(np.where(both, _velocity_error(raw, gt_central), np.nan)),
        yaw_rate_vs_gt_smoothed=_nanmean(np.where(both, np.abs(exported.yaw_rate - gt_smooth.yaw_rate), np.nan)),
        yaw_rate_vs_gt_central=_nanmean(np.where(both, np.abs(exported.yaw_rate - gt_central.yaw_rate), np.nan)),
        raw_yaw_rate_vs_gt_central=_nanmean(np.where(both, np.abs(raw.yaw_rate - gt_central.yaw_rate), np.nan)),
        speed=_nanmean(gt_smooth.speed),
    )


def evaluate_motion(sequence: Sequence, tracks: Seq[ObjectTrack], horizon: int = 30,
                    smoother: SmootherConfig = TRACKER_SMOOTHER, source: str = "tracks") -> MotionAccuracy:
    result = MotionAccuracy(horizon=horizon, source=source)
    for track in tracks:
        result.tracks.append(evaluate_track(sequence, track, horizon, smoother))
    return result


def _cm(value: float) -> str:
    return "–" if not np.isfinite(value) else f"{100 * value:.1f}"


def format_table(acc: MotionAccuracy, ks: Seq[int] = (1, 2, 5, 10, 15, 20, 25, 30)) -> str:
    """Markdown tables: centre error by k, then per-track velocity and yaw-rate errors."""
    m3, n3 = acc.curve("centre_3d")
    mb, _ = acc.curve("centre_bev")
    mr, _ = acc.curve("raw_centre_3d")
    lines = [f"Centre error k frames after the start ({acc.source}; mean over tracks, cm)", "",
             "| k | tracks | exported 3D | exported BEV | raw tracker 3D | exported 3D, median over tracks |",
             "|---:|---:|---:|---:|---:|---:|"]
    med = acc.median_curve("centre_3d")
    for k in ks:
        if k <= acc.horizon:
            lines.append(f"| {k} | {n3[k - 1]} | {_cm(m3[k - 1])} | {_cm(mb[k - 1])} | {_cm(mr[k - 1])} "
                         f"| {_cm(med[k - 1])} |")
    within = m3[: acc.horizon]
    lines += ["", f"mean over k = 1..{acc.horizon}: exported {_cm(_nanmean(within))} cm 3D, "
                  f"{_cm(_nanmean(mb))} cm BEV; raw {_cm(_nanmean(mr))} cm 3D; max over k: exported "
                  f"{_cm(float(np.nanmax(within)) if np.isfinite(within).any() else float('nan'))} cm", ""]
    lines += ["Velocity and yaw-rate errors over all valid frames (mean absolute; gt-smoothed = same CTRV smoother "
              "on the annotated boxes, gt-central = central differences of the annotated boxes)", "",
              "| track | frames | GT speed m/s | centre cm | Δv vs gt-smoothed m/s | Δv vs gt-central m/s "
              "| raw Δv vs gt-central m/s | Δω vs gt-smoothed °/s | Δω vs gt-central °/s | raw Δω vs gt-central °/s |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]

    def row(name, frames, speed, centre, a, b, c, d, e, f):
        return (f"| {name} | {frames} | {speed:.1f} | {_cm(centre)} | {a:.3f} | {b:.3f} | {c:.3f} | "
                f"{np.degrees(d):.2f} | {np.degrees(e):.2f} | {np.degrees(f):.2f} |")

    for t in acc.tracks:
        lines.append(row(t.object_id[:8], t.valid_frames, t.speed, t.mean_centre_3d, t.velocity_vs_gt_smoothed,
                         t.velocity_vs_gt_central, t.raw_velocity_vs_gt_central, t.yaw_rate_vs_gt_smoothed,
                         t.yaw_rate_vs_gt_central, t.raw_yaw_rate_vs_gt_central))
    if acc.tracks:
        lines.append(row("**all (frame-weighted)**", sum(t.valid_frames for t in acc.tracks), acc.pooled("speed"),
                         acc.pooled("mean_centre_3d"), acc.pooled("velocity_vs_gt_smoothed"),
                         acc.pooled("velocity_vs_gt_central"), acc.pooled("raw_velocity_vs_gt_central"),
                         acc.pooled("yaw_rate_vs_gt_smoothed"), acc.pooled("yaw_rate_vs_gt_central"),
                         acc.pooled("raw_yaw_rate_vs_gt_central")))
    return "\n".join(lines)


def plot_accuracy(acc: MotionAccuracy | dict, path: str | Path, title: str = "") -> None:
    """PNG line plot (OpenCV drawing, no matplotlib): mean centre error (cm) vs k. ``acc`` may be a
    :class:`MotionAccuracy` or its :meth:`~MotionAccuracy.to_json` document (what the pipeline saves)."""
    import cv2

    from ..io.atomic import write_bytes

    doc = acc.to_json() if isinstance(acc, MotionAccuracy) else acc

    def series(key: str) -> np.ndarray:
        return np.array([np.nan if v is None else v for v in doc[key]], dtype=np.float64)

    W, H = 900, 560
    left, right, top, bottom = 90, 30, 60, 70
    img = np.full((H, W, 3), 255, np.uint8)
    curves = [("exported (smoothed) 3D", series("mean_centre_3d_by_k"), (200, 90, 20)),
              ("exported (smoothed) BEV", series("mean_centre_bev_by_k"), (60, 160, 60)),
              ("raw tracker 3D", series("mean_raw_centre_3d_by_k"), (60, 60, 220)),
              ("exported 3D, median over tracks", series("median_centre_3d_by_k"), (160, 60, 160))]
    values = np.concatenate([c[1] for c in curves])
    ymax_cm = max(12.0, float(np.nanmax(values) * 100 * 1.1) if np.isfinite(values).any() else 12.0)
    ystep = 2.0 if ymax_cm <= 20 else 5.0 if ymax_cm <= 60 else 20.0
    ymax_cm = ystep * np.ceil(ymax_cm / ystep)
    k_max = int(doc["horizon"])

    def px(k: float, cm: float) -> tuple[int, int]:
        x = left + (k - 0) / k_max * (W - left - right)
        y = H - bottom - cm / ymax_cm * (H - top - bottom)
        return int(round(x)), int(round(y))

    font = cv2.FONT_HERSHEY_SIMPLEX
    for cm in np.arange(0, ymax_cm + 1e-9, ystep):
        cv2.line(img, px(0, cm), px(k_max, cm), (225, 225, 225), 1, cv2.LINE_AA)
        x, y = px(0, cm)
        cv2.putText(img, f"{cm:g}", (x - 40, y + 5), font, 0.45, (60, 60, 60), 1, cv2.LINE_AA)
    for k in range(0, k_max + 1, 5):
        x, y = px(k, 0)
        cv2.line(img, (x, y), (x, y + 5), (60, 60, 60), 1, cv2.LINE_AA)
        cv2.putText(img, str(k), (x - 8, y + 22), font, 0.45, (60, 60, 60), 1, cv2.LINE_AA)
    cv2.line(img, px(0, 0), px(k_max, 0), (0, 0, 0), 1, cv2.LINE_AA)
    cv2.line(img, px(0, 0), px(0, ymax_cm), (0, 0, 0), 1, cv2.LINE_AA)
    # the paper's bound: 10 cm (dashed)
    for k0 in np.arange(0, k_max, 0.8):
        cv2.line(img, px(k0, 10), px(min(k0 + 0.4, k_max), 10), (120, 120, 120), 1, cv2.LINE_AA)
    cv2.putText(img, "10 cm (paper)", (px(k_max, 10)[0] - 120, px(k_max, 10)[1] - 6), font, 0.45, (120, 120, 120), 1,
                cv2.LINE_AA)
    for _, curve, color in curves:
        pts = [px(k + 1, 100 * v) for k, v in enumerate(curve) if np.isfinite(v)]
        for a, b in pairwise(pts):
            cv2.line(img, a, b, color, 2, cv2.LINE_AA)
        for p in pts:
            cv2.circle(img, p, 3, color, -1, cv2.LINE_AA)
    for i, (name, _, color) in enumerate(curves):
        y = top + 10 + 22 * i
        cv2.line(img, (left + 20, y), (left + 50, y), color, 2, cv2.LINE_AA)
        cv2.putText(img, name, (left + 58, y + 5), font, 0.5, (30, 30, 30), 1, cv2.LINE_AA)
    cv2.putText(img, title or "Mean centre error vs. frames after start", (left, 35), font, 0.6, (0, 0, 0), 1,
                cv2.LINE_AA)
    cv2.putText(img, "frames after the start (k)", (W // 2 - 100, H - 20), font, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    label = np.full((24, 240, 3), 255, np.uint8)
    cv2.putText(label, "mean centre error (cm)", (2, 17), font, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    rotated = cv2.rotate(label, cv2.ROTATE_90_COUNTERCLOCKWISE)
    y0 = (H - rotated.shape[0]) // 2
    img[y0:y0 + rotated.shape[0], 8:8 + rotated.shape[1]] = rotated
    ok, buffer = cv2.imencode(".png", img)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    write_bytes(path, buffer.tobytes())


def find_track_dirs(tracks_dir: str | Path, prefixes: Seq[str] | None = None) -> list[Path]:
    """Track directories under ``tracks_dir`` (any depth, each holding track.json), optionally only those whose
    object id starts with one of ``prefixes``."""
    root = Path(tracks_dir)
    if not root.is_dir():
        raise InputError(root, "not a directory of track directories")
    dirs = sorted(p.parent for p in root.rglob("track.json"))
    if prefixes:
        from ..schemas import load_json

        keep = []
        for d in dirs:
            object_id = str(load_json(d / "track.json").get("object_id", ""))
            if any(object_id.startswith(p) for p in prefixes):
                keep.append(d)
        dirs = keep
    if not dirs:
        raise InputError(root, "no track.json found" + (f" for ids {', '.join(prefixes)}" if prefixes else ""))
    return dirs
