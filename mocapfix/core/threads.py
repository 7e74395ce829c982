"""Thread policy: how many threads numpy's BLAS/LAPACK, and a task's own parallel loops, may use.

- In a batch, every worker process (a local process-pool worker, a Dask worker) runs its
  BLAS with **one** thread: the files are the parallelism, and N workers × M BLAS threads
  on N cores only adds contention (issue 13 measured 16 OpenBLAS threads per worker on a
  16-core machine).
- For a single file (or ``-j 1``, which cleans in the calling process) the limit is
  :data:`SINGLE_FILE_THREADS` (one: two measured no faster, see docs/architecture.md,
  "Threads and memory"); ``MOCAPFIX_BLAS_THREADS`` overrides it for a single-process run
  (capped at the cores available).
- Never more threads than cores available to the process.

The limits are set with ``threadpoolctl`` (a runtime dependency) for the whole process,
once per process; kernels may lower them further for their own span, never raise them.

**Task threads.** A few steps have independent pieces of work inside one file —
``trust``'s blocks of markers, ``swaps``' chunks of frames, ``tsmc``'s two GCV smooths —
that :func:`parallel_map` runs on threads (numpy releases the GIL in its array loops, FFTs
and BLAS calls). Work made of many small array operations gains nothing from them: it
holds the GIL between the operations, and two threads spend their time handing it over
(``fill_ensemble``'s gap models, which ran on these threads until issue 39 measured them
slower there: :func:`mocapfix.solvers.pma.member_fills`); with the same budget that work
goes to a forked child process instead (:mod:`mocapfix.core.forked`: the gap models of
half the markers, :func:`mocapfix.solvers.pma.validated_member_fills`). The budget is
:func:`task_threads`: the cores available when one file is cleaned in this process
(``-j 1`` or a single file; divided by the BLAS threads when ``MOCAPFIX_BLAS_THREADS``
raises those; ``MOCAPFIX_THREADS`` lowers it, ``1`` turns it off), one in
a batch worker (the files are the parallelism) and one by default (library use). The
results do not depend on the number of threads: the pieces are the same, each is
computed alone and they are put together in their order.
"""
from __future__ import annotations

import os
import sys
import threading

#: BLAS threads when one file is cleaned in this process (see the module docstring).
SINGLE_FILE_THREADS = 1

_LIMITED: dict = {}
#: threads of :func:`parallel_map` in this process (see the module docstring)
_TASK_THREADS = [1]
#: marks parallel_map's own threads (a nested call runs in the calling thread)
_IN_POOL = threading.local()
#: the GIL's switch interval (s) while :func:`parallel_map`'s threads run: the 4,500-frame
#: case of benchmarks/clean_speed.py, twelve alternating cleans in memory, ``trust`` 191 →
#: 175 ms, the whole clean 0.98x against Python's 5 ms (the same output)
SWITCH_S = 0.0005


def cores() -> int:
    """Cores this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def blas_threads(workers: int) -> int:
    """BLAS threads per process for a run with ``workers`` worker processes."""
    if workers > 1:
        return 1
    wanted = os.environ.get("MOCAPFIX_BLAS_THREADS", "")
    n = int(wanted) if wanted.isdigit() else SINGLE_FILE_THREADS
    return max(1, min(n, cores()))


def limit_blas(threads: int) -> None:
    """Hold BLAS/OpenMP pools of this process to ``threads`` (once per process and value;
    cheap to call before every task)."""
    key = (os.getpid(), threads)
    if key in _LIMITED:
        return
    from threadpoolctl import threadpool_limits

    threadpool_limits(threads)
    _LIMITED.clear()
    _LIMITED[key] = True


def worker_init(threads: int = 1) -> None:
    """Initializer of a batch worker process: environment for any library loaded later,
    the live BLAS pools, one task thread, and freed memory kept between the steps of a
    file (:mod:`mocapfix.core.memory`)."""
    from mocapfix.core.memory import retain_freed_memory

    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(threads)
    limit_blas(threads)
    set_task_threads(1)
    retain_freed_memory()


def single_process_task_threads(blas: int = 1) -> int:
    """Task threads when one file at a time is cleaned in this process with ``blas``
    BLAS threads: the cores available divided by ``blas`` (so that task threads × BLAS
    threads stay within the cores), at most ``MOCAPFIX_THREADS`` (a value that is not a
    positive integer is ignored)."""
    wanted = os.environ.get("MOCAPFIX_THREADS", "")
    room = max(1, cores() // max(1, blas))
    n = int(wanted) if wanted.isdigit() and int(wanted) > 0 else room
    return max(1, min(n, room))


def set_task_threads(n: int) -> None:
    """Set this process's budget of task threads (:func:`parallel_map`)."""
    _TASK_THREADS[0] = max(1, int(n))


def task_threads() -> int:
    """This process's budget of task threads."""
    return _TASK_THREADS[0]


def parallel_map(fn, items) -> list:
    """``[fn(item) for item in items]``, on up to :func:`task_threads` threads (in this
    thread when the budget is one, there is one item, or this is already one of
    parallel_map's threads). ``fn`` must not depend on the order in which the items run;
    exceptions propagate as from the loop."""
    items = list(items)
    n = min(task_threads(), len(items))
    if n <= 1 or getattr(_IN_POOL, "active", False):
        return [fn(item) for item in items]
    from concurrent.futures import ThreadPoolExecutor

    def run(item):
        _IN_POOL.active = True
        return fn(item)

    # a thread waiting for the GIL gets it after SWITCH_S instead of Python's 5 ms: the
    # pieces hand it over between their array operations, and waited for it in turns
    before = sys.getswitchinterval()
    sys.setswitchinterval(min(before, SWITCH_S))
    try:
        with ThreadPoolExecutor(n) as pool:
            return list(pool.map(run, items))
    finally:
        sys.setswitchinterval(before)


def max_blas_threads() -> int:
    """Largest thread count among the BLAS pools loaded in this process (0: none)."""
    from threadpoolctl import threadpool_info

    return max((i["num_threads"] for i in threadpool_info() if i.get("user_api") == "blas"), default=0)
