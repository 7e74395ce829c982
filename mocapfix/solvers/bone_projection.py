"""Bone-length projection: move joints so that bones get their target lengths, each joint
moving in proportion to its uncertainty.

Gauss–Seidel sweeps of distance-constraint projections (position-based dynamics:
Müller et al. 2007, "Position based dynamics", J. Vis. Commun. Image R. 18, §3.3, eq. 8–9
for the distance constraint ``C(p1, p2) = |p1 − p2| − L`` with inverse masses): for a
bone (a, b) with current length ``l`` and target ``L``,

    Δp_a = + s · w_a / (w_a + w_b) · (l − L) · (p_b − p_a) / l
    Δp_b = − s · w_b / (w_a + w_b) · (l − L) · (p_b − p_a) / l

with ``w`` the joints' inverse masses (here: variances, so a well-measured joint barely
moves) and ``s`` the stiffness. Vectorised over frames; the loop is over sweeps and bones.

Links a skeleton does not list but its data holds rigid (:func:`two_bone_pairs`,
:func:`steady_pairs`: the two hips, a forearm with its hand) are found by a test written
for mocapfix, not taken from a paper: the spread of a pair's time-averaged distance
against the spread its measurement noise alone would give.
"""
from __future__ import annotations

import numpy as np

from mocapfix.solvers.rigid import norms


def project_lengths(P: np.ndarray, bones: np.ndarray, lengths: np.ndarray, w: np.ndarray, *,
                    sweeps: int = 8, stiffness: float = 1.0) -> np.ndarray:
    """Project ``P`` (T, J, 3) toward bone ``lengths`` (B,) or per frame (T, B) for
    ``bones`` (B, 2); ``w``
    (T, J) inverse masses (0: the joint does not move). Samples with NaN stay NaN and
    bones touching them are skipped in that frame."""
    P = np.array(P, dtype=np.float64, copy=True)
    bones = np.asarray(bones, dtype=np.intp).reshape(-1, 2)
    lengths = np.asarray(lengths, dtype=np.float64)
    per_frame = lengths.ndim == 2
    Q = np.ascontiguousarray(P.transpose(1, 0, 2))        # (J, T, 3): joints contiguous
    W = np.ascontiguousarray(np.asarray(w, dtype=np.float64).T)
    for _ in range(max(0, sweeps)):
        for i, (a, b) in enumerate(bones):
            L = lengths[:, i] if per_frame else lengths[i]
            if not np.any(np.isfinite(L) & (L > 0)):
                continue
            d = Q[b] - Q[a]
            length = np.sqrt(np.einsum("ij,ij->i", d, d))
            wa, wb = W[a], W[b]
            with np.errstate(invalid="ignore", divide="ignore"):
                k = stiffness * (length - L) / (length * (wa + wb))
            ok = np.isfinite(k) & (length > 1e-9)
            d = np.where(ok[:, None], d, 0.0)            # a missing end moves nothing
            k = np.where(ok, k, 0.0)
            Q[a] += d * (wa * k)[:, None]
            Q[b] -= d * (wb * k)[:, None]
    return Q.transpose(1, 0, 2).copy()


def median_lengths(P: np.ndarray, good: np.ndarray, links: np.ndarray, *,
                   min_frames: int = 1) -> np.ndarray:
    """(K,) median distance in ``P`` (T, J, 3) of each joint pair of ``links`` (K, 2) over
    the frames where both are ``good`` (T, J); NaN with fewer than ``min_frames`` of
    them (:func:`project_lengths` skips such a link)."""
    out = np.full(len(links), np.nan)
    for i, (a, b) in enumerate(np.asarray(links, dtype=np.intp).reshape(-1, 2)):
        both = good[:, a] & good[:, b]
        if both.sum() >= max(min_frames, 1):
            out[i] = np.median(norms(P[both, a] - P[both, b]))
    return out


def two_bone_pairs(bones: np.ndarray, n_joints: int) -> np.ndarray:
    """(K, 2) joint pairs two bones apart (a common neighbour, not a bone themselves):
    siblings such as the two hips, and grandparent-grandchild such as elbow-hand."""
    bones = np.asarray(bones, dtype=np.intp).reshape(-1, 2)
    near = [set() for _ in range(n_joints)]
    for a, b in bones:
        near[a].add(int(b))
        near[b].add(int(a))
    linked = {tuple(sorted(map(int, b))) for b in bones}
    pairs = {tuple(sorted((a, c))) for m in range(n_joints) for a in near[m] for c in near[m]
             if a != c}
    return np.array(sorted(pairs - linked), dtype=np.intp).reshape(-1, 2)


def steady_pairs(P: np.ndarray, good: np.ndarray, pairs: np.ndarray, noise: np.ndarray, *,
                 window: int, ratio: float, min_frames: int) -> np.ndarray:
    """The ``pairs`` (K, 2) of joints whose distance in ``P`` (T, J, 3) holds as steady as
    measurement noise explains: over the frames where both are ``good`` (T, J) (at least
    ``min_frames``), the standard deviation of the distance's ``window``-frame moving
    average is at most ``ratio`` × √((σ_a² + σ_b²) / window), the spread white noise of
    per-coordinate σ (``noise``, (J,)) alone would give it. A rigid link the skeleton does
    not list (the pelvis's hip-hip distance, a thorax's shoulder-shoulder one) passes; a
    pair across a bending joint does not once the bending outgrows the noise. Returns the
    passing rows of ``pairs``."""
    from scipy.ndimage import uniform_filter1d  # imported here: not loaded unless needed

    pairs = np.asarray(pairs, dtype=np.intp).reshape(-1, 2)
    keep = np.zeros(len(pairs), bool)
    for i, (a, b) in enumerate(pairs):
        both = good[:, a] & good[:, b]
        if both.sum() < max(min_frames, 2 * window):
            continue
        dist = norms(P[both, a] - P[both, b])
        spread = float(np.std(uniform_filter1d(dist, window, mode="nearest")))
        keep[i] = spread <= ratio * np.sqrt((noise[a] ** 2 + noise[b] ** 2) / window)
    return pairs[keep]
