"""Two pieces of one file's work at once: one in a child process forked for it, one here.

Work made of many small array operations holds the GIL between them, so two threads of
one process run it one after the other (:mod:`mocapfix.core.threads`). A child forked
from this process has an interpreter of its own and a copy-on-write view of this one's
memory: every module and array is already there, its work starts ~2–3 ms after the call
(a 170 MB process, the 2-core machine), and it sends its result back pickled through a
pipe. The standard library's pools keep workers that outlive a call and move work and
results through queues and feeder threads; one fork per call and one pipe, no thread, is
what this needs.

The child is used only where it is safe and can pay: on Linux (a fork after numpy's BLAS
has started is what macOS warns against), with a task-thread budget of at least two
(:func:`mocapfix.core.threads.task_threads`: a single file cleaned with ``-j 1``, not a
batch worker, which has one core of its own), from a process with no other thread alive
(a lock another thread held at the fork would stay held in the child), and not inside a
child. Otherwise, and whenever the child fails (an error, killed, out of memory), the
work runs here, one piece after the other: the results are the same either way, since
the pieces are the same and which process runs one does not change its values.
"""
from __future__ import annotations

import os
import pickle
import signal
import sys
import threading

#: True in a child forked by :func:`both`
_IN_CHILD = [False]


def can_fork() -> bool:
    """Whether :func:`both` may run a piece in a forked child here (see the module
    docstring)."""
    from mocapfix.core.threads import task_threads

    return (sys.platform.startswith("linux") and hasattr(os, "fork") and not _IN_CHILD[0]
            and task_threads() >= 2 and threading.active_count() == 1)


def both(aside, here, fork: bool = True) -> tuple:
    """``(aside(), here())``: ``aside`` in a forked child while ``here`` runs in this
    process when :func:`can_fork` (and ``fork``), else one after the other here.
    ``aside``'s result must pickle. An error of ``here`` propagates (the child is
    stopped); a failed child's piece is run again here."""
    if not (fork and can_fork()):
        return aside(), here()
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:                                            # the child
        os.close(read_end)
        _child(aside, write_end)
    os.close(write_end)
    done = False
    try:
        mine = here()
        with os.fdopen(read_end, "rb") as pipe:
            read_end = None
            payload = pipe.read()
        done = True
    finally:
        if read_end is not None:
            os.close(read_end)
        if not done:
            _stop(pid)
        os.waitpid(pid, 0)
    try:
        status, value = pickle.loads(payload)
    except Exception:                                       # killed before it wrote all
        status, value = "failed", None
    return (value if status == "ok" else aside()), mine


def _child(aside, write_end: int) -> None:
    """Run ``aside`` and write ``("ok", result)`` (or ``("failed", message)``) to the
    pipe; never returns (``os._exit``: no atexit handler, no buffer of the parent's
    flushed twice)."""
    code = 1
    try:
        _IN_CHILD[0] = True
        signal.signal(signal.SIGINT, signal.SIG_DFL)       # the parent reports an interrupt
        try:
            payload = pickle.dumps(("ok", aside()), protocol=pickle.HIGHEST_PROTOCOL)
        except BaseException as exc:                        # noqa: BLE001 — the parent reruns it
            payload = pickle.dumps(("failed", repr(exc)))
        with os.fdopen(write_end, "wb") as pipe:
            pipe.write(payload)
        code = 0
    finally:
        os._exit(code)


def _stop(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
