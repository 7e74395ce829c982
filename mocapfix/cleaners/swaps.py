"""Marker-swap detection and repair: ``swaps`` (the kernels: :mod:`mocapfix.solvers.swaps`).

A swap is the classic optical labelling error: two labels exchange trajectories for a
stretch of frames. Method (written for mocapfix; the cues are the ones labelling
software uses -- trajectory continuity and near-constant inter-marker distances on a
segment, cf. Herda et al. 2001 "Using skeleton-based tracking to increase the
reliability of optical motion capture", and Meyer et al. 2014 "Online automatic
labelling of motion capture markers"):

1. Events (continuity). For every pair (a, b), predict each marker at frame t by
   constant-velocity extrapolation from t-1, t-2 (and frame t-1 backwards from t, t+1).
   ``keep`` = the summed prediction errors with the labels as they are, ``swap`` = the
   same with a and b exchanged from t on. A label exchange between t-1 and t makes
   ``keep - swap`` about four times the a-b distance while ``swap`` is ~0; on clean
   captures ``keep - swap`` is <= 0 (measured: max 0.0 mm on HDM05 and -162 mm on CMU
   85_02 over all pairs and frames). An event needs ``keep - swap > threshold`` and
   ``swap < keep / 2``; events are local maxima within +-2 frames.
2. Segments (distances). The events of a pair cut the capture into segments. For each
   marker, its most rigid partners (smallest spread of distance over the capture) and their
   median distances form a template; a segment is exchanged when, exchanged, it matches
   the templates better by more than ``threshold / 2`` per frame on average and by a
   factor of two; a swap that runs to the end of the capture (no closing event) is
   repaired this way. When no segment is clear (markers placed symmetrically on one
   segment, e.g. two wrist or forehead markers), an even number of events is trusted and
   the stretches between paired events are exchanged, unless the distances contradict it.
   A single event alone never changes data.

Pairs are processed by decreasing event strength, each on the data as already repaired.
Frames where either marker is missing carry no event (a swap hidden inside a gap is not
detected). Thresholds are physical lengths (default 20 mm) converted to the file's unit.
"""
from __future__ import annotations

from mocapfix.cleaners import register
from mocapfix.cleaners.base import Cleaner, Param
from mocapfix.solvers.swaps import find_swaps


@register
class SwapFix(Cleaner):
    name = "swaps"
    single_thread_blas = True
    summary = "detect and undo marker-label swaps (continuity events + rigid distances)"
    params = (
        Param("threshold", "length", "20 mm",
              "least continuity gain of a swap event; half of it is the least mean "
              "distance-template gain per frame of a repaired segment",
              unit="mm", low=0.0, low_open=True),
        Param("partners", "int", 6, "rigid partner markers per marker for the distance test",
              low=1, high=50),
        Param("max_swaps", "int", 100, "most segments exchanged per capture", low=0),
    )

    def _apply(self, motion):
        P, found = find_swaps(motion.positions, self.length("threshold", motion), self["partners"],
                              self["max_swaps"])
        swaps = sorted((dict(markers=[motion.names[a], motion.names[b]], start=start, end=end,
                             frames=end - start) for a, b, start, end in found),
                       key=lambda s: (s["start"], s["markers"]))
        return motion.replace(positions=P), dict(swaps=swaps)
