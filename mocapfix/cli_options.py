"""Command-line options shared by the batch commands (``clean``, ``check``,
``train-dictionary`` in :mod:`mocapfix.cli`, ``bench`` in :mod:`mocapfix.bench_cli`): where
the work runs. A module of its own so that ``bench_cli`` can use them without importing
``cli`` (which registers ``bench``)."""
from __future__ import annotations

import click


_executor_options = [
    click.option("--scheduler", metavar="tcp://HOST:PORT", default=None,
                 help="Run the files on this Dask cluster (extra: pip install 'mocapfix[dask]'; "
                      "workers need the inputs and outputs at the same paths)."),
    click.option("--dask-workers", type=click.IntRange(1, 1024), default=None, metavar="N",
                 help="Run the files on a local Dask cluster of N worker processes (extra: dask)."),
]


def executors(fn):
    """--scheduler / --dask-workers (Dask) beside a command's -j (local processes)."""
    for opt in reversed(_executor_options):
        fn = opt(fn)
    return fn


def executor_spec(jobs, scheduler, dask_workers):
    """The checked :class:`mocapfix.executors.ExecutorSpec` of the three options."""
    from mocapfix.executors import ExecutorSpec

    return ExecutorSpec(jobs, scheduler, dask_workers).check()
