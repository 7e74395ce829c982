"""A whole-take array kept on disk, read back a piece at a time: the input's values while a
long take is cleaned in windows (:func:`mocapfix.cleaning.clean_motion` with
``keep_input_on_disk``; issue 39).

A take cleaned in windows needs its input only a window at a time, and its report and
writer read the input again a column (one point's trajectory) or a chunk of frames at a
time; held in memory beside the output, the input was half of a long take's peak (24
bytes a sample for the positions of a C3D, 8 more for its confidence, 16 a channel value
of a BVH with its positions). :class:`FramesOnDisk` writes an array (frames first) to an
unlinked temporary file, one column after another, so that a column is one read and a
chunk of frames one read per column, each ``os.preadv`` into an array of its own.

Written here because ``numpy.memmap`` does not serve this: the pages a pass over a
mapped file touches stay in the process's resident memory (they are the process's until
the kernel needs them back), so the report's passes over the input would bring the whole
input back into the peak the memory budget bounds. The temporary file is unlinked when
made (``tempfile.TemporaryFile``): it is gone when the array is, or the process, however
it ends.
"""
from __future__ import annotations

import os
import tempfile
import threading
from pathlib import Path

import numpy as np

from mocapfix.core.motion import missing_samples


class FramesOnDisk(np.lib.mixins.NDArrayOperatorsMixin):
    """A read-only (T, C, ...) array on disk, indexed as the array was: ``a[lo:hi]`` (a
    chunk of frames), ``a[:, j]`` and ``a[lo:hi, j]`` (a column), ``a[:, [j, k]]``
    (columns) read only what they return; any other index, ``np.asarray(a)`` and
    arithmetic read the whole array (right, not small). ``missing``: the (T, J) mask of
    samples with a NaN coordinate, kept in memory for a (T, J, 3) array of positions
    (what :attr:`mocapfix.core.motion.Motion.missing` gives), else None.

    ``folder``: where the temporary file goes (the output's folder: a disk with room for
    the output; a RAM-backed ``/tmp`` would save no memory)."""

    def __init__(self, array: np.ndarray, folder: str | Path | None = None):
        array = np.asarray(array)
        if array.ndim < 2:
            raise ValueError(f"an array of frames × columns is kept on disk, got {array.shape}")
        self.shape, self.dtype = array.shape, array.dtype
        self.missing = None
        if array.ndim == 3 and array.shape[2] == 3 and array.dtype.kind == "f":
            self.missing = missing_samples(array)
            self.missing.flags.writeable = False
        self._row = int(np.prod(array.shape[2:], dtype=np.int64)) * array.dtype.itemsize
        self._column = self._row * array.shape[0]
        self._file = tempfile.TemporaryFile(dir=folder, prefix=".mocapfix-input-")
        try:
            for j in range(array.shape[1]):
                self._file.write(np.ascontiguousarray(array[:, j]).data)
            self._file.flush()
        except BaseException:
            self._file.close()
            raise

    # -- what numpy code asks of an array -----------------------------------------------
    @property
    def ndim(self) -> int:
        return len(self.shape)

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def nbytes(self) -> int:
        return self.size * self.dtype.itemsize

    def __len__(self) -> int:
        return self.shape[0]

    def __array__(self, dtype=None, copy=None):
        whole = self._read(0, self.shape[0], range(self.shape[1]))
        return whole if dtype is None else whole.astype(dtype, copy=False)

    def copy(self) -> np.ndarray:
        return np.asarray(self)

    def __array_ufunc__(self, ufunc, method, *inputs, **kwargs):
        # arithmetic and ufuncs on the whole array read back; never written into
        if any(isinstance(o, FramesOnDisk) for o in kwargs.get("out", ())):
            return NotImplemented
        inputs = [np.asarray(x) if isinstance(x, FramesOnDisk) else x for x in inputs]
        return getattr(ufunc, method)(*inputs, **kwargs)

    def __getattr__(self, name: str):
        # any other ndarray attribute (sum, astype, T, ...) on the whole array read back
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(np.asarray(self), name)

    def close(self) -> None:
        """Let the file go now (else when the array is collected)."""
        self._file.close()

    # -- reads ---------------------------------------------------------------------------
    def __getitem__(self, key):
        key = key if isinstance(key, tuple) else (key,)
        if not key:
            return np.asarray(self)
        frames, squeeze = _frame_range(key[0], self.shape[0])
        columns, one = _columns(key[1] if len(key) > 1 else slice(None), self.shape[1])
        if frames is None or columns is None or any(k is None or k is Ellipsis for k in key):
            return np.asarray(self)[key]
        out = self._read_every(*frames, columns)
        if one:
            out = out[:, 0]
        if squeeze:
            out = out[0]
        if len(key) > 2:                # the trailing axes' own index
            out = out[(slice(None),) * ((not squeeze) + (not one)) + key[2:]]
        return out

    def _read_every(self, start: int, stop: int, step: int, columns) -> np.ndarray:
        """Every ``step``-th frame of ``start:stop`` of ``columns`` (a viewer's frames of a
        long take): blocks of :data:`BLOCK_FRAMES` frames, or one frame at a time when
        the step is longer than that."""
        if step == 1:
            return self._read(start, stop, columns)
        rows = range(start, stop, step)
        if step >= BLOCK_FRAMES:
            parts = [self._read(f, f + 1, columns) for f in rows]
        else:
            block = step * (BLOCK_FRAMES // step)
            parts = [self._read(a, min(a + block, stop), columns)[::step]
                     for a in range(start, stop, block)]
        if not parts:
            return self._read(start, start, columns)
        return np.concatenate(parts)

    def _read(self, start: int, stop: int, columns) -> np.ndarray:
        """Frames ``start:stop`` of ``columns``: a (n, len(columns), ...) array."""
        n = max(stop - start, 0)
        columns = list(columns)
        out = np.empty((len(columns), n, *self.shape[2:]), dtype=self.dtype)
        if n and len(columns):
            for i, j in enumerate(columns):
                _read_exactly(self._file, out[i], j * self._column + start * self._row)
        return out[0][:, None] if len(columns) == 1 else np.ascontiguousarray(np.swapaxes(out, 0, 1))


#: frames read at a time for a strided index (:meth:`FramesOnDisk._read_every`)
BLOCK_FRAMES = 4096


_SEEK_LOCK = threading.Lock()


def _read_exactly(file, into: np.ndarray, offset: int) -> None:
    """Fill ``into`` from ``file`` at ``offset``: ``os.preadv`` where the system has it,
    else a seek and a read under a lock (Windows)."""
    view = memoryview(into).cast("B")
    done = 0
    while done < len(view):
        if hasattr(os, "preadv"):
            got = os.preadv(file.fileno(), [view[done:]], offset + done)
        else:
            with _SEEK_LOCK:
                file.seek(offset + done)
                got = file.readinto(view[done:])
        if not got:
            raise OSError(f"the input kept on disk ended {len(view) - done} bytes early")
        done += got


def _frame_range(key, T: int):
    """``((start, stop, step), squeeze)`` of a frame index that reads a run of frames
    (an int, a slice with a positive step), else ``(None, False)``."""
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        k = int(key) + (T if key < 0 else 0)
        if not 0 <= k < T:
            raise IndexError(f"index {int(key)} is out of bounds for axis 0 with size {T}")
        return (k, k + 1, 1), True
    if isinstance(key, slice):
        start, stop, step = key.indices(T)
        if step > 0:
            return (start, max(start, stop), step), False
    return None, False


def _columns(key, C: int):
    """``(columns, one)`` of a column index that picks columns (an int, a slice, a list or
    array of ints), else ``(None, False)``."""
    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        k = int(key) + (C if key < 0 else 0)
        if not 0 <= k < C:
            raise IndexError(f"index {int(key)} is out of bounds for axis 1 with size {C}")
        return [k], True
    if isinstance(key, slice):
        return list(range(*key.indices(C))), False
    if isinstance(key, (list, np.ndarray)):
        picked = np.asarray(key)
        if picked.ndim == 1 and (picked.dtype.kind in "iu" or picked.size == 0):
            picked = picked.astype(np.intp)
            if ((picked < -C) | (picked >= C)).any():
                raise IndexError(f"column index out of bounds for axis 1 with size {C}")
            return (picked % C if C else picked).tolist(), False
    return None, False
