"""The bridge before a re-lock (``refinement.relock_bridge``): frames the track spent lost are a prediction.

Once a track is lost (re-acquisition, tracker/strategies/reacquire.py), its box coasts on the motion model
(``coasting``) or, where points come back around it, follows them while the search goes on (``searching``). When
the search then re-locks the track elsewhere (``reacquired``), the points it followed may not have been the
object's: a car that turned sparse or hid beside another one is found again metres from where the box went. Then
the online states of that stretch are wrong, and its points are someone else's; a refinement that takes them as
data (the fixed-lag window, the whole-sequence solve) holds the stretch there and its smoothness pulls the frames
on both sides toward it.

A **bridged stretch** is the run of frames a .. k - 1 before a re-locked frame k that were lost
(:func:`~tracker.bidirectional.is_lost`) or searching, when one of a .. k - 2 was searching with the box held on
points (not ``low_points``: at least ``registration.min_points`` object points), and the last such box lies more
than a box width across the re-locked box's heading from it. A stretch that only coasted holds no one else's points;
nor does frame k - 1 alone: the re-lock's candidate is confirmed over two frames, so k - 1 is where the object came
back into view; nor does a box held on a handful of points: a sparse car coming back into view holds it on its own
first points, near it (the re-lock, placed on the centre of what is seen of it, may be the farther one); nor does a
box held in line with the re-lock: a car seen again before the track held it for long enough
(``reacquire.recover_frames``) holds it on its own points, and a part of it seen misplaces the box along it or by
half a width, while another car beside it is a lane (a width or more) away. Its frames take the states interpolated
linearly (x, y, z, heading, the heading along the shorter way) between frame a - 1 and frame k, are flagged
``bridged``, and hold no points: the refinement sees them as predictions, pulled toward the line and by its
smoothness, with no data of their own. Frame 0 (the given box) is never bridged. Applied before the refinement's
solve offline (``relock_bridge`` "offline" or "both") and, with "both", in the fixed-lag window when the re-locked
frame arrives, to the frames of the stretch not yet final (interpolated from the last frame before them)."""

from __future__ import annotations

import dataclasses

import numpy as np

from .bidirectional import is_lost
from .geometry import Box, State, lerp_box
from .shape import to_object_frame
from .sotracker import FrameEstimate, TrackResult

__all__ = ["bridge_start", "bridged_estimates", "bridged_result"]


def bridge_start(estimates: list[FrameEstimate], k: int, lost_points: int) -> int | None:
    """The first frame a of the bridged stretch before frame k (``estimates[k]`` re-locked; ``estimates`` holds
    frames 0 .. k - 1 at least), or None: no frame before k - 1 since the track last held its object was held on
    points while searching, or the last such box was not beside the re-locked one."""
    a = k
    while a > 1 and "reacquired" not in estimates[a - 1].flags and (
            "searching" in estimates[a - 1].flags or is_lost(estimates[a - 1], lost_points)):
        a -= 1
    held = [j for j in range(a, k - 1) if _held_on_points(estimates[j])]
    return a if held and _beside(estimates[held[-1]].box, estimates[k].box) else None


def _beside(held: Box, relock: Box) -> bool:
    """The box held while searching lies more than a box width across the re-locked box's heading from it: what
    it held was beside the object (a part of the object seen misplaces the box along it, or by half a width)."""
    return bool(abs(to_object_frame(held.center[None, :], relock)[0, 1]) > relock.width)


def _held_on_points(estimate: FrameEstimate) -> bool:
    """Searching, with the box held by registration's share of points (not ``low_points``): a sparse object coming
    back into view holds a box on a handful of its own points; a box held on a dense cluster while the track is
    lost, then re-located, held someone else."""
    return "searching" in estimate.flags and "low_points" not in estimate.flags


def bridged_estimates(estimates: list[FrameEstimate], before: Box, after: Box) -> list[FrameEstimate]:
    """``estimates`` (a stretch) moved evenly onto the line from ``before`` to ``after`` (the boxes around it, both
    excluded), without points, flagged ``bridged``."""
    out = []
    for j, estimate in enumerate(estimates, start=1):
        box = lerp_box(before, after, j / (len(estimates) + 1))
        flags = tuple(dict.fromkeys(list(estimate.flags) + ["bridged"]))
        out.append(dataclasses.replace(estimate, state=State.from_array(box.to_array()[:4]), box=box, num_points=0,
                                       points=np.zeros((0, 3)), flags=flags))
    return out


def bridged_result(result: TrackResult, lost_points: int) -> TrackResult:
    """``result`` with every bridged stretch (see the module docstring) replaced; ``result`` itself when none."""
    estimates = list(result.estimates)
    changed = False
    for k in range(2, len(estimates)):
        if "reacquired" not in estimates[k].flags or (a := bridge_start(estimates, k, lost_points)) is None:
            continue
        estimates[a:k] = bridged_estimates(estimates[a:k], estimates[a - 1].box, estimates[k].box)
        changed = True
    return dataclasses.replace(result, estimates=estimates) if changed else result
