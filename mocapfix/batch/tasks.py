"""Run one task per item over an executor and hand back a typed result per item as each
finishes (DESIGN.md, "Batch as tasks over an injected executor"): ``task(item) -> dict``
over a ``concurrent.futures`` executor — a local process pool by default, any executor with
``submit`` injected, or Dask (:mod:`mocapfix.batch.executors`). A task that raises, or
whose worker dies, gives an error result naming its input; the batch goes on.
"""
from __future__ import annotations

import warnings
from concurrent.futures import FIRST_COMPLETED, Executor, wait
from dataclasses import dataclass
from typing import Callable, Iterator



def error_result(item, message: str) -> dict:
    source = getattr(item, "source", None) or getattr(item, "path", item)
    out = {"input": str(source), "status": "ERROR", "error": message}
    if hasattr(item, "output"):
        out["output"] = str(item.output)
    return out


def run_tasks(task: Callable, items: list, workers: int = 1,
              executor: Executor | None = None, spec=None,
              window: int | None = None) -> Iterator[tuple[int, dict]]:
    """Run ``task(item)`` for every item; yield ``(index, result)`` as each finishes.

    Where: an injected ``executor`` (anything with ``submit``), else ``spec``
    (:class:`mocapfix.batch.executors.ExecutorSpec`: local processes or Dask), else ``workers``
    local processes. With one worker (or one item) and no executor the tasks run in this
    process, in order, each with the cores for its own parallel loops; in worker
    processes every task runs with one BLAS thread and one task thread
    (:mod:`mocapfix.core.threads`). At most ``window`` tasks (default: twice the executor's
    slots) are in flight, so memory does not grow with the number of items.

    ``task`` must be picklable for a process pool and must turn its own failures into an
    ``ERROR`` result; a task that raises anyway (a killed worker) becomes one here.
    """
    from mocapfix.batch.executors import ExecutorSpec, open_executor

    if executor is not None:
        yield from _run_on(executor, task, items, window or max(2, 2 * workers))
        return
    with open_executor(spec or ExecutorSpec(jobs=workers), len(items)) as running:
        if running.executor is None:
            from mocapfix.core.memory import release_freed_memory
            from mocapfix.core.threads import (blas_threads, limit_blas, set_task_threads,
                                          single_process_task_threads, task_threads)

            blas = blas_threads(1)
            limit_blas(blas)
            before = task_threads()
            set_task_threads(single_process_task_threads(blas))
            try:
                for n, item in enumerate(items):
                    result = _guarded(task, item)
                    release_freed_memory()
                    yield n, result
            finally:
                set_task_threads(before)
            return
        yield from _run_on(running.executor, task, items, window or 2 * running.slots)


@dataclass(frozen=True)
class InWorker:
    """``task`` run in a batch worker: BLAS held to ``threads`` threads and the task's
    own loops to one thread first."""

    task: Callable
    threads: int = 1

    def __call__(self, item):
        from mocapfix.batch.executors import running_task
        from mocapfix.core.memory import release_freed_memory
        from mocapfix.core.threads import limit_blas, set_task_threads

        limit_blas(self.threads)
        set_task_threads(1)
        try:
            with running_task():
                return self.task(item)
        finally:
            release_freed_memory()


def _run_on(pool: Executor, task, items: list, window: int) -> Iterator[tuple[int, dict]]:
    work = InWorker(task)
    pending: dict = {}
    it = iter(enumerate(items))
    try:
        while True:
            while len(pending) < max(1, window):
                nxt = next(it, None)
                if nxt is None:
                    break
                try:
                    pending[pool.submit(work, nxt[1])] = nxt[0]
                except Exception as exc:  # noqa: BLE001 — a pool broken by a killed worker
                    yield nxt[0], error_result(nxt[1], f"worker failed: {exc}")
            if not pending:
                return
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                n = pending.pop(fut)
                try:
                    result = fut.result()
                except Exception as exc:  # noqa: BLE001 — e.g. a worker killed by the OS
                    result = error_result(items[n], f"worker failed: {exc}")
                yield n, result
    finally:
        for fut in pending:
            fut.cancel()


def internal_error(result: dict) -> dict:
    """``result`` (an ERROR for an unforeseen exception, inside its ``except``) with the
    traceback under ``"traceback"``, which the CLI prints with ``--debug``."""
    import traceback

    result["traceback"] = traceback.format_exc()
    return result


#: NumPy's floating-point warnings ("overflow encountered in multiply"): a file holding
#: values near 1e300 printed a dozen of them naming no file; the code takes the inf and NaN
#: they make for what they are (not finite: reported as missing or as no value)
_FLOAT_NOISE = r"(overflow|invalid value|divide by zero|underflow) encountered"


def quiet_float_warnings() -> None:
    """Hide :data:`_FLOAT_NOISE` in this process (idempotent: one filter however often)."""
    warnings.filterwarnings("ignore", message=_FLOAT_NOISE, category=RuntimeWarning)


def _guarded(task, item) -> dict:
    quiet_float_warnings()          # in the process that runs the task (pool, Dask worker)
    try:
        return task(item)
    except Exception as exc:  # noqa: BLE001 — one bad file must not stop the batch
        return internal_error(error_result(item, f"internal error {type(exc).__name__}: {exc}"))
