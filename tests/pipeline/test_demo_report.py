"""`sot-apps demo` writes an HTML report that opens in headless Chromium with every figure loaded."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import cv2
import pytest


def chromium_dom(page: Path, profile: Path) -> str:
    """The page's DOM after load, dumped by headless Chromium (Debian package ``chromium``)."""
    binary = shutil.which("chromium") or shutil.which("chromium-browser")
    if binary is None:
        pytest.fail("headless Chromium is needed: apt-get install chromium")
    cmd = [binary, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
           "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-dev-shm-usage",
           f"--user-data-dir={profile}", "--virtual-time-budget=10000", "--dump-dom", page.resolve().as_uri()]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def test_readme_first_command_demo_report_opens_with_every_figure(tmp_path):
    """README's first command, `sot-apps demo --out DIR` with its defaults (synthetic world with a camera,
    every stage), then the report in a browser."""
    import sys
    import time

    out = tmp_path / "demo_out"
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "sot_apps.cli.main", "demo", "--out", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    print(f"sot-apps demo took {time.perf_counter() - start:.1f} s")
    assert f"report: {out / 'report' / 'index.html'}" in done.stdout
    page = out / "report" / "index.html"
    source = page.read_text()
    # issue 16, defect 10: the summary and the report say which tracks look lost, not just "done"
    assert "track health (tracker's own evidence" in done.stdout
    assert "Tracks that look lost" in source and "verdict</th>" in source
    sources = re.findall(r'<img src="([^"]+)"', source)
    # the paper-like figures: tracks vs GT, shape growth, flow, simulated scans, motion error curve
    for part in ("tracks_bev", "shape_growth", "front_camera_flow", "scans", "motion_error"):
        assert any(part in s for s in sources), f"no {part} figure in the report"
    for src in sources:
        assert not Path(src).is_absolute() and (page.parent / src).is_file()
        image = cv2.imread(str(page.parent / src))
        assert image is not None and image.shape[0] > 50 and image.shape[1] > 50
    assert (out / "synth_s3" / "motion.mcap").is_file()
    assert json.loads((out / "failures.json").read_text()) == {"failures": []}

    dom = chromium_dom(page, tmp_path / "chromium-profile")
    body = re.search(r"<body[^>]*>", dom).group(0)
    total = int(re.search(r'data-images-total="(\d+)"', body).group(1))
    loaded = int(re.search(r'data-images-loaded="(\d+)"', body).group(1))
    assert total == len(sources) >= 5
    assert loaded == total


def test_report_check_notices_a_missing_figure(tmp_path):
    """The self-check is not vacuous: a page whose figure is missing reports one image fewer."""
    from sot_apps.report.page import Section, render_page

    good = tmp_path / "good.png"
    cv2.imwrite(str(good), (255 * cv2.getGaussianKernel(64, 10) @ cv2.getGaussianKernel(64, 10).T).astype("uint8"))
    html = render_page("check", [], [Section("figures", images=[("good.png", "present"), ("missing.png", "absent")])])
    page = tmp_path / "index.html"
    page.write_text(html)
    dom = chromium_dom(page, tmp_path / "chromium-profile")
    assert 'data-images-total="2"' in dom
    assert 'data-images-loaded="1"' in dom
