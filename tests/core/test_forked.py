"""Two pieces of work at once, one in a forked child (mocapfix.core.forked): the results
are those of running both here, a failed child's piece is run again here, an error here
stops the child, and nothing is forked where the policy says not to."""
import os
import sys
import threading

import numpy as np
import pytest

from mocapfix.core import forked, threads

LINUX = sys.platform.startswith("linux")


@pytest.fixture
def two_task_threads(monkeypatch):
    monkeypatch.setattr(threads, "_TASK_THREADS", [2])


def _no_child_left():
    with pytest.raises(ChildProcessError):
        os.waitpid(-1, os.WNOHANG)


def test_the_piece_aside_runs_in_a_child_and_returns_its_result(two_task_threads):
    x = np.random.default_rng(0).normal(size=(300, 40))
    here_pid = os.getpid()
    (pid, gram), norms = forked.both(lambda: (os.getpid(), x.T @ x),
                                     lambda: np.linalg.norm(x, axis=0))
    assert forked.can_fork() == LINUX and threading.active_count() == 1
    assert (pid != here_pid) == LINUX
    np.testing.assert_array_equal(gram, x.T @ x)
    np.testing.assert_array_equal(norms, np.linalg.norm(x, axis=0))
    _no_child_left()


def test_a_child_that_fails_has_its_piece_run_here(two_task_threads):
    def aside():
        if forked._IN_CHILD[0]:
            raise MemoryError("the child ran out")
        return "made here"

    assert forked.both(aside, lambda: 1) == ("made here", 1)
    _no_child_left()

    def killed():
        if forked._IN_CHILD[0]:
            os._exit(9)                                   # as the OOM killer would leave it
        return "made here"

    assert forked.both(killed, lambda: 2) == ("made here", 2)
    _no_child_left()


def test_an_error_here_propagates_and_stops_the_child(two_task_threads):
    import time

    def slow():
        time.sleep(30 if forked._IN_CHILD[0] else 0)
        return None

    started = time.perf_counter()
    with pytest.raises(ValueError, match="here failed"):
        forked.both(slow, lambda: (_ for _ in ()).throw(ValueError("here failed")))
    assert time.perf_counter() - started < 10
    _no_child_left()


def test_nothing_is_forked_with_one_task_thread_or_inside_a_child(monkeypatch):
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


def test_nothing_is_forked_while_another_thread_runs(two_task_threads):
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert not forked.can_fork()
        assert forked.both(os.getpid, os.getpid) == (os.getpid(), os.getpid())
    finally:
        stop.set()
        other.join()
