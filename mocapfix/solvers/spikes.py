"""Spike detection on marker paths: a Hampel identifier (Hampel 1974; Pearson et al. 2016,
"Generalized Hampel filters") per marker on the 3-D residual to a robust local fit, the
kernel of the ``spikes`` cleaner (:mod:`mocapfix.cleaners.spikes`, whose docstring gives
the steps and the measurements). The robust smooth is a leave-one-out local quadratic
(robust LOESS, Cleveland 1979; :func:`mocapfix.solvers.localfit.local_polyfit`).
"""
from __future__ import annotations

import numpy as np

from mocapfix.solvers.localfit import local_polyfit, moving_median


def _residuals(pos, w, half, observed):
    fit, lev, support = local_polyfit(pos, w, half, degree=2, leave_out=True)
    usable = observed & (support > 0)
    with np.errstate(invalid="ignore"):
        res = pos - fit
        r = np.where(usable, np.linalg.norm(res, axis=2), 0.0)
    return res, r, np.maximum(lev, 0.0), usable


def _local_scale(r, usable, half):
    """Hampel's local scale: the median residual norm over ``±2 half`` samples / 1.5382
    (the median of the norm of a 3-D standard normal)."""
    return np.nan_to_num(moving_median(np.where(usable, r, np.nan), 2 * half) / 1.5382)


#: samples (frames × markers) judged at once: every marker is fitted on its own, so a long
#: take is judged a few markers at a time, and the fits' temporaries (~400 bytes a sample)
#: stay under ~100 MB instead of growing with the take's markers too
GROUP_SAMPLES = 1 << 18


def hampel_flags(pos: np.ndarray, half: int, k: float, floor: float,
                 passes: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Spike mask (T, J) of marker positions ``pos`` (T, J, 3) and the median threshold
    per marker (J,), in the units of ``pos``. See :mod:`mocapfix.cleaners.spikes` for the
    steps. Markers are judged in groups of at most :data:`GROUP_SAMPLES` samples (the
    same flags as all at once: nothing is shared between markers)."""
    T, J, _ = pos.shape
    group = max(1, GROUP_SAMPLES // max(T, 1))
    if J <= group:
        return _hampel_group(pos, half, k, floor, passes)
    parts = [_hampel_group(pos[:, a:a + group], half, k, floor, passes)
             for a in range(0, J, group)]
    return (np.concatenate([f for f, _ in parts], axis=1),
            np.concatenate([t for _, t in parts]))


def _hampel_group(pos: np.ndarray, half: int, k: float, floor: float,
                  passes: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`hampel_flags` of the markers of ``pos`` all at once."""
    T, J, _ = pos.shape
    observed = ~np.isnan(pos).any(axis=2)
    w = observed.astype(np.float64)
    for it in range(max(1, passes)):
        res, r, lev, usable = _residuals(pos, w, half, observed)
        if it == 0:
            absres = np.where(usable[..., None], np.abs(res), np.nan)
            has = usable.any(axis=0)
            scale = np.zeros(J)
            if has.any():
                scale[has] = 1.4826 * np.nanmedian(absres[:, has], axis=(0, 2))
        thr = np.maximum(k * scale[None, :] * np.sqrt(1.0 + lev), floor)
        if it < passes - 1:
            # Tukey biweight of the residual: spikes lose their say in the neighbours' fits
            w = observed * np.clip(1.0 - (r / (2.0 * thr)) ** 2, 0.0, None) ** 2
    # final decision with the local scale of the cleaned fit's residuals: a stretch the
    # local model cannot follow (very fast or jerky movement, dropped frames) has large
    # residuals all along and is not a spike; an isolated spike barely moves the median
    sigma = np.maximum(scale[None, :], _local_scale(r, usable, half))
    thr = np.maximum(k * sigma * np.sqrt(1.0 + lev), floor)
    flags = r > thr
    for _ in range(half):
        if not flags.any():
            break
        # refit without the flagged samples; grow into neighbours that are still off.
        # Only the markers with flags change: the fits are per marker, so the others'
        # refits would give back what they have (the same values, at the cost of all)
        cols = np.flatnonzero(flags.any(axis=0))
        f = flags[:, cols]
        _, r, lev, usable = _residuals(pos[:, cols], (w * ~flags)[:, cols], half, observed[:, cols])
        sigma = np.maximum(scale[None, cols], _local_scale(r, usable, half))
        weak = np.maximum(k * sigma * np.sqrt(1.0 + lev), 0.5 * floor)
        near = np.zeros_like(f)
        near[1:] |= f[:-1]
        near[:-1] |= f[1:]
        grow = near & ~f & (r > weak)
        if not grow.any():
            break
        flags[:, cols] = f | grow
    return flags, np.median(thr, axis=0)
