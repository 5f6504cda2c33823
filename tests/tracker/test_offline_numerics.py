"""The refinement's numerical pieces against independent computations: the banded normal equations
against a dense Kronecker build, the closed-form normals against numpy's eigh, the Gauss-Newton blocks
against finite differences of the residuals, and the cropped region points (with and without de-skew)
against moving the whole sweep first."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree
from tracker_synthetic import make_sequence

from tracker.config import OfflineParams, get_preset
from tracker.frames import LidarFrame
from tracker.geometry import Box, make_transform, points_in_box, rotation_z, transform_points
from tracker.ground import ground_mask
from tracker.offline import _BANDS, _neighbour_covariances, _normals, _prior_band, _Solver, frame_region_points
from tracker.sotracker import Tracker, deskew_points
from tracker.sweep_ground import sweep_ground_mask


def _dense_from_upper_band(band: np.ndarray) -> np.ndarray:
    u, n = band.shape[0] - 1, band.shape[1]
    h = np.zeros((n, n))
    for i in range(n):
        for j in range(i, min(n, i + u + 1)):
            h[i, j] = h[j, i] = band[u + i - j, j]
    return h


@pytest.mark.parametrize("k", [2, 3, 7])
def test_prior_band_is_the_kronecker_hessian(k):
    sig, anchor = np.array([0.03, 0.03, 0.02, 0.01]), np.array([1.0, 1.0, 1.0, 0.3])
    d = np.zeros((max(k - 2, 0), k))
    for r in range(k - 2):
        d[r, r:r + 3] = [1.0, -2.0, 1.0]
    dense = np.kron(d.T @ d, np.diag(1.0 / sig**2)) + np.kron(np.eye(k), np.diag(1.0 / anchor**2))
    band = _prior_band(k, sig, anchor)
    assert band.shape == (_BANDS + 1, 4 * k)
    np.testing.assert_allclose(_dense_from_upper_band(band), dense, rtol=1e-12)


def test_closed_form_normals_are_the_pca_normals():
    rng = np.random.default_rng(0)
    plane = rng.normal(size=(400, 3)) * [1.0, 1.0, 0.01]
    wall = rng.normal(size=(300, 3)) * [0.01, 1.0, 1.0] + [4.0, 0.0, 0.0]
    line = np.c_[np.linspace(0, 2, 40), np.zeros(40), np.zeros(40)] + [0.0, 6.0, 0.0]   # degenerate: eigh decides
    shape = np.unique(np.round(np.vstack([plane, wall, line]) / 0.1) * 0.1 + 0.05, axis=0)
    normals = _normals(shape, 10)
    _, idx = cKDTree(shape).query(shape, k=10)
    nb = shape[idx] - shape[idx].mean(axis=1, keepdims=True)
    cov = np.einsum("mki,mkj->mij", nb, nb) / 10
    values, vectors = np.linalg.eigh(cov)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    # every normal is an eigenvector of the smallest eigenvalue (Rayleigh quotient = that eigenvalue)
    rayleigh = np.einsum("mi,mij,mj->m", normals, cov, normals)
    assert np.all(rayleigh - values[:, 0] <= 1e-9 * (values[:, 2] + 1e-12))
    separated = (values[:, 1] - values[:, 0]) > 1e-3 * values[:, 2]
    assert separated.sum() > 0.9 * len(shape)
    np.testing.assert_allclose(np.abs(np.sum(normals * vectors[:, :, 0], axis=1))[separated], 1.0, atol=1e-9)


def _solver_on_a_synthetic_track(n_frames: int, fixed: int = 0, params: OfflineParams = OfflineParams()
                                 ) -> tuple[_Solver, np.ndarray, OfflineParams]:
    """A refinement solver over a synthetic track's region points, its shapes built and data selected at the true
    states perturbed by a few cm / 1 degree (returned)."""
    seq = make_sequence(n_frames=n_frames, seed=2)
    points = [frame_region_points(seq.lidar_frame(k), b, get_preset("full"), params) for k, b in enumerate(seq.boxes)]
    truth = np.array([[b.x, b.y, b.z, b.heading] for b in seq.boxes])
    states = truth + np.random.default_rng(1).normal(0.0, [0.05, 0.05, 0.02, 0.02], truth.shape)
    solver = _Solver(points, truth, np.array(seq.boxes[0].size), params, np.random.default_rng(0), fixed=fixed)
    assert solver.set_shapes(states)
    solver.select(states)
    return solver, states, params


def test_gauss_newton_blocks_match_finite_differences_of_the_residuals():
    solver, states, params = _solver_on_a_synthetic_track(6, fixed=1)
    assert np.all(solver.frame_idx >= 1) and len(solver.pts) > 100   # the held frame's points are left out
    _, blocks, grads = solver._data(states, True)

    beta, delta = params.tangent_weight, params.huber_delta
    local0 = np.empty_like(solver.pts)
    for k in range(len(states)):
        sel = solver.frame_idx == k
        c, s = np.cos(states[k, 3]), np.sin(states[k, 3])
        local0[sel] = (solver.pts[sel] - states[k, :3]) @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    dist, m, n = solver._match(local0)   # correspondences held fixed, as within one Gauss-Newton step

    def residuals(st: np.ndarray) -> np.ndarray:
        s = st[solver.frame_idx]
        c, si = np.cos(s[:, 3]), np.sin(s[:, 3])
        d = solver.pts - s[:, :3]
        e = np.c_[c * d[:, 0] + si * d[:, 1], -si * d[:, 0] + c * d[:, 1], d[:, 2]] - m
        return (1 - beta) * n * np.sum(n * e, axis=1)[:, None] + beta * e

    r = residuals(states)
    norm = np.linalg.norm(r, axis=1)
    w = solver.point_scale * (dist <= params.max_pair_distance) * np.where(norm <= delta, 1.0, delta / norm)
    jac = np.zeros((len(r), 3, 4))
    for comp in range(4):
        step = np.zeros_like(states)
        step[:, comp] = 1e-6
        jac[:, :, comp] = (residuals(states + step) - residuals(states - step)) / 2e-6
    for k in range(1, len(states)):
        sel = solver.frame_idx == k
        ref_block = np.einsum("p,pia,pib->ab", w[sel], jac[sel], jac[sel])
        ref_grad = np.einsum("p,pia,pi->a", w[sel], jac[sel], r[sel])
        np.testing.assert_allclose(blocks[k], ref_block, rtol=1e-5, atol=1e-6 * np.abs(ref_block).max())
        np.testing.assert_allclose(grads[k], ref_grad, rtol=1e-5, atol=1e-6 * np.abs(ref_grad).max())


def _naive_region(world: np.ndarray, points_ego: np.ndarray, box: Box, params: OfflineParams, config) -> np.ndarray:
    sweep = params.ground == "tracker" and config.ground.remover == "sweep"
    if sweep:  # the tracker's ground: the whole sweep's one plane, on the sensor-frame points
        world = world[~sweep_ground_mask(points_ego, *config.ground.sweep_args())]
    reach = 0.5 * max(box.length, box.width) * params.region_scale + params.ground_margin
    local = world[(np.abs(world[:, 0] - box.x) <= reach) & (np.abs(world[:, 1] - box.y) <= reach)]
    local = local[np.all(np.isfinite(local), axis=1)]
    if not sweep:
        local = local[~ground_mask(local, config.ground.params())]
    return local[points_in_box(local, box, params.region_scale)]


# the tracker's ground: a whole-sweep plane (full) or local planes (ground.remover "local"); local planes on request
@pytest.mark.parametrize("remover, ground", [("sweep", "local"), ("sweep", "tracker"), ("local", "tracker")])
@pytest.mark.parametrize("deskew", [False, True])
def test_region_points_from_the_cropped_sweep_are_those_of_the_whole_sweep(deskew, remover, ground):
    seq = make_sequence(n_frames=3, seed=4, nan_frames=(2,))
    rng = np.random.default_rng(3)
    config = get_preset("full", deskew=deskew, **{"ground.remover": remover})
    params = OfflineParams(ground=ground)
    previous = (seq.frames[0].timestamp_ns, make_transform(rotation_z(-0.15), np.array([-2.0, -0.5, 1.0])))
    for k in (1, 2):
        f = seq.lidar_frame(k)
        offsets = rng.integers(-100_000_000, 0, len(f.points_ego))
        frame = LidarFrame(f.index, f.timestamp_ns, f.points_ego, f.world_from_ego, offsets if deskew else None)
        if deskew:
            whole = deskew_points(frame.points_ego, offsets, frame.timestamp_ns, frame.world_from_ego, *previous)
        else:
            whole = transform_points(frame.world_from_ego, frame.points_ego)
        expected = _naive_region(whole, frame.points_ego, seq.boxes[k], params, config)
        got = frame_region_points(frame, seq.boxes[k], config, params, previous if deskew else None)
        assert len(expected) > 100
        np.testing.assert_array_equal(got, expected)


def test_lazy_normals_are_the_whole_shapes_normals():
    solver, states, params = _solver_on_a_synthetic_track(8)
    solver._data(states, True)
    solver._data(states + 0.01, False)   # a second match adds the newly matched points' normals
    for shape, normals, has in zip(solver.shapes, solver.normals, solver.has_normal, strict=True):
        assert 0 < has.sum() < len(shape)   # only the matched points'
        np.testing.assert_array_equal(normals[has], _normals(shape, params.normal_neighbours)[has])


def test_fixed_trial_pairs_search_correspondences_once_per_step():
    """``trial_pairs="fixed"`` (the fixed-lag window's): a Gauss-Newton step's cost check keeps the pairs it was
    linearised on, so each step searches correspondences once (with "rematch", twice or more), and an accepted
    step lowers the cost on those pairs."""
    for trial_pairs in ("fixed", "rematch"):
        solver, states, _ = _solver_on_a_synthetic_track(8, params=OfflineParams(trial_pairs=trial_pairs))
        searches = []
        match = solver._match
        solver._match = lambda local, searches=searches, match=match: searches.append(len(local)) or match(local)
        for step in range(3):
            before = len(searches)
            new = solver.step(states)
            assert not np.array_equal(new, states)   # accepted
            if trial_pairs == "fixed":
                assert len(searches) == before + 1
                pairs = solver._matched[1]
                assert solver.cost(new, pairs) < solver.cost(states, pairs)
            else:
                assert len(searches) >= before + (2 if step == 0 else 1)
            states = new
        if trial_pairs == "rematch":
            assert len(searches) >= 4


def test_the_online_steps_crop_gives_the_regions_points():
    """The fixed-lag window takes a frame's region from the points the online step searched when the region
    fits inside them (LocalCrop): the same points in the same order as from the sweep; else the sweep."""
    seq = make_sequence(n_frames=6, seed=4)
    config, params = get_preset("full"), OfflineParams()
    tracker = Tracker(config)
    tracker.start(seq.lidar_frame(0), seq.boxes[0])
    used = 0
    for k in range(1, 6):
        frame = seq.lidar_frame(k)
        est = tracker.step(frame)
        crop = tracker.last_crop
        assert crop.frame == k and crop.ground == "sweep"
        expected = frame_region_points(frame, est.box, config, params)
        np.testing.assert_array_equal(frame_region_points(frame, est.box, config, params, crop=crop), expected)
        used += crop.contains(est.box, params.region_scale)
        far = Box(est.box.x + 3.0, est.box.y, est.box.z, est.box.heading, *est.box.size)  # outside: the sweep
        assert not crop.contains(far, params.region_scale)
        np.testing.assert_array_equal(frame_region_points(frame, far, config, params, crop=crop),
                                      frame_region_points(frame, far, config, params))
    assert used >= 3   # the region usually fits in the searched crop
    other = get_preset("full", **{"ground.remover": "local"})   # local ground planes in the step: never reused
    tracker = Tracker(other)
    tracker.start(seq.lidar_frame(0), seq.boxes[0])
    est = tracker.step(seq.lidar_frame(1))
    assert tracker.last_crop.ground == "local"
    frame = seq.lidar_frame(1)
    np.testing.assert_array_equal(frame_region_points(frame, est.box, other, params, crop=tracker.last_crop),
                                  frame_region_points(frame, est.box, other, params))


def _shapes_for_covariances() -> list[np.ndarray]:
    """A voxel-centre shape (lattice, many equal distances) and scattered points."""
    rng = np.random.default_rng(3)
    surface = rng.normal(size=(3000, 3)) * [1.5, 0.8, 0.4]
    lattice = np.unique(np.floor(surface / 0.05), axis=0) * 0.05 + 0.025
    return [lattice, rng.normal(size=(500, 3)) * [2.0, 1.0, 0.5] + [10.0, -3.0, 1.0]]


@pytest.mark.parametrize("k", [3, 10])
def test_neighbour_covariances_are_the_neighbour_axis_sums_bit_for_bit(k):
    """The six covariance entries equal the mean over the k neighbours (numpy's, in neighbour order) and the sums
    of each product over the neighbours taken in the kd-tree's order from 0, exactly, for all rows and a subset."""
    for shape in _shapes_for_covariances():
        tree = cKDTree(shape)
        for rows in (None, np.arange(0, len(shape), 7)):
            got = _neighbour_covariances(shape, k, tree, rows)
            _, idx = tree.query(shape if rows is None else shape[rows], k=k)
            nb = shape[idx]                                      # (m, k, 3)
            mean = nb[:, 0].copy()
            for j in range(1, k):
                mean += nb[:, j]
            d = nb - (mean / k)[:, None]
            for entry, (a, b) in zip(got, ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)), strict=True):
                want = np.zeros(len(idx))
                for j in range(k):
                    want = want + d[:, j, a] * d[:, j, b]
                assert np.array_equal(entry, want / k)


