"""Bidirectional refinement: once a track holds its object densely after frames it lost, track BACKWARDS from
there through the lost frames and fuse the two passes (CTRL's "once detected, never lost").

The forward (online) pass loses a far, sparse or hidden object and keeps a box that does not follow it (the
start box held, or the motion model's prediction); once it is re-locked (``reacquired``) or dense, the object
and its shape are known there, and the same tracker run on the frames in reverse order (time mirrored about the
pass's first frame) follows it back into the frames the forward pass lost, with the dense frames' shape and
motion to hold it:

1. a frame is **lost** when the forward estimate had no support (flags ``prior_only``, ``coasting``,
   ``waiting``, ``no_sweep``, or fewer than ``backward_lost_points`` object points) and **weak** when it is
   lost or has fewer than ``backward_dense_points`` points; an **anchor** is a frame that is not weak (or is
   ``reacquired`` and not lost) after a run of weak frames that holds at least ``backward_lost_frames`` (>= 1)
   lost ones;
2. for an anchor k whose weak run starts after frame s (frame 0 — the given start box — or the last dense frame
   before the run), :class:`~tracker.sotracker.Tracker` starts with the forward box at frame m, its motion prior
   seeded with the forward motion there reversed, and steps through frames m - 1, ..., s. Offline, m is the
   frame with the most points among k and the frames after it that the forward pass held (at most
   ``backward_reach`` on), so the pass enters the run with the densest shape and an established motion; with a
   fixed lag, m = k + ``backward_lag_lead`` (the newest frame when the forward pass has held it that long). The
   tracker sees the vehicle driving forwards in mirrored time with its box turned by pi (its frame-1 search and
   motion model look ahead along the heading); the headings are turned back;
3. fusion: the frames of the run that the forward pass held keep their forward states; each stretch of lost
   frames takes the backward states, moved by the mismatch between the two passes at the held frames on
   either side, blended linearly across the stretch, so the fused track meets the forward one at both ends
   (where the backward pass had no points either, a two-ended interpolation); with ``backward_arrival`` > 0 a
   stretch the forward pass coasted to where it found the object again keeps the forward coast
   (:func:`coasts_that_arrive`);
4. the refinement that follows (offline: :func:`~tracker.offline.refine_offline`; fixed lag:
   :class:`~tracker.fixed_lag.FixedLagSmoother`) takes the fused states as its data (its initial states and
   the anchors of its weak pull), and gathers each frame's points around the fused box.

With ``lag`` N (fixed lag) it is causal: an anchor is recognised from the frames so far, and the pass revises
only the lost frames of the run still in the window (when the frame before them is final and lost, the stretch
takes the mismatch at the anchor throughout). Deterministic for a given ``config.seed``. De-skew is not applied
in the backward pass (mirrored time would de-skew with the wrong sign).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .config import TrackerConfig
from .frames import FrameSource, LidarFrame
from .geometry import Box, State, wrap_angle
from .sotracker import FrameEstimate, Tracker, TrackResult

__all__ = ["AnchorDetector", "anchors", "is_lost", "coasts_that_arrive", "backward_run", "backward_states",
           "fuse_backward", "fused_result",
           "refine_bidirectional", "reversed_motion"]

_LOST_FLAGS = frozenset({"prior_only", "coasting", "waiting", "no_sweep"})


def is_lost(estimate: FrameEstimate, lost_points: int) -> bool:
    """The forward estimate had no support (flagged prior_only, coasting, waiting, no_sweep, or too few points)."""
    return bool(_LOST_FLAGS.intersection(estimate.flags)) or estimate.num_points < lost_points


class AnchorDetector:
    """Recognises anchors as the estimates arrive (causal): ``add`` returns (s, k) when estimate k is an anchor
    (s: the index before its weak run), else None."""

    def __init__(self, config: TrackerConfig) -> None:
        self.refinement = config.refinement
        self.count = 0
        self.run_start, self.run_lost = 1, 0  # the current weak run: its first index, how many lost frames it holds

    def add(self, estimate: FrameEstimate) -> tuple[int, int] | None:
        k, r = self.count, self.refinement
        self.count += 1
        if k == 0:
            return None
        lost = is_lost(estimate, r.backward_lost_points)
        dense = estimate.num_points >= r.backward_dense_points
        strong = not lost and (dense or "reacquired" in estimate.flags)
        out = (self.run_start - 1, k) if strong and self.run_lost >= max(1, r.backward_lost_frames) else None
        if strong and dense:
            self.run_start, self.run_lost = k + 1, 0
        elif not strong:
            self.run_lost += int(lost)
        return out


def anchors(estimates: list[FrameEstimate], config: TrackerConfig) -> list[tuple[int, int]]:
    """(s, k) pairs, in order: anchor k (index into ``estimates``) and the index s before its weak run."""
    detector = AnchorDetector(config)
    return [pair for pair in (detector.add(e) for e in estimates) if pair is not None]


def _mirrored(frame: LidarFrame, about_ns: int) -> LidarFrame:
    """The frame with its time mirrored about ``about_ns`` (earlier frames come later), no per-point times."""
    return dataclasses.replace(frame, timestamp_ns=2 * about_ns - int(frame.timestamp_ns), point_time_offset_ns=None)


def backward_states(frames: list[LidarFrame], box: Box, config: TrackerConfig,
                    motion: np.ndarray | None) -> list[FrameEstimate]:
    """Track backwards: ``frames`` in reverse time order (the anchor frame first), from ``box`` at the first;
    ``motion``: the per-frame motion (world) to seed the prior with (the forward motion reversed), or None.
    Returns the estimates of frames[1:], in the order given. In reversed time the vehicle drives backwards; the
    tracker sees it driving forwards with its box turned by pi (the same box: the tracker's frame-1 search and
    motion model look ahead along the heading), and the headings are turned back."""
    tracker = Tracker(dataclasses.replace(config, deskew=False))
    about = int(frames[0].timestamp_ns)
    tracker.start(_mirrored(frames[0], about), _turned(box), None, motion)
    out = []
    for f in frames[1:]:
        est = tracker.step(_mirrored(f, about))
        turned = _turned(est.box)
        out.append(dataclasses.replace(est, box=turned, state=State.from_array(turned.to_array()[:4])))
    return out


def _turned(box: Box) -> Box:
    """The same box with its heading turned by pi."""
    return dataclasses.replace(box, heading=float(wrap_angle(box.heading + np.pi)))


def reversed_motion(earlier: FrameEstimate | None, later: FrameEstimate | None) -> np.ndarray | None:
    """The forward per-frame motion between two consecutive estimates, reversed (None: one is missing or had no
    support)."""
    if earlier is None or later is None or any(_LOST_FLAGS.intersection(e.flags) for e in (earlier, later)):
        return None
    out = earlier.state.to_array() - later.state.to_array()
    out[3] = wrap_angle(out[3])
    return out


def fuse_backward(forward: np.ndarray, backward: np.ndarray, lost: np.ndarray) -> np.ndarray:
    """Fused states (rows: frames s..k in time order; row 0 the run's start s, the last the anchor k) of the
    forward states ``forward`` and the backward pass's ``backward``: rows where the forward pass held the object
    (``lost`` False) keep the forward state; each stretch of lost rows takes the backward states, moved by the
    mismatch (forward - backward) at the held rows on either side of it, blended linearly across the stretch, so
    the fused track meets the forward one at both ends (where the backward pass coasted, it is a two-ended
    interpolation). A stretch that begins at row 0 (row 0 lost: a final frame of a window) takes the mismatch of
    its other end throughout."""
    out = forward.copy()
    lost = np.asarray(lost, dtype=bool)
    mismatch = forward - backward
    mismatch[:, 3] = wrap_angle(mismatch[:, 3])
    for a, j in _stretches(lost):
        before = mismatch[a - 1] if a > 0 else None
        after = mismatch[j] if j < len(out) else None
        before = after if before is None else before
        after = before if after is None else after
        if before is None or after is None:
            break  # no held row at all: nothing to tie the backward pass to
        t = (np.arange(a, j) - (a - 1)) / (j - (a - 1))  # 0 at the held row before, 1 at the one after
        out[a:j] = backward[a:j] + (1.0 - t)[:, None] * before[None, :] + t[:, None] * after[None, :]
    out[:, 3] = wrap_angle(out[:, 3])
    return out


def _stretches(lost: np.ndarray) -> list[tuple[int, int]]:
    """The runs of True rows of ``lost``: (first row, row after the last), in order."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(lost, dtype=np.int8), [0]])))
    return [(int(a), int(j)) for a, j in zip(edges[::2], edges[1::2], strict=True)]


def coasts_that_arrive(forward: np.ndarray, lost: np.ndarray, arrival: float) -> np.ndarray:
    """The lost rows whose stretch the forward pass coasted to where it found the object again: its last step
    through the stretch, carried one frame on, lands within ``arrival`` (m, horizontally) of its state at the held
    row after the stretch. Such a coast needs no fill (the backward pass's coast is no better evidence); a stretch
    whose coast arrives farther (a car that turned or changed speed while unseen) or that no held row follows does
    not arrive."""
    out = np.zeros(len(lost), dtype=bool)
    for a, j in _stretches(lost):
        if j < len(lost) and j >= 2:
            landed = 2.0 * forward[j - 1, :2] - forward[j - 2, :2]
            out[a:j] = float(np.hypot(*(forward[j, :2] - landed))) <= arrival
    return out


def backward_run(frames: list[LidarFrame], start: FrameEstimate, motion: np.ndarray | None,
                 forward: list[FrameEstimate], config: TrackerConfig, size: np.ndarray,
                 start_lost: bool = False) -> list[FrameEstimate]:
    """Fused estimates of a weak run. ``forward``: the current estimates of s .. k (time order, the anchor k
    last); ``frames``: the frames from the backward pass's ``start`` (the anchor, or a frame after it) backwards
    down to s. Returns the estimates of s + 1 .. k - 1: the forward ones where the forward pass held the object,
    the fused backward ones (flag ``backward``) where it lost it. ``start_lost``: s itself is lost (a final frame
    of a window: no mismatch there)."""
    n = len(forward)
    forward_states = np.array([e.state.to_array() for e in forward])
    lost = np.array([is_lost(e, config.refinement.backward_lost_points) for e in forward])
    lost[0], lost[-1] = start_lost, False
    if config.refinement.backward_arrival > 0:
        lost &= ~coasts_that_arrive(forward_states, lost, config.refinement.backward_arrival)
    if not lost.any():
        return forward[1:n - 1]   # nothing to fill: no backward pass
    back = backward_states(frames, start.box, config, motion)[::-1]  # time order: s .. (pass start) - 1
    states = [b.state.to_array() for b in back] + [start.state.to_array()]
    fused = fuse_backward(forward_states, np.array(states[:n]), lost)
    return [_replaced(forward[j], fused[j], size, back[j]) if lost[j] else forward[j] for j in range(1, n - 1)]


def _replaced(est: FrameEstimate, state: np.ndarray, size: np.ndarray, back: FrameEstimate) -> FrameEstimate:
    box = Box(float(state[0]), float(state[1]), float(state[2]), float(wrap_angle(state[3])),
              float(size[0]), float(size[1]), float(size[2]))
    flags = tuple(dict.fromkeys(list(est.flags) + ["backward"]))
    return dataclasses.replace(est, state=State.from_array(box.to_array()[:4]), box=box, num_points=back.num_points,
                               points=back.points, flags=flags)


def _start_after(estimates: list[FrameEstimate], k: int, lost_points: int, reach: int) -> int:
    """The backward pass's start for anchor k (offline): the frame with the most points among k and the frames
    after it that the forward pass held (up to ``reach`` frames on), so the pass has the densest shape and an
    established motion when it enters the run."""
    end = k + 1
    while end < min(len(estimates), k + reach + 1) and not is_lost(estimates[end], lost_points):
        end += 1
    return k + int(np.argmax([e.num_points for e in estimates[k:end]]))


def fused_result(source: FrameSource, result: TrackResult, config: TrackerConfig | None = None) -> TrackResult:
    """The online ``result`` with the weak run before each anchor replaced by the fused backward pass over the
    whole run (its start s reliable: frame 0 or a dense frame), the pass started from the densest frame the
    forward pass held from the anchor on. Of anchors that share a run, the last runs."""
    config = config or result.config
    r = config.refinement
    estimates = list(result.estimates)
    size = np.asarray(result.size, dtype=np.float64)
    pairs = anchors(result.estimates, config)
    for i, (s, k) in enumerate(pairs):
        if i + 1 < len(pairs) and pairs[i + 1][0] == s:
            continue  # a later anchor covers the same run
        m = _start_after(estimates, k, r.backward_lost_points, r.backward_reach)
        frames = [source.lidar_frame(estimates[j].frame) for j in range(m, s - 1, -1)]
        after = estimates[m + 1] if m + 1 < len(estimates) else None
        motion = reversed_motion(estimates[m], after) if after is not None else reversed_motion(estimates[m - 1],
                                                                                                 estimates[m])
        estimates[s + 1:k] = backward_run(frames, estimates[m], motion, estimates[s:k + 1], config, size)
    return dataclasses.replace(result, estimates=estimates)


def refine_bidirectional(source: FrameSource, result: TrackResult, config: TrackerConfig | None = None,
                         lag: int | None = None) -> TrackResult:
    """The offline (``lag`` None) or fixed-lag (``lag`` N) refinement of the online ``result`` with backward
    passes from its anchors (see the module docstring), whatever ``config.refinement.backward`` says."""
    config = config or result.config
    config = config.updated({"refinement.backward": "both"})
    if lag is None:
        from .offline import refine_offline

        return refine_offline(source, result, config)
    from .fixed_lag import refine_fixed_lag

    return refine_fixed_lag(source, result, lag, config)
