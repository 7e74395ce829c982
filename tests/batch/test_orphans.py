"""Workers die with their parent (issue 40, item 4): a real ``kill -9`` of a running
``mocapfix clean -j 2`` (or ``--dask-workers 2``) leaves no worker process behind."""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import SAMPLE_DATA


def _descendants(pid: int) -> set[int]:
    """Every live descendant of ``pid`` (Linux /proc)."""
    found, todo = set(), [pid]
    while todo:
        p = todo.pop()
        for task in Path(f"/proc/{p}/task").glob("*"):
            try:
                children = (task / "children").read_text().split()
            except OSError:
                continue
            for c in map(int, children):
                if c not in found:
                    found.add(c)
                    todo.append(c)
    return found


def _alive(pid: int) -> bool:
    """Running (not gone, not a zombie waiting for a reaper)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return False
    return stat.rpartition(")")[2].split()[0] != "Z"


def _describe(pid: int) -> str:
    with contextlib.suppress(OSError):
        return (Path(f"/proc/{pid}/stat").read_text()[:60] + " "
                + Path(f"/proc/{pid}/cmdline").read_text().replace("\0", " ")[:80])
    return "gone"


def _kill_parent_mid_batch(tmp_path, options: list[str], workers: int) -> set[int]:
    src = tmp_path / "in"
    src.mkdir()
    for n in range(12):
        shutil.copy(SAMPLE_DATA / "walk_markers.c3d", src / f"take{n}.c3d")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    parent = subprocess.Popen([sys.executable, "-m", "mocapfix.cli", "clean", str(src), "-o",
                               str(tmp_path / "out"), *options], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    kids: set[int] = set()
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            kids = {p for p in _descendants(parent.pid) if _alive(p)}
            # python workers that are already cleaning (an output folder exists)
            if len(kids) >= workers and (tmp_path / "out" / "mocapfix-manifest.jsonl").exists():
                break
            assert parent.poll() is None, "the batch ended before its workers were seen"
            time.sleep(0.1)
        else:
            pytest.fail("the workers never started")
        parent.send_signal(signal.SIGKILL)
        parent.wait(10)
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline and any(_alive(p) for p in kids):
            time.sleep(0.2)
        return {f"{p}: {_describe(p)}" for p in kids if _alive(p)}
    finally:
        for p in {p for p in _descendants(parent.pid) | kids if _alive(p)}:
            with contextlib.suppress(OSError):
                os.kill(p, signal.SIGKILL)


@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads /proc (Linux)")
def test_workers_of_a_killed_clean_j2_exit(tmp_path):
    left = _kill_parent_mid_batch(tmp_path, ["-j", "2"], 2)
    assert not left, f"worker processes {sorted(left)} outlived their killed parent"


@pytest.mark.slow           # starts a local Dask cluster (~3 s)
@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="reads /proc (Linux)")
def test_dask_workers_of_a_killed_clean_exit(tmp_path):
    pytest.importorskip("distributed")
    left = _kill_parent_mid_batch(tmp_path, ["--dask-workers", "2"], 2)
    assert not left, f"worker processes {sorted(left)} outlived their killed parent"
