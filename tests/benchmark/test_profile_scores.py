"""Scores of the hard profiles on analytic IoU and heading sequences."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sot_apps.benchmark.profile_scores import heading_error_deg, pool_figures, tracklet_figures


def test_relock_counts_the_reappearing_frame_and_three_after():
    ious = np.zeros(19)  # frames 1..19
    hidden = {"profile": "hidden", "reappear_frame": 10}
    assert tracklet_figures(hidden, ious, [0.0], [0.0])["relocked"] == 0.0
    ious[13 - 1] = 0.5   # frame 13 = reappear + 3
    assert tracklet_figures(hidden, ious, [0.0], [0.0])["relocked"] == 1.0
    ious[:] = 0.0
    ious[14 - 1] = 0.9   # frame 14: one frame too late
    assert tracklet_figures(hidden, ious, [0.0], [0.0])["relocked"] == 0.0


def test_relock_must_hold_from_the_first_locked_frame_to_the_end_of_the_window():
    hidden = {"profile": "hidden", "reappear_frame": 10}
    ious = np.zeros(19)               # frames 1..19; the window is frames 10..13
    ious[11 - 1:] = 0.6               # locked at frame 11 and held after: re-locked both ways
    figures = tracklet_figures(hidden, ious, [0.0], [0.0])
    assert figures["relocked"] == 1.0 and figures["relocked_any"] == 1.0
    ious[12 - 1] = 0.1                # captured by something else at frame 12, back at 13: not held
    figures = tracklet_figures(hidden, ious, [0.0], [0.0])
    assert figures["relocked"] == 0.0 and figures["relocked_any"] == 1.0
    ious[:] = 0.0
    ious[10 - 1] = 0.5                # touched at the re-appearing frame only, then lost
    figures = tracklet_figures(hidden, ious, [0.0], [0.0])
    assert figures["relocked"] == 0.0 and figures["relocked_any"] == 1.0
    ious[:] = 0.0
    ious[17 - 1] = 0.5                # a window cut by the tracklet's end: frames 16..17 of frames 0..17
    short = tracklet_figures({"profile": "hidden", "reappear_frame": 16}, ious[:17], [0.0], [0.0])
    assert short["relocked"] == 1.0
    pooled = pool_figures([figures, short])
    assert pooled["relock_share"] == pytest.approx(0.5) and pooled["relock_any_share"] == pytest.approx(1.0)


def test_found_near_and_heading_error_at_the_last_frame():
    ious = np.full(9, 0.1)
    ious[4 - 1] = 0.31
    far = tracklet_figures({"profile": "far_approach", "near_frame": 4}, ious, [0.0], [0.0])
    assert far == {"found_near": 1.0}
    assert tracklet_figures({"profile": "far_approach", "near_frame": None}, ious, [0.0], [0.0]) == {}
    oblique = tracklet_figures({"profile": "oblique"}, ious, [0.0, math.radians(178.0)], [0.0, math.radians(-178.0)])
    assert oblique["heading_err_last_deg"] == pytest.approx(4.0)
    assert heading_error_deg(math.radians(10.0), math.radians(-35.0)) == pytest.approx(45.0)


def test_pool_shares_and_median():
    pooled = pool_figures([{"relocked": 1.0}, {"relocked": 0.0}, {"relocked": 1.0}, {"heading_err_last_deg": 3.0},
                           {"heading_err_last_deg": 9.0}, {"heading_err_last_deg": 4.0}, {}])
    assert pooled["relock_share"] == pytest.approx(2 / 3) and pooled["relock_n"] == 3
    assert pooled["heading_err_last_med_deg"] == 4.0 and "found_near_share" not in pooled
