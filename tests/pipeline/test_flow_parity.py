"""``sot-apps run`` and ``sot-apps flow --tracks`` give byte-identical flow for the same tracks and pairs."""

from __future__ import annotations

import json

from sot_apps.cli.main import main


def _files(root):
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and not p.relative_to(root).as_posix().startswith(("pairs/", "vis/"))
            and p.name not in ("stats.json", "instances.json")}


def _without_provenance(doc):
    """stats.json / instances.json minus what names where the objects came from and how long pairs took."""
    if isinstance(doc, dict):
        return {k: _without_provenance(v) for k, v in doc.items() if k not in ("source", "seconds", "ms", "time_ms")}
    if isinstance(doc, list):
        return [_without_provenance(v) for v in doc]
    return doc


def test_pipeline_flow_equals_the_flow_command(reference_run, tiny_worlds, tmp_path):
    result, _ = reference_run
    pipeline_cam = result.out / "synth_s4" / "flow" / "front_camera"
    track_dirs = sorted(str(p) for p in (pipeline_cam.parents[1] / "tracks").iterdir() if p.is_dir())
    assert len(track_dirs) == 3
    cli_out = tmp_path / "flow"
    assert main(["flow", str(tiny_worlds[0]), "--tracks", *track_dirs, "--camera", "front_camera", "--pairs", "0:5",
                 "--out", str(cli_out), "--quiet"]) == 0
    cli_cam = cli_out / "front_camera"
    pipeline_files, cli_files = _files(pipeline_cam), _files(cli_cam)
    assert len(pipeline_files) >= 10 and sorted(pipeline_files) == sorted(cli_files)
    assert [k for k in pipeline_files if pipeline_files[k] != cli_files[k]] == []
    for name in ("stats.json", "instances.json"):
        docs = [_without_provenance(json.loads((c / name).read_text())) for c in (pipeline_cam, cli_cam)]
        assert docs[0] == docs[1], name
