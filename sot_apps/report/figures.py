"""The report's figures (PNG, OpenCV): tracks vs. ground truth, shape growth, flow, simulated scans, motion error."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracker import Box, transform_points

from ..io.sequence import Sequence
from ..io.tracks import TrackFile, read_track
from .draw import BLACK, GT_COLOR, GREY, BevCanvas, colour_for, hstack, text, title_bar, vstack, write_png

__all__ = ["TrackScore", "score_tracks", "tracks_bev_figure", "shape_growth_figure", "flow_figure",
           "scans_figure", "motion_figure"]


@dataclass
class TrackScore:
    object_id: str
    label: str
    frames: int
    mean_iou: float | None            # 3D IoU against the annotated box (None: no annotations)
    mean_centre_error_m: float | None
    mean_points: float
    mean_quality: float
    shape_points: int


def score_tracks(seq: Sequence, tracks: list[tuple[TrackFile, np.ndarray]]) -> list[TrackScore]:
    from tracker import centre_errors_batch, iou_3d_batch

    gt_tracks = seq.tracks() if seq.annotations is not None else {}
    out = []
    for t, shape in tracks:
        gt = gt_tracks.get(t.object_id)
        pred, truth = [], []
        for r in t.frames:
            g = gt.box_at(r.frame) if gt is not None else None
            if g is not None:
                pred.append(t.box_at_record(r))
                truth.append(g)
        iou = float(np.mean(iou_3d_batch(pred, truth))) if pred else None
        err = float(np.mean(centre_errors_batch(pred, truth))) if pred else None
        out.append(TrackScore(t.object_id, t.label or "", len(t.frames), iou, err,
                              float(np.mean([r.num_points for r in t.frames])),
                              float(np.mean([r.quality for r in t.frames])), int(len(shape))))
    return out


def tracks_bev_figure(seq: Sequence, tracks: list[tuple[TrackFile, np.ndarray]], path: Path,
                      box_every: int = 3, width: int = 1000) -> Path:
    """Bird's-eye view: LiDAR points of the middle frame (grey), annotated boxes (green) and tracked boxes
    (one colour per object) every ``box_every`` frames, with the centre trajectories."""
    gt_tracks = seq.tracks() if seq.annotations is not None else {}
    boxes = [t.box_at_record(r) for t, _ in tracks for r in t.frames]
    centres = np.array([[b.x, b.y] for b in boxes])
    canvas = BevCanvas.fit(centres.min(axis=0), centres.max(axis=0), width=width, margin=12.0, max_height=700)
    canvas.grid(10.0)
    frames = sorted({r.frame for t, _ in tracks for r in t.frames})
    mid = frames[len(frames) // 2]
    world = seq.points_world(mid)
    ground_z = np.percentile(world[:, 2], 10) if len(world) else 0.0
    above = world[world[:, 2] > ground_z + 0.3]
    canvas.points(above[:, :2], (200, 200, 200))
    for i, (t, _) in enumerate(tracks):
        color = colour_for(i)
        gt = gt_tracks.get(t.object_id)
        if gt is not None:
            gt_frames = [k for k in gt.frames if t.start_frame <= k <= t.end_frame]
            canvas.polyline(np.array([[gt.box_at(k).x, gt.box_at(k).y] for k in gt_frames]), GT_COLOR, 2)
            for k in gt_frames[::box_every]:
                canvas.box(gt.box_at(k), GT_COLOR, 1)
        records = t.frames
        canvas.polyline(np.array([[r.state.x, r.state.y] for r in records]), color, 2)
        for r in records[::box_every]:
            canvas.box(t.box_at_record(r), color, 2 if r is records[0] else 1)
        c = canvas.px([records[-1].state.x, records[-1].state.y])[0]
        text(canvas.image, t.object_id[:8], (c[0] + 8, c[1] - 8), 0.45, color)
    canvas.scale_bar(10.0)
    img = canvas.image
    legend = np.full((28, img.shape[1], 3), 255, np.uint8)
    cv2.line(legend, (10, 14), (40, 14), GT_COLOR, 2)
    text(legend, "ground truth", (46, 19))
    cv2.line(legend, (170, 14), (200, 14), colour_for(0), 2)
    text(legend, f"tracked (one colour per object; boxes every {box_every} frames; grey: LiDAR frame {mid})", (206, 19))
    return write_png(path, title_bar(np.concatenate([img, legend]), f"{seq.id}: tracks in bird's-eye view"))


def _shape_panel(points: np.ndarray, size: np.ndarray, label: str, px_per_m: float = 60.0) -> np.ndarray:
    """Top view (x right, y up) above side view (x right, z up) of object-frame points with the box outline."""
    length, width, height = (float(v) for v in size)
    margin = 0.4
    w = int((length + 2 * margin) * px_per_m)
    top_h = int((width + 2 * margin) * px_per_m)
    side_h = int((height + 2 * margin) * px_per_m)
    panel = np.full((top_h + side_h + 30, w, 3), 255, np.uint8)

    def to_px(u, v, v_half, row0):
        col = (u + length / 2 + margin) * px_per_m
        row = row0 + (v_half + margin - v) * px_per_m
        return col, row

    z = points[:, 2] if len(points) else np.zeros(0)
    t = np.clip((z + height / 2) / max(height, 1e-6), 0, 1)
    colors = cv2.applyColorMap((t * 255).astype(np.uint8).reshape(-1, 1), cv2.COLORMAP_VIRIDIS).reshape(-1, 3) \
        if len(points) else np.zeros((0, 3), np.uint8)
    for (u, v, half, row0) in ((0, 1, width / 2, 0), (0, 2, height / 2, top_h)):
        c0, r0 = to_px(-length / 2, half, half, row0)
        c1, r1 = to_px(length / 2, -half, half, row0)
        cv2.rectangle(panel, (int(c0), int(r0)), (int(c1), int(r1)), GREY, 1)
        if len(points):
            c, r = to_px(points[:, u], points[:, v], half, row0)
            for (cc, rr), col in zip(np.stack([c, r], axis=1).astype(int), colors):
                cv2.circle(panel, (int(cc), int(rr)), 1, tuple(int(x) for x in col), -1)
    text(panel, label, (4, top_h + side_h + 22), 0.5)
    return panel


def shape_growth_figure(seq: Sequence, track: TrackFile, path: Path, shots: int = 4) -> Path:
    """The shape filling in: the tracker is rerun on this object and its aggregated shape (object frame)
    is drawn at a few frames, top view above side view."""
    from tracker import TrackerConfig
    from tracker import Tracker

    config = TrackerConfig.from_dict({k: v for k, v in track.config.items() if k in TrackerConfig.__dataclass_fields__})
    tracker = Tracker(config)
    tracker.start(seq.lidar_frame(track.start_frame), track.init_box)
    frames = list(range(track.start_frame + 1, track.end_frame + 1))
    shapes = {track.start_frame: tracker.shape_points()}
    for k in frames:   # keep the shape after every frame that changed it (key frames)
        tracker.step(seq.lidar_frame(k))
        if len(tracker.shape.points) != len(shapes[max(shapes)]):
            shapes[k] = tracker.shape_points()
    keys = sorted(shapes)
    if len(keys) > shots:   # the start, the last change and evenly spaced changes between
        keys = sorted({keys[int(round(i))] for i in np.linspace(0, len(keys) - 1, shots)})
    shapes = {k: shapes[k] for k in keys}
    size = track.size.to_array()
    panels = [_shape_panel(pts, size, f"frame {k} (+{k - track.start_frame}): {len(pts)} pts")
              for k, pts in sorted(shapes.items())]
    img = hstack(panels, gap=14)
    return write_png(path, title_bar(img, f"{track.object_id}: shape filling in over time (top: from above, "
                                          f"bottom: from the side; colour = height)"))


def flow_figure(seq: Sequence, flow_root: Path, camera: str, path: Path, pairs: int = 3, width: int = 400) -> Path | None:
    """Rows of (image k, flow colour wheel, overlay) for a few pairs written by the flow stage."""
    cam_root = flow_root / camera
    stats_path = cam_root / "stats.json"
    if not stats_path.is_file():
        return None
    stats = json.loads(stats_path.read_text())
    records = [p for p in stats["pairs"] if sum(o["pixels"] for o in p["objects"]) > 0] or stats["pairs"]
    if not records:
        return None
    chosen = [records[int(round(i))] for i in np.linspace(0, len(records) - 1, min(pairs, len(records)))]
    rows = []
    seen = set()
    for rec in chosen:
        k = int(rec["frame"] if "frame" in rec else rec["k"])
        if k in seen:
            continue
        seen.add(k)
        image = cv2.imread(str(seq.cameras[camera].frames[k].image_path))
        flow_png = cv2.imread(str(cam_root / "vis" / f"{k:06d}_flow.png"))
        over = cv2.imread(str(cam_root / "vis" / f"{k:06d}_overlay.jpg"))
        tiles = []
        for name, tile in ((f"image {k}", image), ("flow (colour wheel)", flow_png), ("overlay", over)):
            if tile is None:
                continue
            scale = width / tile.shape[1]
            tile = cv2.resize(tile, (width, int(round(tile.shape[0] * scale))), interpolation=cv2.INTER_AREA)
            tiles.append(title_bar(tile, name, 24, 0.5))
        pixels = sum(o["pixels"] for o in rec["objects"])
        rows.append(title_bar(hstack(tiles), f"pair {k} -> {k + 1}: {pixels} object pixels", 26, 0.5))
    img = vstack(rows, gap=12)
    return write_png(path, title_bar(img, f"{seq.id} / {camera}: optical flow from tracked shapes"))


def _crop_bev(xyz: np.ndarray, mask: np.ndarray, box: Box, size_px: int = 220, half_m: float | None = None) -> np.ndarray:
    half_m = max(4.0, 0.5 * max(box.length, box.width) + 1.0) if half_m is None else half_m
    canvas = BevCanvas(box.x - half_m, box.y - half_m, box.x + half_m, box.y + half_m, size_px / (2 * half_m),
                       np.full((size_px, size_px, 3), 255, np.uint8))
    canvas.box(box, GREY, 1)
    pts = xyz[mask]
    if len(pts):
        canvas.points(pts[:, :2], (200, 80, 20), radius=1)
    return canvas.image


def scans_figure(scans_root: Path, scene_dirs: list[Path], path: Path) -> Path | None:
    """Rows = ranges, columns = headings: the simulated points on each inserted bank vehicle (bird's-eye view,
    at least 8 m x 8 m around the box, x right; the sensor is at the scene origin), with point counts."""
    rows = []
    for d in scene_dirs:
        scan_path, boxes_path = d / "scan.npz", d / "boxes.json"
        if not scan_path.is_file() or not boxes_path.is_file():
            continue
        with np.load(scan_path) as data:
            xyz = np.asarray(data["xyz"]).reshape(-1, 3)
            instance = np.asarray(data["instance"]).reshape(-1)
        finite = np.isfinite(xyz).all(axis=1)
        xyz, instance = xyz[finite], instance[finite]
        scene = json.loads((d / "scene.json").read_text())
        tiles = []
        for i, o in enumerate(scene["objects"]):
            entry = json.loads(boxes_path.read_text())
            b = entry["boxes"][i] if isinstance(entry, dict) and "boxes" in entry else entry[i]
            box = Box(*(float(b[k]) for k in ("x", "y", "z", "heading", "length", "width", "height")))
            n = int((instance == i).sum())
            tile = _crop_bev(xyz, instance == i, box)
            text(tile, f"heading {np.degrees(o['heading']):.0f} deg", (4, 16), 0.42)
            text(tile, f"{n} points", (4, 212), 0.42)
            tiles.append(tile)
        if tiles:
            r = float(np.hypot(scene["objects"][0]["x"], scene["objects"][0]["y"]))
            rows.append(title_bar(hstack(tiles), f"{d.name.split('__r')[0]} at {r:.0f} m", 26, 0.5))
    if not rows:
        return None
    img = vstack(rows, gap=12)
    return write_png(path, title_bar(img, "Simulated scans of a bank vehicle at several ranges and headings"))


def motion_figure(seq: Sequence, track_dirs: list[Path], path: Path, horizon: int = 30) -> tuple[Path | None, dict | None]:
    """Mean centre error of the motion export vs. k frames after the start (helper: sot_apps.evaluation.motion)."""
    from ..evaluation.motion import evaluate_motion, plot_accuracy
    from ..motion_export.sources import tracks_from_dirs

    if not seq.tracks():
        return None, None
    gt = seq.tracks()
    dirs = [d for d in track_dirs if read_track(d)[0].object_id in gt]
    if not dirs:
        return None, None
    tracks = tracks_from_dirs(dirs, seq)
    horizon = max(1, min(horizon, max(len(t.frames) for t in tracks) - 1))
    acc = evaluate_motion(seq, tracks, horizon=horizon, source="pipeline tracks")
    plot_accuracy(acc, path, f"Motion export vs. ground truth, {seq.id}, {len(tracks)} tracks")
    return Path(path), acc.to_json()


def placeholder(path: Path, message: str) -> Path:
    img = np.full((120, 700, 3), 245, np.uint8)
    text(img, message, (10, 65), 0.55, BLACK)
    return write_png(path, img)
