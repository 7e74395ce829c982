"""Heap thresholds for the cleaning processes (mocapfix.allocator): set through glibc's
mallopt where the C library is glibc, a no-op elsewhere, once per process."""
import platform

from mocapfix import allocator


def test_tune_sets_the_thresholds_on_glibc_only():
    glibc = platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"
    assert allocator.tune() is glibc
    assert allocator.tune() is glibc                # again: cached, same answer


def test_a_batch_in_this_process_tunes_the_heap(tmp_path, monkeypatch):
    """The in-process batch path (one file, -j 1) calls tune before its tasks."""
    from mocapfix import batch

    calls = []
    monkeypatch.setattr(allocator, "tune", lambda: calls.append(1) or True)
    results = list(batch.run_tasks(lambda item: {"status": "OK", "item": item}, [1, 2]))
    assert [r["item"] for _, r in results] == [1, 2]
    assert calls == [1]
