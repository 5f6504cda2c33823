"""Re-acquisition strategies (``reacquire.mode``): what a track does when its points no longer support it.

"none" (:class:`NoReacquire`): nothing; a frame without data keeps the prediction
(``registration.data_free_frames``).
"clusters" (:class:`ClusterReacquire`): support is lost after ``lost_frames`` frames with fewer than
``min_points`` object points in the box (or frames that continued on the prior); the track keeps predicting on
its motion model (flag ``coasting``) while the sweep's non-ground points in a region around the prediction,
growing with the time since support was lost, are clustered (tracker/reacquire.py) and the clusters of the
box's size are kept as candidates. The search goes on when points come back (a box that coasted off the object
follows its points at an offset) until the track holds its object again, a candidate moves it, or
``recover_frames`` frames in a row had support. The track holds when a confirmed candidate is within
``hold_distance`` of the box, or (``hold_frames`` > 0; 2 in full) when on ``hold_frames`` frames in a row the frame
had support and the box held a candidate (``hold_share`` of its points, in the box scaled by
``search.crop_scale``; at least ``min_points``; its extent at least the box's length and width - 2 x
``hold_distance``, so that any box over it is within ``hold_distance`` of its centred placement; the box no
further from that placement than half the unseen length + ``cell``) whose extent changed at most ``size_gate``
from one frame to the next: the object re-appeared where the motion model put the box and the normal step follows
it (a partial view's centred candidate may be more than ``hold_distance`` off, and a single frame pair's velocity
of it is not reliable). A start box with fewer than
``start_points`` points is a lost start: its box is held and the region runs along its heading, ``max_speed`` x
the time since the start ahead and a third of that behind. With ``start_fill_frames`` > 0 a lost start whose held
box itself holds ``start_points`` non-ground points on that many frames in a row starts there (the vehicle is where
the start box said and now shows enough points; a slow or stopping one never gives a candidate moving at
``min_speed``). The track re-locks (restarts at the candidate, flag ``reacquired``) only on a candidate matched to
one of the previous frame's candidates in position, size and motion (with ``relock_points`` > 0, off in full, each
of the two holding at least that many points where the candidate would move a lost track, i.e. is not within
``hold_distance`` of its box: a 1-2-point blob's frame pair reads metres per second of noise; a lost start's
candidates need no more than ``cluster_points``):
for a lost track a velocity within
``velocity_gate`` of the predicted one and a place on the object's path (not more than ``reach`` behind the box
of the last supported frame along its heading, the way it moves: a hidden vehicle does not end up behind where
it was lost, something it passed is there; not more than ``reach`` + ``lateral_growth`` x the time since across
the predicted path: a vehicle a lane over is another one; with ``centre_in_reach`` (off in full) its centre within
``reach`` + ``growth`` x the time since of the predicted box centre; with ``whole_candidates`` (off in full) not
a cluster the region cuts; with ``drift_gate`` > 0 (off in full) its centre within ``reach`` + (``drift_gate`` x
|the velocity of its uncut end - the predicted one| + ``lateral_growth``) x the time since of the predicted box
centre, or a box length: a candidate far from the prediction must move unlike it; with ``static_share`` > 0 (0.5 in
full) fewer than that share of its points within ``static_radius`` of the non-ground points of the sweep where the
support was lost, outside the box grown by ``reach``: not something that was already there, e.g. a parked car
the growing region reaches); for a lost start a velocity
along the start box's heading line (within ``max_angle``, between ``min_speed`` and ``max_speed``) that agrees
with the distance travelled from the start box since the start.
"""

from __future__ import annotations

import numpy as np

from ..config import ReacquireConfig
from ..geometry import Box
from ..reacquire import Candidate, EarlierSweep, search_region

__all__ = ["Reacquire", "NoReacquire", "ClusterReacquire", "Relock", "choose_reacquire"]


class Relock:
    """Where a confirmed candidate puts the track: ``centre`` (xy, world) and the velocity to seed the motion
    model with (m/s, xy, world)."""

    def __init__(self, centre: np.ndarray, velocity: np.ndarray) -> None:
        self.centre = centre
        self.velocity = velocity


