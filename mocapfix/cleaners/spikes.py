"""Spike (outlier) detection: marks implausible samples missing so a gap filler takes over.

A Hampel identifier (Hampel 1974; Pearson et al. 2016, "Generalized Hampel filters") per
marker on the 3-D residual to a robust local fit: a leave-one-out local quadratic
(robust LOESS, Cleveland 1979; :func:`mocapfix.solvers.localfit.local_polyfit`) rather
than a running median, which lags at the turning points of fast movements.

1. fit every sample from its neighbours within ``window`` (itself left out), weighted;
2. ``r_t = ||x_t − fit_t||`` (3-D residual norm);
3. global noise scale per marker ``s = 1.4826 · median |x − fit|``;
4. ``passes`` rounds of iterative reweighting (Tukey biweight) so that a spike loses its
   say in its neighbours' fits; a leverage term accounts for one-sided fits;
5. decision: ``r_t > max(k σ_t √(1 + leverage_t), min_jump)`` with
   ``σ_t = max(s, local scale)`` (Hampel's local MAD over ``±window``);
6. shoulders of wide spikes: neighbours of flagged samples are flagged too above
   ``max(k σ √(1 + leverage), min_jump / 2)``;
7. evidence: a flagged run is kept only when the marker's own path contradicts it
   (:func:`mocapfix.solvers.glitches.contradicted_by_path`); ``kept_by_path`` counts the
   samples left as measured.

Recall and false positives on the shared captures: docs/methods/spikes.md.
"""
from __future__ import annotations

import numpy as np

from mocapfix.cleaners import register
from mocapfix.cleaners.base import Cleaner, Param
from mocapfix.core.motion import Motion
from mocapfix.solvers.glitches import contradicted_by_path
from mocapfix.solvers.spikes import hampel_flags


@register
class Spikes(Cleaner):
    """Flag spikes (Hampel identifier on the residual to a robust local quadratic fit, per
    marker on the 3-D residual norm) and mark them missing. See the module docstring."""

    name = "spikes"
    flags_samples = True
    summary = "mark spikes/outliers missing (Hampel on the residual to a robust local fit)"
    params = (
        Param("window", "time", "0.08 s", "length of the local-fit window", unit="s",
              low=0.0, low_open=True, high=2.0),
        Param("k", "float", 5.0, "threshold in robust standard deviations (MAD × 1.4826)",
              low=1.0, high=100.0),
        Param("min_jump", "length", "10 mm", "smallest residual ever flagged", unit="mm",
              low=0.0, low_open=True),
        Param("passes", "int", 3, "reweighting passes of the robust fit", low=1, high=5),
    )

    def _apply(self, motion: Motion):
        pos = motion.positions
        T, J, _ = pos.shape
        if pos.size == 0:
            return motion.copy(), {"flagged": 0, "flagged_per_marker": {}}
        # at least 2 samples a side: with one, the leave-one-out quadratic of a 30 fps
        # skeleton had no support and nothing was ever flagged (issue 12)
        half = max(2, int(round(self.frames("window", motion) / 2.0)))
        flags, thr = hampel_flags(pos, half, self["k"], self.length("min_jump", motion),
                                  self["passes"])
        flags &= ~motion.missing
        # a residual is a suspicion; the marker's own path must contradict it
        supported = contradicted_by_path(pos, flags)
        kept = int((flags & ~supported).sum())
        flags = supported
        out = pos.copy()
        out[flags] = np.nan
        per = flags.sum(axis=0)
        info = {
            "flagged": int(per.sum()),
            "flagged_per_marker": {motion.names[j]: int(per[j]) for j in np.flatnonzero(per)},
            "threshold_mm": round(float(np.median(thr)) * motion.metres_per_unit * 1e3, 3),
            "kept_by_path": kept,
        }
        return motion.replace(positions=out), info
