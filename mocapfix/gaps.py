"""Runs of missing samples ("gaps") along time, vectorised over channels."""
from __future__ import annotations

import numpy as np


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


def gap_table(mask: np.ndarray) -> list[dict]:
    col, start, length = runs(mask)
    return [dict(column=int(c), start=int(s), length=int(n)) for c, s, n in zip(col, start, length)]


def interior(start: np.ndarray, length: np.ndarray, n_frames: int) -> np.ndarray:
    """True for runs that touch neither end of the sequence."""
    return (start > 0) & (start + length < n_frames)
