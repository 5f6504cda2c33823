"""The HTML report of a pipeline run: ``OUT/report/index.html`` + ``OUT/report/figures/*.png``.

Figures (like the paper's): tracks in bird's-eye view against ground truth, the shape filling in over
time, optical flow, simulated scans of a bank vehicle at several ranges and headings, and the motion
export's centre error vs. frames after the start. Drawn with OpenCV (no matplotlib).

The report renders what the pipeline saved: track files, the track stage's shape-growth records
(``shape_growth.json``), the motion stage's evaluation (``motion_eval.json``), the flow stage's files and the
scan units' results. It runs no tracker and no evaluation of its own.
"""

from __future__ import annotations

import html
import json
import time
from pathlib import Path

from ..io.tracks import read_track
from ..pipeline.plan import open_cached
from ..pipeline.runner import PipelineResult
from ..pipeline.stages import MOTION_EVAL_FILE, track_dir
from ..tracking import read_shape_growth
from .figures import flow_figure, motion_figure, scans_figure, score_tracks, shape_growth_figure, tracks_bev_figure
from .page import Section, table_html, write_page

__all__ = ["build_report"]


def _fmt(value, digits: int = 2, scale: float = 1.0) -> str:
    return "–" if value is None else f"{value * scale:.{digits}f}"


