"""Where inserted vehicles go: a motion profile placed on free ground of the background, clear of every real
object, of the ego and of the other inserted vehicles, at every frame.

A path is judged by its *swept boxes*: for each frame k, the oriented box (along the heading at the frame time
t_k) that holds the vehicle's box, enlarged by ``margin`` m, at every pose of the sweep window
[t_k - T, t_k] (T: the frame interval; the ground-truth box of frame k is the pose at some instant of that
window, when the beams pass the vehicle's centre). A path is accepted when

- its swept boxes (sampled every <= 0.5 m) cover no blocked cell of the :class:`~.background.GroundMap`
  and lie 90 % on observed free ground;
- at every frame its swept box overlaps no annotated real box of that frame, the ego's box and no other
  inserted vehicle's swept box of the same frame (exact bird's-eye-view polygon intersection): two
  vehicles may use the same ground at different times;
- it stays at least 4 m from the sensor and never crosses the scan's seam (the azimuth where the sweep starts
  and ends: a vehicle there is seen at both ends of the sweep, 0.1 s apart, and no box holds both).

Search (fast, and shaped by the free road rather than by blind redraws): the static facts are rasters built
once per background: blocked cells, ground cells, and per frame the cells of the real boxes and of the ego
(bit-packed, one bit per frame). Each copy adds the swept boxes of its inserted vehicles to its own copy of
the per-frame raster. For a drawn motion and a heading, the swept-box samples of the path are integer cell
offsets from the start cell, so every free start cell within the wanted range band is tested at once by
lookups (coarse samples first); the survivors are tested against the per-frame raster, then in random
order by the exact polygon test. When no start fits, the motion is redrawn slower (fit to the free road)
a bounded number of times, then the caller moves on.

An ``occluded`` tracklet gets a second, unlisted inserted vehicle (the occluder) that is on the line of
sight from the sensor to the target at the middle frame (25-80 % of the way), crossing it along or across
the road. Ground height: the median ground of the footprint at each frame, smoothed (:func:`ground_profile`:
a running median over 5 frames, then no step steeper than the road grade).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np

from tracker import iou_3d_batch

from ..objects.motion_profiles import MotionPath, MotionSpec, integrate_motion, place_path, sample_motion
from .background import MAX_GRADE, GroundMap
from .deps import Trajectory
from .hard_profiles import extra_headings, geometry_ok

__all__ = ["InsertedVehicle", "ground_profile", "PlacementContext", "place_vehicle", "place_occluder", "swept_boxes", "EGO_SIZE",
           "STEP_S", "SPEED_SCALES"]

# The ego is kept out by a square around the sensor, whatever its heading: which ego axis points forward is
# dataset-specific (PandaSet's pose frame has y forward) and the sensor sits up to ~2 m off the car's centre.
EGO_SIZE = (6.0, 6.0)
MIN_GROUND_FRACTION = 0.9
STEP_S = 0.01
SAMPLE_M = 0.5                          # footprint sample spacing
SPEED_SCALES = (1.0, 0.7, 0.5, 0.35)  # a motion that fits nowhere is redrawn this much slower
MAX_STARTS = 1500                       # start cells tested per (motion, heading)


@dataclass(frozen=True)
class InsertedVehicle:
    """One inserted vehicle: its bank mesh, its motion and its world trajectory (x, y, z, heading)."""

    id: str
    bank_id: str
    label: str
    size: tuple[float, float, float]
    motion: MotionSpec
    times_ns: np.ndarray
    states: np.ndarray
    listed: bool = True
    occluder_of: str | None = None
    span: tuple[int, int] | None = None   # listed frames (indices into the copy's frames); None: all
    replaces: str | None = None           # a real track this vehicle stands in for (its points are cut)
    hidden: tuple[int, int] | None = None  # frames (first, last; copy indices) whose points are all removed

    def states_at(self, t_ns: np.ndarray | int) -> np.ndarray:
        """(..., 4) x, y, z, heading at the given times (linear between samples, held outside)."""
        return Trajectory(self.times_ns, self.states).states_at(t_ns)


def _rigid(xy: np.ndarray, x0, y0, heading) -> np.ndarray:
    """(..., 2) local points placed at (x0, y0) turned by ``heading`` (scalars or arrays broadcasting)."""
    c, s = np.cos(heading), np.sin(heading)
    return np.stack([x0 + c * xy[..., 0] - s * xy[..., 1], y0 + s * xy[..., 0] + c * xy[..., 1]], axis=-1)


def _box_cells(grid_shape: tuple[int, int], origin: np.ndarray, cell: float, box: np.ndarray, grow: float
               ) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the cells whose centre lies in the BEV box (x, y, heading, length, width) grown by
    ``grow`` on each side."""
    x, y, h, length, width = box
    hl, hw = length / 2 + grow, width / 2 + grow
    reach = math.hypot(hl, hw)
    c0, c1 = int(math.floor((x - reach - origin[0]) / cell)), int(math.ceil((x + reach - origin[0]) / cell))
    r0, r1 = int(math.floor((y - reach - origin[1]) / cell)), int(math.ceil((y + reach - origin[1]) / cell))
    c0, r0 = max(c0, 0), max(r0, 0)
    c1, r1 = min(c1, grid_shape[1] - 1), min(r1, grid_shape[0] - 1)
    if c1 < c0 or r1 < r0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    rows, cols = np.mgrid[r0:r1 + 1, c0:c1 + 1]
    dx = origin[0] + (cols + 0.5) * cell - x
    dy = origin[1] + (rows + 0.5) * cell - y
    u = math.cos(h) * dx + math.sin(h) * dy
    v = -math.sin(h) * dx + math.cos(h) * dy
    inside = (np.abs(u) <= hl) & (np.abs(v) <= hw)
    return rows[inside], cols[inside]


