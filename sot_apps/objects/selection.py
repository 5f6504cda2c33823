"""Which annotated objects are vehicles, which move, and which are sparse: one rule for every app.

``info``, pipeline planning (objects from annotations), ``bank build --all``, ``flow --from-annotations
--moving-only`` and ``eval --all-moving`` all ask :data:`DEFAULT_SELECTION`, so they agree on a sequence.

**Vehicle** (:meth:`Selection.is_vehicle`): the label, lower-cased and split into words at spaces, ``-``,
``_``, ``.`` and ``/``, has a word starting with one of ``vehicle_words`` (car, truck, bus, van, vehicle,
pickup, trailer, tram, suv) and no word starting with one of ``two_wheeler_words`` (motorcycle, motorbike,
bicycle, cyclist, moped, scooter). Four-wheeled (and larger) road vehicles only: the tracker models a
rigid box with a vehicle's shape and motion; LiDAR-SOT evaluates vehicles only.

**Moving** (:meth:`Selection.motion`): the box centre gets at least ``min_displacement_m`` (1.0 m) away
from its first position in x, y at some annotated frame, or — for tracks only a few frames long — its
first-to-last displacement is at least ``min_short_displacement_m`` (0.3 m) at a mean speed of at least
``min_short_speed_mps`` (1 m/s). Why these values: annotation jitter of a still box is centimetres (PandaSet
parked boxes move 0.00 m), 1 m is a fifth of a car length, and on pandaset_002 moving vehicles travel
6-78 m, so the rule has wide margins either way. Dataset flags such as PandaSet's ``stationary`` are not used.

**Evaluable** (:meth:`Selection.evaluable`, LiDAR-SOT's criteria adapted to short sequences; used by
``eval --all-moving``; ``info`` prints the same statistic): the first contiguous annotated span has at least
``min_frames`` (10) frames, and the mean number of sweep points in the box over its first
``difficulty_frames`` (10) frames is at least ``min_mean_points`` (15; LiDAR-SOT asks for more than 20
points in each of the first 10 frames). A tracker cannot start on a box with a handful of points.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING
from typing import Sequence as Seq

if TYPE_CHECKING:   # numpy loads in the methods: `sot-apps --help` imports this module (info's help text)
    import numpy as np

__all__ = ["Selection", "TrackMotion", "DEFAULT_SELECTION", "annotated_span"]


@dataclass(frozen=True)
class TrackMotion:
    """How far an annotated track's box centre travels (metres, x-y) and whether that counts as moving."""

    moving: bool
    displacement_m: float       # first to last annotated frame
    max_displacement_m: float   # largest distance from the first centre


def annotated_span(frames: Seq[int]) -> tuple[int, int]:
    """First contiguous run of annotated frame indices: (start, end) inclusive."""
    frames = sorted(int(f) for f in frames)
    end = frames[0]
    for f in frames[1:]:
        if f != end + 1:
            break
        end = f
    return frames[0], end


def _words(label: str) -> list[str]:
    text = label.lower()
    for sep in "-_./":
        text = text.replace(sep, " ")
    return text.split()


@dataclass(frozen=True)
class Selection:
    """The selection rules as data (thresholds documented in the module docstring)."""

    vehicle_words: tuple[str, ...] = ("car", "truck", "bus", "van", "vehicle", "pickup", "trailer", "tram", "suv")
    two_wheeler_words: tuple[str, ...] = ("motorcycle", "motorbike", "bicycle", "cyclist", "moped", "scooter")
    min_displacement_m: float = 1.0
    min_short_displacement_m: float = 0.3
    min_short_speed_mps: float = 1.0
    min_frames: int = 10
    difficulty_frames: int = 10
    min_mean_points: float = 15.0

    def is_vehicle(self, label: str) -> bool:
        words = _words(label)
        if any(w.startswith(t) for w in words for t in self.two_wheeler_words):
            return False
        return any(w.startswith(v) for w in words for v in self.vehicle_words)

    def motion(self, centres_xy: np.ndarray, times_ns: np.ndarray) -> TrackMotion:
        """Motion of a track from its (T, 2) box centres and (T,) integer timestamps in ns."""
        import numpy as np

        centres = np.asarray(centres_xy, dtype=np.float64).reshape(-1, 2)
        distances = np.linalg.norm(centres - centres[0], axis=1)
        displacement = float(distances[-1])
        duration_s = (int(times_ns[-1]) - int(times_ns[0])) * 1e-9
        speed = displacement / duration_s if duration_s > 0 else 0.0
        moving = float(distances.max()) >= self.min_displacement_m or (
            displacement >= self.min_short_displacement_m and speed >= self.min_short_speed_mps)
        return TrackMotion(moving, displacement, float(distances.max()))

    def track_motion(self, track, timestamps_ns: np.ndarray) -> TrackMotion:
        """Motion of an :class:`~sot_apps.io.object_track.ObjectTrack` (frame timestamps of its sequence)."""
        import numpy as np

        return self.motion(track.boxes[:, :2], np.asarray(timestamps_ns)[track.frames])

    def is_moving_vehicle(self, track, timestamps_ns: np.ndarray) -> bool:
        return self.is_vehicle(track.label) and self.track_motion(track, timestamps_ns).moving

    def vehicles(self, sequence) -> list[str]:
        """Ids of every annotated vehicle track, sorted."""
        return sorted(tid for tid, t in sequence.tracks().items() if self.is_vehicle(t.label))

    def vehicle_labels(self, sequence) -> tuple[str, ...]:
        """The distinct class labels of the sequence's annotated vehicles, sorted (for APIs that filter by label)."""
        return tuple(sorted({t.label for t in sequence.tracks().values() if self.is_vehicle(t.label)}))

    def moving_vehicles(self, sequence) -> list[str]:
        """Ids of the moving vehicle tracks, sorted."""
        stamps = sequence.timestamps_ns
        return sorted(tid for tid, t in sequence.tracks().items() if self.is_moving_vehicle(t, stamps))

    def evaluable(self, span_frames: int, mean_points_first: float) -> bool:
        """LiDAR-SOT's start criteria: long enough and dense enough at the start."""
        return span_frames >= self.min_frames and mean_points_first >= self.min_mean_points


DEFAULT_SELECTION = Selection()
