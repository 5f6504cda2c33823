"""The auto-labels app (not a version-1 stage: it runs when the pipeline file has a section for it)."""

from __future__ import annotations

import uuid

import numpy as np

from .conftest import tracking_doc


def test_autolabels_app_writes_av2_labels_of_the_tracks(tmp_path, tiny_world):
    import pyarrow.feather as feather

    from sot_apps.io import open_sequence
    from sot_apps.pipeline.config import PipelineConfig
    from sot_apps.pipeline.executors import ExecutorSpec
    from sot_apps.pipeline.runner import run_pipeline

    out = tmp_path / "out"
    config = PipelineConfig.from_json(tracking_doc(tiny_world, out, autolabels={}))
    result = run_pipeline(config, ExecutorSpec("inline"), progress=False)
    assert not result.failed
    [unit] = result.by_stage("autolabels")
    assert unit.status == "done" and unit.result["labels"] == 3
    assert "kitti: not written" in unit.result["notes"][0]        # no camera in this world
    table = feather.read_table(next(out.glob("*/labels/av2/annotations.feather"))).to_pandas()
    seq = open_sequence(tiny_world)
    ids = {str(uuid.uuid5(uuid.NAMESPACE_URL, f"sot-apps:{seq.id}:{t}")): t for t in ("veh_000", "veh_001", "veh_002")}
    assert set(table["track_uuid"]) == set(ids)
    assert len(table) == unit.result["boxes"]
    # the labels are the tracked boxes (AV2: in the ego frame of their sweep): close to the annotations
    tracks = seq.tracks()
    errors = []
    for row in table.itertuples():
        frame = int(np.argmin(np.abs(seq.timestamps_ns - int(row.timestamp_ns))))
        box = tracks[ids[row.track_uuid]].box_at(frame)
        ego = np.linalg.inv(seq.frames[frame].world_from_ego) @ [box.x, box.y, box.z, 1.0]
        errors.append(np.hypot(row.tx_m - ego[0], row.ty_m - ego[1]))
    assert np.median(errors) < 0.3, np.median(errors)

    again = run_pipeline(config, ExecutorSpec("inline"), progress=False)
    [unit2] = again.by_stage("autolabels")
    assert unit2.status == "cached" and unit2.result == unit.result
