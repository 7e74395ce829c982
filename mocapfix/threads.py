"""BLAS/OpenMP thread policy: never more threads than cores.

numpy's OpenBLAS (and any OpenMP runtime SciPy loads) starts one thread per core. A batch
of ``N`` worker processes on ``C`` cores would then run ``N x C`` threads on ``C`` cores;
issue 13 measured a single clean 2x slower on a 16-core machine for that reason. The
policy: each of ``N`` workers gets ``max(1, C // N)`` threads (one per worker when there
are at least as many workers as cores). Kernels may lower the limit further inside
(:func:`mocapfix.solvers.lowrank.blas_single_thread`); nothing raises it.

Wiring (batch runner)::

    from mocapfix import threads
    n = threads.worker_threads(workers)
    ProcessPoolExecutor(max_workers=workers, initializer=threads.limit_process_threads,
                        initargs=(n,))

and, for a run in the calling process (``-j 1``), ``threads.limit_process_threads(
threads.worker_threads(1))`` or leave the libraries' default (one thread per core).
"""
from __future__ import annotations

import os

_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS",
        "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
_limiter = None  # the process-wide threadpoolctl limit, kept alive while it applies


def available_cores() -> int:
    """Cores this process may run on (CPU affinity, e.g. a container's or taskset's share)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def worker_threads(workers: int, cores: int | None = None) -> int:
    """BLAS/OpenMP threads for each of ``workers`` processes sharing ``cores``."""
    cores = available_cores() if cores is None else max(1, int(cores))
    return max(1, cores // max(1, int(workers)))


def limit_process_threads(threads: int) -> None:
    """Hold every BLAS/OpenMP pool of this process to ``threads`` from now on.

    Sets the environment (for libraries loaded later, and for child processes) and limits
    the pools already loaded through threadpoolctl. Meant as a worker initializer.
    """
    global _limiter
    threads = max(1, int(threads))
    for name in _ENV:
        os.environ[name] = str(threads)
    from threadpoolctl import threadpool_limits

    _limiter = threadpool_limits(limits=threads)


def pool_threads() -> dict[str, int]:
    """The thread count of each loaded BLAS/OpenMP pool, by library (``threadpool_info``)."""
    from threadpoolctl import threadpool_info

    out: dict[str, int] = {}
    for pool in threadpool_info():
        key = f"{pool.get('internal_api')}:{os.path.basename(pool.get('filepath', ''))}"
        out[key] = max(out.get(key, 0), int(pool.get("num_threads", 0)))
    return out
