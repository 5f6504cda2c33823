"""Roadside clutter in the synthetic worlds: unannotated, off the road, and the rest of the world unchanged."""

from __future__ import annotations

import numpy as np

from sot_apps.synth.clutter import CLUTTER_KINDS, clutter_objects
from sot_apps.synth.world import make_world


def test_clutter_is_background_on_the_sidewalk_and_leaves_the_rest_of_the_world_alone():
    plain = make_world(frames=3, vehicles=3, seed=4)
    cluttered = make_world(frames=3, vehicles=3, seed=4, clutter=True)
    # the same vehicles (sizes, paths) and the same walls and poles: clutter draws from its own generator
    assert [o.id for o in plain.objects] == [o.id for o in cluttered.objects]
    for a, b in zip(plain.objects, cluttered.objects, strict=True):
        assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.trajectory.states, b.trajectory.states)
    n = len(plain.background)
    assert [o.name for o in cluttered.background[:n]] == [o.name for o in plain.background]
    extra = cluttered.background[n:]
    assert len(extra) >= 10 and {o.name for o in extra} <= set(CLUTTER_KINDS)
    assert all(o.instance == -1 for o in extra)                # background: never annotated
    for o in extra:                                            # on the sidewalk band, off the road and its parked cars
        y = np.abs(o.vertices[:, 1])
        assert y.min() >= 10.5 if o.name != "tree" else np.median(y) >= 11.0, (o.name, y.min())
        assert -0.5 <= o.vertices[:, 2].min() <= 3.5      # on the ground (foliage sinks into it a little)


def test_every_clutter_kind_is_drawn_and_vehicle_like_in_size():
    objects = clutter_objects(np.random.default_rng(0), 0.0, 400.0)
    kinds = {o.name for o in objects}
    assert kinds == set(CLUTTER_KINDS)
    # bushes and hedges are as long as cars and about as high: the detector's size gates alone cannot drop them
    sizes = [np.ptp(o.vertices, axis=0) for o in objects if o.name in ("bush", "hedge")]
    assert any(1.0 <= s[2] <= 2.0 and s[0] >= 3.0 for s in sizes)
