"""Known-answer checks of the sparse-coding kernels (mocapfix.solvers.sparse)."""
from __future__ import annotations

import numpy as np

from mocapfix.solvers import sparse


def test_fista_matches_soft_threshold_for_an_orthonormal_dictionary():
    rng = np.random.default_rng(0)
    D, _ = np.linalg.qr(rng.normal(size=(20, 20)))
    Z = rng.normal(size=(20, 30))
    lam = 0.7
    psi, _ = sparse.fista(D.T @ D, D.T @ Z, lam, n_iter=500, tol=1e-12)
    # min ||z − Dψ||² + λ||ψ||₁ with DᵀD = I: ψ = soft(Dᵀz, λ/2)
    c = D.T @ Z
    expected = np.sign(c) * np.maximum(np.abs(c) - lam / 2, 0)
    assert np.allclose(psi, expected, atol=1e-8)


def test_fista_graph_term_pulls_neighbours_together():
    rng = np.random.default_rng(1)
    D, _ = np.linalg.qr(rng.normal(size=(10, 10)))
    Z = rng.normal(size=(10, 40))
    lap = sparse.knn_laplacian(np.arange(40.0)[:, None], k=2)
    free, _ = sparse.fista(D.T @ D, D.T @ Z, 0.0, n_iter=300, tol=0)
    smooth, _ = sparse.fista(D.T @ D, D.T @ Z, 0.0, laplacian=lap, lam_graph=5.0, n_iter=300, tol=0)
    rough = lambda P: float(np.trace(P @ lap @ P.T))  # noqa: E731
    assert rough(smooth) < 0.2 * rough(free)


def test_omp_recovers_exact_sparse_codes():
    rng = np.random.default_rng(2)
    D = rng.normal(size=(40, 80))
    D /= np.linalg.norm(D, axis=0)
    W = np.zeros((80, 25))
    for j in range(25):
        W[rng.choice(80, 3, replace=False), j] = rng.normal(size=3) + 2 * np.sign(rng.normal(size=3))
    X = D @ W
    codes = sparse.omp(D.T @ D, D.T @ X, 3)
    assert np.allclose(codes, W, atol=1e-6)


def test_dictionary_step_and_ksvd_reduce_the_residual():
    rng = np.random.default_rng(3)
    true = rng.normal(size=(12, 6))
    true /= np.linalg.norm(true, axis=0)
    W = rng.normal(size=(6, 200)) * (rng.random((6, 200)) < 0.4)
    X = true @ W
    D = rng.normal(size=(12, 6))
    D /= np.linalg.norm(D, axis=0)
    before = np.linalg.norm(X - D @ W)
    D1 = sparse.dictionary_step(D, W @ W.T, X @ W.T, sweeps=5)
    assert np.linalg.norm(X - D1 @ W) < 0.5 * before
    assert np.all(np.linalg.norm(D1, axis=0) <= 1 + 1e-9)
    codes = sparse.omp(D.T @ D, D.T @ X, 2)
    D2, W2 = sparse.ksvd_step(X, D, codes)
    assert np.linalg.norm(X - D2 @ W2) < np.linalg.norm(X - D @ codes)


def test_knn_laplacian_of_points_on_a_line():
    lap = sparse.knn_laplacian(np.arange(6.0)[:, None], k=1).toarray()
    # each point's nearest neighbour is next to it: the graph is the path 0-1-2-3-4-5
    expected = np.diag([1, 2, 2, 2, 2, 1.0]) - (np.eye(6, k=1) + np.eye(6, k=-1))
    assert np.array_equal(lap, expected)


def test_group_shrink_p1_converges_to_group_soft_threshold():
    rng = np.random.default_rng(4)
    Q = rng.normal(size=(50, 3)) * 5
    E = Q.copy()
    for _ in range(200):
        E = sparse.group_shrink_lp(Q, E, 2.0, 1.0)
    n = np.linalg.norm(Q, axis=1, keepdims=True)
    expected = Q * np.maximum(1 - 1.0 / n, 0)     # threshold λ/2 = 1
    assert np.allclose(E, expected, atol=1e-3)
