"""The App registry and config sections: the built-in apps are registered like third-party ones, a pipeline
file's stages map onto them, and a bad section is refused naming the field."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import tomllib

from sot_apps.apps import BUILTIN_APPS, ENTRY_POINT_GROUP, App, build_config, get_app, installed_apps
from sot_apps.errors import InputError

REPO = Path(__file__).resolve().parents[2]


def test_pyproject_registers_the_builtin_apps_in_the_entry_point_group():
    doc = tomllib.loads((REPO / "pyproject.toml").read_text())
    registered = doc["project"]["entry-points"][ENTRY_POINT_GROUP]
    assert registered == BUILTIN_APPS and len(registered) >= 5


def test_every_builtin_app_loads_and_follows_the_protocol():
    apps = installed_apps()
    for name in BUILTIN_APPS:
        app = apps[name]
        assert isinstance(app, App) and app.name == name
        assert app.config_type.__dataclass_params__.frozen
        build_config(app.config_type, {}, f"stages.{name}")   # every field has a default


def test_the_example_pipeline_maps_onto_the_registered_apps():
    """examples/pipeline.json as it is (version 1): bank, motion, flow, scans with the file's values."""
    from sot_apps.pipeline.config import load_config

    doc = json.loads((REPO / "examples" / "pipeline.json").read_text())
    config = load_config(REPO / "examples" / "pipeline.json")
    assert [name for name, _ in config.stages.apps] == ["bank", "motion", "flow", "scans"]
    for name, section in doc["stages"].items():
        if name == "track":
            continue
        cfg = config.stages.app(name)
        assert isinstance(cfg, get_app(name).config_type)
        for field, value in section.items():
            assert getattr(cfg, field) == (tuple(value) if isinstance(value, list) else value), (name, field)
    assert config.stages.track.preset == doc["stages"]["track"]["preset"]
    # and back: to_json of the config loads to the same stages
    again = json.loads(json.dumps(config.to_json()))
    from sot_apps.pipeline.config import PipelineConfig

    assert PipelineConfig.from_json(again).stages == config.stages


def test_disabled_version1_apps_and_extra_apps(tmp_path):
    from sot_apps.pipeline.config import PipelineConfig

    doc = {"out": "o", "sequences": [{"path": "s"}],
           "stages": {"flow": {"enabled": False}, "scans": {"enabled": False}, "autolabels": {"min_quality": 0.2}}}
    stages = PipelineConfig.from_json(doc, tmp_path).stages
    assert [name for name, _ in stages.apps] == ["bank", "motion", "autolabels"]
    assert stages.app("autolabels").min_quality == 0.2 and stages.app("flow") is None


@pytest.mark.parametrize("stages, message", [
    ({"nope": {}}, "stages.nope: no installed app named 'nope'"),
    ({"autolabels": {"formatz": ["av2"]}}, "stages.autolabels.formatz: unknown field"),
    ({"autolabels": {"min_quality": "high"}}, "stages.autolabels.min_quality: expected a number, got 'high'"),
    ({"autolabels": {"formats": "av2"}}, "stages.autolabels.formats: expected a list"),
])
def test_a_bad_app_section_is_refused_naming_the_field(tmp_path, stages, message):
    from sot_apps.pipeline.config import load_config

    path = tmp_path / "p.json"
    path.write_text(json.dumps({"out": "o", "sequences": [{"path": "s"}], "stages": stages}))
    with pytest.raises(InputError) as err:
        load_config(path)
    assert str(path) in str(err.value) and message in str(err.value)


def test_build_config_types():
    from sot_apps.apps.flow import FlowConfig

    cfg = build_config(FlowConfig, {"enabled": True, "cameras": ["front_camera"], "max_pairs": 3}, "stages.flow")
    assert cfg == FlowConfig(cameras=("front_camera",), max_pairs=3)
    assert build_config(FlowConfig, {"max_pairs": None}, "stages.flow").max_pairs is None
    with pytest.raises(InputError, match=r"stages\.flow\.max_pairs: expected an integer, got 2\.5"):
        build_config(FlowConfig, {"max_pairs": 2.5}, "stages.flow")
    with pytest.raises(InputError, match=r"stages\.flow\.cameras\[1\]: expected a string, got 3"):
        build_config(FlowConfig, {"cameras": ["a", 3]}, "stages.flow")


def test_sot_apps_apps_lists_the_installed_apps(capsys):
    from sot_apps.cli.main import main

    assert main(["apps", "--json"]) == 0
    docs = {d["name"]: d for d in json.loads(capsys.readouterr().out)}
    assert set(BUILTIN_APPS) <= set(docs)
    assert docs["scans"]["needs"] == ["bank"] and docs["bank"]["runs_by_default"]
    assert not docs["autolabels"]["runs_by_default"]
    assert {f["field"] for f in docs["flow"]["config"]} == {"cameras", "mode", "max_pairs", "use_lidar", "vis"}
    assert main(["apps"]) == 0
    assert "stages.motion:" in capsys.readouterr().out


def test_listing_the_apps_loads_no_heavy_library():
    """``sot-apps apps`` imports each app's module, which imports its libraries only when a unit runs."""
    import os
    import subprocess
    import sys

    probe = ("import json, sys\nfrom sot_apps.cli.main import main\nimport contextlib, io\n"
             "with contextlib.redirect_stdout(io.StringIO()):\n    code = main(['apps'])\n"
             "print(json.dumps([code, sorted({m.split('.')[0] for m in sys.modules})]))")
    done = subprocess.run([sys.executable, "-c", probe], env={**os.environ, "PYTHONPATH": str(REPO)},
                          capture_output=True, text=True, timeout=120)
    code, modules = json.loads(done.stdout.splitlines()[-1])
    assert code == 0
    assert [m for m in ("scipy", "cv2", "trimesh", "pyarrow", "mcap", "embreex") if m in modules] == []