@dataclass
class PlacementContext:
    """The background's facts for placement (world frame) and what has been placed so far in one copy.

    Build it once per background; :meth:`fresh` gives each copy its own empty placement state."""

    ground: GroundMap
    frame_times_ns: np.ndarray           # (F,) frame timestamps of the tracklet frames
    sensor_xyh: np.ndarray               # (F, 3) sensor x, y, heading at the frames
    real_boxes: list[np.ndarray]         # per frame (R, 7) annotated boxes
    range_m: tuple[float, float] = (5.0, 80.0)
    margin: float = 0.5
    min_sensor_distance: float = 4.0
    seam_deg: float | None = None        # azimuth of the scan's seam (first column) in the sensor frame

    def __post_init__(self) -> None:
        self.placed: list[np.ndarray] = []  # (F, 7) swept boxes of the placed vehicles
        n = len(self.frame_times_ns)
        ego = np.zeros((n, 7))
        ego[:, 0], ego[:, 1], ego[:, 3] = self.sensor_xyh[:, 0], self.sensor_xyh[:, 1], self.sensor_xyh[:, 2]
        ego[:, 4], ego[:, 5], ego[:, 6] = EGO_SIZE[0], EGO_SIZE[1], 2.0
        self._ego = ego
        self._real_frame = np.concatenate([np.full(len(r), f) for f, r in enumerate(self.real_boxes)] + [np.zeros(0, int)])
        self._real = np.vstack([r.reshape(-1, 7) for r in self.real_boxes] + [np.zeros((0, 7))])
        self.window_s = float(np.median(np.diff(self.frame_times_ns))) * 1e-9 if n > 1 else 0.1
        g = self.ground
        self._grow = g.cell * math.sqrt(0.5)  # a point in a box lies in a cell whose centre is this close to it
        # per-frame occupancy, one bit per frame: real boxes and the ego (inserted vehicles are added per copy)
        occupied = np.zeros((n,) + g.ground.shape, dtype=bool)
        for f in range(n):
            for b in list(self.real_boxes[f].reshape(-1, 7)) + [ego[f]]:
                r, c = _box_cells(g.ground.shape, g.origin, g.cell, b[[0, 1, 3, 4, 5]], self._grow)
                occupied[f, r, c] = True
        self._base_frames = np.ascontiguousarray(np.moveaxis(np.packbits(occupied, axis=0, bitorder="little"), 0, -1))
        self.frames_bits = self._base_frames.copy()
        # never free: blocked, or a real object (a parked car) stands there at every frame
        self._bad = g.blocked | occupied.all(axis=0)
        self._start_ok = g.ground & ~self._bad
        rows, cols = np.nonzero(self._start_ok)
        self._start_rc = np.column_stack([rows, cols])
        self._start_xy = g.origin + (np.column_stack([cols, rows]) + 0.5) * g.cell

    def fresh(self) -> "PlacementContext":
        """The same background with nothing placed (shares the static rasters)."""
        other = object.__new__(PlacementContext)
        other.__dict__.update(self.__dict__)
        other.placed = []
        other.frames_bits = self._base_frames.copy()
        return other

    def path_start_ns(self) -> int:
        return int(self.frame_times_ns[0]) - 200_000_000

    def duration_s(self) -> float:
        return (int(self.frame_times_ns[-1]) - self.path_start_ns()) * 1e-9 + 0.1

    def add(self, boxes: np.ndarray) -> None:
        """Record a placed vehicle's (F, 7) swept boxes (exact list and per-frame raster)."""
        self.placed.append(boxes)
        g = self.ground
        for f, b in enumerate(boxes):
            r, c = _box_cells(g.ground.shape, g.origin, g.cell, b[[0, 1, 3, 4, 5]], self._grow)
            self.frames_bits[r, c, f >> 3] |= np.uint8(1 << (f & 7))

    def remove_last(self) -> None:
        """Undo the last :meth:`add` (the raster is rebuilt from the remaining vehicles)."""
        self.placed.pop()
        kept, self.placed = self.placed, []
        self.frames_bits = self._base_frames.copy()
        for boxes in kept:
            self.add(boxes)


