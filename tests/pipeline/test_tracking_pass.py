"""The multi-object pass (sot_apps.tracking.track_objects) gives every object the result of tracking it alone,
bit for bit, online, with fixed-lag and offline refinement, while reading each sweep once."""

from __future__ import annotations

import numpy as np
import pytest

from sot_apps.io import open_sequence
from sot_apps.tracking import (
    ObjectRequest,
    TrackingFailed,
    first_box_with_points,
    refine_track_fixed_lag,
    refine_track_offline,
    track_objects,
)
from tracker import Box, get_preset, track


def _alone(seq, request: ObjectRequest, config, mode: str, lag: int):
    """The per-object path (sot-apps track / the former per-object pipeline task)."""
    if request.annotated:
        start, box = first_box_with_points(seq, request.annotated, config)
    else:
        start, box = request.start, request.init_box
    end = request.end if request.max_frames is None else min(request.end, start + request.max_frames)
    result = track(seq, box, start, end, config)
    if mode == "lag":
        result = refine_track_fixed_lag(seq, result, lag)
    elif mode == "offline":
        result = refine_track_offline(seq, result)
    return result


def _assert_identical(seq, requests, mode: str, lag: int = 3, config=None) -> None:
    config = config or get_preset("full")
    reads: list[int] = []
    loader = seq.load_sweep
    seq.load_sweep = lambda k: reads.append(k) or loader(k)
    seq.cache_size = 1   # no sweep comes back from the sequence's own cache: every read is counted
    tracks, times = track_objects(seq, requests, config, mode=mode, lag=lag)
    assert len(reads) == len(set(reads)) == times.sweeps   # each sweep read once
    seq.load_sweep = loader
    seq.cache_size = 4
    for request, got in zip(requests, tracks, strict=True):
        assert got.error is None, got.error
        want = _alone(seq, request, config, mode, lag)
        assert got.result.mode == want.mode and got.result.frames == want.frames
        assert np.array_equal([e.box.to_array() for e in got.result.estimates],
                              [e.box.to_array() for e in want.estimates])
        assert [e.num_points for e in got.result.estimates] == [e.num_points for e in want.estimates]
        assert [e.flags for e in got.result.estimates] == [e.flags for e in want.estimates]
        assert np.array_equal(got.result.shape, want.shape)


def _requests(seq, ids, starts, end, max_frames=None):
    tracks = seq.tracks()
    out = []
    for tid, start in zip(ids, starts, strict=True):
        t = tracks[tid]
        frames = [k for k in t.frames if start <= k <= end]
        if start == 0:   # annotated: starts at its first box with enough points
            out.append(ObjectRequest(tid, t.box_at(frames[0]), frames[0], frames[-1],
                                     tuple((k, t.box_at(k)) for k in frames), max_frames))
        else:            # a given box at a later frame
            out.append(ObjectRequest(tid, t.box_at(start), start, frames[-1], max_frames=max_frames))
    return out


@pytest.mark.parametrize("mode", ["online", "lag", "offline"])
def test_synthetic_objects_in_one_pass_equal_each_tracked_alone(tiny_worlds, mode):
    seq = open_sequence(tiny_worlds[0])
    requests = _requests(seq, ["veh_000", "veh_001", "veh_002"], [0, 2, 1], 5, max_frames=None)
    _assert_identical(seq, requests, mode, lag=2)


@pytest.mark.parametrize("mode", ["online", "lag", "offline"])
def test_pandaset_dev_objects_in_one_pass_equal_each_tracked_alone(mode, pandaset_root):
    seq = open_sequence(pandaset_root)
    ids = {t[:8]: t for t in seq.tracks()}
    # three dev vehicles starting at frames 0, 2 and 4 (annotated, given boxes); one capped by max_frames
    requests = _requests(seq, [ids["8ac00bad"], ids["91aa5b5c"], ids["71a404f3"]], [0, 2, 4], 9)
    requests[0] = ObjectRequest(**{**requests[0].__dict__, "max_frames": 6})
    _assert_identical(seq, requests, mode, lag=3)


