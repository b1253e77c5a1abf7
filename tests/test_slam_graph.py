"""The pose-graph optimiser: exact chains, a consistent loop, a robust kernel against a wrong loop,
and agreement with scipy's generic least squares on a random graph."""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from app.ocslam.se2 import between, compose, wrap_angle
from app.ocslam.slam.graph import edge_errors, optimize

INFO = np.array([1 / 0.02**2, 1 / 0.02**2, 1 / 0.01**2])


def _square(n_side=5, step=0.5):
    poses = [np.zeros(3)]
    for _side in range(4):
        for i in range(n_side):
            if i == n_side - 1:
                poses.append(compose(poses[-1], [step, 0.0, np.pi / 2]))
            else:
                poses.append(compose(poses[-1], [step, 0.0, 0.0]))
    return np.array(poses)


def test_chain_is_recovered_exactly():
    truth = _square()
    ij = np.stack([np.arange(len(truth) - 1), np.arange(1, len(truth))], 1)
    z = between(truth[ij[:, 0]], truth[ij[:, 1]])
    init = truth + np.random.default_rng(0).normal(0, 0.05, truth.shape)
    init[0] = truth[0]
    res = optimize(init, ij, z, np.tile(INFO, (len(ij), 1)), np.zeros(len(ij), bool), iterations=30)
    assert np.allclose(res.poses[:, :2], truth[:, :2], atol=1e-6)
    assert np.allclose(wrap_angle(res.poses[:, 2] - truth[:, 2]), 0, atol=1e-6)
    assert res.final_cost < 1e-9


def test_loop_corrects_drift_and_robust_kernel_rejects_a_wrong_loop():
    truth = _square()
    n = len(truth)
    ij = [(i, i + 1) for i in range(n - 1)]
    z = [between(truth[i], truth[j]) + np.array([0.0, 0.0, 0.01]) for i, j in ij]  # drifting headings
    ij.append((0, n - 1))  # the true loop (end = start)
    z.append(between(truth[0], truth[n - 1]))
    ij, z = np.array(ij), np.array(z)
    info = np.tile(INFO, (len(ij), 1))
    robust = np.zeros(len(ij), bool)
    robust[-1] = True
    init = truth[:1].copy()
    for d in z[:-1]:
        init = np.vstack([init, compose(init[-1], d)])
    drift = np.hypot(*(init[-1, :2] - truth[-1, :2]))
    res = optimize(init, ij, z, info, robust, iterations=30)
    err = np.hypot(*(res.poses[:, :2] - truth[:, :2]).T).max()
    assert drift > 0.3 and err < 0.1 * drift
    # a wrong loop (2 m off) with a Cauchy kernel barely bends the graph
    ij2 = np.vstack([ij, [[5, 15]]])
    z2 = np.vstack([z, compose(between(truth[5], truth[15]), [2.0, 0.0, 0.0])])
    res2 = optimize(init, ij2, z2, np.tile(INFO, (len(ij2), 1)), np.r_[robust, True], iterations=30)
    assert np.hypot(*(res2.poses[:, :2] - res.poses[:, :2]).T).max() < 0.05
    assert res2.loop_weights[-1] < 0.01 and res2.loop_weights[-2] > 0.5


def test_agrees_with_scipy_least_squares():
    rng = np.random.default_rng(3)
    truth = np.cumsum(rng.normal(0, [0.5, 0.5, 0.3], (8, 3)), axis=0)
    truth[0] = 0
    ij = np.array([(i, i + 1) for i in range(7)] + [(0, 5), (2, 7), (1, 6)])
    z = between(truth[ij[:, 0]], truth[ij[:, 1]]) + rng.normal(0, [0.05, 0.05, 0.02], (len(ij), 3))
    info = rng.uniform(50, 500, (len(ij), 3))
    init = truth + rng.normal(0, 0.1, truth.shape)
    init[0] = truth[0]
    res = optimize(init, ij, z, info, np.zeros(len(ij), bool), iterations=50, tol=1e-12, rel_tol=1e-15)

    def fun(v):
        x = np.vstack([init[:1], v.reshape(-1, 3)])
        return (edge_errors(x, ij, z) * np.sqrt(info)).ravel()

    ls = least_squares(fun, init[1:].ravel(), xtol=1e-14, ftol=1e-14, gtol=1e-14)
    ref = np.vstack([init[:1], ls.x.reshape(-1, 3)])
    assert np.allclose(res.poses[:, :2], ref[:, :2], atol=1e-6)
    assert np.allclose(wrap_angle(res.poses[:, 2] - ref[:, 2]), 0, atol=1e-6)


def test_factor_spd_solves_like_a_dense_solve_and_refuses_a_singular_matrix():
    import pytest
    import scipy.sparse as sp

    from app.ocslam.slam.graph import factor_spd

    rng = np.random.default_rng(3)
    # a sparse SPD matrix with a chain-plus-loops pattern, like a pose graph's normal equations
    n = 60
    A = sp.lil_matrix((n, n))
    for i in range(n - 1):
        A[i, i + 1] = A[i + 1, i] = -1.0
    for i, j in rng.integers(0, n, (10, 2)):
        if i != j:
            A[i, j] = A[j, i] = -0.5
    A = A.tocsr()
    A = A + sp.diags(np.abs(A).sum(axis=1).A1 + 0.1)
    b = rng.normal(size=n)
    np.testing.assert_allclose(factor_spd(A).solve(b), np.linalg.solve(A.toarray(), b), atol=1e-10)
    S = sp.csr_matrix(np.diag([1.0, 2.0, 0.0]))
    with pytest.raises(RuntimeError):
        factor_spd(S)
