"""Batched rigid (Kabsch) fits, one per frame; shared by the body-frame alignments of
``fill_pca``, ``tsmc`` and the model-averaging gap filler."""
from __future__ import annotations

import numpy as np


def kabsch(source, target, weights):
    """Per-frame rigid fit ``R_t (source_t - cs_t) + ct_t ~ target_t`` (Kabsch 1976).

    source, target: (T, J, 3) without NaN; weights: (T, J) >= 0 with a positive sum per
    frame. Returns R (T, 3, 3), cs (T, 3), ct (T, 3). Batched 3x3 SVDs, no frame loop.
    """
    wsum = weights.sum(axis=1, keepdims=True)
    cs = (weights[:, None, :] @ source)[:, 0] / wsum
    ct = (weights[:, None, :] @ target)[:, 0] / wsum
    # batched products (matmul) rather than multi-operand einsum: several times faster
    H = np.swapaxes((source - cs[:, None]) * weights[..., None], 1, 2) @ (target - ct[:, None])
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(U @ Vt))
    d[d == 0] = 1.0
    Vt = Vt.copy()
    Vt[:, 2] *= d[:, None]
    R = np.swapaxes(U @ Vt, 1, 2)                 # V diag(1, 1, d) U^T
    return R, cs, ct
