"""Point association: 1-NN pairs through a kd-tree, and RANSAC with a 2D (bird's-eye) rigid model.

RANSAC is vectorised: hypotheses are drawn in batches, each fitted in closed form (2D Kabsch) and scored
against all pairs at once; the number of iterations adapts to the inlier ratio (confidence) up to a cap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["NearestNeighbors", "RansacDraws", "RansacResult", "fit_rigid_2d", "ransac_rigid_2d", "random_subset",
           "smallest_per_row"]


class NearestNeighbors:
    """A kd-tree over fixed target points; ``query`` returns distances and target indices."""

    def __init__(self, target: np.ndarray) -> None:
        self.target = np.asarray(target, dtype=np.float64).reshape(-1, 3)
        self.tree = cKDTree(self.target) if len(self.target) else None

    def __len__(self) -> int:
        return len(self.target)

    def query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.tree is None or len(points) == 0:
            return np.zeros(0), np.zeros(0, dtype=np.int64)
        dist, idx = self.tree.query(points, k=1)
        return dist, idx


def random_subset(points: np.ndarray, max_points: int, rng: np.random.Generator) -> np.ndarray:
    """At most ``max_points`` rows of ``points`` chosen at random (order kept); all of them if fewer."""
    if len(points) <= max_points:
        return points
    keep = np.sort(rng.choice(len(points), size=max_points, replace=False))
    return points[keep]


def fit_rigid_2d(src: np.ndarray, dst: np.ndarray, weights: np.ndarray | None = None) -> tuple[float, np.ndarray]:
    """Least-squares 2D rotation angle and translation with dst ~ R(angle) @ src + t (closed form)."""
    w = np.ones(len(src)) if weights is None else weights
    wsum = max(float(w.sum()), 1e-12)
    cs = (w[:, None] * src).sum(axis=0) / wsum
    cd = (w[:, None] * dst).sum(axis=0) / wsum
    a, b = src - cs, dst - cd
    cos_sum = float((w * (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])).sum())
    sin_sum = float((w * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])).sum())
    angle = float(np.arctan2(sin_sum, cos_sum))
    c, s = np.cos(angle), np.sin(angle)
    t = cd - np.array([c * cs[0] - s * cs[1], s * cs[0] + c * cs[1]])
    return angle, t


def smallest_per_row(values: np.ndarray, k: int) -> np.ndarray:
    """Column indices of the ``k`` smallest entries of each row of finite ``values`` (r, m), in ascending order:
    what ``np.argpartition(values, k - 1, axis=1)[:, :k]`` returns for k <= 3 (numpy's selection for so small a k,
    and its SIMD selection, both leave the k smallest sorted), found by k row-wise argmins (several times faster).
    Rows with a tie among or next to the k smallest are left to argpartition itself, so the result never differs."""
    rows = np.arange(len(values))
    if k > 3 or k >= values.shape[1]:
        return np.argpartition(values, k - 1, axis=1)[:, :k]
    work = values.copy()
    out = np.empty((len(values), k), dtype=np.intp)
    picked = np.empty((len(values), k))
    for j in range(k):
        i = work.argmin(axis=1)
        out[:, j] = i
        picked[:, j] = work[rows, i]
        work[rows, i] = np.inf
    # distinct: strictly increasing, and no other entry of the row as small as the k-th
    tie = np.any(picked[:, 1:] <= picked[:, :-1], axis=1) | np.any(work <= picked[:, -1:], axis=1)
    if tie.any():
        out[tie] = np.argpartition(values[tie], k - 1, axis=1)[:, :k]
    return out


class RansacDraws:
    """The random draws of :func:`ransac_rigid_2d` for ``n`` pairs: the scored subset (``pick``, None: all pairs)
    and each batch's sample indices, drawn from ``rng`` in the order the search asks for them and kept, so a search
    repeated from the same generator state on the same number of pairs (:class:`~tracker.strategies.inliers.
    FixedRansac`: every outer iteration of a frame) replays them instead of drawing again. They depend only on the
    generator's state and the sizes, never on the points."""

    def __init__(self, rng: np.random.Generator, n: int, max_score_pairs: int, sample_size: int) -> None:
        self.rng, self.sample_size = rng, sample_size
        self.pick = rng.choice(n, size=max_score_pairs, replace=False) if n > max_score_pairs else None
        self.m = n if self.pick is None else max_score_pairs
        self._batches: list[np.ndarray] = []

    def samples(self, batch: int, size: int) -> np.ndarray:
        """(size, sample_size) indices into the scored pairs for batch number ``batch`` (0, 1, ...)."""
        while len(self._batches) <= batch:
            self._batches.append(smallest_per_row(self.rng.random((size, self.m)), self.sample_size))
        drawn = self._batches[batch]
        assert len(drawn) == size, "a replayed batch has the size it was drawn with"
        return drawn


@dataclass(frozen=True)
class RansacResult:
    inliers: np.ndarray     # (N,) bool
    angle: float
    translation: np.ndarray  # (2,)
    iterations: int


_add = np.add.reduce   # ndarray.sum / mean's own reduction, without their Python wrappers (the same sums)


def _squared_bev(d: np.ndarray) -> np.ndarray:
    """``(d ** 2).sum(axis=1)`` of (N, 2) differences, bit for bit (two non-negative squares: their one sum),
    without numpy's slow reduction over a short axis."""
    return d[:, 0] ** 2 + d[:, 1] ** 2


