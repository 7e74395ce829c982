"""Heap settings for the processes that clean files (glibc only).

glibc serves every allocation above its mmap threshold (128 KiB at start; raised only
after such a block is freed, and only up to the size freed) with a fresh ``mmap`` and
unmaps it on free, so the next temporary of that size page-faults on every page it
touches. The cleaners make many short-lived (frames × channels) temporaries — one DCT
smoothing step of 4,600 frames × 123 channels makes four of 4.5 MB — and on the 2-core
machine the page faults cost as much as the arithmetic: the orthonormal DCT of 123 ×
4,608 took 9.7 ms and its inverse 11.7 ms (medians of 25, process time) against 5.2 and
5.5 ms with the settings below. :func:`tune` sets the mmap threshold to 32 MiB (glibc's
largest on 64-bit systems) and the trim threshold to 128 MiB once per process, so freed
temporaries are reused from the heap; arrays above 32 MiB are still mapped and returned
at once. It is called where a batch runs its tasks (in the calling process or in a
worker), not on import: a program that imports mocapfix as a library keeps its own
allocator settings. Elsewhere (macOS, musl) it does nothing. No library exposes
``mallopt``; it is reached through ``ctypes``.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import os

#: glibc's mallopt parameters (malloc.h)
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD = 32 << 20
TRIM_THRESHOLD = 128 << 20

_TUNED: set = set()


def tune() -> bool:
    """Set the heap thresholds of this process (once per process); True when set."""
    pid = os.getpid()
    if pid in _TUNED:
        return True
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    ok = bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(
        mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    if ok:
        _TUNED.add(pid)
    return ok
