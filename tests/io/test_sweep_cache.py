"""The one-time conversion cache of decoded sweeps: cached reads equal the reader's bit for bit, and a changed
source (points file or pose) is converted again, never read stale."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sot_apps.io import open_sequence
from sot_apps.io.sweep_cache import SweepCache, with_sweep_cache


def _same(a, b) -> bool:
    def eq(x, y):
        return (x is None and y is None) or (x is not None and y is not None and x.dtype == y.dtype
                                             and np.array_equal(x, y))
    return eq(a.xyz, b.xyz) and eq(a.intensity, b.intensity) and eq(a.time_offset_ns, b.time_offset_ns)


@pytest.fixture
def world(tmp_path) -> Path:
    from sot_apps.synth import write_world

    return write_world(tmp_path / "world", frames=3, vehicles=1, sensor="vlp16", seed=1)


def test_cached_pandaset_sweeps_equal_the_readers_bit_for_bit(tmp_path, pandaset_root):
    pandaset = pandaset_root
    plain = open_sequence(pandaset)
    first = with_sweep_cache(open_sequence(pandaset), tmp_path / "cache")
    for k in (0, 1, 30):
        assert _same(first.sweep(k), plain.load_sweep(k))          # converted now
    again = with_sweep_cache(open_sequence(pandaset), tmp_path / "cache")
    cache = again.load_sweep.__self__
    assert isinstance(cache, SweepCache)
    for k in (0, 1, 30):
        assert _same(again.load_sweep(k), plain.load_sweep(k))      # read from the cache
    assert (cache.hits, cache.misses) == (3, 0)
    # the tracker sees the same frame (points, per-point times, pose)
    a, b = again.lidar_frame(30), plain.lidar_frame(30)
    assert np.array_equal(a.points_ego, b.points_ego) and np.array_equal(a.point_time_offset_ns, b.point_time_offset_ns)
    assert not any(pandaset.rglob("*.npy"))                        # nothing written into the input


def test_a_changed_points_file_or_pose_is_converted_again(world, tmp_path):
    root = tmp_path / "cache"
    seq = with_sweep_cache(open_sequence(world), root)
    before = seq.load_sweep(1)
    path = seq.frames[1].points_path
    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["xyz"] = arrays["xyz"] + np.float32(0.5)
    np.savez(path, **arrays)
    changed = with_sweep_cache(open_sequence(world), root)
    after = changed.load_sweep(1)
    assert changed.load_sweep.__self__.misses == 1
    assert np.array_equal(after.xyz, before.xyz + np.float32(0.5))
    assert _same(after, open_sequence(world).load_sweep(1))
    assert len(list(changed.load_sweep.__self__.directory.glob("000001-*"))) == 1   # the stale entry is gone

    changed.load_sweep(0)
    changed.load_sweep(2)
    doc = json.loads((world / "sequence.json").read_text())
    doc["frames"][2]["world_from_ego"][0][3] += 1.0               # a new pose: the key of frame 2 changes
    (world / "sequence.json").write_text(json.dumps(doc))
    moved = with_sweep_cache(open_sequence(world), root)
    cache = moved.load_sweep.__self__
    assert _same(moved.load_sweep(0), open_sequence(world).load_sweep(0))
    assert (cache.hits, cache.misses) == (1, 0)
    assert _same(moved.load_sweep(2), open_sequence(world).load_sweep(2))
    assert (cache.hits, cache.misses) == (1, 1)


def test_off_and_a_cache_inside_the_input_leave_the_sequence_uncached(world, monkeypatch, capsys):
    monkeypatch.setenv("SOT_APPS_CACHE_DIR", "off")
    seq = open_sequence(world, cache=True)
    assert not isinstance(getattr(seq.load_sweep, "__self__", None), SweepCache)
    inside = with_sweep_cache(open_sequence(world), world / "cache")
    assert not isinstance(getattr(inside.load_sweep, "__self__", None), SweepCache)
    assert "inside the input" in capsys.readouterr().err
    assert not (world / "cache").exists()
