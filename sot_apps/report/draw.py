"""Small OpenCV drawing helpers for the report figures (no matplotlib)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from tracker import Box

from ..io.atomic import write_bytes

__all__ = ["WHITE", "BLACK", "GREY", "GT_COLOR", "PALETTE", "BevCanvas", "text", "write_png", "hstack", "vstack",
           "title_bar", "colour_for"]

WHITE = (255, 255, 255)
BLACK = (0, 0, 0)
GREY = (150, 150, 150)
GT_COLOR = (60, 170, 60)        # BGR green
PALETTE = [(40, 110, 230), (200, 90, 20), (170, 60, 170), (20, 160, 200), (90, 90, 220), (30, 140, 110),
           (200, 50, 120), (120, 120, 30)]
FONT = cv2.FONT_HERSHEY_SIMPLEX


def colour_for(i: int) -> tuple[int, int, int]:
    return PALETTE[i % len(PALETTE)]


def text(img: np.ndarray, s: str, org: tuple[int, int], scale: float = 0.5, color=BLACK, thickness: int = 1) -> None:
    cv2.putText(img, s, (int(org[0]), int(org[1])), FONT, scale, color, thickness, cv2.LINE_AA)


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

    def scale_bar(self, metres: float = 10.0) -> None:
        h = self.image.shape[0]
        x = 12
        length = int(metres * self.scale)
        cv2.line(self.image, (x, h - 14), (x + length, h - 14), BLACK, 2)
        text(self.image, f"{metres:g} m", (x, h - 20), 0.45)
