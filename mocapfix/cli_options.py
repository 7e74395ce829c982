"""Command-line options shared by the batch commands (``clean``, ``check``,
``train-dictionary`` in :mod:`mocapfix.cli`, ``bench`` in :mod:`mocapfix.bench.cli`): where
the work runs, and the exit codes and error line they share. A module of its own so that
``bench_cli`` can use them without importing ``cli`` (which registers ``bench``)."""
from __future__ import annotations

import math

import click

from mocapfix.core.errors import one_line, printable

#: docs/commands.md "Exit codes"
EXIT_OK, EXIT_SOME_FAILED, EXIT_USAGE, EXIT_UNREADABLE = 0, 1, 2, 3


def error_line(message) -> None:
    """``mocapfix: error: MESSAGE`` on stderr, one line (a line break or control character
    in a file name shown escaped)."""
    click.echo(printable(f"mocapfix: error: {one_line(message)}"), err=True)


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
    """The checked :class:`mocapfix.batch.executors.ExecutorSpec` of the three options."""
    from mocapfix.batch.executors import ExecutorSpec

    return ExecutorSpec(jobs, scheduler, dask_workers).check()


class FrameRate(click.ParamType):
    """``--fps``: a frame rate in Hz, finite and within the range the readers accept
    (:data:`mocapfix.core.quantity.MIN_FRAME_RATE_HZ` – ``MAX_FRAME_RATE_HZ``). A bad value is
    a usage error (exit 2) before any file is read, not one error per file — and never
    ``nan``, ``inf`` or ``0`` taken silently."""

    name = "fps"

    def convert(self, value, param, ctx):
        from mocapfix.core.quantity import frame_rate

        try:
            return frame_rate(value)
        except ValueError as exc:
            self.fail(str(exc), param, ctx)


FPS = FrameRate()


class FiniteFloatRange(click.FloatRange):
    """``click.FloatRange`` that refuses ``nan``, which passes its bounds (every comparison
    with it is false): ``view --budget nan`` said only "cannot convert float NaN to
    integer"."""

    def convert(self, value, param, ctx):
        number = super().convert(value, param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a number", param, ctx)
        return number


class GivenPath(click.Path):
    """``click.Path`` that refuses an empty string: ``""`` (an unset shell variable in
    ``-o "$OUT"`` or an input ``"$TAKES"``) meant the current folder, so ``clean`` wrote
    its outputs there, and as an input the whole current tree was cleaned, checked or
    listed; ``--junit ""`` silently wrote no report."""

    def convert(self, value, param, ctx):
        if isinstance(value, str) and not value.strip():
            self.fail("is empty (an unset variable?); give a path", param, ctx)
        return super().convert(value, param, ctx)


def not_empty(ctx, param, value):
    """Callback for a name-or-path option: ``-c ""`` (an unset variable) silently ran the
    default config instead of the user's, ``-r ""`` the default rules, ``--would-clean ""``
    nothing."""
    if isinstance(value, str) and not value.strip():
        raise click.BadParameter("is empty (an unset variable?); give a file or a preset name")
    return value
