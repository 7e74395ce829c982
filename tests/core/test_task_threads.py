"""Task threads (mocapfix.core.threads.parallel_map): the independent pieces of work inside one
file (trust's marker blocks, swaps' frame chunks, tsmc's two GCV smooths) run on the cores
available to a single-file clean, one thread in a batch worker, and the results do not
depend on the number of threads."""
from __future__ import annotations

import sys
import threading

import numpy as np
import pytest

from conftest import shared
from mocapfix import read
from mocapfix.core import threads
from mocapfix.batch.tasks import InWorker, run_tasks
from mocapfix.bench.corrupt import occlusion
from mocapfix.config import load_config
from mocapfix.core.presets import resolve_config


@pytest.fixture
def budget():
    """Restore the process's budget after the test."""
    before = threads.task_threads()
    yield threads.set_task_threads
    threads.set_task_threads(before)


def test_parallel_map_keeps_order_and_uses_the_budget(budget):
    budget(2)
    started = threading.Barrier(2, timeout=10)

    def item(k):
        if k < 2:
            started.wait()          # both first items run at once: two threads, or a hang
        return k * k, threading.get_ident()

    out = threads.parallel_map(item, range(6))
    assert [v for v, _ in out] == [k * k for k in range(6)]
    assert len({ident for _, ident in out}) == 2
    assert threading.get_ident() not in {ident for _, ident in out}


def test_parallel_map_runs_in_the_caller_with_one_thread_or_nested(budget):
    budget(1)
    here = threading.get_ident()
    assert {threads.parallel_map(lambda _: threading.get_ident(), range(4))[k]
            for k in range(4)} == {here}
    budget(2)
    # a call from inside a pool thread stays in that thread (no nested pools)
    inner = threads.parallel_map(
        lambda _: (threading.get_ident(), set(threads.parallel_map(lambda _: threading.get_ident(),
                                                                      range(3)))), range(2))
    assert all(nested == {outer} for outer, nested in inner)


def test_parallel_map_propagates_exceptions(budget):
    budget(2)

    def item(k):
        if k == 3:
            raise ValueError("piece 3 failed")
        return k

    with pytest.raises(ValueError, match="piece 3"):
        threads.parallel_map(item, range(5))


def test_budget_single_file_worker_and_environment(budget, monkeypatch):
    monkeypatch.setattr(threads, "cores", lambda: 4)        # the same on any machine
    monkeypatch.delenv("MOCAPFIX_THREADS", raising=False)
    monkeypatch.delenv("MOCAPFIX_BLAS_THREADS", raising=False)
    assert threads.single_process_task_threads() == 4
    assert threads.single_process_task_threads(blas=2) == 2   # threads x BLAS <= cores
    monkeypatch.setenv("MOCAPFIX_THREADS", "1")
    assert threads.single_process_task_threads() == 1
    monkeypatch.setenv("MOCAPFIX_THREADS", "999")
    assert threads.single_process_task_threads() == 4
    for ignored in ("0", "-2", "many"):
        monkeypatch.setenv("MOCAPFIX_THREADS", ignored)
        assert threads.single_process_task_threads() == 4
    monkeypatch.delenv("MOCAPFIX_THREADS")
    budget(1)
    # in this process: the tasks see the single-file budget, restored afterwards
    seen = [r for _, r in run_tasks(lambda _: {"threads": threads.task_threads()}, [0, 1])]
    assert [r["threads"] for r in seen] == [4, 4]
    assert threads.task_threads() == 1
    # two BLAS threads asked for: half the task threads (the BLAS limit itself is not
    # applied here, so that it does not outlive the test)
    monkeypatch.setenv("MOCAPFIX_BLAS_THREADS", "2")
    monkeypatch.setattr(threads, "limit_blas", lambda n: None)
    seen = [r for _, r in run_tasks(lambda _: {"threads": threads.task_threads()}, [0])]
    assert [r["threads"] for r in seen] == [2]
    # a batch worker runs every task with one thread
    budget(4)
    assert InWorker(lambda _: threads.task_threads())(None) == 1


@pytest.mark.slow
def test_default_clean_is_identical_with_one_and_two_threads(budget, fork_calls):
    """The default pipeline on a real capture with gaps, jitter and spikes (every threaded
    step has work, and with two threads the fill ensemble's two pieces that go to a
    forked child on Linux do): the same output, bit for bit, with one and with two task
    threads."""
    base = read(shared("c3d/cmu_85_02.c3d"))
    clean = base.replace(positions=np.concatenate([base.positions, base.positions[::-1]]),
                         source=None, confidence=None)
    corrupted, _ = occlusion(clean, "mixed", 3)
    pipeline = load_config(resolve_config("default"))
    outs = []
    for n in (1, 2):
        budget(n)
        fork_calls.clear()
        out, records = pipeline.run(corrupted)
        assert {r.cleaner for r in records if r.seconds > 0} >= {"swaps", "trust", "fill_ensemble"}
        outs.append(out)
    # the distance statistics; the validated fits with their combinations on the windows
    assert sum(fork_calls) == (2 if sys.platform.startswith("linux") else 0)
    a, b = outs
    assert np.array_equal(a.positions, b.positions, equal_nan=True)
    assert np.array_equal(a.confidence, b.confidence, equal_nan=True)
    # the fills' error estimates and bounds too (the gate's decisions rest on them)
    assert a.fill_errors == b.fill_errors
    # and the clean did something: the corrupted capture had gaps, now filled where the
    # fill could be trusted (the default's fill gate leaves the others missing)
    assert (np.isnan(corrupted.positions) & ~np.isnan(a.positions)).any()
