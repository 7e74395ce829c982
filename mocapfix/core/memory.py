"""Process memory policy of the command-line tool: freed heap memory stays in the process
while a file is cleaned, and goes back to the system between files.

glibc serves a large allocation by a fresh ``mmap`` and hands the top of the heap back to
the system once more than a trim threshold is free; solvers that allocate and free arrays
of a few MB in every iteration then pay a page fault per 4 KB on every step.
:func:`retain_freed_memory` sets ``M_MMAP_THRESHOLD`` (256 MB) and ``M_TRIM_THRESHOLD``
(1 GB; 32 MB where an older glibc refuses more) with glibc's ``mallopt``;
:func:`release_freed_memory` (``malloc_trim``) returns what is free after each file of a
batch, after a file is read (the reader's temporaries, before the take is cleaned), and
after the last window of a take cleaned in windows (before its report). Both
do nothing on other C libraries (macOS, Windows, musl) and in processes that did not ask:
the CLI and the process-pool workers mocapfix starts call
:func:`retain_freed_memory`; importing mocapfix changes nothing in the calling process,
and Dask workers (not ours) are left as they are. Written here because no maintained
package exposes ``mallopt``; ``ctypes`` reaches it. The measurements behind the policy:
docs/architecture.md, "Threads and memory".
"""
from __future__ import annotations

import ctypes
import functools

#: glibc's mallopt parameter numbers (malloc.h)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD = 256 << 20
#: the largest mmap threshold older glibc accepts (HEAP_MAX_SIZE / 2 on 64-bit)
MMAP_THRESHOLD_OLD_GLIBC = 32 << 20
TRIM_THRESHOLD = 1 << 30

_RETAINED = [False]


@functools.lru_cache(maxsize=1)
def _libc():
    """The C library's handle when it has ``mallopt`` and ``malloc_trim`` (glibc)."""
    try:
        libc = ctypes.CDLL(None)            # the symbols already loaded: libc on Linux
    except (OSError, TypeError):
        return None
    if not hasattr(libc, "mallopt") or not hasattr(libc, "malloc_trim"):
        return None
    return libc


def retain_freed_memory() -> bool:
    """Keep freed memory in this process (glibc); True when the setting took."""
    if _RETAINED[0]:
        return True
    libc = _libc()
    if libc is None:
        return False
    # glibc before ~2.35 refuses an mmap threshold above 32 MiB; the trim threshold alone
    # would turn off the adaptive mmap threshold and make things worse, so it is set only
    # once an mmap threshold took
    took = any(libc.mallopt(M_MMAP_THRESHOLD, ctypes.c_int(value)) == 1
               for value in (MMAP_THRESHOLD, MMAP_THRESHOLD_OLD_GLIBC))
    if took:
        took = libc.mallopt(M_TRIM_THRESHOLD, ctypes.c_int(TRIM_THRESHOLD)) == 1
    _RETAINED[0] = took
    return took


def release_freed_memory() -> None:
    """Return the free heap to the system (after a file, and after the windows of a take
    cleaned in windows), if this process retains it."""
    if _RETAINED[0]:
        libc = _libc()
        if libc is not None:
            libc.malloc_trim(ctypes.c_size_t(0))
