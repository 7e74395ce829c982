"""Batches over executors (issue 13): a Dask cluster gives the same outputs as a local
run, the pipeline is parsed once per worker, Dask is optional, and no BLAS call in a batch
worker runs with more threads than the policy gives it (mocapfix.core.threads). A
malformed or unreachable scheduler address is refused before the output folder changes."""
from __future__ import annotations

import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from click.testing import CliRunner
from threadpoolctl import threadpool_info, threadpool_limits

from conftest import SAMPLE_DATA, config_file, md5_tree, no_traceback, output_tree
from mocapfix.batch import clean as batch_clean
from mocapfix.core import threads
from mocapfix.batch.clean import CleanTask, run_batch
from mocapfix.batch.discovery import discover_inputs
from mocapfix.batch.plan import plan_outputs
from mocapfix.batch.tasks import run_tasks
from mocapfix.cli import main
from mocapfix.core.errors import ConfigError
from mocapfix.batch.executors import ExecutorSpec
from mocapfix.config import load_config
from mocapfix.core.presets import resolve_config

MOTION = (".c3d", ".bvh", ".amc", ".asf", ".csv")
BVH = SAMPLE_DATA / "walk.bvh"


def _jobs(outdir):
    found = discover_inputs([SAMPLE_DATA])
    return plan_outputs(found.files, outdir, inputs=[SAMPLE_DATA])


def _tree(folder: Path) -> dict:
    return output_tree(folder)


@pytest.mark.slow
def test_dask_local_cluster_gives_byte_identical_outputs(tmp_path):
    import distributed          # a dev dependency: missing it fails, never skips

    pipeline = load_config(resolve_config("default"))
    local = run_batch(_jobs(tmp_path / "local"), pipeline.config(), str(pipeline.source))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        seen = []
        dask = run_batch(_jobs(tmp_path / "dask"), pipeline.config(), str(pipeline.source),
                         executor=client.get_executor(pure=False), on_result=seen.append)
    assert [r["status"] for r in local] == [r["status"] for r in dask]
    assert all(r["status"] != "ERROR" for r in dask)
    assert len(seen) == len(dask) == 4                      # streamed, one per file
    a, b = _tree(tmp_path / "local"), _tree(tmp_path / "dask")
    assert sorted(a) == sorted(b) and any(k.endswith(".c3d") for k in a)
    for rel in a:
        assert a[rel] == b[rel], rel
    # and the reports do carry real content (not two empty dicts compared)
    assert a["walk_markers.c3d.report.json"]["file"]["frames"] > 100


@pytest.mark.slow
def test_cli_dask_workers_match_local(tmp_path):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("pipeline:\n  - cleaner: fill\n    max_gap: 0.5 s\n  - cleaner: gaussian\n")
    r1 = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA), "-o", str(tmp_path / "a"), "-c", str(cfg), "-q"])
    r2 = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA), "-o", str(tmp_path / "b"), "-c", str(cfg),
                                   "--dask-workers", "2", "-q"])
    assert r1.exit_code == 0 and r2.exit_code == 0, r1.output + r2.output
    a, b = _tree(tmp_path / "a"), _tree(tmp_path / "b")
    assert a == b and len(a) >= 8


def test_dask_missing_names_the_extra(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "distributed", None)      # import fails
    with pytest.raises(ConfigError, match=r"mocapfix\[dask\]"):
        ExecutorSpec(dask_workers=2).check()
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA), "-o", str(tmp_path / "o"),
                                  "--scheduler", "tcp://127.0.0.1:8786"])
    assert r.exit_code == 2 and "mocapfix[dask]" in r.output
    assert not (tmp_path / "o").exists()
    # local runs never import it
    assert ExecutorSpec(jobs=2).check().dask is False


def test_executor_options_conflict(tmp_path):
    r = CliRunner().invoke(main, ["check", str(SAMPLE_DATA), "-j", "2", "--dask-workers", "2"])
    assert r.exit_code == 2 and "-j/--jobs" in r.output


@pytest.mark.slow
def test_pipeline_parsed_once_per_process(monkeypatch, tmp_path):
    import mocapfix.config as pl

    calls = []
    real = pl.parse_config
    monkeypatch.setattr(pl, "parse_config", lambda *a, **k: calls.append(1) or real(*a, **k))
    batch_clean._PIPELINES.clear()
    pipeline = load_config(resolve_config("default"))
    calls.clear()                               # the CLI's own parse of the config
    results = run_batch(_jobs(tmp_path / "o"), pipeline.config(), str(pipeline.source))
    assert len(results) == 4 and len(calls) == 1


# -- BLAS threads ------------------------------------------------------------------------

_LINALG = ("svd", "eigh", "eigvalsh", "solve", "inv", "det", "lstsq", "qr", "cholesky", "pinv")


