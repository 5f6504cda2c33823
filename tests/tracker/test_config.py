"""The nested tracker configuration: sections, files, dotted overrides, errors naming the field, strategies."""

from __future__ import annotations

import dataclasses
import json

import pytest
import yaml

from tracker.config import PRESETS, MotionConfig, TrackerConfig, get_preset, parse_overrides
from tracker.geometry import Box
from tracker.motion_filter import AverageMotion, CTRVMotion
from tracker.sotracker import Tracker
from tracker.strategies.association import GlobalAssociation
from tracker.strategies.first_frame import HypothesesSearch, MovingSearch
from tracker.strategies.ground import LocalGround, NoGround, RemovedGround, SweepGround
from tracker.strategies.height import FilterHeight, FixedHeight, GroundHeight, IcpHeight
from tracker.strategies.inliers import AllPairs, FixedRansac
from tracker.strategies.loss import KeepPrior, PriorReference, SymmetricConsistency, XOnlyConsistency
from tracker.strategies.metric import PlaneMetric, PointMetric
from tracker.strategies.motion import choose_motion_model


def test_at_most_15_top_level_fields_each_section_frozen():
    fields = dataclasses.fields(TrackerConfig)
    assert len(fields) <= 15
    config = TrackerConfig()
    for f in fields:
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            with pytest.raises(dataclasses.FrozenInstanceError):
                setattr(value, dataclasses.fields(value)[0].name, None)


@pytest.mark.parametrize("name", list(PRESETS))
def test_every_preset_round_trips_through_json_and_yaml(tmp_path, name):
    config = get_preset(name, seed=3)
    (tmp_path / "c.json").write_text(json.dumps(config.to_dict()))
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(config.to_dict()))
    assert TrackerConfig.from_file(tmp_path / "c.json") == config
    assert TrackerConfig.from_file(tmp_path / "c.yaml") == config


def test_a_partial_file_keeps_the_defaults(tmp_path):
    (tmp_path / "c.yaml").write_text("motion:\n  model: ctrv\n  ctrv:\n    accel_sigma: 2\nseed: 4\n")
    config = TrackerConfig.from_file(tmp_path / "c.yaml")
    assert (config.motion.model, config.motion.ctrv.accel_sigma, config.seed) == ("ctrv", 2.0, 4)
    assert config.motion.alpha == MotionConfig().alpha and config.ground == TrackerConfig().ground


@pytest.mark.parametrize("data, message", [
    ({"motion": {"alpha": "x"}}, "motion.alpha: expected a number, got 'x'"),
    ({"shape": {"ransac": {"min_inliers": 2.5}}}, "shape.ransac.min_inliers: expected an integer, got 2.5"),
    ({"shape": {"enabled": "maybe"}}, "shape.enabled: expected true or false, got 'maybe'"),
    ({"motion": {"modle": "ctrv"}}, "motion.modle: unknown tracker setting; did you mean motion.model"),
    ({"motion": 3}, "motion: expected a section (mapping), got 3"),
    ({"height": {"model": "laser"}}, "height.model: expected one of icp, ground, fixed, filter, got 'laser'"),
    ({"search": {"scale": 0}}, "search.scale: must be positive"),
    ({"shape": {"ransac": {"score_pairs": 0}}}, "shape.ransac.score_pairs: must be positive"),
    ({"footprint": {"containment": {"gap": 0}}}, "footprint.containment.gap: must be positive"),
    ({"refinement": {"offline": {"gauge": "x"}}}, "refinement.offline.gauge: expected one of regauge, fix_first"),
])
def test_errors_name_the_field_path(data, message):
    with pytest.raises(ValueError) as info:
        TrackerConfig.from_dict(data)
    assert message in str(info.value)


def test_a_file_error_names_the_file_and_the_field(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"motion": {"alpha": "x"}}))
    with pytest.raises(ValueError, match=r"bad.json: motion.alpha: expected a number"):
        TrackerConfig.from_file(path)


def test_dotted_overrides_are_typed_like_their_field():
    assert parse_overrides(["motion.alpha=0.6", "shape.enabled=false", "search.max_points=300",
                            "ground.remover=local", "seed=2"]) == {
        "motion.alpha": 0.6, "shape.enabled": False, "search.max_points": 300, "ground.remover": "local", "seed": 2}
    config = get_preset("full").with_overrides(["motion.alpha=0.7", "shape.ransac.mode=none"])
    assert config.motion.alpha == 0.7 and config.shape.ransac.mode == "none"
    assert config.preset == "full" and get_preset("full").motion.alpha == 0.6   # a copy
    assert get_preset("full", **{"motion.alpha": 0.7, "shape.ransac.mode": "none"}) == config
    for bad, message in [("motion.alpha", "expected PATH=VALUE"), ("motion=1", "is a section"),
                         ("motion.alpha=x", "motion.alpha: expected a number, got 'x'"),
                         ("weight_det=0.1", "weight_det: unknown tracker setting")]:
        with pytest.raises(ValueError, match=message):
            parse_overrides([bad])



@pytest.mark.parametrize(("path", "value"), [("motion.coast_max_slip", -0.1), ("motion.coast_max_slip", 1.6),
                                             ("motion.coast_steady_frames", -1), ("motion.coast_steady_max", -0.1)])
def test_a_coast_setting_out_of_range_is_refused_by_name(path, value):
    with pytest.raises(ValueError, match=path.replace(".", r"\.")):
        get_preset("full", **{path: value})

def _strategies(config: TrackerConfig) -> tuple:
    s = Tracker(config).strategies
    r = s.registration
    return (type(s.ground), type(s.road), type(r.association), type(r.inliers), type(r.metric), type(r.reference),
            type(r.consistency), type(r.data_free), type(s.first_frame), type(s.height))


def test_strategies_are_chosen_from_the_config_once():
    assert _strategies(get_preset("full")) == (SweepGround, RemovedGround, GlobalAssociation, FixedRansac, PointMetric,
                                               PriorReference, XOnlyConsistency, KeepPrior, HypothesesSearch,
                                               FilterHeight)
    default = _strategies(TrackerConfig())
    assert default[0] is LocalGround and default[6] is SymmetricConsistency and default[8] is MovingSearch
    assert default[9] is IcpHeight
    changed = TrackerConfig().with_overrides(["ground.remover=none", "shape.ransac.mode=none", "registration.metric=plane",
                                              "height.model=fixed"])
    assert _strategies(changed)[0] is NoGround and _strategies(changed)[3] is AllPairs
    assert _strategies(changed)[4] is PlaneMetric and _strategies(changed)[9] is FixedHeight
    assert _strategies(TrackerConfig().with_overrides(["height.model=ground"]))[9] is GroundHeight


@pytest.mark.parametrize("model, frame", [("average", "world"), ("object", "object"), ("turn", "turn")])
def test_the_motion_model_names_its_frame(model, frame):
    motion = choose_motion_model(MotionConfig(model=model), Box(0, 0, 0, 0, 4, 2, 1.5))
    assert isinstance(motion, AverageMotion) and motion.prior.frame == frame
    assert isinstance(choose_motion_model(MotionConfig(model="ctrv"), Box(0, 0, 0, 0, 4, 2, 1.5)), CTRVMotion)
