"""Held frames: frames that repeat the frame before them exactly.

A recorder with no new sample may write the last one again: a tracker's dropped frames, a
30 Hz stream saved at 60 Hz, an export resampled by holding each pose. Such a frame is no
new measurement, but the cleaners take it for one — a motion that stops dead between
every two frames, twice as fast in between — and judge the real samples wrong: with
every frame of CMU 85_02 written twice the default judged 2,998 samples wrong, left
1,078 of them missing and wrote a toe marker 1.1 m from where it was
(``benchmarks/degenerate_takes.py``; benchmarks/RESULTS.md, "Degenerate takes and
held frames").

So a take with held frames is cleaned on its distinct frames (:meth:`HeldFrames.take`),
and every held frame comes out as the frame it repeats (:meth:`HeldFrames.expand`), with
the steps' records and the frame numbers in their ``info`` made the take's
(:func:`~mocapfix.cleaners.base.map_frames`). A frame is held when every point, its
confidence and (for a rig) every channel equal the frame before's bit for bit, missing
where it was missing, and it holds a seen point (empty frames are not measurements
either way, and stay as the take has them).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from mocapfix.cleaners.base import map_frames
from mocapfix.core.motion import Motion
from mocapfix.pipeline.steps import written_fill_errors

#: frames compared at a time (the comparison's temporaries stay a few MB)
BLOCK = 4096


def held_frames(motion: Motion) -> np.ndarray:
    """(T,) True where a frame repeats the frame before it (see the module docstring)."""
    T = motion.n_frames
    held = np.zeros(T, bool)
    arrays = [a.reshape(T, -1) for a in (motion.positions, motion.confidence, motion.channels)
              if a is not None and len(a) == T]
    for a in range(1, T, BLOCK):
        b = min(a + BLOCK, T)
        same = np.ones(b - a, bool)
        for x in arrays:
            now, before = x[a:b], x[a - 1:b - 1]
            same &= ((now == before) | (np.isnan(now) & np.isnan(before))).all(axis=1)
        seen = ~np.isnan(motion.positions[a:b]).all(axis=(1, 2))
        held[a:b] = same & seen
    return held


@dataclass(frozen=True)
class HeldFrames:
    """A take's distinct frames: ``kept`` (K,) the take's frame of each, ``of`` (T,) the
    distinct frame each of the take's frames repeats (itself when it is kept)."""

    kept: np.ndarray
    of: np.ndarray

    @classmethod
    def find(cls, motion: Motion) -> HeldFrames | None:
        """The take's distinct frames, or None when no frame is held."""
        held = held_frames(motion)
        if not held.any():
            return None
        return cls(np.flatnonzero(~held), np.cumsum(~held) - 1)

    @property
    def stop(self) -> np.ndarray:
        """(K,) the take's frame after the last repeat of each distinct frame."""
        return np.append(self.kept[1:], len(self.of))

    def note(self) -> str:
        T, K = len(self.of), len(self.kept)
        return (f"{T - K} of {T} frames repeat the frame before them exactly (held frames: "
                f"no new measurement); the take was cleaned on its {K} distinct frames and "
                "each held frame written as the frame it repeats")

    def take(self, motion: Motion) -> Motion:
        """The distinct frames of ``motion`` (without its writer's ``source``, which
        describes the whole file)."""
        def pick(a):
            return None if a is None else a[self.kept]
        return motion.replace(positions=motion.positions[self.kept],
                              confidence=pick(motion.confidence), channels=pick(motion.channels),
                              times=pick(motion.times), source=None)

    def expand(self, motion: Motion, cleaned: Motion, records: list, residual):
        """``(cleaned, records, residual)`` of the distinct frames made the whole take's:
        every frame as the distinct frame it repeats came out, on ``motion``'s times and
        writer's source, with the fill errors of its fills; the records' per-sample masks
        and their ``info`` frames likewise."""
        def grow(a):
            return None if a is None else a[self.of]
        whole = motion.replace(positions=grow(cleaned.positions),
                               confidence=grow(cleaned.confidence),
                               channels=grow(cleaned.channels),
                               notes=[*cleaned.notes, self.note()], fill_errors=None)
        stop = self.stop
        grown = [replace(r, filled=grow(r.filled), flagged=grow(r.flagged),
                         moved=grow(r.moved) if r.moved.shape[:1] == cleaned.positions.shape[:1]
                         else r.moved,
                         replaced=grow(r.replaced),
                         info=map_frames(r.info, self.kept, stop) if not r.skipped else r.info)
                 for r in records]
        whole.fill_errors = written_fill_errors(whole, grown)
        return whole, grown, grow(residual)
