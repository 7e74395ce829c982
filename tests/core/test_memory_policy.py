"""The CLI's memory policy (mocapfix.core.memory): freed memory stays in the process while a
file is cleaned and goes back after it. Measured on the process's resident set (Linux,
glibc: the platform the policy acts on; elsewhere it does nothing)."""
import subprocess
import sys

import pytest

SCRIPT = """
import numpy as np
from mocapfix.core.memory import retain_freed_memory, release_freed_memory

def rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20

retained = {retain} and retain_freed_memory()
base = rss_mb()
a = np.ones(40 * 2**20 // 8)            # 40 MB, written
del a
kept = rss_mb() - base
release_freed_memory()
after = rss_mb() - base
print(retained, round(kept), round(after))
"""


def _run(retain: bool):
    out = subprocess.run([sys.executable, "-c", SCRIPT.format(retain=retain)], check=True,
                         capture_output=True, text=True).stdout.split()
    return out[0] == "True", float(out[1]), float(out[2])


@pytest.mark.slow
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt, /proc")
def test_freed_memory_is_kept_until_released():
    retained, kept, after = _run(True)
    assert retained
    assert kept > 35 and after < 5, (kept, after)
    # without the policy glibc gives a 40 MB block back as soon as it is freed
    retained, kept, after = _run(False)
    assert not retained and kept < 5


def test_cli_and_pool_workers_keep_freed_memory(monkeypatch):
    import mocapfix.core.memory as memory
    from click.testing import CliRunner

    from mocapfix.cli import main
    from mocapfix.core.threads import set_task_threads, task_threads, worker_init

    calls = []
    monkeypatch.setattr(memory, "retain_freed_memory", lambda: calls.append(1) or True)
    assert CliRunner().invoke(main, ["configs"]).exit_code == 0
    assert len(calls) == 1
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        monkeypatch.setenv(var, "1")                # restored after the test
    before = task_threads()
    try:
        worker_init(1)
    finally:
        set_task_threads(before)
    assert len(calls) == 2


def test_freed_memory_is_returned_after_every_file(monkeypatch):
    """In the calling process (-j 1) and in a batch worker, each file ends with a trim."""
    import mocapfix.core.memory as memory
    from mocapfix.batch.tasks import InWorker, run_tasks

    calls = []
    monkeypatch.setattr(memory, "release_freed_memory", lambda: calls.append(1))
    results = [r for _, r in run_tasks(lambda item: {"status": "OK", "item": item}, [1, 2, 3])]
    assert [r["item"] for r in results] == [1, 2, 3] and len(calls) == 3
    assert InWorker(lambda item: item * 2)(4) == 8 and len(calls) == 4
