"""tracker/rows.py: the column forms give numpy's row-wise reductions of (N, 3) arrays bit for bit."""

import numpy as np

from tracker.rows import all3, finite3, inside3, norm3, sum3


def _rows(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    a = rng.standard_normal((20000, 3)) * rng.uniform(1e-6, 1e6, (20000, 1))   # magnitudes that round differently
    a[:10] = [[np.nan, 0, 1], [np.inf, 1, 2], [-np.inf, np.inf, 0], [0.0, -0.0, -0.0], [-0.0, -0.0, -0.0],
              [1e308, 1e308, 1.0], [1, 1e-300, -1], [0.1, 0.2, 0.3], [3, 4, 12], [1, 1, 1]]
    return a


def test_sums_and_norms_are_numpys_bit_for_bit():
    a = _rows()
    with np.errstate(all="ignore"):   # the rows that overflow or hold inf and NaN
        pairs = ((sum3(a), np.sum(a, axis=1)), (norm3(a), np.linalg.norm(a, axis=1)),
                 (sum3(a * a[::-1]), np.sum(a * a[::-1], axis=1)))
    for got, want in pairs:
        assert np.array_equal(got, want, equal_nan=True)
        assert np.array_equal(np.signbit(got), np.signbit(want))   # signed zeros too
    assert norm3(np.array([[3.0, 4.0, 12.0]]))[0] == 13.0


def test_masks_are_numpys():
    a = _rows(1)
    half = np.array([0.5, 2.0, 1e3])
    assert np.array_equal(all3(a > 0), np.all(a > 0, axis=1))
    assert np.array_equal(finite3(a), np.all(np.isfinite(a), axis=1))
    assert np.array_equal(inside3(a, half), np.all(np.abs(a) <= half, axis=1))
    assert inside3(np.array([[0.5, -2.0, 1e3], [0.5, 2.0, np.nan]]), half).tolist() == [True, False]
