"""RANSAC's draws: the row-wise k smallest (what argpartition gives), and draws replayed for a repeated search
give the same result as drawing them again from the same seed (FixedRansac's per-frame cache)."""

from __future__ import annotations

import numpy as np

from tracker.association import RansacDraws, ransac_rigid_2d, smallest_per_row
from tracker.config import RansacConfig
from tracker.strategies.inliers import FixedRansac


def test_smallest_per_row_is_the_sorted_k_smallest_and_argpartitions_answer():
    rng = np.random.default_rng(3)
    for m in (3, 4, 7, 150, 300):
        values = rng.random((50, m))
        values[0, :3] = values[0, 3 % m]   # a tie among the smallest
        values[1, 1] = values[1].min()     # a tie at the minimum
        values[2, 2:] = 0.5                # ties everywhere
        for k in (1, 2, 3):
            got = smallest_per_row(values, k)
            want_values = np.sort(values, axis=1)[:, :k]
            assert np.array_equal(np.take_along_axis(values, got, axis=1), want_values)
            assert np.array_equal(got, np.argpartition(values, k - 1, axis=1)[:, :k])
            assert all(len(set(row)) == k for row in got.tolist())


def _pairs(rng: np.random.Generator, n: int, angle: float) -> tuple[np.ndarray, np.ndarray]:
    src = rng.uniform(-2.0, 2.0, (n, 2))
    c, s = np.cos(angle), np.sin(angle)
    dst = src @ np.array([[c, s], [-s, c]]) + np.array([0.4, -0.2]) + rng.normal(0.0, 0.02, (n, 2))
    outliers = rng.random(n) < 0.3
    dst[outliers] += rng.uniform(-3.0, 3.0, (int(outliers.sum()), 2))
    return src, dst


def test_replayed_draws_give_the_result_of_fresh_draws():
    rng = np.random.default_rng(0)
    for n in (40, 400):   # all pairs scored, and a scored subset
        draws = RansacDraws(np.random.default_rng(11), n, 150, 3)
        for angle in (0.05, -0.1, 0.3):   # different points, same number of pairs: the draws are replayed
            src, dst = _pairs(rng, n, angle)
            fresh = ransac_rigid_2d(src, dst, np.random.default_rng(11), max_score_pairs=150)
            replayed = ransac_rigid_2d(src, dst, draws.rng, max_score_pairs=150, draws=draws)
            assert np.array_equal(fresh.inliers, replayed.inliers)
            assert (fresh.angle, fresh.iterations) == (replayed.angle, replayed.iterations)
            assert np.array_equal(fresh.translation, replayed.translation)
            assert abs(fresh.angle - angle) < 0.02 and int(fresh.inliers.sum()) > 0.6 * n


def test_fixed_ransac_with_its_cache_matches_a_fresh_generator_per_call():
    params = RansacConfig(mode="fixed", max_iterations=200, confidence=0.99, sample_size=3, inlier_threshold=0.2,
                          min_inliers=10, score_pairs=300)
    strategy = FixedRansac(params)
    rng = np.random.default_rng(5)
    for seed, n, angle in [(7, 500, 0.1), (7, 500, 0.12), (7, 320, 0.1), (7, 500, 0.11), (9, 500, 0.1)]:
        src, dst = _pairs(rng, n, angle)
        src3, dst3 = np.c_[src, np.zeros(n)], np.c_[dst, np.zeros(n)]
        idx = np.arange(n)
        kept = strategy.select(src3, idx, dst3, src3, seed, rng)
        want = ransac_rigid_2d(src, dst, np.random.default_rng(seed), max_iterations=200, confidence=0.99,
                               sample_size=3, threshold=0.2, max_score_pairs=300).inliers
        assert np.array_equal(kept[1], idx[want])
