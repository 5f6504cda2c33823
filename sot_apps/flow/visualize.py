"""Flow pictures: the Middlebury colour wheel (Baker et al. 2011) and an overlay on the camera image."""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["color_wheel", "flow_to_color", "overlay"]


def color_wheel() -> np.ndarray:
    """(55, 3) uint8 RGB wheel: red-yellow 15, yellow-green 6, green-cyan 4, cyan-blue 11, blue-magenta 13, magenta-red 6."""
    segments = [(15, (255, 0, 0), (255, 255, 0)), (6, (255, 255, 0), (0, 255, 0)), (4, (0, 255, 0), (0, 255, 255)),
                (11, (0, 255, 255), (0, 0, 255)), (13, (0, 0, 255), (255, 0, 255)), (6, (255, 0, 255), (255, 0, 0))]
    rows = []
    for n, start, end in segments:
        a = np.arange(n)[:, None] / n
        delta = np.array(end) - np.array(start)
        rows.append(np.array(start) + np.sign(delta) * np.floor(a * np.abs(delta)))
    return np.concatenate(rows).astype(np.uint8)


def flow_to_color(flow: np.ndarray, valid: np.ndarray | None = None, max_flow: float | None = None) -> np.ndarray:
    """(H, W, 3) uint8 RGB: hue = direction, saturation = magnitude / ``max_flow``; invalid pixels black.

    Only valid pixels are computed (object masks are a small part of an image).
    """
    flow = np.asarray(flow)
    valid = np.ones(flow.shape[:2], bool) if valid is None else np.asarray(valid, bool)
    out = np.zeros(flow.shape[:2] + (3,), np.uint8)
    if not valid.any():
        return out
    f = np.nan_to_num(flow[valid].astype(np.float64))
    u, v = f[:, 0], f[:, 1]
    rad = np.hypot(u, v)
    if max_flow is None:
        max_flow = float(rad.max())
    max_flow = max(max_flow, 1e-6)
    u, v, rad = u / max_flow, v / max_flow, rad / max_flow
    wheel = color_wheel().astype(np.float64) / 255.0
    ncols = len(wheel)
    angle = np.arctan2(-v, -u) / np.pi
    fk = (angle + 1.0) / 2.0 * (ncols - 1)
    k0 = np.floor(fk).astype(int)
    k1 = (k0 + 1) % ncols
    frac = (fk - k0)[:, None]
    col = (1 - frac) * wheel[k0] + frac * wheel[k1]
    small = (rad <= 1)[:, None]
    col = np.where(small, 1 - rad[:, None] * (1 - col), col * 0.75)
    out[valid] = np.floor(255 * col).astype(np.uint8)
    return out


def overlay(image_bgr: np.ndarray, flow: np.ndarray, valid: np.ndarray, instance: np.ndarray | None = None,
            alpha: float = 0.65, max_flow: float | None = None, arrow_step: int = 24) -> np.ndarray:
    """The image with flow colours blended over valid pixels, object outlines and sparse arrows (BGR)."""
    out = image_bgr.copy()
    colour = cv2.cvtColor(flow_to_color(flow, valid, max_flow), cv2.COLOR_RGB2BGR)
    out[valid] = (alpha * colour[valid] + (1 - alpha) * out[valid]).astype(np.uint8)
    if instance is not None and instance.any():
        # Outline of the (closed) object region: also readable for sparse masks.
        region = cv2.morphologyEx((instance > 0).astype(np.uint8) * 255, cv2.MORPH_CLOSE, np.ones((9, 9), np.uint8))
        edges = cv2.morphologyEx(region, cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8))
        out[edges > 0] = (255, 255, 255)
    vs, us = np.nonzero(valid[::arrow_step, ::arrow_step])
    for u, v in zip(us * arrow_step, vs * arrow_step, strict=True):  # a few hundred arrows at most
        du, dv = flow[v, u]
        cv2.arrowedLine(out, (int(u), int(v)), (int(round(u + du)), int(round(v + dv))), (0, 0, 0), 1, cv2.LINE_AA,
                        tipLength=0.25)
    return out
