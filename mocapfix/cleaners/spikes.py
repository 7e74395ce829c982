"""Spike (outlier) detection: marks implausible samples missing so a gap filler takes over
(ALGORITHMS.md §0).

Hampel identifier (Hampel 1974; Pearson et al. 2016, "Generalized Hampel filters") applied
per marker to the 3-D residual to a robust running median:

1. ``b`` = running median of each coordinate over ``window``, computed per observed
   segment with robust straight-line extension at segment ends
   (:func:`mocapfix.solvers.segments.running_median`), so a moving marker does not look
   like an outlier next to a gap or at the ends of the capture;
2. ``r_t = ||x_t − b_t||`` (3-D residual norm);
3. noise scale per marker ``s = 1.4826 · median |x − b|`` over its samples and coordinates
   (MAD about the running median);
4. a sample is a spike when ``r_t > max(k s, min_jump)``: the physical floor keeps clean
   data with a tiny MAD from being flagged;
5. shoulders of wide spikes (2–5 frames, ramping in and out): neighbours of a flagged
   sample whose residual exceeds half the threshold are flagged too (hysteresis, grown up
   to half a window);
6. a second pass recomputes the running median with the flagged samples replaced by the
   first baseline, which sharpens the baseline next to clustered spikes.
"""
from __future__ import annotations

import numpy as np

from mocapfix.cleaners import register
from mocapfix.cleaners.base import Cleaner, Param
from mocapfix.motion import Motion
from mocapfix.solvers.segments import running_median


def hampel_flags(pos: np.ndarray, half: int, k: float, floor: float,
                 passes: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Spike mask (T, J) of marker positions ``pos`` (T, J, 3) and the threshold per marker
    (J,), in the units of ``pos``. See the module docstring for the method."""
    T, J, _ = pos.shape
    x = pos.reshape(T, 3 * J)
    work = x
    flags = np.zeros((T, J), dtype=bool)
    thr = np.full(J, float(floor))
    for _ in range(max(1, passes)):
        base = running_median(work, half)
        res = (x - base).reshape(T, J, 3)
        with np.errstate(invalid="ignore"):
            r = np.linalg.norm(res, axis=2)
        absres = np.abs(res).reshape(T, 3 * J).reshape(T, J, 3)
        valid = ~np.isnan(absres).all(axis=(0, 2))
        scale = np.zeros(J)
        if valid.any():
            scale[valid] = 1.4826 * np.nanmedian(absres[:, valid].transpose(1, 0, 2).reshape(int(valid.sum()), -1), axis=1)
        thr = np.maximum(k * scale, floor)
        with np.errstate(invalid="ignore"):
            core = r > thr
            weak = r > 0.5 * thr
        flags = core
        for _ in range(half):
            grown = flags.copy()
            grown[1:] |= flags[:-1]
            grown[:-1] |= flags[1:]
            grown &= weak
            if np.array_equal(grown, flags):
                break
            flags = grown
        if not flags.any():
            break
        # next pass: flagged samples replaced by this pass's baseline (no new segments)
        rep = np.repeat(flags, 3, axis=1)
        work = np.where(rep, base, x)
    return flags, thr


@register
class Spikes(Cleaner):
    """Flag spikes (Hampel identifier on the residual to a robust running median, per
    marker on the 3-D residual norm) and mark them missing. See the module docstring."""

    name = "spikes"
    summary = "mark spikes/outliers missing (Hampel on the residual to a running median)"
    params = (
        Param("window", "time", "0.1 s", "length of the running-median window", unit="s",
              low=0.0, low_open=True),
        Param("k", "float", 6.0, "threshold in robust standard deviations (MAD × 1.4826)",
              low=1.0, high=100.0),
        Param("min_jump", "length", "10 mm", "smallest residual ever flagged", unit="mm",
              low=0.0, low_open=True),
        Param("passes", "int", 2, "detection passes (each re-estimates the baseline "
              "without the flagged samples)", low=1, high=5),
    )

    def _apply(self, motion: Motion):
        pos = motion.positions
        T, J, _ = pos.shape
        if T == 0 or J == 0:
            return motion.copy(), {"flagged": 0, "flagged_per_marker": {}}
        half = max(1, int(round(self.frames("window", motion) / 2.0)))
        flags, thr = hampel_flags(pos, half, self["k"], self.length("min_jump", motion),
                                  self["passes"])
        flags &= ~motion.missing
        out = pos.copy()
        out[flags] = np.nan
        per = flags.sum(axis=0)
        info = {
            "flagged": int(per.sum()),
            "flagged_per_marker": {motion.names[j]: int(per[j]) for j in np.flatnonzero(per)},
            "threshold_mm": round(float(np.median(thr)) * motion.metres_per_unit * 1e3, 3),
        }
        return motion.replace(positions=out), info