class Reacquire:
    """The interface (and the "none" behaviour). ``earlier``: the non-ground points of the sweep where the
    support was lost, set by the tracker when ``reacquire.static_share`` > 0 (None: not taken yet)."""

    earlier: EarlierSweep | None = None

    def reset(self, time_s: float, centre: np.ndarray) -> None:
        """A track (re)starts at ``time_s`` with its box at ``centre`` (xy, world)."""

    def lost_start(self, points: int) -> bool:
        """Whether a start box holding ``points`` object points is a lost start."""
        return False

    def start_filled(self, points: int) -> bool:
        """Whether a lost start's held box, holding ``points`` non-ground points this frame, has held enough on
        enough frames in a row to start there (``start_fill_frames``)."""
        return False

    def holds(self, points: int, coasted: bool, time_s: float, centre: np.ndarray) -> bool:
        """Whether the frame's support holds the track (``coasted``: the frame continued on the prior; ``centre``:
        the frame's box centre, xy)."""
        return True

    def region(self, box: Box, time_s: float, start: Box | None) -> Box:
        """The region to search: around the predicted ``box``, or along the lost ``start`` box's heading."""
        raise NotImplementedError

    def holds_object(self, candidates: list[Candidate], box: Box, supported: bool) -> bool:
        """Whether a lost track holds its object again at ``box`` (``supported``: the frame's estimate has
        support)."""
        return False

    def confirm(self, candidates: list[Candidate], box: Box, velocity: np.ndarray | None,
                start: Box | None) -> Relock | None:
        """A candidate consistent with one of the previous frame's, or None (the candidates are kept)."""
        raise NotImplementedError


class NoReacquire(Reacquire):
    pass


