"""The golden boxes of the tracker refactor: every frame's box and flags of the 9 dev tracks of PandaSet 002
(the tracks ``sot-apps eval ../shared/data/pandaset_002 --all-moving`` selects), tracked online with the presets
``full`` and ``faithful`` and seeds 0, 1, 2.

``python tests/tracker/golden_boxes.py`` writes tests/tracker/golden/dev_tracks_boxes.npz (made with the code
before the configuration was nested; tests/tracker/test_golden_boxes.py checks that today's code gives the same
boxes); ``python tests/tracker/golden_boxes.py full`` remakes only the named presets' entries (a preset that was
changed on purpose) and keeps the others' as they are. The file holds, per (preset, seed, track): the (K, 7)
float64 boxes x, y, z, heading, l, w, h, and the flags of each frame joined by ',' (a fixed-width unicode array).

``python tests/tracker/golden_boxes.py offline`` writes tests/tracker/golden/dev_tracks_offline_boxes.npz: the same
tracks with ``full``, seed 0, online and then refined offline (:func:`tracker.refine_offline`), the boxes as above
(made with today's solve with its voxel look-up reverted to the kd-tree it replaced;
tests/tracker/test_golden_boxes.py checks today's offline solve gives them bit for bit), with the settings of
``full`` when the file was made (``OFFLINE_SETTINGS``: no dense grid, no own-motion compensation anywhere, no
containment check), so it keeps checking the look-up.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
GOLDEN = REPO / "tests" / "tracker" / "golden" / "dev_tracks_boxes.npz"
GOLDEN_OFFLINE = REPO / "tests" / "tracker" / "golden" / "dev_tracks_offline_boxes.npz"
PRESETS = ("full", "faithful")
# ``full``'s settings as the offline file was made (the dense tracks' finer fold grid and the own-motion
# compensation, offline, online and in the window, and the containment check came later)
OFFLINE_SETTINGS = {"refinement.offline.dense_voxel": 0.0, "refinement.lag.dense_voxel": 0.0,
                    "refinement.offline.own_motion_spread": 0.0, "search.own_motion_spread": 0.0,
                    "refinement.lag.own_motion_spread": 0.0, "footprint.containment.min_points": 0}
SEEDS = (0, 1, 2)


def dev_tracks(sequence) -> list[tuple[str, int, int, object]]:
    """(track id, start frame, end frame, start box) of the evaluated moving vehicles, sorted by id."""
    from sot_apps.evaluation.tracker import CachedSource, select_moving_vehicle_tracks
    from sot_apps.objects.selection import annotated_span

    source = CachedSource(sequence)
    tracks = sequence.tracks()
    out = []
    for tid in select_moving_vehicle_tracks(sequence, source=source):
        start, end = annotated_span(tracks[tid].frames)
        out.append((tid, start, end, tracks[tid].box_at(start)))
    return out


def key(preset: str, seed: int, track_id: str) -> str:
    return f"{preset}/{seed}/{track_id}"


def track_boxes(source, tracks, preset: str, seed: int, track_ids=None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{key: (boxes (K, 7), flags (K,))} of ``preset`` with ``seed`` on ``tracks`` (only ``track_ids`` if given)."""
    from tracker import get_preset, track

    out = {}
    for tid, start, end, box in tracks:
        if track_ids is not None and tid not in track_ids:
            continue
        result = track(source, box, start, end, get_preset(preset, seed=seed))
        boxes = np.array([e.box.to_array()[:7] for e in result.estimates], dtype=np.float64)
        flags = np.array([",".join(e.flags) for e in result.estimates])
        out[key(preset, seed, tid)] = (boxes, flags)
    return out


def offline_boxes(source, tracks, seed: int = 0) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{key("offline", seed, id): (boxes (K, 7), flags (K,))}: ``full`` online, then the offline refinement."""
    from tracker import get_preset, refine_offline, track

    out = {}
    for tid, start, end, box in tracks:
        config = get_preset("full", seed=seed, **OFFLINE_SETTINGS)
        result = refine_offline(source, track(source, box, start, end, config), config)
        boxes = np.array([e.box.to_array()[:7] for e in result.estimates], dtype=np.float64)
        out[key("offline", seed, tid)] = (boxes, np.array([",".join(e.flags) for e in result.estimates]))
    return out


def write_offline() -> int:
    from sot_apps.evaluation.tracker import CachedSource
    from sot_apps.io import open_sequence

    sequence = open_sequence(REPO.parent / "shared" / "data" / "pandaset_002")
    tracks = dev_tracks(sequence)
    arrays: dict[str, np.ndarray] = {"track_ids": np.array([t[0] for t in tracks])}
    for k, (boxes, flags) in offline_boxes(CachedSource(sequence), tracks).items():
        arrays[k + "/boxes"], arrays[k + "/flags"] = boxes, flags
    np.savez_compressed(GOLDEN_OFFLINE, **arrays)
    print(f"{GOLDEN_OFFLINE}: {len(tracks)} tracks", file=sys.stderr)
    return 0


def main(presets: list[str]) -> int:
    from sot_apps.evaluation.tracker import CachedSource
    from sot_apps.io import open_sequence

    sequence = open_sequence(REPO.parent / "shared" / "data" / "pandaset_002")
    source = CachedSource(sequence)
    tracks = dev_tracks(sequence)
    arrays: dict[str, np.ndarray] = {"track_ids": np.array([t[0] for t in tracks])}
    if presets:  # keep the other presets' entries
        with np.load(GOLDEN) as old:
            arrays.update({k: old[k] for k in old.files if k.split("/")[0] not in presets and k != "track_ids"})
    for preset in presets or PRESETS:
        for seed in SEEDS:
            for k, (boxes, flags) in track_boxes(source, tracks, preset, seed).items():
                arrays[k + "/boxes"] = boxes
                arrays[k + "/flags"] = flags
            print(preset, seed, "done", file=sys.stderr)
    GOLDEN.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(GOLDEN, **arrays)
    print(f"{GOLDEN}: {len(tracks)} tracks", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(write_offline() if sys.argv[1:] == ["offline"] else main([p for p in sys.argv[1:] if p in PRESETS]))