@pytest.mark.parametrize("mode", ["lag", "offline"])
def test_own_motion_taken_out_in_one_pass_as_each_tracked_alone(tiny_worlds, mode):
    """With the own-motion settings (online step, window, offline solve) the pass keeps the regions' capture times:
    the same boxes as tracking each object alone. A 1 ms spread reaches every object of the tiny world, so the
    boxes differ from those without it."""
    seq = open_sequence(tiny_worlds[0])
    requests = _requests(seq, ["veh_000", "veh_001", "veh_002"], [0, 2, 1], 5)
    spread = ("search.own_motion_spread", "refinement.lag.own_motion_spread", "refinement.offline.own_motion_spread")
    config = get_preset("full", **dict.fromkeys(spread, 0.001))
    _assert_identical(seq, requests, mode, config=config)
    with_it = [_alone(seq, r, config, mode, 3) for r in requests]
    without = [_alone(seq, r, get_preset("full", **dict.fromkeys(spread, 0.0)), mode, 3) for r in requests]
    assert any(not np.array_equal([e.box.to_array() for e in a.estimates], [e.box.to_array() for e in b.estimates])
               for a, b in zip(with_it, without, strict=True))


def test_an_object_without_points_fails_alone(tiny_worlds):
    seq = open_sequence(tiny_worlds[0])
    good = _requests(seq, ["veh_000"], [0], 5)[0]
    empty = ObjectRequest("empty", Box(150.0, -150.0, 1.0, 0.0, 4.5, 1.9, 1.6), 0, 5)
    far = seq.tracks()["veh_001"]
    never = ObjectRequest("never", far.box_at(0), 0, 5,
                          tuple((k, Box(150.0, -150.0, 1.0, 0.0, 4.5, 1.9, 1.6)) for k in range(6)))
    tracks, _ = track_objects(seq, [empty, good, never], get_preset("full"), mode="online")
    assert [t.error is None for t in tracks] == [False, True, False]
    assert tracks[0].lacks_points and "0 LiDAR points in the initial box" in tracks[0].error
    with pytest.raises(TrackingFailed) as alone:
        first_box_with_points(seq, never.annotated, get_preset("full"))
    assert tracks[2].lacks_points and tracks[2].error == str(alone.value)
    want = track(seq, good.init_box, 0, 5, get_preset("full"))
    assert np.array_equal([e.box.to_array() for e in tracks[1].result.estimates],
                          [e.box.to_array() for e in want.estimates])


def test_ground_masks_stored_in_the_sweep_cache_give_the_same_tracks(tiny_worlds, tmp_path):
    """A pass over a sequence read through the sweep cache stores each sweep's ground mask there; a later pass
    (another process, another chunk) takes the masks from it, and both give the per-object results."""
    from sot_apps.io.sweep_cache import SweepCache, with_sweep_cache

    plain = open_sequence(tiny_worlds[0])
    requests = _requests(plain, ["veh_000", "veh_002"], [0, 1], 5)
    config = get_preset("full")
    want = [_alone(plain, r, config, "online", 0) for r in requests]
    for _ in range(2):
        seq = with_sweep_cache(open_sequence(tiny_worlds[0]), tmp_path / "cache")
        tracks, _ = track_objects(seq, requests, config)
        for got, alone in zip(tracks, want, strict=True):
            assert np.array_equal([e.box.to_array() for e in got.result.estimates],
                                  [e.box.to_array() for e in alone.estimates])
        cache = SweepCache.of(seq)
        stored = [p for k in range(6) for p in cache.entry(k).glob("ground-*.npz")]
        assert len(stored) == 6
    from tracker.sweep_ground import sweep_ground_mask

    name = stored[0].name[:-4]
    for k in range(6):
        assert np.array_equal(cache.load_mask(k, name),
                              sweep_ground_mask(plain.lidar_frame(k).points_ego, *config.ground.sweep_args()))