def test_gauss_newton_blocks_are_the_per_point_products_summed_per_frame_bit_for_bit():
    """:meth:`_Solver._data`'s blocks against the per-point J'WJ and J'Wr written out (D'n, D'r stacked) and summed
    frame by frame in point order: the upper triangle (the entries the solve reads) bit for bit, the lower one its
    mirror."""
    solver, states, params = _solver_on_a_synthetic_track(6, fixed=1)
    cost, blocks, grads = solver._data(states, True)
    c, si, lx, ly, n, ne, r, norm, weight, cost_r = solver._residuals(states)
    beta, delta = params.tangent_weight, params.huber_delta
    w = weight * np.where(norm <= delta, 1.0, delta / np.maximum(norm, 1e-12))
    nj = np.stack([-c * n[:, 0] + si * n[:, 1], -si * n[:, 0] - c * n[:, 1], -n[:, 2], ly * n[:, 0] - lx * n[:, 1]], 1)
    dr = np.stack([-c * r[:, 0] + si * r[:, 1], -si * r[:, 0] - c * r[:, 1], -r[:, 2], ly * r[:, 0] - lx * r[:, 1]], 1)
    jtj = nj[:, :, None] * ((1.0 - beta**2) * nj)[:, None, :]
    jtj[:, [0, 1, 2], [0, 1, 2]] += beta**2
    jtj[:, 3, 3] += beta**2 * (lx**2 + ly**2)
    for a, g in ((0, -c * ly - si * lx), (1, c * lx - si * ly)):
        jtj[:, a, 3] += beta**2 * g
        jtj[:, 3, a] += beta**2 * g
    jtr = (1.0 - beta) * nj * ne[:, None] + beta * dr
    assert cost == cost_r
    for k in range(solver.k):
        want_h, want_g = np.zeros((4, 4)), np.zeros(4)
        for i in np.flatnonzero(solver.frame_idx == k):
            want_h = want_h + jtj[i] * w[i]
            want_g = want_g + jtr[i] * w[i]
        upper = np.triu_indices(4)
        assert np.array_equal(blocks[k][upper], want_h[upper]) and np.array_equal(grads[k], want_g), k
        assert np.array_equal(blocks[k], blocks[k].T), k
