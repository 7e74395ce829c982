"""Closed-form Kabsch rotations (solvers.rigid), the vectorised distance statistics and
short-gap Hermite fill of solvers.pma: known answers and agreement with the direct
(SVD / per-pair / per-gap) computations they replace."""
import numpy as np
import pytest

from mocapfix.solvers import pma
from mocapfix.solvers import rigid
from mocapfix.solvers.rigid import _best_rotation, _best_rotation_svd, kabsch, kabsch_to_shapes


def _random_rotations(rng, n):
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


@pytest.mark.parametrize("K", [3, 4, 5, 40])
def test_kabsch_recovers_a_known_rigid_motion(K):
    rng = np.random.default_rng(K)
    n = 500
    src = rng.normal(size=(n, K, 3)) * [120.0, 60.0, 25.0] + rng.normal(size=(n, 1, 3)) * 500
    R_true = _random_rotations(rng, n)
    shift = rng.normal(size=(n, 3)) * 300
    tgt = src @ np.swapaxes(R_true, 1, 2) + shift[:, None]
    R, cs, ct = kabsch(src, tgt, np.ones((n, K)))
    # closed form: ~1e-10 where two singular values nearly coincide (1e-7 mm at 1 m)
    assert np.abs(R - R_true).max() < 1e-8
    fitted = (src - cs[:, None]) @ np.swapaxes(R, 1, 2) + ct[:, None]
    assert np.abs(fitted - tgt).max() < 1e-8


@pytest.mark.parametrize("K", [3, 4, 5, 12])
def test_closed_form_rotation_matches_the_svd_on_noisy_and_mirrored_sets(K):
    rng = np.random.default_rng(10 + K)
    n = 2000
    src = rng.normal(size=(n, K, 3)) * [100.0, 50.0, 20.0]
    tgt = src @ np.swapaxes(_random_rotations(rng, n), 1, 2) + rng.normal(size=src.shape) * 5
    tgt[::7] *= [-1.0, 1.0, 1.0]              # mirrored targets: the det(R) = 1 correction
    H = np.swapaxes(src - src.mean(1, keepdims=True), 1, 2) @ (tgt - tgt.mean(1, keepdims=True))
    R, R_svd = _best_rotation(H), _best_rotation_svd(H)
    assert np.abs(R - R_svd).max() < 1e-8
    assert np.allclose(np.linalg.det(R), 1.0, atol=1e-12)
    assert np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max() < 1e-12


def test_degenerate_matrices_fall_back_to_the_svd():
    H = np.stack([np.zeros((3, 3)), np.eye(3), np.diag([1.0, 1.0, 0.0]), np.diag([1.0, 0, 0]),
                  np.diag([2.0, 1.0, 1.0]), np.diag([1.0, 1.0, -1.0]), -np.eye(3),
                  np.outer([1.0, 2.0, 3.0], [0.0, 1.0, 1.0])])
    assert np.array_equal(_best_rotation(H), _best_rotation_svd(H))


@pytest.mark.parametrize("K", [3, 5, 40])
def test_kabsch_to_one_shape_recovers_the_motion_and_matches_kabsch(K):
    """Frames that are rigid motions of one shape: the fit onto the shape undoes each
    motion, and equals the general kernel with that shape broadcast and unit weights."""
    rng = np.random.default_rng(K)
    n = 300
    shape = rng.normal(size=(K, 3)) * [120.0, 60.0, 25.0] + 400.0
    R_true = _random_rotations(rng, n)
    pts = (shape - shape.mean(axis=0)) @ np.swapaxes(R_true, 1, 2) + rng.normal(size=(n, 1, 3)) * 900
    (R, cs, ct), = kabsch_to_shapes([(pts, shape)])
    back = (pts - cs[:, None]) @ np.swapaxes(R, 1, 2) + ct[:, None]
    assert np.max(np.abs(back - shape)) < 1e-9
    R2, cs2, ct2 = kabsch(pts, np.broadcast_to(shape, pts.shape), np.ones((n, K)))
    assert np.max(np.abs(R - R2)) < 1e-12
    assert np.max(np.abs(cs - cs2)) < 1e-9 and np.max(np.abs(ct - ct2)) < 1e-9


