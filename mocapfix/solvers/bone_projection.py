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
"""
from __future__ import annotations

import numpy as np


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
