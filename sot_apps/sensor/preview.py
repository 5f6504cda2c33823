"""Bird's-eye-view preview PNG of a scan with its boxes (OpenCV).

Sensor frame from above, x to the right and y up (as every bird's-eye view of the project); a box's heading
is the angle of its length axis from +x, counter-clockwise, drawn as a line from its centre to its front.
The sensor is a white arrowhead (pointing along +x) at the origin, labelled, with range rings labelled in
metres. Background points are grey (brighter = higher); each object's points and box get their own colour.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from tracker import Box

from ..io.atomic import write_bytes

__all__ = ["bev_image", "write_bev_png"]

_PALETTE = np.array([[66, 135, 245], [245, 66, 93], [66, 245, 135], [245, 185, 66], [185, 66, 245], [66, 230, 245],
                     [245, 120, 200], [160, 245, 66], [245, 100, 40], [120, 120, 255]], dtype=np.uint8)  # BGR


def bev_image(xyz: np.ndarray, instance: np.ndarray, boxes: list[Box], extent: float = 50.0, size: int = 800,
              centre: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """(size, size, 3) uint8 BGR image covering +-extent metres around ``centre``."""
    image = np.full((size, size, 3), 18, dtype=np.uint8)
    scale = size / (2.0 * extent)

    def to_px(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        col = (size / 2.0 + (x - centre[0]) * scale)
        row = (size / 2.0 - (y - centre[1]) * scale)
        return col, row

    for r in (10, 20, 30, 40, 50, 75, 100):
        if r < extent * 1.5 and centre == (0.0, 0.0):
            cv2.circle(image, (size // 2, size // 2), int(r * scale), (60, 60, 60), 1, cv2.LINE_AA)
            # labelled where the ring crosses the view's upper-left diagonal
            p = (int(size / 2 - r * scale * 0.7071) + 3, int(size / 2 - r * scale * 0.7071) - 3)
            if 0 <= p[0] < size - 30 and 12 <= p[1] < size:
                cv2.putText(image, f"{r} m", p, cv2.FONT_HERSHEY_SIMPLEX, 0.4, (150, 150, 150), 1, cv2.LINE_AA)
    col, row = to_px(xyz[:, 0], xyz[:, 1])
    inside = (col >= 0) & (col < size) & (row >= 0) & (row < size)
    col, row = col[inside].astype(int), row[inside].astype(int)
    inst = instance[inside]
    z = xyz[inside, 2]
    grey = np.clip(120 + (z - np.percentile(z, 5) if len(z) else z) * 40, 110, 240).astype(np.uint8)
    bg = inst < 0
    image[row[bg], col[bg]] = grey[bg, None]
    fg = ~bg
    image[row[fg], col[fg]] = _PALETTE[inst[fg] % len(_PALETTE)]
    for i, box in enumerate(boxes):
        corners = box.bev_corners()
        c, r = to_px(corners[:, 0], corners[:, 1])
        if not (np.abs(np.concatenate([c, r]) - size / 2.0) < 8 * size).all():
            continue   # far outside the view (pixel coordinates would not even fit OpenCV's int32)
        pts = np.stack([c, r], axis=1).round().astype(np.int32)
        color = tuple(int(v) for v in _PALETTE[i % len(_PALETTE)])
        cv2.polylines(image, [pts], True, color, 1, cv2.LINE_AA)
        front = np.array([box.x + np.cos(box.heading) * box.length / 2, box.y + np.sin(box.heading) * box.length / 2])
        c0, r0 = to_px(np.array([box.x]), np.array([box.y]))
        c1, r1 = to_px(front[:1], front[1:])
        cv2.line(image, (int(c0[0]), int(r0[0])), (int(c1[0]), int(r1[0])), color, 1, cv2.LINE_AA)
    if centre == (0.0, 0.0):
        c = np.array([size / 2.0, size / 2.0])
        tip = np.array([[c[0] + 9, c[1]], [c[0] - 6, c[1] - 6], [c[0] - 3, c[1]], [c[0] - 6, c[1] + 6]])
        cv2.fillPoly(image, [np.round(tip * 16).astype(np.int32)], (255, 255, 255), cv2.LINE_AA, shift=4)
        cv2.putText(image, "sensor (+x)", (int(c[0]) + 8, int(c[1]) + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    (230, 230, 230), 1, cv2.LINE_AA)
    return image


def write_bev_png(path: Path, xyz: np.ndarray, instance: np.ndarray, boxes: list[Box], extent: float = 50.0,
                  size: int = 800) -> None:
    ok, data = cv2.imencode(".png", bev_image(xyz, instance, boxes, extent, size))
    if not ok:
        raise RuntimeError("PNG encoding failed")
    write_bytes(path, data.tobytes())


def object_gallery(xyz: np.ndarray, instance: np.ndarray, boxes: list[Box], panel: int = 240, half_m: float = 3.5,
                   columns: int | None = None) -> np.ndarray:
    """One bird's-eye panel per object (+-``half_m`` around its box; x right, y up), with range, heading and point
    count, and an arrow towards the sensor; panels are ordered as the boxes, ``columns`` per row (default: up to 4)."""
    n = len(boxes)
    columns = columns or min(4, max(1, n))
    rows = (n + columns - 1) // columns
    image = np.full((rows * panel, columns * panel, 3), 18, dtype=np.uint8)
    for i, box in enumerate(boxes):
        sub = bev_image(xyz, instance, [], extent=half_m, size=panel, centre=(float(box.x), float(box.y)))
        # keep only this object's colour inside the panel's box outline
        corners = box.bev_corners()
        scale = panel / (2 * half_m)
        pts = np.stack([panel / 2 + (corners[:, 0] - box.x) * scale, panel / 2 - (corners[:, 1] - box.y) * scale], axis=1)
        color = tuple(int(v) for v in _PALETTE[i % len(_PALETTE)])
        cv2.polylines(sub, [pts.round().astype(np.int32)], True, color, 1, cv2.LINE_AA)
        front = np.array([np.cos(box.heading), np.sin(box.heading)]) * box.length / 2 * scale
        cv2.line(sub, (panel // 2, panel // 2), (int(panel / 2 + front[0]), int(panel / 2 - front[1])), color, 1,
                 cv2.LINE_AA)
        towards = -np.array([box.x, box.y]) / max(float(np.hypot(box.x, box.y)), 1e-9)
        start = np.array([panel - 34.0 if towards[0] > 0 else 34.0, 30.0])
        end = start + 20 * np.array([towards[0], -towards[1]])
        cv2.arrowedLine(sub, tuple(int(v) for v in start), tuple(int(v) for v in end), (230, 230, 230), 1,
                        cv2.LINE_AA, tipLength=0.3)
        cv2.putText(sub, "sensor", (int(start[0]) - 22, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (230, 230, 230), 1,
                    cv2.LINE_AA)
        count = int((instance == i).sum())
        label = f"{np.hypot(box.x, box.y):.0f} m, {np.degrees(box.heading):.0f} deg, {count} pts"
        cv2.putText(sub, label, (6, panel - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.42, (230, 230, 230), 1, cv2.LINE_AA)
        r, c = divmod(i, columns)
        image[r * panel:(r + 1) * panel, c * panel:(c + 1) * panel] = sub
        cv2.rectangle(image, (c * panel, r * panel), ((c + 1) * panel - 1, (r + 1) * panel - 1), (60, 60, 60), 1)
    return image


def write_object_gallery(path: Path, xyz: np.ndarray, instance: np.ndarray, boxes: list[Box]) -> None:
    ok, data = cv2.imencode(".png", object_gallery(xyz, instance, boxes))
    if not ok:
        raise RuntimeError("PNG encoding failed")
    write_bytes(path, data.tobytes())