class ClusterReacquire(Reacquire):
    def __init__(self, config: ReacquireConfig) -> None:
        self.c = config
        self.reset(0.0, np.zeros(2))

    def reset(self, time_s: float, centre: np.ndarray) -> None:
        self.earlier = None                          # the support is held: no sweep of its loss yet
        self._held_s, self._held_at = time_s, np.asarray(centre, dtype=np.float64)[:2].copy()
        self._misses = 0
        self._lost = False
        self._supported = 0
        self._previous: list[Candidate] = []
        self._held: list[list[Candidate]] = []      # per frame in a row: the candidates the supported box held
        self._filled = 0                             # a lost start: frames in a row its held box held start_points

    def lost_start(self, points: int) -> bool:
        return points < self.c.start_points

    def start_filled(self, points: int) -> bool:
        self._filled = self._filled + 1 if points >= self.c.start_points else 0
        return 0 < self.c.start_fill_frames <= self._filled

    def holds(self, points: int, coasted: bool, time_s: float, centre: np.ndarray) -> bool:
        supported = points >= self.c.min_points and not coasted
        if not self._lost:
            if supported:
                self._held_s, self._misses = time_s, 0
                self._held_at = np.asarray(centre, dtype=np.float64)[:2].copy()
                return True
            self._misses += 1
            self._lost = self._misses >= self.c.lost_frames
            return not self._lost
        # lost: the search goes on while the points come back (the box may follow them off the object's centre)
        # until a candidate confirms the track or ``recover_frames`` supported frames in a row
        self._supported = self._supported + 1 if supported else 0
        if self._supported >= self.c.recover_frames:
            self.reset(time_s, centre)
            return True
        return False

    def region(self, box: Box, time_s: float, start: Box | None) -> Box:
        c = self.c
        lost_s = max(time_s - self._held_s, 0.0)
        if start is not None:
            ahead = min(c.max_speed * lost_s, c.max_reach)
            return search_region(start, ahead, ahead / 3.0, c.reach, c.rise)
        reach = min(c.reach + c.growth * lost_s, c.max_reach)
        return search_region(box, reach, reach, reach, c.rise)

    def holds_object(self, candidates: list[Candidate], box: Box, supported: bool) -> bool:
        c = self.c
        # held: the candidate's points in the box, the box pinned by them to within ``hold_distance`` (a box slides
        # along a short cluster by the unseen length: a far car's nose in one end of a box that coasted off), and
        # the box no further from the cluster's centre than the unseen length allows (+ a grid cell: extents are
        # measured on it): a box off a nearly whole cluster is not held
        size = np.array([box.length, box.width])
        axis = np.array([np.cos(box.heading), np.sin(box.heading)])
        frame = np.array([axis, [-axis[1], axis[0]]])
        held = [k for k in candidates if supported and k.count >= c.min_points and k.held >= c.hold_share * k.count
                and np.all(k.extent >= size - 2.0 * c.hold_distance)
                and np.all(np.abs(frame @ (k.centre - box.center[:2])) <= 0.5 * (size - k.extent) + c.cell)]
        if not held:
            self._held = []
            return False
        if self._held and not any(np.all(np.abs(now.extent - before.extent) <= c.size_gate)
                                  for now in held for before in self._held[-1]):
            self._held = []
        self._held.append(held)
        return 0 < c.hold_frames <= len(self._held)

    def confirm(self, candidates: list[Candidate], box: Box, velocity: np.ndarray | None,
                start: Box | None) -> Relock | None:
        c = self.c
        previous, self._previous = self._previous, candidates
        best: tuple[float, Relock] | None = None
        for now in candidates:
            if now.cut and start is None and c.whole_candidates:
                continue
            # ``relock_points``: a candidate that moves a lost track (not one within ``hold_distance`` of its box,
            # which ends the search where the box is) holds at least that many points on both frames; a lost
            # start's does not (a far car coming into view shows 2-3-point fragments first)
            moves = start is None and float(np.linalg.norm(now.centre - box.center[:2])) >= c.hold_distance
            floor = c.relock_points if moves else 0
            if now.count < floor:
                continue
            # ``static_share``: a candidate that moves a lost track is not something that was already there when
            # the support was lost (a parked car the growing region reaches: at a slow car's speed it passes the
            # velocity gate, and ahead it is on the path)
            if moves and 0 < c.static_share <= now.before:
                continue
            for before in previous:
                dt = now.time_s - before.time_s
                if dt <= 0 or before.count < floor or np.any(np.abs(now.extent - before.extent) > c.size_gate):
                    continue
                v = (now.centre - before.centre) / dt
                relock = (self._from_start(now, v, start) if start is not None else
                          self._from_track(now, v, box, velocity, _own_velocity(now, before, dt)))
                if relock is None:
                    continue
                # a lost track: the candidate nearest the prediction; a lost start: the steadiest motion
                score = float(np.linalg.norm(now.centre - box.center[:2]) if start is None
                              else np.linalg.norm(v - relock.velocity))
                if best is None or score < best[0]:
                    best = (score, relock)
        return None if best is None else best[1]

    def _from_track(self, now: Candidate, v: np.ndarray, box: Box, velocity: np.ndarray | None,
                    own: np.ndarray) -> Relock | None:
        predicted = np.zeros(2) if velocity is None else velocity
        if np.linalg.norm(v - predicted) > self.c.velocity_gate:
            return None
        # the object's path since the loss: a hidden vehicle that keeps going does not end up behind where its
        # support was lost (along its heading, the way it moves; more than ``reach``): a candidate there is
        # something it passed (a parked car, the occluder that hid it)
        axis = np.array([np.cos(box.heading), np.sin(box.heading)])
        way = float(np.sign(predicted @ axis))
        if way != 0 and way * float((now.centre - self._held_at) @ axis) < -self.c.reach:
            return None
        # nor far across its predicted path: lanes change at a metre or two per second (a candidate a lane over is
        # a vehicle beside it, e.g. the one that hid it, driving alongside)
        lost_s = max(now.time_s - self._held_s, 0.0)
        across = abs(float((now.centre - box.center[:2]) @ np.array([-axis[1], axis[0]])))
        if across > self.c.reach + self.c.lateral_growth * lost_s:
            return None
        # nor further from the prediction than the object can have strayed from it since (``centre_in_reach``: the
        # region's own bound on the candidate's centre; a parked car at the region's edge reaches in with its points)
        if self.c.centre_in_reach and float(np.linalg.norm(now.centre - box.center[:2])) > min(
                self.c.reach + self.c.growth * lost_s, self.c.max_reach):
            return None
        # nor further from the prediction than its own motion explains (``drift_gate``): an object found d m from
        # where the motion model put it has moved unlike the model, by about d / (lost time) on average; a
        # candidate moving like the prediction but far from it is something else. The motion is that of the
        # cluster's own end (``own``: a parked car's part that the growing region cuts seems to move with the
        # region, its uncut end does not). Never less than a box length: the box may have slid that far off its
        # object along a partial view before the support was lost (then the object moves like the prediction)
        if self.c.drift_gate > 0 and float(np.linalg.norm(now.centre - box.center[:2])) > max(self.c.reach + (
                self.c.drift_gate * float(np.linalg.norm(own - predicted)) + self.c.lateral_growth) * lost_s,
                box.length):
            return None
        return Relock(now.centre, predicted.copy())

    def _from_start(self, now: Candidate, v: np.ndarray, start: Box) -> Relock | None:
        c = self.c
        axis = np.array([np.cos(start.heading), np.sin(start.heading)])
        speed = float(np.linalg.norm(v))
        if not c.min_speed <= speed <= c.max_speed:
            return None
        if abs(float(v @ axis)) < speed * np.cos(c.max_angle):   # not along the heading line (either way)
            return None
        travelled = float((now.centre - start.center[:2]) @ axis)
        elapsed = now.time_s - self._held_s
        if elapsed <= 0 or travelled * float(v @ axis) <= 0:   # it must have come from the start box
            return None
        mean = travelled / elapsed                          # the mean velocity along the heading since the start
        if not c.min_speed <= abs(mean) <= c.max_speed or abs(abs(mean) - speed) > c.velocity_gate:
            return None
        return Relock(now.centre, mean * axis)


def _own_velocity(now: Candidate, before: Candidate, dt: float) -> np.ndarray:
    """The velocity of a candidate's own end between two frames (its ``anchor``; the centre without one)."""
    if now.anchor is None or before.anchor is None:
        return (now.centre - before.centre) / dt
    return (now.anchor - before.anchor) / dt


def choose_reacquire(config: ReacquireConfig) -> Reacquire:
    return ClusterReacquire(config) if config.mode == "clusters" else NoReacquire()
