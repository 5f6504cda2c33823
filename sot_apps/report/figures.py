"""The report's figures (PNG, OpenCV): tracks vs. ground truth, shape growth, flow, simulated scans, motion error."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracker import Box

from ..io.object_track import ObjectTrack
from ..io.sequence import Sequence
from ..tracking import ShapeGrowth
from .draw import (
    BLACK,
    EGO_COLOR,
    GREY,
    GT_COLOR,
    WHITE,
    BevCanvas,
    LegendEntry,
    colour_bar,
    colour_for,
    hstack,
    legend_panel,
    place_labels,
    text,
    text_size,
    title_bar,
    vstack,
    with_metre_axes,
    write_png,
)

__all__ = ["TrackScore", "score_tracks", "BevFigure", "tracks_bev_figure", "shape_growth_figure", "flow_figure",
           "flow_key", "scans_figure", "motion_figure"]


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


def score_tracks(seq: Sequence, tracks: list[ObjectTrack]) -> list[TrackScore]:
    """Each track file's rows (``read_track``) against the sequence's annotations."""
    from tracker import centre_errors_batch, iou_3d_batch

    gt_tracks = seq.tracks() if seq.annotations is not None else {}
    out = []
    for t in tracks:
        gt = gt_tracks.get(t.object_id)
        pred, truth = [], []
        for i, frame in enumerate(t.frames):
            g = gt.box_at(int(frame)) if gt is not None else None
            if g is not None:
                pred.append(t.box(i))
                truth.append(g)
        iou = float(np.mean(iou_3d_batch(pred, truth))) if pred else None
        err = float(np.mean(centre_errors_batch(pred, truth))) if pred else None
        shape = t.shape_points if t.shape_points is not None else np.zeros((0, 3))
        out.append(TrackScore(t.object_id, t.label, len(t), iou, err, float(np.mean(t.num_points)),
                              float(np.mean(t.scores)), int(len(shape))))
    return out


@dataclass(frozen=True)
class BevFigure:
    """What :func:`tracks_bev_figure` drew: the file, one legend label per tracked object (in track order), their
    colours and the pixel rectangles of the on-map labels (map image coordinates)."""

    path: Path
    object_labels: tuple[str, ...]
    object_colours: tuple[tuple[int, int, int], ...]
    label_rects: tuple[tuple[int, int, int, int], ...]


def _nice_step(span_m: float, target: int = 8) -> float:
    for step in (1.0, 2.0, 5.0, 10.0, 20.0, 25.0, 50.0, 100.0):
        if span_m / step <= target:
            return step
    return 200.0


def tracks_bev_figure(seq: Sequence, tracks: list[ObjectTrack], path: Path,
                      box_every: int = 3, width: int = 900) -> BevFigure:
    """Bird's-eye view (world frame, metre axes): LiDAR points of the middle frame (grey), the ego's path and its
    position and heading at that frame, annotated boxes (green) and each tracked object in its own colour
    (boxes every ``box_every`` frames, centre path, a numbered label), with a legend naming every object."""
    gt_tracks = seq.tracks() if seq.annotations is not None else {}
    frames = sorted({int(k) for t in tracks for k in t.frames})
    mid = frames[len(frames) // 2]
    ego_xy = np.array([seq.frames[k].world_from_ego[:2, 3] for k in frames])
    extent = np.concatenate([np.concatenate([t.states[:, :2] for t in tracks]), ego_xy])
    canvas = BevCanvas.fit(extent.min(axis=0), extent.max(axis=0), width=width, margin=8.0, max_height=760)
    step = _nice_step(max(canvas.x1 - canvas.x0, canvas.y1 - canvas.y0))
    canvas.grid(step)
    world = seq.points_world(mid)
    ground_z = np.percentile(world[:, 2], 10) if len(world) else 0.0
    above = world[world[:, 2] > ground_z + 0.3]
    canvas.points(above[:, :2], (205, 205, 205))
    canvas.polyline(ego_xy, EGO_COLOR, 1)
    anchors, colours, numbers, labels = [], [], [], []
    for i, t in enumerate(tracks):
        colour = colour_for(i)
        gt = gt_tracks.get(t.object_id)
        if gt is not None:
            gt_frames = [k for k in gt.frames if t.frames[0] <= k <= t.frames[-1]]
            canvas.polyline(np.array([[gt.box_at(k).x, gt.box_at(k).y] for k in gt_frames]), GT_COLOR, 1)
            for k in gt_frames[::box_every]:
                canvas.box(gt.box_at(k), GT_COLOR, 1)
        canvas.polyline(t.states[:, :2], colour, 2)
        for row in range(0, len(t), box_every):
            canvas.box(t.box(row), colour, 2 if row == 0 else 1)
        anchors.append(canvas.px(t.states[-1, :2])[0])
        colours.append(colour)
        numbers.append(str(i + 1))
        labels.append(f"{i + 1}: {t.object_id[:10]} {t.label} ({len(t)} fr)".rstrip())
    canvas.ego(seq.frames[mid].world_from_ego)
    scale = 0.5
    sizes = [(text_size(n, scale, 2)[0] + 8, text_size(n, scale, 2)[1] + 8) for n in numbers]
    h, w = canvas.image.shape[:2]
    ego_px = canvas.px(seq.frames[mid].world_from_ego[:2, 3])[0]
    ego_rect = (int(ego_px[0]) - 12, int(ego_px[1]) - 12, int(ego_px[0]) + 12, int(ego_px[1]) + 12)
    rects = place_labels(np.array(anchors), sizes, (w, h), occupied=[ego_rect])
    for anchor, rect, colour, n in zip(anchors, rects, colours, numbers, strict=True):
        nearest = (int(np.clip(anchor[0], rect[0], rect[2])), int(np.clip(anchor[1], rect[1], rect[3])))
        cv2.line(canvas.image, (int(anchor[0]), int(anchor[1])), nearest, colour, 1, cv2.LINE_AA)
        cv2.rectangle(canvas.image, rect[:2], (rect[2] - 1, rect[3] - 1), WHITE, -1)
        cv2.rectangle(canvas.image, rect[:2], (rect[2] - 1, rect[3] - 1), colour, 1)
        text(canvas.image, n, (rect[0] + 4, rect[3] - 5), scale, colour, 2)
    entries = [LegendEntry("line", GT_COLOR, "ground truth (annotated boxes)"),
               LegendEntry("ego", EGO_COLOR, f"ego at frame {mid} (arrow: heading)"),
               LegendEntry("line", EGO_COLOR, "ego path"),
               LegendEntry("points", (170, 170, 170), f"LiDAR points, frame {mid}")]
    entries += [LegendEntry("box", c, s) for c, s in zip(colours, labels, strict=True)]
    legend = legend_panel(entries, f"tracked objects (boxes every {box_every} frames)", width=330)
    img = hstack([with_metre_axes(canvas, step), legend], gap=10)
    write_png(path, title_bar(img, f"{seq.id}: tracks in bird's-eye view (world frame)"))
    return BevFigure(Path(path), tuple(labels), tuple(colours), tuple(rects))


def _object_view(points: np.ndarray, colours: np.ndarray, size: np.ndarray, axes: tuple[int, int],
                 px_per_m: float = 50.0) -> np.ndarray:
    """One view of object-frame points (``axes`` = the two coordinates drawn) with the box outline and metre axes."""
    half = np.asarray(size, dtype=np.float64) / 2.0
    margin = 0.4
    u, v = axes
    canvas = BevCanvas.fit(-half[[u, v]], half[[u, v]], width=int((2 * half[u] + 2 * margin) * px_per_m), margin=margin,
                           max_height=10_000)
    canvas.polyline(np.array([[-half[u], -half[v]], [half[u], -half[v]], [half[u], half[v]], [-half[u], half[v]]]),
                    GREY, 1, closed=True)
    if len(points):
        canvas.points(points[:, [u, v]], colours, radius=0)
        p = np.round(canvas.px(points[:, [u, v]])).astype(int)
        for d in ((1, 0), (0, 1), (1, 1)):   # 2x2 dots
            q = p + d
            ok = (q[:, 0] >= 0) & (q[:, 0] < canvas.image.shape[1]) & (q[:, 1] >= 0) & (q[:, 1] < canvas.image.shape[0])
            canvas.image[q[ok, 1], q[ok, 0]] = colours[ok]
    names = "xyz"
    return with_metre_axes(canvas, 1.0, f"{names[u]} (m, object frame)", f"{names[v]} (m)")


def shape_growth_figure(growth: ShapeGrowth, path: Path) -> Path:
    """The shape filling in, from the track stage's record (:class:`sot_apps.tracking.ShapeGrowth`): for each
    recorded frame the aggregated points from above (x-y) over the side view (x-z); colour = height above
    the box bottom, with its colour bar."""
    size = np.asarray(growth.size, dtype=np.float64)
    height = float(size[2])
    panels = []
    for k, pts in zip(growth.frames, growth.points, strict=True):
        t = np.clip((pts[:, 2] + height / 2) / max(height, 1e-6), 0, 1) if len(pts) else np.zeros(0)
        colours = cv2.applyColorMap((t * 255).astype(np.uint8).reshape(-1, 1), cv2.COLORMAP_VIRIDIS).reshape(-1, 3)
        top = _object_view(pts, colours, size, (0, 1))
        side = _object_view(pts, colours, size, (0, 2))
        panels.append(title_bar(vstack([top, side], gap=6),
                                f"frame {k} (+{k - growth.start_frame}): {len(pts)} points", 26, 0.5))
    bar = colour_bar(cv2.COLORMAP_VIRIDIS, 0.0, height, "height above box bottom (m)", height=220,
                     unit_format="{:.2f}")
    img = hstack(panels + [bar], gap=14)
    return write_png(path, title_bar(img, f"{growth.object_id}: shape filling in over time (top: from above, "
                                          "bottom: from the side)"))


FLOW_BACKGROUND = (70, 70, 70)   # pixels without flow: dark, so that small (pale) flows stay visible


def flow_key(max_flow: float, size: int = 150) -> np.ndarray:
    """The colour-wheel key of flow images drawn with ``max_flow``: a disc whose colour at (u, v) is that of a
    flow (u, v) pixels, axes and the saturation radius labelled."""
    from ..flow.visualize import flow_to_color

    r = size // 2 - 4
    grid = np.mgrid[-r:r + 1, -r:r + 1].astype(np.float64)
    flow = np.stack([grid[1], grid[0]], axis=-1) * (max_flow / r)        # u right, v down (image axes)
    inside = np.hypot(grid[0], grid[1]) <= r
    disc = cv2.cvtColor(flow_to_color(flow, inside, max_flow), cv2.COLOR_RGB2BGR)
    disc[~inside] = 255
    pad = 26
    img = np.full((disc.shape[0] + 2 * pad + 18, disc.shape[1] + 2 * pad, 3), 255, np.uint8)
    img[pad:pad + disc.shape[0], pad:pad + disc.shape[1]] = disc
    c = (pad + r, pad + r)
    cv2.circle(img, c, r, GREY, 1, cv2.LINE_AA)
    cv2.arrowedLine(img, c, (c[0] + r + 18, c[1]), BLACK, 1, cv2.LINE_AA, tipLength=0.08)
    cv2.arrowedLine(img, c, (c[0], c[1] + r + 18), BLACK, 1, cv2.LINE_AA, tipLength=0.08)
    text(img, "+u", (c[0] + r + 2, c[1] + 18), 0.42)
    text(img, "+v", (c[0] + 8, c[1] + r + 16), 0.42)
    text(img, "flow key", (4, 16), 0.45)
    label = f"rim: |flow| = {max_flow:.1f} px"
    text(img, label, (4, img.shape[0] - 6), 0.42)
    return img


def flow_figure(seq: Sequence, flow_root: Path, camera: str, path: Path, pairs: int = 3, width: int = 400) -> Path | None:
    """Rows of (image k, flow, overlay) for a few pairs written by the flow stage, and beside them the colour-wheel
    key. The flow column is drawn here from the stage's KITTI flow (``flow_occ``) with ONE saturation radius
    for all rows (the 99th percentile of their flow magnitudes), which the key states."""
    from ..flow.kitti_io import read_kitti_flow
    from ..flow.visualize import flow_to_color

    cam_root = flow_root / camera
    stats_path = cam_root / "stats.json"
    if not stats_path.is_file():
        return None
    stats = json.loads(stats_path.read_text())
    records = [p for p in stats["pairs"] if sum(o["pixels"] for o in p["objects"]) > 0] or stats["pairs"]
    if not records:
        return None
    chosen = [records[int(round(i))] for i in np.linspace(0, len(records) - 1, min(pairs, len(records)))]
    ks = sorted({int(rec["frame"] if "frame" in rec else rec["k"]) for rec in chosen})
    flows = {}
    for k in ks:
        occ = cam_root / "flow_occ" / f"{k:06d}.png"
        if occ.is_file():
            flows[k] = read_kitti_flow(occ)
    magnitudes = np.concatenate([np.linalg.norm(f[v], axis=1) for f, v in flows.values()]) if flows else np.zeros(0)
    max_flow = float(np.percentile(magnitudes, 99)) if magnitudes.size else 1.0
    max_flow = max(max_flow, 1.0)
    rows = []
    for rec in chosen:
        k = int(rec["frame"] if "frame" in rec else rec["k"])
        if any(r[0] == k for r in rows):
            continue
        image = cv2.imread(str(seq.cameras[camera].frames[k].image_path))
        flow_img = None
        if k in flows:
            flow, valid = flows[k]
            flow_img = cv2.cvtColor(flow_to_color(flow, valid, max_flow), cv2.COLOR_RGB2BGR)
            flow_img[~valid] = FLOW_BACKGROUND
        over = cv2.imread(str(cam_root / "vis" / f"{k:06d}_overlay.jpg"))
        tiles = []
        for name, tile in ((f"image {k}", image), ("flow (colour: see key)", flow_img), ("overlay", over)):
            if tile is None:
                continue
            scale = width / tile.shape[1]
            tile = cv2.resize(tile, (width, int(round(tile.shape[0] * scale))), interpolation=cv2.INTER_AREA)
            tiles.append(title_bar(tile, name, 24, 0.5))
        pixels = sum(o["pixels"] for o in rec["objects"])
        rows.append((k, title_bar(hstack(tiles), f"pair {k} -> {k + 1}: {pixels} object pixels", 26, 0.5)))
    img = hstack([vstack([r for _, r in rows], gap=12), flow_key(max_flow)], gap=12)
    return write_png(path, title_bar(img, f"{seq.id} / {camera}: optical flow from tracked shapes"))


def _crop_view(xyz: np.ndarray, mask: np.ndarray, box: Box, size_px: int = 230, half_m: float = 4.0) -> np.ndarray:
    """The points of one inserted vehicle from above (sensor frame, x right, y up), range rings around the
    sensor every metre (labelled every 2 m), an arrow towards the sensor, metre axes."""
    half_m = max(half_m, 0.5 * max(box.length, box.width) + 1.0)
    canvas = BevCanvas(box.x - half_m, box.y - half_m, box.x + half_m, box.y + half_m, size_px / (2 * half_m),
                       np.full((size_px, size_px, 3), 255, np.uint8))
    r = float(np.hypot(box.x, box.y))
    rings = np.arange(np.floor(r - 1.5 * half_m), np.ceil(r + 1.5 * half_m) + 1)
    rings = rings[rings > 0]
    canvas.range_rings((0.0, 0.0), [v for v in rings if v % 2 == 1], (225, 225, 225), label=False)
    canvas.range_rings((0.0, 0.0), [v for v in rings if v % 2 == 0], (190, 190, 190))
    canvas.box(box, GREY, 1)
    pts = xyz[mask]
    if len(pts):
        canvas.points(pts[:, :2], (200, 80, 20), radius=1)
    # towards the sensor, from the lower corner nearest to it
    d = -np.array([box.x, box.y]) / max(r, 1e-9)
    start = np.array([size_px - 40.0, size_px - 40.0]) if d[0] > 0 else np.array([40.0, size_px - 40.0])
    tip = start + 26 * np.array([d[0], -d[1]])
    cv2.arrowedLine(canvas.image, tuple(int(v) for v in start), tuple(int(v) for v in tip), EGO_COLOR, 1,
                    cv2.LINE_AA, tipLength=0.3)
    text(canvas.image, "sensor", (int(start[0]) - 22, int(start[1]) + (16 if tip[1] <= start[1] else -8)), 0.4)
    return with_metre_axes(canvas, 2.0, "x (m, sensor)", "y (m)")


def _scene_overview(boxes: list[Box], max_range: float, size_px: int = 260) -> np.ndarray:
    """Where the vehicles of a scene are: the sensor (arrow = its heading, +x) at the origin, labelled range rings."""
    extent = max(max_range, max(max(abs(b.x), abs(b.y)) + 0.6 * b.length for b in boxes)) + 3.0
    canvas = BevCanvas(-extent, -extent, extent, extent, size_px / (2 * extent),
                       np.full((size_px, size_px, 3), 255, np.uint8))
    step = 10.0 if extent > 15 else 5.0
    canvas.range_rings((0.0, 0.0), list(np.arange(step, extent + 1e-9, step)))
    for b in boxes:
        canvas.box(b, (200, 80, 20), 1)
    canvas.ego(np.eye(4), size=9)
    text(canvas.image, "sensor", (size_px // 2 + 8, size_px // 2 + 16), 0.4)
    return with_metre_axes(canvas, step * 2, "x (m, sensor)", "y (m)")


def scans_figure(scans_root: Path, scene_dirs: list[Path], path: Path) -> Path | None:
    """Rows = ranges: an overview (sensor, range rings, the inserted vehicles), then one panel per heading with the
    simulated points on that vehicle (sensor frame, x right, y up; heading = angle of the length axis from +x,
    counter-clockwise, as everywhere), with point counts."""
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
        doc = json.loads(boxes_path.read_text())
        raw = doc["boxes"] if isinstance(doc, dict) and "boxes" in doc else doc
        boxes = [Box(*(float(b[k]) for k in ("x", "y", "z", "heading", "length", "width", "height")))
                 for b in raw[:len(scene["objects"])]]
        if not boxes:
            continue
        r = float(np.hypot(boxes[0].x, boxes[0].y))
        tiles = [title_bar(_scene_overview(boxes, r), "scene (from above)", 24, 0.45)]
        for i, box in enumerate(boxes):
            n = int((instance == i).sum())
            tile = _crop_view(xyz, instance == i, box)
            tiles.append(title_bar(tile, f"heading {np.degrees(box.heading):.0f} deg: {n} points", 24, 0.45))
        rows.append(title_bar(hstack(tiles, gap=10), f"vehicle at {r:.0f} m from the sensor", 26, 0.5))
    if not rows:
        return None
    img = vstack(rows, gap=12)
    return write_png(path, title_bar(img, "Simulated scans of a bank vehicle at several ranges and headings "
                                          "(heading: length axis from +x, counter-clockwise)"))


def motion_figure(evaluation: dict, path: Path, title: str) -> Path:
    """Mean centre error of the motion export vs. k frames after the start, from the motion stage's evaluation
    (``motion_eval.json``, :meth:`sot_apps.evaluation.motion.MotionAccuracy.to_json`)."""
    from ..evaluation.motion import plot_accuracy

    plot_accuracy(evaluation, path, title)
    return Path(path)


def placeholder(path: Path, message: str) -> Path:
    img = np.full((120, 700, 3), 245, np.uint8)
    text(img, message, (10, 65), 0.55, BLACK)
    return write_png(path, img)
