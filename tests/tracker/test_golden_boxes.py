"""The tracker gives the same boxes as the golden file made before its configuration was nested
(tests/tracker/golden_boxes.py): the 9 dev tracks of PandaSet 002, presets ``full`` and ``faithful``, online; and
the same offline solve as before its matching became a voxel look-up (``full``, seed 0).

The default run checks ``full`` with seeds 0-2 on all 9 tracks and ``faithful`` with seed 0 on the first 2 tracks;
``SOT_APPS_GOLDEN_ALL=1`` checks every preset, seed and track of the file (about 4 minutes on a shared core).
"""

from __future__ import annotations

import os

import numpy as np
import pytest
from golden_boxes import GOLDEN, GOLDEN_OFFLINE, dev_tracks, offline_boxes, track_boxes

ALL = os.environ.get("SOT_APPS_GOLDEN_ALL", "") not in ("", "0")
CASES = ([(p, s, None) for p in ("full", "faithful") for s in (0, 1, 2)] if ALL
         else [("full", 0, None), ("full", 1, None), ("full", 2, None), ("faithful", 0, 2)])


@pytest.fixture(scope="module")
def dev(pandaset):
    from sot_apps.evaluation.tracker import CachedSource

    return CachedSource(pandaset), dev_tracks(pandaset)


@pytest.mark.slow
@pytest.mark.realdata
@pytest.mark.parametrize("preset, seed, n_tracks", CASES)
def test_same_boxes_as_before_the_refactor(dev, preset, seed, n_tracks):
    source, tracks = dev
    golden = np.load(GOLDEN)
    assert [t[0] for t in tracks] == list(golden["track_ids"])   # the selection itself is unchanged
    ids = None if n_tracks is None else {t[0] for t in tracks[:n_tracks]}
    got = track_boxes(source, tracks, preset, seed, ids)
    assert len(got) == (len(tracks) if ids is None else len(ids))
    for k, (boxes, flags) in got.items():
        want = golden[k + "/boxes"]
        assert boxes.shape == want.shape, k
        assert np.array_equal(boxes, want), (k, float(np.max(np.abs(boxes - want))))
        assert list(flags) == list(golden[k + "/flags"]), k


@pytest.mark.slow
@pytest.mark.realdata
def test_same_offline_boxes_as_before_the_voxel_lookup(dev):
    """The offline solve (``full``, seed 0) gives the boxes it gave with kd-tree matching, bit for bit."""
    source, tracks = dev
    golden = np.load(GOLDEN_OFFLINE)
    assert [t[0] for t in tracks] == list(golden["track_ids"])
    got = offline_boxes(source, tracks)
    assert len(got) == len(tracks)
    for k, (boxes, flags) in got.items():
        want = golden[k + "/boxes"]
        assert boxes.shape == want.shape, k
        assert np.array_equal(boxes, want), (k, float(np.max(np.abs(boxes - want))))
        assert list(flags) == list(golden[k + "/flags"]), k
