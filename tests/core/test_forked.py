"""Two pieces of work at once, one in a forked child (mocapfix.core.forked): the results
are those of running both here, a failed child's piece is run again here, an error here
stops the child, and nothing is forked where the policy says not to."""
import os
import subprocess
import sys
import threading

import numpy as np
import pytest

from mocapfix.core import forked, threads

LINUX = sys.platform.startswith("linux")


@pytest.fixture
def two_task_threads(monkeypatch, fork_allowed):
    monkeypatch.setattr(threads, "_TASK_THREADS", [2])


@pytest.fixture
def forks(monkeypatch):
    """The pids of the children forked during the test."""
    made, fork = [], os.fork

    def recorded():
        pid = fork()
        if pid:
            made.append(pid)
        return pid

    monkeypatch.setattr(forked.os, "fork", recorded)
    return made


def _none_left(pids):
    """Every child forked has been reaped (none left a zombie or still running)."""
    for pid in pids:
        with pytest.raises(ChildProcessError):
            os.waitpid(pid, os.WNOHANG)


def test_the_piece_aside_runs_in_a_child_and_returns_its_result(two_task_threads, forks):
    x = np.random.default_rng(0).normal(size=(300, 40))
    here_pid = os.getpid()
    (pid, gram), norms = forked.both(lambda: (os.getpid(), x.T @ x),
                                     lambda: np.linalg.norm(x, axis=0))
    assert forked.can_fork() == LINUX
    assert (pid != here_pid) == LINUX
    np.testing.assert_array_equal(gram, x.T @ x)
    np.testing.assert_array_equal(norms, np.linalg.norm(x, axis=0))
    assert len(forks) == LINUX * 1
    _none_left(forks)


def test_a_child_that_fails_has_its_piece_run_here(two_task_threads, forks):
    def aside():
        if forked._IN_CHILD[0]:
            raise MemoryError("the child ran out")
        return "made here"

    assert forked.both(aside, lambda: 1) == ("made here", 1)
    assert len(forks) == LINUX * 1
    _none_left(forks)

    def killed():
        if forked._IN_CHILD[0]:
            os._exit(9)                                   # as the OOM killer would leave it
        return "made here"

    assert forked.both(killed, lambda: 2) == ("made here", 2)
    assert len(forks) == LINUX * 2
    _none_left(forks)


def test_an_error_here_propagates_and_stops_the_child(two_task_threads, forks):
    import time

    def slow():
        time.sleep(30 if forked._IN_CHILD[0] else 0)
        return None

    started = time.perf_counter()
    with pytest.raises(ValueError, match="here failed"):
        forked.both(slow, lambda: (_ for _ in ()).throw(ValueError("here failed")))
    assert time.perf_counter() - started < 10
    assert len(forks) == LINUX * 1
    _none_left(forks)


def test_nothing_is_forked_with_one_task_thread_or_inside_a_child(monkeypatch, fork_allowed):
    here_pid = os.getpid()
    monkeypatch.setattr(threads, "_TASK_THREADS", [1])
    assert not forked.can_fork()
    assert forked.both(os.getpid, os.getpid) == (here_pid, here_pid)
    monkeypatch.setattr(threads, "_TASK_THREADS", [2])
    assert forked.both(os.getpid, os.getpid, fork=False) == (here_pid, here_pid)
    monkeypatch.setattr(forked, "_IN_CHILD", [True])
    assert not forked.can_fork()
    # a nested call inside a child runs both pieces in that child
    monkeypatch.setattr(forked, "_IN_CHILD", [False])
    inner = forked.both(lambda: forked.both(os.getpid, os.getpid), os.getpid)
    assert inner[0][0] == inner[0][1] and (inner[0][0] != here_pid) == LINUX


def test_a_process_of_one_thread_forks_on_linux():
    """A fresh interpreter (as ``mocapfix clean`` of one file is) with two task threads
    may fork: the policy does not turn the child off where it should be used."""
    code = ("from mocapfix.core import forked, threads; threads.set_task_threads(2); "
            "import os; pid, here = forked.both(os.getpid, os.getpid); "
            "print(forked.can_fork(), pid != here)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split()
    assert out == ([str(LINUX)] * 2)


def test_nothing_is_forked_while_another_thread_runs(monkeypatch):
    monkeypatch.setattr(threads, "_TASK_THREADS", [2])
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert not forked.can_fork()
        assert forked.both(os.getpid, os.getpid) == (os.getpid(), os.getpid())
    finally:
        stop.set()
        other.join()