# ---------------------------------------------------------------------------------------------------------------
# swept boxes and their samples, in the path's local frame


@dataclass(frozen=True)
class _Footprint:
    """A path's swept boxes and their samples in its LOCAL frame (start at the origin, heading +x)."""

    boxes: np.ndarray     # (F, 5) x, y, heading, length, width (enlarged by the margin)
    points: np.ndarray    # (F, P, 2) samples every <= SAMPLE_M over each box
    coarse: np.ndarray    # (F, Q, 2) a few of them (centre line ends and middle)


def _window_index(ctx: PlacementContext, times_ns: np.ndarray) -> np.ndarray:
    """(F, W) path sample indices of each frame's sweep window [t_k - T, t_k]."""
    step_ns = STEP_S * 1e9
    end = np.round((ctx.frame_times_ns - times_ns[0]) / step_ns).astype(np.int64)
    w = int(math.ceil(ctx.window_s / STEP_S)) + 1
    return np.clip(end[:, None] - np.arange(w)[None, ::-1], 0, len(times_ns) - 1)


def swept_boxes(states: np.ndarray, window: np.ndarray, length: float, width: float) -> np.ndarray:
    """(F, 5) x, y, heading, length, width: per frame, the box along the heading at the window's last sample that
    holds the ``length`` x ``width`` box at every (x, y, heading) state of the window (``window``: (F, W))."""
    xyh = states[window]                                            # (F, W, 3)
    corners = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]], float) * [length / 2, width / 2]
    pts = _rigid(corners[None, None], xyh[..., 0:1], xyh[..., 1:2], xyh[..., 2:3]).reshape(len(xyh), -1, 2)
    h = xyh[:, -1, 2]
    c, s = np.cos(h)[:, None], np.sin(h)[:, None]
    u = c * pts[..., 0] + s * pts[..., 1]
    v = -s * pts[..., 0] + c * pts[..., 1]
    uc, vc = (u.max(1) + u.min(1)) / 2, (v.max(1) + v.min(1)) / 2
    cx, cy = c[:, 0] * uc - s[:, 0] * vc, s[:, 0] * uc + c[:, 0] * vc
    return np.column_stack([cx, cy, h, u.max(1) - u.min(1), v.max(1) - v.min(1)])


@functools.lru_cache(maxsize=8)
def _unit_grid(nu: int, nv: int) -> np.ndarray:
    u, v = np.meshgrid(np.linspace(-0.5, 0.5, nu), np.linspace(-0.5, 0.5, nv))
    return np.column_stack([u.ravel(), v.ravel()])