def ransac_rigid_2d(src: np.ndarray, dst: np.ndarray, rng: np.random.Generator, *, max_iterations: int = 200,
                    confidence: float = 0.99, sample_size: int = 3, threshold: float = 0.2,
                    batch_size: int = 50, max_score_pairs: int = 150, identity_first: bool = False,
                    draws: RansacDraws | None = None) -> RansacResult:
    """RANSAC for a 2D rigid transform between paired (N, 2) points ``src`` -> ``dst``.

    Inlier: BEV residual <= ``threshold``. Hypotheses are scored on at most ``max_score_pairs`` random
    pairs (for speed); the best one is refitted on its inliers among all pairs once. With
    ``identity_first`` the identity is the starting best hypothesis (a sample must beat it; upstream).
    A batch's squared residuals come from one product: with p, q the scored pairs (centred on the mean of
    ``src``) and hypothesis (R, t), |R p + t - q|^2 = |p|^2 + |q|^2 + |t|^2 + 2 [t.R p - q.R p - t.q], and the
    bracket is linear in the per-pair features (p_x, p_y, p.q, p x q, q_x, q_y).
    ``draws``: the random draws for these ``n`` pairs made before (:class:`RansacDraws`, from a generator in the
    state ``rng`` would be in); None: drawn from ``rng``.
    """
    src = np.asarray(src, dtype=np.float64)[:, :2]
    dst = np.asarray(dst, dtype=np.float64)[:, :2]
    n = len(src)
    if n < sample_size:
        return RansacResult(np.zeros(n, dtype=bool), 0.0, np.zeros(2), 0)
    centre = src.mean(axis=0)   # a rigid fit commutes with a common shift: centred coordinates, small squares
    src_c, dst_c = src - centre, dst - centre
    if draws is None:
        draws = RansacDraws(rng, n, max_score_pairs, sample_size)
    score_src, score_dst = src_c, dst_c
    if draws.pick is not None:
        score_src, score_dst = src_c[draws.pick], dst_c[draws.pick]
    m = len(score_src)
    px, py, qx, qy = score_src[:, 0], score_src[:, 1], score_dst[:, 0], score_dst[:, 1]
    features = np.stack([px, py, px * qx + py * qy, px * qy - py * qx, qx, qy])       # (6, m)
    norms = px * px + py * py + qx * qx + qy * qy                                      # (m,)
    best_count, best_angle, best_t = -1, 0.0, np.zeros(2)
    if identity_first:
        best_count = int((((score_src - score_dst) ** 2).sum(axis=1) <= threshold * threshold).sum())
    done, needed, batch = 0, max_iterations, 0
    thr2 = threshold * threshold
    while done < min(needed, max_iterations):
        b = min(batch_size, max_iterations - done)
        samples = draws.samples(batch, b)
        batch += 1
        ps, pd = score_src[samples], score_dst[samples]                     # (b, s, 2)
        cs, cd = _add(ps, axis=1) / sample_size, _add(pd, axis=1) / sample_size   # ps.mean(axis=1), bit for bit
        a, c_ = ps - cs[:, None], pd - cd[:, None]
        cos_sum = _add(a[..., 0] * c_[..., 0] + a[..., 1] * c_[..., 1], axis=1)
        sin_sum = _add(a[..., 0] * c_[..., 1] - a[..., 1] * c_[..., 0], axis=1)
        ang = np.arctan2(sin_sum, cos_sum)
        co, si = np.cos(ang), np.sin(ang)
        tx = cd[:, 0] - (co * cs[:, 0] - si * cs[:, 1])
        ty = cd[:, 1] - (si * cs[:, 0] + co * cs[:, 1])
        coefficients = np.empty((len(ang), 6))                              # (b, 6)
        coefficients[:, 0] = tx * co + ty * si
        coefficients[:, 1] = ty * co - tx * si
        np.negative(co, out=coefficients[:, 2])
        np.negative(si, out=coefficients[:, 3])
        np.negative(tx, out=coefficients[:, 4])
        np.negative(ty, out=coefficients[:, 5])
        squared = coefficients @ features
        squared *= 2.0
        squared += norms
        squared += (tx * tx + ty * ty)[:, None]
        counts = np.count_nonzero(squared <= thr2, axis=1)
        j = int(np.argmax(counts))
        if counts[j] > best_count:
            best_count, best_angle, best_t = int(counts[j]), float(ang[j]), np.array([tx[j], ty[j]])
        done += b
        ratio = best_count / m
        if ratio >= 1.0:
            needed = done
        elif ratio > 0:
            needed = int(np.ceil(np.log(1.0 - confidence) / np.log(1.0 - ratio ** sample_size)))
    co, si = np.cos(best_angle), np.sin(best_angle)
    moved = src_c @ np.array([[co, si], [-si, co]]) + best_t
    inliers = _squared_bev(moved - dst_c) <= thr2
    if inliers.sum() >= sample_size:
        angle, t = fit_rigid_2d(src_c[inliers], dst_c[inliers])
        co, si = np.cos(angle), np.sin(angle)
        moved = src_c @ np.array([[co, si], [-si, co]]) + t
        refit = _squared_bev(moved - dst_c) <= thr2
        if refit.sum() >= inliers.sum():
            inliers, best_angle, best_t = refit, angle, t
    # back from centred coordinates: dst = R (src - centre) + t + centre
    co, si = np.cos(best_angle), np.sin(best_angle)
    translation = best_t + centre - np.array([co * centre[0] - si * centre[1], si * centre[0] + co * centre[1]])
    return RansacResult(inliers, best_angle, translation, done)
