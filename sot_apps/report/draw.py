"""Small OpenCV drawing helpers for the report figures (no matplotlib).

One font everywhere (``FONT``, Hershey simplex); metre axes around bird's-eye views; legends; colour bars;
labels placed so that they do not overlap (:func:`place_labels`). Bird's-eye views are x right, y up (world
or sensor frame), and a heading is the angle of the length axis from +x, counter-clockwise, drawn as a tick
from the box centre to the front.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracker import Box

from ..io.atomic import write_bytes

__all__ = ["WHITE", "BLACK", "GREY", "GT_COLOR", "EGO_COLOR", "PALETTE", "FONT", "BevCanvas", "text", "text_size",
           "write_png", "hstack", "vstack", "title_bar", "colour_for", "place_labels", "LegendEntry", "legend_panel",
           "colour_bar", "with_metre_axes", "Rect", "rects_overlap"]

WHITE = (255, 255, 255)
BLACK = (0, 0, 0)
GREY = (150, 150, 150)
GT_COLOR = (60, 170, 60)        # BGR green
EGO_COLOR = (20, 20, 20)
# 20 distinguishable colours (BGR; "tab20"-like, the light green of ground truth left out), so a busy sequence
# (15 tracks) gets a colour per object.
PALETTE = [(180, 119, 31), (14, 127, 255), (40, 39, 214), (189, 103, 148), (75, 86, 140), (194, 119, 227),
           (127, 127, 127), (34, 189, 188), (207, 190, 23), (232, 199, 174), (120, 187, 255), (150, 152, 255),
           (213, 176, 197), (148, 156, 196), (210, 182, 247), (141, 219, 219), (229, 218, 158), (0, 90, 160),
           (100, 0, 100), (0, 0, 128)]
FONT = cv2.FONT_HERSHEY_SIMPLEX

Rect = tuple[int, int, int, int]   # x0, y0, x1, y1 (pixels, exclusive ends)


def colour_for(i: int) -> tuple[int, int, int]:
    return PALETTE[i % len(PALETTE)]


def text(img: np.ndarray, s: str, org: tuple[int, int], scale: float = 0.5, color=BLACK, thickness: int = 1) -> None:
    cv2.putText(img, s, (int(org[0]), int(org[1])), FONT, scale, color, thickness, cv2.LINE_AA)


def text_size(s: str, scale: float = 0.5, thickness: int = 1) -> tuple[int, int, int]:
    """(width, height above the baseline, baseline) of ``s`` in pixels."""
    (w, h), base = cv2.getTextSize(s, FONT, scale, thickness)
    return w, h, base


def rects_overlap(a: Rect, b: Rect) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def place_labels(anchors: np.ndarray, sizes: list[tuple[int, int]], bounds: tuple[int, int],
                 occupied: list[Rect] = ()) -> list[Rect]:
    """Rectangles for labels of ``sizes`` (w, h) near ``anchors`` (N, 2) pixels that overlap neither each other
    nor ``occupied`` and stay inside ``bounds`` (w, h): greedy, nearest free spot on rings of growing radius
    around each anchor (the most crowded anchors first). When no free spot is found within 160 px, the spot
    with the least overlap is used."""
    anchors = np.asarray(anchors, dtype=np.float64).reshape(-1, 2)
    placed: list[Rect] = list(occupied)
    out: list[Rect | None] = [None] * len(anchors)
    if len(anchors) == 0:
        return []
    crowd = (np.linalg.norm(anchors[:, None] - anchors[None], axis=2) < 60).sum(axis=1)
    angles = np.radians(np.arange(0, 360, 22.5))
    for i in np.argsort(-crowd, kind="stable"):
        w, h = sizes[i]
        best, best_cost = None, None
        for radius in (6, 14, 24, 36, 50, 66, 84, 104, 130, 160):
            for a in angles:
                cx, cy = anchors[i] + radius * np.array([np.cos(a), -np.sin(a)])
                # the label's nearest corner/edge sits on the ring point
                x0 = int(round(cx if np.cos(a) > 0.3 else cx - w if np.cos(a) < -0.3 else cx - w / 2))
                y0 = int(round(cy - h if np.sin(a) > 0.3 else cy if np.sin(a) < -0.3 else cy - h / 2))
                rect = (x0, y0, x0 + w, y0 + h)
                if x0 < 0 or y0 < 0 or rect[2] > bounds[0] or rect[3] > bounds[1]:
                    continue
                cost = sum(rects_overlap(rect, r) for r in placed)
                if cost == 0:
                    best, best_cost = rect, 0
                    break
                if best_cost is None or cost < best_cost:
                    best, best_cost = rect, cost
            if best_cost == 0:
                break
        if best is None:
            x0 = int(np.clip(anchors[i, 0], 0, max(bounds[0] - w, 0)))
            y0 = int(np.clip(anchors[i, 1], 0, max(bounds[1] - h, 0)))
            best = (x0, y0, x0 + w, y0 + h)
        out[i] = best
        placed.append(best)
    return [r for r in out if r is not None]


@dataclass(frozen=True)
class LegendEntry:
    """One legend row: ``kind`` "line", "box", "points" or "ego", its colour and text."""

    kind: str
    colour: tuple[int, int, int]
    label: str


def _legend_glyph(img: np.ndarray, entry: LegendEntry, x: int, y: int) -> None:
    if entry.kind == "line":
        cv2.line(img, (x, y), (x + 26, y), entry.colour, 2, cv2.LINE_AA)
    elif entry.kind == "box":
        cv2.rectangle(img, (x + 2, y - 6), (x + 24, y + 6), entry.colour, 2, cv2.LINE_AA)
        cv2.line(img, (x + 13, y), (x + 24, y), entry.colour, 2, cv2.LINE_AA)
    elif entry.kind == "points":
        for dx in (4, 11, 18, 24):
            cv2.circle(img, (x + dx, y + (dx % 3) - 1), 2, entry.colour, -1, cv2.LINE_AA)
    elif entry.kind == "ego":
        draw_ego_marker(img, (x + 13, y), 0.0, entry.colour, 9)
    else:
        raise ValueError(f"unknown legend glyph {entry.kind!r}")


def legend_panel(entries: list[LegendEntry], title: str = "", width: int = 300, row: int = 22,
                 scale: float = 0.45) -> np.ndarray:
    """A white panel listing ``entries`` one per row (glyph + text)."""
    top = row if title else 4
    img = np.full((top + row * len(entries) + 8, width, 3), 255, np.uint8)
    if title:
        text(img, title, (6, row - 6), scale + 0.05)
    for i, e in enumerate(entries):
        y = top + row * i + row // 2
        _legend_glyph(img, e, 8, y)
        text(img, e.label, (42, y + 5), scale)
    return img


def draw_ego_marker(img: np.ndarray, centre_px, heading_image: float, colour=EGO_COLOR, size: int = 11) -> None:
    """A filled arrowhead at ``centre_px`` pointing along ``heading_image`` (radians, image x right, y UP)."""
    c = np.asarray(centre_px, dtype=np.float64)
    d = np.array([np.cos(heading_image), -np.sin(heading_image)])
    n = np.array([-d[1], d[0]])
    pts = np.array([c + d * size, c - d * size * 0.6 + n * size * 0.6, c - d * size * 0.25,
                    c - d * size * 0.6 - n * size * 0.6])
    cv2.fillPoly(img, [np.round(pts * 16).astype(np.int32)], colour, cv2.LINE_AA, shift=4)


def colour_bar(colormap: int, vmin: float, vmax: float, label: str, height: int = 200, width: int = 16,
               ticks: int = 5, unit_format: str = "{:.1f}") -> np.ndarray:
    """A vertical colour bar (OpenCV ``colormap``, low at the bottom) with ``ticks`` labelled values and a title."""
    lw = max(text_size(unit_format.format(v), 0.42)[0] for v in np.linspace(vmin, vmax, ticks))
    tw = text_size(label, 0.45)[0]
    pad_top = 24
    img = np.full((height + pad_top + 12, max(width + 12 + lw + 8, tw + 8), 3), 255, np.uint8)
    ramp = np.linspace(255, 0, height).astype(np.uint8).reshape(-1, 1)
    bar = cv2.applyColorMap(np.repeat(ramp, width, axis=1), colormap)
    x0 = 4
    img[pad_top:pad_top + height, x0:x0 + width] = bar
    cv2.rectangle(img, (x0, pad_top), (x0 + width - 1, pad_top + height - 1), GREY, 1)
    for v in np.linspace(vmin, vmax, ticks):
        y = int(round(pad_top + (vmax - v) / max(vmax - vmin, 1e-12) * (height - 1)))
        cv2.line(img, (x0 + width, y), (x0 + width + 4, y), BLACK, 1)
        text(img, unit_format.format(v), (x0 + width + 7, y + 5), 0.42)
    text(img, label, (4, 16), 0.45)
    return img


def with_metre_axes(canvas: "BevCanvas", step: float, x_label: str = "x (m)", y_label: str = "y (m)") -> np.ndarray:
    """The canvas image framed by metre axes: ticks and values every ``step`` metres, axis names."""
    img = canvas.image
    h, w = img.shape[:2]
    left, bottom, top, right = 64, 46, 10, 14
    out = np.full((h + top + bottom, w + left + right, 3), 255, np.uint8)
    out[top:top + h, left:left + w] = img
    cv2.rectangle(out, (left - 1, top - 1), (left + w, top + h), BLACK, 1)
    for x in np.arange(np.ceil(canvas.x0 / step) * step, canvas.x1 + 1e-9, step):
        c = int(round(left + (x - canvas.x0) * canvas.scale))
        cv2.line(out, (c, top + h), (c, top + h + 5), BLACK, 1)
        s = f"{x + 0.0:g}"
        text(out, s, (c - text_size(s, 0.42)[0] // 2, top + h + 20), 0.42)
    for y in np.arange(np.ceil(canvas.y0 / step) * step, canvas.y1 + 1e-9, step):
        r = int(round(top + (canvas.y1 - y) * canvas.scale))
        cv2.line(out, (left - 5, r), (left, r), BLACK, 1)
        s = f"{y + 0.0:g}"
        text(out, s, (left - 8 - text_size(s, 0.42)[0], r + 5), 0.42)
    text(out, x_label, (left + w // 2 - text_size(x_label, 0.5)[0] // 2, top + h + 40), 0.5)
    label = np.full((22, text_size(y_label, 0.5)[0] + 6, 3), 255, np.uint8)
    text(label, y_label, (3, 16), 0.5)
    rotated = cv2.rotate(label, cv2.ROTATE_90_COUNTERCLOCKWISE)
    y0 = top + max(0, (h - rotated.shape[0]) // 2)
    hh = min(rotated.shape[0], out.shape[0] - y0)
    out[y0:y0 + hh, 2:2 + rotated.shape[1]] = rotated[:hh]
    return out


def write_png(path: str | Path, img: np.ndarray) -> Path:
    ok, buffer = cv2.imencode(".png", img)
    if not ok:
        raise RuntimeError(f"PNG encoding failed for {path}")
    write_bytes(path, buffer.tobytes())
    return Path(path)


def _pad_to(img: np.ndarray, h: int | None = None, w: int | None = None) -> np.ndarray:
    h = h or img.shape[0]
    w = w or img.shape[1]
    out = np.full((h, w, 3), 255, np.uint8)
    out[: img.shape[0], : img.shape[1]] = img
    return out


def _stack(images: list[np.ndarray], axis: int, gap: int) -> np.ndarray:
    """Images side by side (axis 1) or one above the other (axis 0), padded white, ``gap`` px apart."""
    extent = max(i.shape[1 - axis] for i in images)
    parts = []
    for i, img in enumerate(images):
        parts.append(_pad_to(img, h=extent) if axis == 1 else _pad_to(img, w=extent))
        if i < len(images) - 1:
            parts.append(np.full((extent, gap, 3) if axis == 1 else (gap, extent, 3), 255, np.uint8))
    return np.concatenate(parts, axis=axis)


def hstack(images: list[np.ndarray], gap: int = 8) -> np.ndarray:
    return _stack(images, axis=1, gap=gap)


def vstack(images: list[np.ndarray], gap: int = 8) -> np.ndarray:
    return _stack(images, axis=0, gap=gap)


def title_bar(img: np.ndarray, title: str, height: int = 30, scale: float = 0.6) -> np.ndarray:
    bar = np.full((height, img.shape[1], 3), 255, np.uint8)
    text(bar, title, (6, height - 9), scale)
    return np.concatenate([bar, img], axis=0)


@dataclass
class BevCanvas:
    """A bird's-eye view of a world rectangle: x to the right, y up; ``scale`` pixels per metre."""

    x0: float
    y0: float
    x1: float
    y1: float
    scale: float
    image: np.ndarray

    @classmethod
    def fit(cls, xy_min: np.ndarray, xy_max: np.ndarray, width: int = 900, margin: float = 5.0,
            max_height: int = 900, background=(255, 255, 255)) -> "BevCanvas":
        x0, y0 = float(xy_min[0]) - margin, float(xy_min[1]) - margin
        x1, y1 = float(xy_max[0]) + margin, float(xy_max[1]) + margin
        scale = width / max(x1 - x0, 1e-6)
        if (y1 - y0) * scale > max_height:
            scale = max_height / (y1 - y0)
        w, h = int(np.ceil((x1 - x0) * scale)), int(np.ceil((y1 - y0) * scale))
        image = np.empty((max(h, 1), max(w, 1), 3), np.uint8)
        image[:] = background
        return cls(x0, y0, x1, y1, scale, image)

    def px(self, xy: np.ndarray) -> np.ndarray:
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        col = (xy[:, 0] - self.x0) * self.scale
        row = (self.y1 - xy[:, 1]) * self.scale
        return np.stack([col, row], axis=1)

    def points(self, xy: np.ndarray, color, radius: int = 0) -> None:
        p = np.round(self.px(xy)).astype(int)
        h, w = self.image.shape[:2]
        ok = (p[:, 0] >= 0) & (p[:, 0] < w) & (p[:, 1] >= 0) & (p[:, 1] < h)
        p = p[ok]
        if radius <= 0:
            colors = np.asarray(color, dtype=np.uint8)
            if colors.ndim == 2:
                colors = colors[ok]
            self.image[p[:, 1], p[:, 0]] = colors
        else:
            for c, r in p:
                cv2.circle(self.image, (int(c), int(r)), radius, color, -1, cv2.LINE_AA)

    def polyline(self, xy: np.ndarray, color, thickness: int = 1, closed: bool = False) -> None:
        p = np.round(self.px(xy) * 16).astype(np.int32)
        if len(p) >= 2:
            cv2.polylines(self.image, [p], closed, color, thickness, cv2.LINE_AA, shift=4)

    def box(self, box: Box, color, thickness: int = 1, heading_tick: bool = True) -> None:
        corners = box.bev_corners()
        self.polyline(corners, color, thickness, closed=True)
        if heading_tick:
            c = np.array([box.x, box.y])
            tip = c + 0.5 * box.length * np.array([np.cos(box.heading), np.sin(box.heading)])
            self.polyline(np.stack([c, tip]), color, thickness)

    def grid(self, step: float = 10.0, color=(235, 235, 235)) -> None:
        for x in np.arange(np.ceil(self.x0 / step) * step, self.x1, step):
            self.polyline(np.array([[x, self.y0], [x, self.y1]]), color)
        for y in np.arange(np.ceil(self.y0 / step) * step, self.y1, step):
            self.polyline(np.array([[self.x0, y], [self.x1, y]]), color)

    def ego(self, world_from_ego: np.ndarray, colour=EGO_COLOR, size: int = 11) -> None:
        """The ego vehicle: an arrowhead at its position pointing along its heading (+x of the ego frame)."""
        T = np.asarray(world_from_ego, dtype=np.float64)
        centre = self.px(T[:2, 3])[0]
        draw_ego_marker(self.image, centre, float(np.arctan2(T[1, 0], T[0, 0])), colour, size)

    def range_rings(self, centre_xy, radii, colour=(190, 190, 190), label: bool = True) -> list[Rect]:
        """Circles of ``radii`` metres around ``centre_xy``, each labelled "R m" where it crosses the view;
        returns the label rectangles."""
        rects = []
        c = np.asarray(centre_xy, dtype=np.float64)
        h, w = self.image.shape[:2]
        for r in radii:
            a = np.linspace(0, 2 * np.pi, 721)
            self.polyline(c + r * np.stack([np.cos(a), np.sin(a)], axis=1), colour, 1)
            if not label:
                continue
            ring_px = self.px(c + r * np.stack([np.cos(a), np.sin(a)], axis=1))
            inside = np.flatnonzero((ring_px[:, 0] > 4) & (ring_px[:, 0] < w - 40) & (ring_px[:, 1] > 14)
                                    & (ring_px[:, 1] < h - 4))
            if inside.size == 0:
                continue
            p = ring_px[inside[np.argmin(ring_px[inside, 1])]]   # the topmost visible point of the ring
            s = f"{r:g} m"
            tw, th, _ = text_size(s, 0.4)
            x0, y0 = int(p[0]) + 3, int(p[1]) - 3
            cv2.rectangle(self.image, (x0 - 1, y0 - th - 1), (x0 + tw + 1, y0 + 3), WHITE, -1)
            text(self.image, s, (x0, y0), 0.4, (110, 110, 110))
            rects.append((x0 - 1, y0 - th - 1, x0 + tw + 1, y0 + 3))
        return rects