def build_report(result: PipelineResult, title: str = "sot-apps pipeline report", intro: list[str] | None = None,
                 max_sequences: int = 2) -> Path:
    """Write ``OUT/report/index.html`` for a finished :func:`run_pipeline` result; returns its path."""
    out = Path(result.out)
    report = out / "report"
    figures = report / "figures"
    sections: list[Section] = []
    start = time.perf_counter()

    # --- overview
    overview = Section("Run overview")
    rows = []
    for stage in ("track", "bank", "motion", "flow", "scans"):
        units = result.by_stage(stage)
        if units:
            rows.append([stage, sum(u.status == "done" for u in units), sum(u.status == "cached" for u in units),
                         sum(u.status == "failed" for u in units), sum(u.status == "skipped" for u in units),
                         f"{result.stage_seconds.get(stage, 0.0):.1f}"])
    overview.tables.append(table_html(["stage", "ran", "already done", "failed", "skipped", "seconds"], rows))
    overview.paragraphs.append(f"Outputs: <code>{html.escape(str(out))}</code> (manifest.json, failures.json; "
                               "tree described in docs/pipeline.md). Total pipeline time "
                               f"{result.seconds:.1f} s.")
    if result.failed:
        overview.tables.append(table_html(["failed unit", "error"], [[u.key, (u.error or "")[:160]] for u in result.failed]))
    sections.append(overview)

    for s in result.plan.sequences[:max_sequences]:
        seq = open_cached(s.path, s.format)
        tracked = [o.object_id for o in s.objects if (track_dir(out, s.name, o.object_id) / "track.json").is_file()]
        if not tracked:
            sections.append(Section(f"{s.name}: tracking", [f"No object of {html.escape(s.name)} was tracked."]))
            continue
        dirs = [track_dir(out, s.name, o) for o in tracked]
        tracks = [read_track(d)[1] for d in dirs]
        scores = score_tracks(seq, tracks)
        sec = Section(f"{s.name}: tracks against ground truth")
        health = {h["object"]: h for h in result.track_health if h["sequence"] == s.name}
        sec.tables.append(table_html(
            ["#", "object", "label", "frames", "measured frames", "tracker's verdict", "mean 3D IoU",
             "mean centre error (cm)", "points / frame", "quality", "shape points"],
            [[i + 1, sc.object_id[:12], sc.label, sc.frames, _measured(health.get(sc.object_id)),
              health.get(sc.object_id, {}).get("status", "?"), _fmt(sc.mean_iou, 3),
              _fmt(sc.mean_centre_error_m, 1, 100), f"{sc.mean_points:.0f}", f"{sc.mean_quality:.2f}", sc.shape_points]
             for i, sc in enumerate(scores)]))
        sec.paragraphs.append(_lost_paragraph(health, scores))
        name = f"{s.name}_tracks_bev.png"
        tracks_bev_figure(seq, tracks, figures / name)
        sec.images.append((f"figures/{name}", "Tracked objects (one colour and number each, see the legend), annotated "
                                              "boxes (green) and the ego, bird's-eye view"))
        sections.append(sec)

        recorded = [(len(t.shape_points), t.object_id, d) for t, d in zip(tracks, dirs, strict=True)]
        growth = next((g for _, _, d in sorted(recorded, reverse=True) if (g := read_shape_growth(d)) is not None), None)
        if growth is not None:
            name = f"{s.name}_shape_growth.png"
            shape_growth_figure(growth, figures / name)
            sections.append(Section(f"{s.name}: shape filling in over time", [
                f"Object <code>{html.escape(growth.object_id)}</code>: the tracker's aggregated shape (object frame) "
                "after a few frames, as recorded by the track stage; key frames add the points of the current "
                "frame."], [(f"figures/{name}", "Shape growth")]))

        flow_imgs = []
        for camera in s.cameras:
            name = f"{s.name}_{camera}_flow.png"
            if flow_figure(seq, out / s.name / "flow", camera, figures / name) is not None:
                flow_imgs.append((f"figures/{name}", f"{camera}: image, flow, overlay"))
        if flow_imgs:
            sections.append(Section(f"{s.name}: optical flow", [
                "Flow of the tracked objects between consecutive images, from their shapes moved by the tracked "
                "motion (Middlebury colour wheel; overlay outlines each object)."], flow_imgs))

        evaluation_path = out / s.name / MOTION_EVAL_FILE
        if evaluation_path.is_file():
            acc = json.loads(evaluation_path.read_text())
            name = f"{s.name}_motion_error.png"
            motion_figure(acc, figures / name,
                          f"Motion export vs. ground truth, {seq.id}, {len(acc['tracks'])} tracks")
            curve = acc.get("mean_centre_3d_by_k") or []
            ks = [k for k in (1, 2, 5, 10, 15, 20, 30) if k <= len(curve)]
            table = table_html(["k (frames after start)"] + [str(k) for k in ks],
                               [["mean centre error (cm)"] + [_fmt(curve[k - 1], 1, 100) for k in ks]])
            sections.append(Section(f"{s.name}: motion export error", [
                "Centre error of the exported (smoothed) motion against the annotations, k frames after each "
                "track's start."], [(f"figures/{name}", "Centre error vs k")], [table]))

    scenes = [u.result for u in result.by_stage("scans") if u.status in ("done", "cached") and u.result]
    if scenes:
        entry = min(s["entry"] for s in scenes)
        mine = sorted((s for s in scenes if s["entry"] == entry), key=lambda s: s["range_m"])
        dirs = [out / "scans" / s["scene"] for s in mine]
        ranges = ", ".join(f"{s['range_m']:g} m" for s in mine)
        name = "scans.png"
        if scans_figure(out / "scans", dirs, figures / name) is not None:
            sections.append(Section("Simulated scans", [
                f"Bank vehicle <code>{html.escape(entry)}</code> (meshed from its tracked shape) ray cast at "
                f"{ranges}, several headings. Scan files in "
                "<code>scans/</code>."], [(f"figures/{name}", "Simulated scans")]))

    intro = list(intro or [])
    intro.append(f"Report written in {time.perf_counter() - start:.1f} s.")
    return write_page(report / "index.html", title, intro, sections)


GT_LOST_IOU = 0.3   # mean 3D IoU below which the report calls a track lost against the annotations


def _measured(h: dict | None) -> str:
    return "?" if h is None else f"{h['measured']}/{h['frames']}"


def _lost_paragraph(health: dict, scores) -> str:
    """Which tracks look lost by the tracker's own evidence (no ground truth needed) and which are lost
    against the annotations (mean 3D IoU < GT_LOST_IOU)."""
    own = sorted(o[:8] for o, h in health.items() if h["status"] == "lost")
    weak = sorted(o[:8] for o, h in health.items() if h["status"] == "weak")
    truth = sorted(sc.object_id[:8] for sc in scores if sc.mean_iou is not None and sc.mean_iou < GT_LOST_IOU)
    return (f"<b>Tracks that look lost</b> (the tracker's own evidence: measured in fewer than 20 % of the frames after "
            f"the start; rule in docs/pipeline.md): {html.escape(', '.join(own) or 'none')}. Weak (measured in fewer "
            f"than 80 %): {html.escape(', '.join(weak) or 'none')}. Lost against the annotations (mean 3D IoU below "
            f"{GT_LOST_IOU}): {html.escape(', '.join(truth) or 'none')}.")
