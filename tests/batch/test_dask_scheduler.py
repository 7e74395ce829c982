"""``--scheduler tcp://…`` against a Dask cluster that mocapfix did not start: a scheduler
and a worker launched as separate processes by the ``dask`` command (as on a cluster's
head node), reached over TCP. The outputs must be byte for byte those of a local run."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import SAMPLE_DATA, output_tree
from mocapfix.cli import main

# slow: starts a Dask scheduler and worker as processes (~3 s)
pytestmark = pytest.mark.slow


def _dask_command() -> list[str]:
    exe = shutil.which("dask", path=str(Path(sys.executable).parent)) or shutil.which("dask")
    assert exe, "the `dask` command of the dev extra (dask[distributed]) is missing"
    return [exe]


def _start(args: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen(_dask_command() + args, stdout=log.open("wb"), stderr=subprocess.STDOUT,
                            env=dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1"))


def _wait_for_worker(address: str, timeout: float = 60.0) -> None:
    import distributed

    with distributed.Client(address, timeout=timeout) as client:
        client.wait_for_workers(1, timeout=timeout)


def _tasks_processed(address: str) -> int:
    import distributed

    with distributed.Client(address, timeout=30) as client:
        counts = client.run_on_scheduler(lambda dask_scheduler: [
            dict(prefix.state_counts) for prefix in dask_scheduler.task_prefixes.values()])
    return sum(c.get("processing", 0) for c in counts)


def test_clean_on_an_external_scheduler_matches_local(tmp_path):
    import distributed  # noqa: F401  (a dev dependency: missing it fails, never skips)

    info = tmp_path / "scheduler.json"
    scheduler = _start(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
                        "--scheduler-file", str(info)], tmp_path / "scheduler.log")
    worker = None
    try:
        deadline = time.monotonic() + 60
        while not info.exists() and time.monotonic() < deadline:
            assert scheduler.poll() is None, (tmp_path / "scheduler.log").read_text()
            time.sleep(0.2)
        address = json.loads(info.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        worker = _start(["worker", address, "--nworkers", "1", "--nthreads", "1",
                         "--no-dashboard"], tmp_path / "worker.log")
        _wait_for_worker(address)

        cfg = tmp_path / "cfg.yaml"
        cfg.write_text("pipeline:\n  - cleaner: fill\n    max_gap: 0.5 s\n  - cleaner: gaussian\n")
        local = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA), "-o", str(tmp_path / "local"),
                                          "-c", str(cfg), "-q"])
        remote = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA), "-o", str(tmp_path / "remote"),
                                           "-c", str(cfg), "--scheduler", address, "-q"])
        assert local.exit_code == 0, local.output
        assert remote.exit_code == 0, remote.output + (tmp_path / "worker.log").read_text()[-2000:]
        a, b = output_tree(tmp_path / "local"), output_tree(tmp_path / "remote")
        assert a == b and len(a) >= 8
        # the files were cleaned by the external cluster: its scheduler handed out a task
        # per motion file (4 in sample_data)
        processed = _tasks_processed(address)
        assert processed >= 4, processed
        assert scheduler.poll() is None and worker.poll() is None
    finally:
        for proc in (worker, scheduler):
            if proc is not None:
                proc.terminate()
                try:
                    proc.wait(timeout=20)
                except subprocess.TimeoutExpired:
                    proc.kill()