def test_fits_made_together_undo_each_motion_and_match_each_made_alone(monkeypatch):
    """Many requests of different sizes and point counts (a few frames to several hundred,
    3 to 40 points), some mirrored: made together, each fit still undoes its own rigid
    motions, and agrees with each request made alone to rounding; the
    matrices are split into chunks of at most CHUNK (here 500, so several calls)."""
    monkeypatch.setattr(rigid, "CHUNK", 500)
    rng = np.random.default_rng(7)
    requests = []
    for n, K in [(4, 3), (60, 5), (250, 3), (1, 40), (130, 12), (17, 4), (900, 6)]:
        shape = rng.normal(size=(K, 3)) * [120.0, 60.0, 25.0] + 400.0
        R_true = _random_rotations(rng, n)
        pts = (shape - shape.mean(axis=0)) @ np.swapaxes(R_true, 1, 2) + rng.normal(size=(n, 1, 3)) * 900
        requests.append((pts, shape))
    noisy = rng.normal(size=(90, 5, 3)) * 100
    requests.append((noisy * [-1.0, 1.0, 1.0], noisy[0]))          # a mirrored, noisy set
    calls = []
    monkeypatch.setattr(rigid, "_best_rotation", lambda H: calls.append(len(H)) or _best_rotation(H))
    together = kabsch_to_shapes(requests)
    assert len(calls) > 1 and max(calls) <= 500 and sum(calls) == sum(len(p) for p, _ in requests)
    for (pts, shape), (R, cs, ct) in zip(requests[:-1], together):
        back = (pts - cs[:, None]) @ np.swapaxes(R, 1, 2) + ct[:, None]
        assert np.max(np.abs(back - shape)) < 1e-8
    for (pts, shape), (R, cs, ct) in zip(requests, together):
        (R1, cs1, ct1), = kabsch_to_shapes([(pts, shape)])
        assert np.max(np.abs(R - R1)) < 1e-10
        assert np.array_equal(cs, cs1) and np.array_equal(ct, ct1)
        assert np.allclose(np.linalg.det(R), 1.0, atol=1e-12)
    assert kabsch_to_shapes([]) == []


def test_distance_stats_match_the_per_pair_computation():
    rng = np.random.default_rng(3)
    T, J = 1300, 7
    pos = rng.normal(size=(T, J, 3)) * 50 + np.arange(J)[None, :, None] * 200
    observed = rng.random((T, J)) > 0.2
    observed[:, 6] = False
    observed[:2, 6] = True                     # seen twice: fewer than min_frames
    mu, sd = pma.distance_stats(np.where(observed[..., None], pos, np.nan), observed)
    for a in range(J):
        for b in range(J):
            both = observed[:, a] & observed[:, b]
            if both.sum() < 3:
                assert np.isnan(mu[a, b]) and np.isnan(sd[a, b])
                continue
            d = np.linalg.norm(pos[both, a] - pos[both, b], axis=1)
            assert mu[a, b] == pytest.approx(d.mean(), abs=1e-9)
            assert sd[a, b] == pytest.approx(d.std(ddof=1), abs=1e-9)


def test_hermite_short_gaps_rebuild_linear_motion_and_skip_end_gaps():
    T, J = 60, 3
    t = np.arange(T, dtype=float)[:, None, None]
    truth = np.broadcast_to(t * np.array([1.0, -2.0, 0.5]) + 10.0, (T, J, 3)).copy()
    pos = truth.copy()
    gaps = [(0, 5, 8), (0, 20, 21), (1, 1, 4), (2, 30, 40), (2, 0, 3), (1, 55, 60)]
    observed = np.ones((T, J), bool)
    for j, s, e in gaps:
        pos[s:e, j] = np.nan
        observed[s:e, j] = False
    done = pma.hermite_short_gaps(pos, observed, gaps)
    assert done == [g for g in gaps if g[1] > 0 and g[2] < T]
    for j, s, e in done:
        assert np.allclose(pos[s:e, j], truth[s:e, j], atol=1e-12)
    assert np.isnan(pos[0:3, 2]).all() and np.isnan(pos[55:60, 1]).all()
