"""The BLAS thread policy (mocapfix/threads.py): workers get cores // workers threads, and
no kernel of a whole clean runs with more BLAS/OpenMP threads than the worker was given
(sampled with threadpoolctl from a second thread while the clean runs)."""
from __future__ import annotations

import threading
from concurrent.futures import ProcessPoolExecutor

import pytest

from mocapfix import threads
from mocapfix.formats import read
from mocapfix.pipeline import loads_config
from conftest import SAMPLE_DATA

CONFIG = "pipeline:\n  - cleaner: fill_pca\n    max_iter: 30\n  - cleaner: butterworth\n"


def test_worker_threads_divides_the_cores():
    assert threads.worker_threads(1, cores=16) == 16
    assert threads.worker_threads(4, cores=16) == 4
    assert threads.worker_threads(3, cores=16) == 5
    assert threads.worker_threads(16, cores=16) == 1
    assert threads.worker_threads(32, cores=2) == 1
    assert threads.worker_threads(0, cores=2) == 2
    assert 1 <= threads.worker_threads(1) == threads.available_cores()


def _clean_and_watch(start_threads: int) -> tuple[int, int]:
    """In a worker: optionally raise the pools to ``start_threads`` (as numpy's default is
    on a bigger machine), then clean the first 300 frames of the sample C3D (PCA fill +
    filter) while a second thread samples the pools' thread counts. Returns (most
    threads seen, samples taken)."""
    from threadpoolctl import threadpool_limits

    motion = read(SAMPLE_DATA / "walk_markers.c3d")
    motion = motion.replace(positions=motion.positions[:300].copy(), confidence=None)

    seen: list[int] = []
    stop = threading.Event()

    def sample():
        while not stop.is_set():
            seen.append(max(threads.pool_threads().values(), default=0))
            stop.wait(0.01)

    watcher = threading.Thread(target=sample)
    if start_threads:
        threadpool_limits(limits=start_threads)
    watcher.start()
    try:
        loads_config(CONFIG).run(motion)
    finally:
        stop.set()
        watcher.join()
    return max(seen), len(seen)


def _pool_threads_now() -> int:
    return max(threads.pool_threads().values(), default=0)


def test_no_kernel_exceeds_the_workers_thread_limit():
    loads_config(CONFIG)  # cleaners and SciPy imported once, before the workers fork
    if not threads.pool_threads():
        pytest.fail("threadpoolctl sees no BLAS library: the check would be empty")
    # control: without the policy, a worker runs with the library default (2 here)
    with ProcessPoolExecutor(max_workers=1) as pool:
        raised = pool.submit(_clean_and_watch, 2).result()
    # with the policy: workers forked from a process running 2 threads (the default on
    # this 2-core machine) hold the initializer's limit through every kernel
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=2), \
            ProcessPoolExecutor(max_workers=1, initializer=threads.limit_process_threads,
                                initargs=(1,)) as pool:
        assert pool.submit(_pool_threads_now).result() == 1
        limited = pool.submit(_clean_and_watch, 0).result()
    assert limited[1] > 10 and raised[1] > 10           # the clean was sampled throughout
    assert limited[0] == 1, f"a kernel ran with {limited[0]} threads under a limit of 1"
    if raised[0] < 2:
        pytest.fail(f"control did not show 2 threads ({raised}): the sampler cannot see a breach")
