"""Where a batch's tasks run: this process, a local process pool, or a Dask cluster.

Every choice is a ``concurrent.futures`` executor (or None: in this process), so
:func:`mocapfix.batch.tasks.run_tasks` treats them alike (DESIGN.md, "Batch as tasks over an
injected executor"):

- local (default): ``ProcessPoolExecutor`` whose workers start with one BLAS thread
  (:func:`mocapfix.core.threads.worker_init`), which exit when their parent dies
  (:func:`pool_worker_init`);
- Dask distributed (optional extra ``pip install 'mocapfix[dask]'``): ``--scheduler
  tcp://host:port`` connects to a running cluster, ``--dask-workers N`` starts a local
  cluster of N single-threaded worker processes; both through ``Client.get_executor()``.
  Workers read inputs and write outputs by the paths the client gives them, so a remote
  cluster needs the input and output folders at the same paths (a shared file system).

Dask is imported only when asked for; without it the error names the extra.
"""
from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass

from mocapfix.core.errors import ConfigError
from mocapfix.core.threads import worker_init

DASK_MISSING = ("Dask is not installed: --scheduler and --dask-workers need the optional "
                "extra, `pip install 'mocapfix[dask]'`")


@dataclass(frozen=True)
class ExecutorSpec:
    """How to run a batch: ``jobs`` local processes, or Dask (``scheduler`` address or
    ``dask_workers`` local worker processes)."""

    jobs: int = 1
    scheduler: str | None = None
    dask_workers: int | None = None

    @property
    def dask(self) -> bool:
        return bool(self.scheduler) or bool(self.dask_workers)

    def check(self) -> "ExecutorSpec":
        if self.scheduler and self.dask_workers:
            raise ConfigError("give --scheduler or --dask-workers, not both")
        if self.dask and self.jobs > 1:
            raise ConfigError("-j/--jobs is for local processes; with Dask the cluster's "
                              "workers run the files")
        if self.dask:
            import_distributed()
        if self.scheduler:
            _check_address(self.scheduler)
        return self


def _check_address(address: str) -> None:
    """A malformed --scheduler ('foo', 'tcp://host' without a port) was found only when
    the batch started (after the output folder and its manifest were made) and raised
    ValueError; refuse it with the options, before anything is written."""
    from distributed.comm import parse_address, parse_host_port

    try:
        scheme, location = parse_address(address)
        if scheme in ("tcp", "tls"):
            parse_host_port(location)
    except ValueError as exc:
        raise ConfigError(f"--scheduler {address!r} is not a Dask scheduler address ({exc}); "
                          "give tcp://HOST:PORT") from None


def pool_worker_init(threads: int = 1, creator: int | None = None) -> None:
    """:func:`~mocapfix.core.threads.worker_init`, and the worker exits (within a second)
    once ``creator``, the process that started the pool, is gone -- also when it died
    before this worker got here: a ``kill -9`` of ``mocapfix clean -j N`` left its idle
    workers waiting forever on a queue whose other end their siblings keep open. (Dask's
    worker processes watch their parent themselves.) The run's output-folder lock is not
    held by the worker (:func:`~mocapfix.batch.manifest.drop_inherited_locks`)."""
    from mocapfix.batch.manifest import drop_inherited_locks

    _kill_me_with_parent()
    drop_inherited_locks()
    signal.signal(signal.SIGINT, _on_interrupt)
    if creator is not None:
        threading.Thread(target=_exit_when_gone, args=(creator,), daemon=True,
                         name="mocapfix-parent-watch").start()
    worker_init(threads)


#: tasks running in this process (:class:`~mocapfix.batch.tasks.InWorker`)
_TASKS = [0]


@contextlib.contextmanager
def running_task():
    """Mark a task as running in this worker process (see :func:`_on_interrupt`)."""
    _TASKS[0] += 1
    try:
        yield
    finally:
        _TASKS[0] -= 1


def _on_interrupt(signum, frame) -> None:
    """Ctrl-C (SIGINT to the whole process group) in a local pool worker: a running task is
    interrupted (KeyboardInterrupt: its cleanup removes its temporary files, and the pool
    hands the interrupt back as its result); an idle worker, waiting for its next task,
    exits at once -- interrupted there it printed multiprocessing's "Process
    ForkProcess-1: Traceback ... KeyboardInterrupt" under the run's "mocapfix:
    interrupted"."""
    if _TASKS[0]:
        raise KeyboardInterrupt
    os._exit(128 + signum)


def _kill_me_with_parent() -> None:
    """On Linux, have the kernel SIGKILL this process when its parent dies (prctl
    PR_SET_PDEATHSIG): at once, even while a task holds the GIL."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes

    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL), 0, 0, 0)  # PR_SET_PDEATHSIG


def _exit_when_gone(pid: int, every: float = 0.5) -> None:
    while not _gone(pid):
        time.sleep(every)
    os._exit(1)


def _gone(pid: int) -> bool:
    """Process ``pid`` has ended (a zombie not yet reaped counts as ended, on Linux)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rpartition(")")[2].split()[0] in ("Z", "X")
    except (OSError, IndexError):
        return False


def import_distributed():
    try:
        import distributed
    except ImportError:
        raise ConfigError(DASK_MISSING) from None
    return distributed


@dataclass
class Running:
    """An open executor (None: run in this process) and how many tasks it runs at once."""

    executor: object | None
    slots: int
    description: str


@contextlib.contextmanager
def open_executor(spec: ExecutorSpec, n_items: int):
    """Yield a :class:`Running` for ``spec``; closes what it started (a local pool, a local
    Dask cluster and the client), leaves a remote cluster running."""
    spec.check()
    if not spec.dask:
        if spec.jobs <= 1 or n_items <= 1:
            yield Running(None, 1, "this process")
            return
        from concurrent.futures import ProcessPoolExecutor     # (multiprocessing: ~10 ms to import)

        workers = min(spec.jobs, n_items)
        pool = ProcessPoolExecutor(max_workers=workers, initializer=pool_worker_init,
                                   initargs=(1, os.getpid()))
        try:
            yield Running(pool, workers, f"{workers} local processes")
        finally:
            pool.shutdown(cancel_futures=True)
        return
    distributed = import_distributed()
    with contextlib.ExitStack() as stack:
        if spec.scheduler:
            try:
                client = stack.enter_context(distributed.Client(spec.scheduler, timeout="10s"))
            except (OSError, TimeoutError, ValueError) as exc:
                raise ConfigError(f"cannot reach the Dask scheduler {spec.scheduler}: {exc}") from None
            where = f"Dask scheduler {spec.scheduler}"
        else:
            import dask

            # Dask's nanny sets MALLOC_TRIM_THRESHOLD_=65536 in its workers by default;
            # with it a clean ran 1.7x slower (every large numpy temporary mmapped and
            # unmapped: sample C3D 1.65 s against 0.98 s in a plain worker process)
            stack.enter_context(dask.config.set(
                {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}))
            cluster = stack.enter_context(distributed.LocalCluster(
                n_workers=spec.dask_workers, threads_per_worker=1, processes=True,
                dashboard_address=None, silence_logs=40))
            client = stack.enter_context(distributed.Client(cluster))
            where = f"local Dask cluster of {spec.dask_workers} workers"
        slots = max(1, sum(client.nthreads().values()))
        yield Running(client.get_executor(pure=False), slots, where)
