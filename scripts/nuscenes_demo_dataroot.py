"""Write ../shared's nuScenes demo keyframe (mmdetection3d's info layout) as a one-sample nuScenes dataroot that
`sot_apps.io.nuscenes` opens, with the category names of the info file's metainfo (the bank of docs/benchmark.md).

    python scripts/nuscenes_demo_dataroot.py ../shared/data/readers/nuscenes_demo OUT_DIR
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tests.readers import test_nuscenes  # noqa: E402  (the reader tests' independent table writer)


def main(demo: Path, out: Path) -> None:
    if out.exists():
        sys.exit(f"{out}: exists; remove it first")
    test_nuscenes.NUSCENES_DEMO = demo
    names = {str(index): name for name, index in
             json.loads((demo / "DERIVED_info_from_pkl.json").read_text())["metainfo"]["categories"].items()}
    with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
        root, _ = test_nuscenes._demo_dataroot(Path(tmp))
        table = root / "v1.0-mini" / "category.json"
        rows = json.loads(table.read_text())
        for row in rows:
            row["name"] = names.get(row["name"], row["name"])
        table.write_text(json.dumps(rows))
        shutil.move(str(root), str(out))


if __name__ == "__main__":
    main(Path(sys.argv[1]).resolve(), Path(sys.argv[2]).resolve())
