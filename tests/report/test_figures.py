"""The report's figures have what a paper's figures have (issue 16): checked on their properties, not pixels."""

from __future__ import annotations

import cv2
import numpy as np

from sot_apps.io.object_track import ObjectTrack
from sot_apps.report.draw import (
    BevCanvas,
    LegendEntry,
    colour_bar,
    legend_panel,
    place_labels,
    rects_overlap,
    with_metre_axes,
)
from sot_apps.report.figures import flow_key, shape_growth_figure, tracks_bev_figure
from sot_apps.tracking import ShapeGrowth


def _tracks_from_annotations(seq, count: int) -> list[ObjectTrack]:
    """``count`` annotated PandaSet tracks, longest first, as a track file's rows would hold them (one box size)."""
    annotated = seq.tracks()
    ids = sorted(annotated, key=lambda t: (-len(annotated[t].frames), t))[:count]
    out = []
    for tid in ids:
        gt = annotated[tid]
        n = len(gt)
        out.append(ObjectTrack.from_states(tid, gt.label, gt.boxes[0, 4:7], gt.frames, gt.timestamps_ns, gt.states,
                                           None, scores=[0.9] * n, num_points=[50] * n, shape_points=np.zeros((0, 3))))
    return out


def test_bev_of_a_busy_sequence_names_every_object_and_its_labels_do_not_overlap(pandaset, tmp_path):
    tracks = _tracks_from_annotations(pandaset, 15)
    figure = tracks_bev_figure(pandaset, tracks, tmp_path / "bev.png")
    image = cv2.imread(str(figure.path))
    assert image is not None and image.shape[0] > 400
    # one legend entry and one distinct colour per object (not one "tracked" colour for all)
    assert len(figure.object_labels) == 15
    assert all(t.object_id[:10] in label for t, label in zip(tracks, figure.object_labels, strict=True))
    assert len(set(figure.object_colours)) == 15
    # one numbered label per object, none overlapping another
    assert len(figure.label_rects) == 15
    rects = figure.label_rects
    assert not any(rects_overlap(rects[i], rects[j]) for i in range(15) for j in range(i + 1, 15))


def test_place_labels_separates_labels_of_anchors_at_one_spot():
    anchors = np.array([[200.0, 150.0]] * 15 + [[10.0, 10.0]])
    rects = place_labels(anchors, [(30, 20)] * 16, (400, 300))
    assert len(rects) == 16
    assert not any(rects_overlap(rects[i], rects[j]) for i in range(16) for j in range(i + 1, 16))
    assert all(0 <= r[0] and 0 <= r[1] and r[2] <= 400 and r[3] <= 300 for r in rects)


def test_metre_axes_frame_the_view_and_the_colour_bar_has_a_ramp():
    canvas = BevCanvas.fit(np.array([0.0, 0.0]), np.array([40.0, 20.0]), width=400, margin=0.0)
    framed = with_metre_axes(canvas, 10.0)
    assert framed.shape[0] > canvas.image.shape[0] and framed.shape[1] > canvas.image.shape[1]
    # tick labels are drawn left of and below the view (dark pixels in the margins)
    assert (framed[:, :50] < 100).any() and (framed[-40:] < 100).any()
    bar = colour_bar(cv2.COLORMAP_VIRIDIS, 0.0, 1.5, "height (m)", height=100)
    column = bar[24:124, 8].astype(int)
    assert np.abs(np.diff(column, axis=0)).sum() > 200          # the colour changes along the bar
    assert legend_panel([LegendEntry("box", (0, 0, 255), "a"), LegendEntry("ego", (0, 0, 0), "b")]).shape[0] >= 44


def test_shape_growth_figure_draws_the_record_with_a_colour_bar(tmp_path):
    rng = np.random.default_rng(0)
    size = (4.0, 1.8, 1.5)
    points = tuple(rng.uniform(-0.5, 0.5, (n, 3)) * np.array(size) for n in (50, 200, 400))
    growth = ShapeGrowth("car", 3, size, (3, 8, 12), points)
    assert ShapeGrowth.from_json(growth.to_json()).frames == (3, 8, 12)
    path = shape_growth_figure(growth, tmp_path / "growth.png")
    image = cv2.imread(str(path))
    # the viridis bar at the right edge: its top (yellow) and bottom (purple) colours are present
    right = image[:, -240:].reshape(-1, 3).astype(int)
    assert (np.abs(right - np.array([36, 231, 253])).sum(axis=1) < 60).any()   # yellow (BGR)
    assert (np.abs(right - np.array([84, 1, 68])).sum(axis=1) < 60).any()      # purple (BGR)


def test_flow_key_is_a_colour_wheel_saturated_at_its_rim():
    key = flow_key(20.0, size=150)
    r = 150 // 2 - 4
    centre = np.array([26 + r, 26 + r])
    hues = {tuple(int(v) // 40 for v in key[int(centre[1] - 0.9 * r * np.sin(a)), int(centre[0] + 0.9 * r * np.cos(a))])
            for a in np.linspace(0, 2 * np.pi, 12, endpoint=False)}
    assert len(hues) >= 8                                          # different directions, different colours
    assert (key[centre[1] - 3, centre[0] - 3] > 230).all()         # (near) zero flow is white (the axes start at 0)