def _samples(boxes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(F, P, 2) samples every <= SAMPLE_M over each box, and (F, 3, 2) coarse ones (front, centre, back)."""
    nu = max(2, int(math.ceil(boxes[:, 3].max() / SAMPLE_M)) + 1)
    nv = max(2, int(math.ceil(boxes[:, 4].max() / SAMPLE_M)) + 1)
    unit = _unit_grid(nu, nv)
    local = unit[None] * boxes[:, None, 3:5]
    pts = _rigid(local, boxes[:, 0:1], boxes[:, 1:2], boxes[:, 2:3])
    line = np.array([[-0.5, 0.0], [0.0, 0.0], [0.5, 0.0]])[None] * boxes[:, None, 3:5]
    return pts, _rigid(line, boxes[:, 0:1], boxes[:, 1:2], boxes[:, 2:3])


def _footprint(states: np.ndarray, window: np.ndarray, size, margin: float) -> _Footprint:
    boxes = swept_boxes(states, window, size[0] + 2 * margin, size[1] + 2 * margin)
    points, coarse = _samples(boxes)
    return _Footprint(boxes, points, coarse)


def _world_boxes(fp: _Footprint, x0: float, y0: float, heading: float, height: float) -> np.ndarray:
    """(F, 7) world boxes (z 0) of a footprint placed at (x0, y0, heading)."""
    out = np.zeros((len(fp.boxes), 7))
    out[:, 0:2] = _rigid(fp.boxes[:, 0:2], x0, y0, heading)
    out[:, 3] = (fp.boxes[:, 2] + heading + np.pi) % (2 * np.pi) - np.pi
    out[:, 4:6] = fp.boxes[:, 3:5]
    out[:, 6] = height
    return out


# ---------------------------------------------------------------------------------------------------------------
# the tests


def _lookup(mask: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    h, w = mask.shape[:2]
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    return inside & mask[np.where(inside, rows, 0), np.where(inside, cols, 0)]


def _frame_hits(ctx: PlacementContext, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """(..., F, P) -> (...,) any sample in a cell occupied at its own frame (real box, ego, inserted vehicle)."""
    h, w = ctx.frames_bits.shape[:2]
    inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
    f = np.arange(rows.shape[-2])[:, None]
    byte = ctx.frames_bits[np.where(inside, rows, 0), np.where(inside, cols, 0), f >> 3]
    return (inside & ((byte >> (f & 7)) & 1).astype(bool)).any(axis=(-1, -2))


def _raster_ok(ctx: PlacementContext, points: np.ndarray) -> np.ndarray:
    """(M, F, P, 2) world samples of M candidates -> (M,) passes the raster tests (static and per frame)."""
    g = ctx.ground
    rows = np.floor((points[..., 1] - g.origin[1]) / g.cell).astype(np.int64)
    cols = np.floor((points[..., 0] - g.origin[0]) / g.cell).astype(np.int64)
    m = len(points)
    flat_r, flat_c = rows.reshape(m, -1), cols.reshape(m, -1)
    ok = ~_lookup(g.blocked, flat_r, flat_c).any(axis=1)
    ok &= _lookup(g.ground, flat_r, flat_c).mean(axis=1) >= MIN_GROUND_FRACTION
    idx = np.flatnonzero(ok)
    if idx.size:
        ok[idx[_frame_hits(ctx, rows[idx], cols[idx])]] = False
    return ok


def _overlaps(boxes: np.ndarray, others: np.ndarray) -> bool:
    """Any (F, 7) box overlapping the (F, 7) other box of the same frame (bird's-eye view)?"""
    reach = np.hypot(boxes[:, 4], boxes[:, 5]) / 2 + np.hypot(others[:, 4], others[:, 5]) / 2
    close = np.flatnonzero(np.hypot(boxes[:, 0] - others[:, 0], boxes[:, 1] - others[:, 1]) < reach)
    if close.size == 0:
        return False
    flat_a, flat_b = boxes[close].copy(), others[close].copy()  # same z and height: 3D IoU = bird's-eye IoU
    flat_a[:, 2] = flat_b[:, 2] = 0.0
    flat_a[:, 6] = flat_b[:, 6] = 1.0
    return bool((iou_3d_batch(flat_a, flat_b) > 1e-9).any())


def _on_seam(ctx: PlacementContext, boxes: np.ndarray) -> bool:
    """Does any (F, 7) box cross the scan's seam ray (the sensor would see its two ends 0.1 s apart)?"""
    if ctx.seam_deg is None:
        return False
    c, s = np.cos(boxes[:, 3])[:, None], np.sin(boxes[:, 3])[:, None]
    u = np.array([1, 1, -1, -1])[None] * boxes[:, 4:5] / 2
    v = np.array([1, -1, -1, 1])[None] * boxes[:, 5:6] / 2
    dx = boxes[:, 0:1] + c * u - s * v - ctx.sensor_xyh[:, 0:1]
    dy = boxes[:, 1:2] + s * u + c * v - ctx.sensor_xyh[:, 1:2]
    seam = ctx.sensor_xyh[:, 2:3] + math.radians(ctx.seam_deg)
    a = (np.arctan2(dy, dx) - seam + np.pi) % (2 * np.pi) - np.pi
    return bool(((a.min(axis=1) < 0.0) & (a.max(axis=1) > 0.0) & (np.ptp(a, axis=1) < np.pi)).any())


def _exact_ok(ctx: PlacementContext, boxes: np.ndarray) -> bool:
    """The exact test of (F, 7) swept world boxes: sensor distance, scan seam, ego, real boxes, placed vehicles."""
    d = np.hypot(boxes[:, 0] - ctx.sensor_xyh[:, 0], boxes[:, 1] - ctx.sensor_xyh[:, 1])
    if d.min() < ctx.min_sensor_distance or _on_seam(ctx, boxes):
        return False
    if _overlaps(boxes, ctx._ego):
        return False
    if len(ctx._real) and _overlaps(boxes[ctx._real_frame], ctx._real):
        return False
    return not any(_overlaps(boxes, other) for other in ctx.placed)


def _starts(ctx: PlacementContext, fp: _Footprint, heading: float, band: tuple[float, float],
            rng: np.random.Generator) -> np.ndarray:
    """Start cells (indices into ``ctx._start_rc``) whose placed footprint passes the static raster tests and
    whose frame-0 box centre is in the range ``band`` from the sensor; random order."""
    g = ctx.ground
    centre0 = _rigid(fp.boxes[0, 0:2], 0.0, 0.0, heading)
    r = np.hypot(*(ctx._start_xy + centre0 - ctx.sensor_xyh[0, :2]).T)
    cand = np.flatnonzero((r >= band[0]) & (r < band[1]))
    if cand.size > MAX_STARTS:
        cand = rng.choice(cand, MAX_STARTS, replace=False)
    else:
        cand = rng.permutation(cand)
    if cand.size == 0:
        return cand

    def offsets(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Unique (row, col) offsets of samples placed at a start cell's centre, and their multiplicity."""
        p = _rigid(points.reshape(-1, 2), 0.0, 0.0, heading)
        off = np.floor(0.5 + p / g.cell).astype(np.int64)
        lo = off.min(axis=0)
        span = off.max(axis=0) - lo + 1
        counts = np.bincount((off[:, 1] - lo[1]) * span[0] + off[:, 0] - lo[0], minlength=int(span.prod()))
        at = np.flatnonzero(counts)
        return at // span[0] + lo[1], at % span[0] + lo[0], counts[at]

    rc = ctx._start_rc[cand]
    dr, dc, _ = offsets(fp.coarse)
    rows, cols = rc[:, :1] + dr, rc[:, 1:] + dc  # coarse: no never-free cell, mostly ground
    cand = cand[~_lookup(ctx._bad, rows, cols).any(axis=1) & (_lookup(g.ground, rows, cols).mean(axis=1) >= 0.75)]
    if cand.size == 0:
        return cand
    dr, dc, weight = offsets(fp.points)
    keep = []
    chunk = max(1, 2_000_000 // len(dr))
    for i in range(0, len(cand), chunk):
        part = cand[i:i + chunk]
        rc = ctx._start_rc[part]
        rows, cols = rc[:, :1] + dr, rc[:, 1:] + dc
        ok = ~_lookup(g.blocked, rows, cols).any(axis=1)
        ok &= (_lookup(g.ground, rows, cols) * weight).sum(axis=1) >= MIN_GROUND_FRACTION * weight.sum()
        keep.append(part[ok])
    return np.concatenate(keep)


def _path(ctx: PlacementContext, spec: MotionSpec) -> tuple[MotionPath, np.ndarray]:
    path = integrate_motion(spec, ctx.duration_s(), STEP_S)
    times_ns = ctx.path_start_ns() + np.round(path.times_s * 1e9).astype(np.int64)
    return path, times_ns


def ground_profile(footprint_z: np.ndarray, step_m: np.ndarray, window: int = 5) -> np.ndarray:
    """A vehicle's ground height per frame from its footprint's median ground height per frame.

    A running median over ``window`` frames (centred: it narrows towards the ends, so a steady slope is kept and
    an end frame gets no extra votes), then no step steeper than the road grade (MAX_GRADE of the ``step_m``
    metres moved between frames, plus 2 cm), walking out both ways from the frame whose height is the path's
    median (a loop over frames, not points)."""
    n = len(footprint_z)
    half = np.minimum(np.minimum(np.arange(n), np.arange(n)[::-1]), window // 2)
    z = np.array([np.median(footprint_z[k - h:k + h + 1]) for k, h in enumerate(half)])
    bound = MAX_GRADE * np.asarray(step_m, dtype=np.float64) + 0.02
    anchor = int(np.argmin(np.abs(z - np.median(z))))
    for k in range(anchor + 1, n):
        z[k] = np.clip(z[k], z[k - 1] - bound[k - 1], z[k - 1] + bound[k - 1])
    for k in range(anchor - 1, -1, -1):
        z[k] = np.clip(z[k], z[k + 1] - bound[k], z[k + 1] + bound[k])
    return z


def _finish(ctx: PlacementContext, vid: str, bank_id: str, label: str, size, spec: MotionSpec, world: np.ndarray,
            times_ns: np.ndarray, boxes: np.ndarray, listed: bool, occluder_of: str | None,
            span: tuple[int, int] | None = None) -> InsertedVehicle:
    t = ctx.frame_times_ns.astype(np.float64)
    at_frames = np.column_stack([np.interp(t, times_ns.astype(np.float64), world[:, i]) for i in range(2)] +
                                [np.interp(t, times_ns.astype(np.float64), np.unwrap(world[:, 2]))])
    unit = _unit_grid(max(2, int(math.ceil(size[0] / SAMPLE_M)) + 1), max(2, int(math.ceil(size[1] / SAMPLE_M)) + 1))
    foot = _rigid(unit[None] * [size[0], size[1]], at_frames[:, 0:1], at_frames[:, 1:2], at_frames[:, 2:3])
    ground = np.median(ctx.ground.z(foot.reshape(-1, 2)).reshape(foot.shape[:2]), axis=1)
    ground = ground_profile(ground, np.hypot(*np.diff(at_frames[:, :2], axis=0).T))
    z = np.interp(times_ns.astype(np.float64), t, ground) + size[2] / 2
    states = np.column_stack([world[:, 0], world[:, 1], z, world[:, 2]])
    ctx.add(boxes)
    return InsertedVehicle(vid, bank_id, label, tuple(float(s) for s in size), spec, times_ns, states, listed,
                           occluder_of, span)


def _headings(ctx: PlacementContext, rng: np.random.Generator, profile: str = "") -> list[float]:
    """Along, against and across the ego's direction of travel, plus the profile's own (``oblique``: the
    diagonals); random order, a little noise."""
    sh = float(ctx.sensor_xyh[0, 2])
    turns = [0.0, math.pi, math.pi / 2, -math.pi / 2] + [h - sh for h in extra_headings(profile, sh)]
    return [sh + float(turn) + float(rng.normal(0.0, 0.01)) for turn in rng.permutation(turns)]


def _frame_states(ctx: PlacementContext, path: MotionPath, times_ns: np.ndarray) -> np.ndarray:
    """(F, 3) local x, y, heading of a path at the frame times."""
    t = (ctx.frame_times_ns - times_ns[0]) * 1e-9
    return np.column_stack([np.interp(t, path.times_s, v) for v in (path.x, path.y, path.heading)])


def _geometry_filter(ctx: PlacementContext, profile: str, local: np.ndarray, heading: float,
                     starts: np.ndarray) -> np.ndarray:
    """The start cells whose path has the profile's geometry relative to the sensor (hard_profiles.py)."""
    if starts.size == 0:
        return starts
    xy = ctx._start_xy[starts]
    positions = _rigid(local[None, :, 0:2], xy[:, 0:1], xy[:, 1:2], heading)
    headings = np.broadcast_to(local[None, :, 2] + heading, positions.shape[:2])
    times_s = (ctx.frame_times_ns - ctx.frame_times_ns[0]) * 1e-9
    return starts[geometry_ok(profile, positions, headings, ctx.sensor_xyh, times_s)]


def place_vehicle(ctx: PlacementContext, rng: np.random.Generator, vid: str, bank_id: str, label: str,
                  size: tuple[float, float, float], profile: str, band: tuple[float, float] | None = None,
                  draws: int = 2) -> InsertedVehicle | None:
    """Place one listed vehicle with a motion of ``profile`` whose frame-0 range is in ``band`` (default: the
    context's range); None if no place after ``draws`` motions, each tried at the speeds of
    :data:`SPEED_SCALES` (the realised motion is reported per tracklet: ``motion.speed0``)."""
    band = band or ctx.range_m
    for _ in range(draws):
        drawn = sample_motion(profile, rng, ctx.duration_s())
        for scale in SPEED_SCALES:
            spec = drawn if scale == 1.0 else replace(drawn, speed0=drawn.speed0 * scale)
            path, times_ns = _path(ctx, spec)
            states = path.states()
            window = _window_index(ctx, times_ns)
            fp = _footprint(states, window, size, ctx.margin)
            local = _frame_states(ctx, path, times_ns)
            for heading in _headings(ctx, rng, profile):
                starts = _geometry_filter(ctx, profile, local, heading, _starts(ctx, fp, heading, band, rng))
                if starts.size == 0:
                    continue
                for chunk in np.array_split(starts, max(1, len(starts) // 64)):
                    xy = ctx._start_xy[chunk]
                    pts = _rigid(fp.points[None], xy[:, None, None, 0], xy[:, None, None, 1], heading)
                    for i in chunk[_raster_ok(ctx, pts)]:
                        x0, y0 = ctx._start_xy[i]
                        boxes = _world_boxes(fp, x0, y0, heading, size[2])
                        if _exact_ok(ctx, boxes):
                            world = place_path(path, x0, y0, heading)
                            return _finish(ctx, vid, bank_id, label, size, spec, world, times_ns, boxes, True, None)
    return None


def place_occluder(ctx: PlacementContext, rng: np.random.Generator, target: InsertedVehicle, vid: str, bank_id: str,
                   label: str, size: tuple[float, float, float]) -> InsertedVehicle | None:
    """An unlisted vehicle on the sensor-target line of sight at the middle frame, at constant speed.

    All crossing points every 0.5 m over 25-80 % of the sight line and 6 headings (the target's own either way,
    the sensor's either way, across the sight line either way) are tested at once (raster), then in random order
    (exact), for 3 driving speeds in random order; where none fits (a busy street leaves little free lane for a
    20 m swept path), a parked occluder (speed 0) on the sight line is tried last."""
    mid = len(ctx.frame_times_ns) // 2
    t_mid = int(ctx.frame_times_ns[mid])
    at_mid = target.states_at(t_mid)
    p = at_mid[:2]
    s = ctx.sensor_xyh[mid, :2]
    sight = math.atan2(p[1] - s[1], p[0] - s[0])
    road = float(ctx.sensor_xyh[mid, 2])
    fractions = np.arange(0.25, 0.8, SAMPLE_M / max(float(np.hypot(*(p - s))), 1.0))
    own = float(at_mid[3])
    headings = [own, own + math.pi, road, road + math.pi, sight + math.pi / 2, sight - math.pi / 2]
    for speed in list(rng.permutation([1.5, 3.0, 5.0])) + [0.0]:
        jitter = float(rng.uniform(-0.5, 0.5)) if speed > 0 else 0.0
        spec = MotionSpec("constant_speed", float(speed) + jitter)
        path, times_ns = _path(ctx, spec)
        fp = _footprint(path.states(), _window_index(ctx, times_ns), size, ctx.margin)
        back = spec.speed0 * (t_mid - times_ns[0]) * 1e-9  # where to start so that it is at q at t_mid
        q = s + fractions[:, None] * (p - s)
        cand = np.array([(qx - back * math.cos(h), qy - back * math.sin(h), h) for h in headings for qx, qy in q])
        cand = cand[rng.permutation(len(cand))]
        for chunk in np.array_split(cand, max(1, len(cand) // 64)):
            pts = _rigid(fp.points[None], chunk[:, None, None, 0], chunk[:, None, None, 1], chunk[:, None, None, 2])
            for x0, y0, heading in chunk[_raster_ok(ctx, pts)]:
                boxes = _world_boxes(fp, x0, y0, heading, size[2])
                if _exact_ok(ctx, boxes):
                    world = place_path(path, x0, y0, heading)
                    return _finish(ctx, vid, bank_id, label, size, spec, world, times_ns, boxes, False, target.id)
    return None
