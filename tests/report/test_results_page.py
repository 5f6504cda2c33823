"""docs/results.md is generated from saved result JSON by one command (``sot-apps results``), each section stamped
with the commands, machine and date of its file."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from sot_apps.cli.main import main
from sot_apps.provenance import cpu_model, invoked_command
from sot_apps.report.results import read_results, render_results

REPO = Path(__file__).resolve().parents[2]


def test_docs_results_is_the_page_of_the_saved_results():
    """The committed page is what `sot-apps results results --out docs/results.md` makes of results/ now."""
    page = render_results(read_results(REPO / "results"), "results")
    assert (REPO / "docs" / "results.md").read_text() == page


@pytest.mark.slow
def test_eval_json_is_stamped_and_rendered_with_its_figures(pandaset_root, tmp_path, capsys):
    results = tmp_path / "results"
    results.mkdir()
    eval_json = results / "a_dev.eval.json"
    assert main(["eval", str(pandaset_root), "--tracks", "91aa5b5c", "--end-frame", "5", "--json", str(eval_json)]) == 0
    doc = json.loads(eval_json.read_text())
    prov = doc["provenance"]
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", prov["date"])
    assert prov["machine"]["cpu"] == cpu_model() and prov["commands"] == [invoked_command()]
    # a command that records no provenance: stamped afterwards
    flat = results / "b_speed.json"
    flat.write_text(json.dumps({"rays": 1000, "cast_rays_per_s": 2.5e6, "backend": "compiled"}))
    assert main(["results", "--stamp", str(flat), "--command", "sot-apps bench raycast --json b_speed.json",
                 "--date", "2026-01-02T03:04:05Z", "--title", "Ray casting"]) == 0
    page_path = tmp_path / "results.md"
    assert main(["results", str(results), "--out", str(page_path)]) == 0
    capsys.readouterr()
    page = page_path.read_text()
    pooled = doc["rows"][0]["pooled"]
    row = next(line for line in page.splitlines() if line.startswith("| `full` |"))
    assert row.startswith(f"| `full` | {100 * pooled['acc']:.1f} / {100 * pooled['rob']:.1f} |")
    assert f"{pooled['precision']:.1f}" in row
    assert "## Ray casting" in page and "| `cast_rays_per_s` | 2.5e+06 |" in page and "| `backend` | compiled |" in page
    assert "measured 2026-01-02T03:04:05Z" in page and "sot-apps bench raycast --json b_speed.json" in page
    assert f"- {cpu_model()}, " in page and page.index("a_dev.eval.json") < page.index("## Ray casting")
    # the same files give the same page
    assert render_results(read_results(results), str(results), str(page_path)) == page


def test_a_result_without_provenance_is_a_one_line_error(tmp_path, capsys):
    results = tmp_path / "results"
    results.mkdir()
    (results / "old.json").write_text(json.dumps({"rays": 10}))
    out = tmp_path / "page.md"
    assert main(["results", str(results), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "old.json" in err and "provenance" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
    (results / "old.json").write_text("[1, 2]")
    assert main(["results", str(results)]) == 2 and "JSON object" in capsys.readouterr().err
    assert main(["results", str(tmp_path / "none")]) == 2 and "not a directory" in capsys.readouterr().err