def test_eval_tracks_every_object_in_one_pass_as_each_alone(tiny_worlds, monkeypatch):
    """``sot-apps eval`` (bench.sequence_eval.evaluate) scores, per preset and seed, the tracks of one pass over the
    sweeps; each is the track ``tracker.track`` gives from the object's first annotated box."""
    import sot_apps.evaluation.tracker as evaluation
    from sot_apps.bench.sequence_eval import evaluate
    from sot_apps.io.cached_source import CachedSource

    seq = open_sequence(tiny_worlds[1])
    ids = ["veh_000", "veh_001", "veh_002"]
    scored: list = []
    score = evaluation.score_result
    monkeypatch.setattr(evaluation, "score_result", lambda spec, result, config: scored.append((spec, result))
                        or score(spec, result, config))
    reads: list[int] = []
    loader = seq.lidar_frame
    seq.lidar_frame = lambda k: reads.append(k) or loader(k)
    report = evaluate(seq, ids, presets=("full",), seeds=(0, 1), end_frame=5, with_shape=False)
    seq.lidar_frame = loader
    assert len(reads) == len(set(reads))                 # every sweep read once (two seeds: the source keeps them)
    assert [spec.track_id for spec, _ in scored] == ids * 2 and len(report.rows) == 1
    for i, (spec, got) in enumerate(scored):
        want = track(CachedSource(seq), spec.boxes[0], int(spec.frames[0]), int(spec.frames[-1]),
                     get_preset("full", seed=i // len(ids)))
        assert got.frames == want.frames and len(want.frames) > 3
        assert np.array_equal([e.box.to_array() for e in got.estimates], [e.box.to_array() for e in want.estimates])
        assert [(e.num_points, e.flags) for e in got.estimates] == [(e.num_points, e.flags) for e in want.estimates]
        assert np.array_equal(got.shape, want.shape)


class _Reversed:
    """The sequence's frames last..0 in reversed order (each frame keeps its own index)."""

    def __init__(self, seq):
        self.seq = seq

    def __len__(self):
        return len(self.seq)

    def lidar_frame(self, index):
        return self.seq.lidar_frame(len(self.seq) - 1 - index)


def test_own_detections_initial_motion_and_a_reversed_source_as_tracked_alone(tiny_worlds):
    """Per-object detections and initial motion (the auto-labeller's requests), on a source serving its frames in
    reversed order, give what tracker.track gives with the same inputs."""
    from tracker import FrameDetections

    seq = open_sequence(tiny_worlds[0])
    source, last = _Reversed(seq), len(seq) - 1
    config = get_preset("det_sot")
    requests, wants = [], []
    for tid, start in (("veh_000", 1), ("veh_002", 2)):
        t = seq.tracks()[tid]
        box = t.box_at(last - start)
        turned = Box(box.x, box.y, box.z, box.heading + np.pi, box.length, box.width, box.height)
        own = {last - k: FrameDetections(t.box_at(k).to_array()[None], np.array([0.9])) for k in t.frames}
        motion = np.array([0.3, -0.1, 0.0, 0.0])
        requests.append(ObjectRequest(tid, turned, start, 5, detections=own, initial_motion=motion))
        wants.append(track(source, turned, start, 5, config, detections=own, initial_motion=motion))
    tracks, _ = track_objects(source, requests, config, mode="online", min_points=None)
    for got, want, request in zip(tracks, wants, requests, strict=True):
        assert got.error is None and got.start == request.start   # positions in the source, not frame indices
        assert got.result.frames == want.frames == [last - k for k in range(request.start, 6)]
        assert np.array_equal([e.box.to_array() for e in got.result.estimates],
                              [e.box.to_array() for e in want.estimates])
