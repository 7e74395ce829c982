"""Runs of missing samples ("gaps") along time, vectorised over channels."""
from __future__ import annotations

import numpy as np


#: a fill spanning more than this is a *long fill*: listed as such in the report (its
#: samples rest on the model, not on a nearby measurement; the C3D marks every filled
#: sample alike, residual 0 and camera mask 0)
LONG_FILL_S = 0.5


def runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Runs of True along axis 0 of a (T, ...) boolean array.

    Returns ``(column, start, length)`` arrays, one entry per run, where ``column`` is the
    flat index over the trailing axes. No Python loop over frames.
    """
    mask = np.asarray(mask, dtype=bool)
    T = mask.shape[0]
    flat = mask.reshape(T, int(np.prod(mask.shape[1:], dtype=np.int64)))
    padded = np.zeros((T + 2, flat.shape[1]), dtype=np.int8)
    padded[1:-1] = flat
    d = np.diff(padded, axis=0)
    # np.nonzero on the transposed array orders by column, then time: starts and ends pair up
    column, start = np.nonzero(d.T == 1)
    _, end = np.nonzero(d.T == -1)
    return column, start, end - start


def take_frames(missing: np.ndarray, points: np.ndarray | None = None) -> slice:
    """The frames of the take: from the first to the last frame on which one of
    ``points`` (default all) is seen. Frames before and after, where none is (an export's
    empty first or last frames, a recording left running), hold nothing to clean or
    fill: they are not graded. All frames when no point is ever seen."""
    seen = ~missing if points is None else ~missing[:, points]
    any_seen = np.flatnonzero(seen.any(axis=1))
    if not len(any_seen):
        return slice(0, missing.shape[0])
    return slice(int(any_seen[0]), int(any_seen[-1]) + 1)


def gap_table(mask: np.ndarray) -> list[dict]:
    col, start, length = runs(mask)
    return [dict(column=int(c), start=int(s), length=int(n)) for c, s, n in zip(col, start, length)]


def interior(start: np.ndarray, length: np.ndarray, n_frames: int) -> np.ndarray:
    """True for runs that touch neither end of the sequence."""
    return (start > 0) & (start + length < n_frames)


def gap_report(missing: np.ndarray, still_missing: np.ndarray, fps: float) -> dict:
    """Counts of the marker gaps (runs in a (T, J) mask) that were filled, left because they
    touch an end of the capture, or left for another reason (too long); shared by every
    cleaner that fills."""
    T = missing.shape[0]
    col, start, length = runs(missing)
    edge = (start == 0) | (start + length == T)
    # a gap counts as filled when none of its samples is still missing
    left = np.zeros(len(col), dtype=bool)
    if len(col):
        miss_cum = np.concatenate([np.zeros((1, missing.shape[1]), dtype=np.int64),
                                   np.cumsum(still_missing, axis=0)])
        left = (miss_cum[start + length, col] - miss_cum[start, col]) > 0
    long_left = left & ~edge
    return {
        "gaps": int(len(col)),
        "gaps_filled": int(np.sum(~left)),
        "gaps_left_long": int(np.sum(long_left)),
        "gaps_left_edge": int(np.sum(left & edge)),
        "samples_filled": int(np.sum(missing & ~still_missing)),
        "longest_left_s": (round(float(length[long_left].max()) / fps, 4)
                           if long_left.any() else 0.0),
    }