class ProbeTask(CleanTask):
    """A real clean, with every numpy/scipy decomposition wrapped to record the largest
    BLAS pool size in force when it ran (in the worker process)."""

    def __call__(self, job):
        seen = []
        # a worker forked from this test process inherits the caches earlier tests filled
        # (glitches' cubic weights: one pinv per run length), which would hide the calls
        for module in [m for name, m in sys.modules.items() if name.startswith("mocapfix.")]:
            for obj in list(vars(module).values()):
                if callable(getattr(obj, "cache_clear", None)):
                    obj.cache_clear()

        def wrap(fn):
            def probe(*a, **k):
                seen.append(max(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"))
                return fn(*a, **k)
            return probe

        saved = []
        for mod in (np.linalg, scipy.linalg):
            for name in _LINALG:
                if hasattr(mod, name):
                    saved.append((mod, name, getattr(mod, name)))
                    setattr(mod, name, wrap(getattr(mod, name)))
        try:
            result = super().__call__(job)
        finally:
            for mod, name, fn in saved:
                setattr(mod, name, fn)
        return {**result, "blas_calls": len(seen), "blas_max": max(seen, default=0)}


@pytest.mark.slow
def test_batch_workers_never_run_blas_with_more_than_one_thread(tmp_path):
    pipeline = load_config(resolve_config("default"))
    jobs = _jobs(tmp_path / "o")
    task = ProbeTask(pipeline.config(), str(pipeline.source))
    with threadpool_limits(2):                  # the parent would hand 2 threads down
        # control: a bare pool inherits the parent's 2 threads, and the probe sees them
        with ProcessPoolExecutor(1) as pool:
            bare = pool.submit(task, jobs[0]).result()
        assert bare["blas_calls"] > 0 and bare["blas_max"] == 2
        results = [r for _, r in run_tasks(task, jobs, workers=2)]
    assert all(r["status"] != "ERROR" for r in results)
    assert sum(r["blas_calls"] for r in results) > 10
    assert max(r["blas_max"] for r in results) == 1


def test_thread_policy_numbers(monkeypatch):
    assert threads.blas_threads(4) == 1
    monkeypatch.setenv("MOCAPFIX_BLAS_THREADS", "999")
    assert threads.blas_threads(1) == threads.cores()          # capped at the cores
    monkeypatch.delenv("MOCAPFIX_BLAS_THREADS")
    assert threads.blas_threads(1) == threads.SINGLE_FILE_THREADS


@pytest.mark.slow
def test_check_on_dask_matches_local():
    import distributed

    from mocapfix.batch.check import CheckTask
    from mocapfix.quality.rules import load_rules, resolve_rules_path

    task = CheckTask(load_rules(resolve_rules_path("default")))
    paths = [f.path for f in discover_inputs([SAMPLE_DATA]).files]

    def strip(results):
        return {r["path"]: {k: v for k, v in r.items() if k != "seconds"} for _, r in results}

    local = strip(run_tasks(task, paths))
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        dask = strip(run_tasks(task, paths, executor=client.get_executor(pure=False)))
    assert len(local) == 4 and local == dask
    assert {r["status"] for r in local.values()} <= {"OK", "WARN", "FAIL"}


def test_a_malformed_scheduler_address_is_refused_before_anything_is_written(tmp_path):
    # "--scheduler foo" raised ValueError (a traceback) when the batch started, after the
    # output folder and its manifest had been made; dask is in the dev extra
    out = tmp_path / "out"
    for address in ("foo", "tcp://host-without-port", "tcp://127.0.0.1:x"):
        for args in (["clean", str(BVH), "-o", str(out), "-c", config_file(tmp_path)], ["check", str(BVH)]):
            r = CliRunner().invoke(main, [*args, "--scheduler", address])
            no_traceback(r)
            assert r.exit_code == 2, r.output
            assert f"--scheduler {address!r} is not a Dask scheduler address" in r.output
    assert not out.exists()


def test_an_unreachable_scheduler_leaves_the_output_folder_as_it_was(tmp_path, monkeypatch):
    # a well-formed address nobody answers: the run used to leave the folders it made and
    # a manifest of "started" records behind (or append them to an existing manifest)
    import distributed                                     # the dev extra has it

    def refuse(*args, **kwargs):
        raise OSError("Timed out trying to connect to tcp://10.0.0.1:8786 after 10 s")
    monkeypatch.setattr(distributed, "Client", refuse)
    fresh = tmp_path / "new" / "out"
    r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(fresh), "-c", config_file(tmp_path),
                                  "--scheduler", "tcp://10.0.0.1:8786"])
    no_traceback(r)
    assert r.exit_code == 2 and "cannot reach the Dask scheduler" in r.output, r.output
    assert not (tmp_path / "new").exists()
    used = tmp_path / "used"
    r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(used), "-c", config_file(tmp_path)])
    assert r.exit_code == 0, r.output
    before = md5_tree(used)
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA), "-o", str(used), "-c", config_file(tmp_path),
                                  "--overwrite", "--scheduler", "tcp://10.0.0.1:8786"])
    assert r.exit_code == 2, r.output
    assert md5_tree(used) == before                           # the manifest as it was


def _sleep(seconds: float) -> float:
    import time

    time.sleep(seconds)
    return seconds


def test_ctrl_c_in_a_pool_worker_interrupts_its_task_or_ends_it_quietly(capfd):
    # Ctrl-C reaches every process of the group. A worker running a task has the task
    # interrupted (KeyboardInterrupt, handed back as its result; its cleanup ran) and goes
    # on; an idle one exits at once. Idle, it printed multiprocessing's "Process
    # ForkProcess-1: Traceback ... KeyboardInterrupt" under the run's "mocapfix:
    # interrupted" (a flaky failure of test_resume's interrupted batch)
    import os
    import signal
    import time

    from mocapfix.batch.executors import _gone, pool_worker_init
    from mocapfix.batch.tasks import InWorker

    with ProcessPoolExecutor(1, initializer=pool_worker_init, initargs=(1, os.getpid())) as pool:
        pid = pool.submit(os.getpid).result()
        busy = pool.submit(InWorker(_sleep), 30.0)
        time.sleep(1.0)
        os.kill(pid, signal.SIGINT)
        assert isinstance(busy.exception(timeout=20), KeyboardInterrupt)
        assert pool.submit(os.getpid).result(timeout=20) == pid      # the worker goes on
        os.kill(pid, signal.SIGINT)                                    # idle now
        deadline = time.monotonic() + 20
        while not _gone(pid) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert _gone(pid)
    err = capfd.readouterr().err
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err
