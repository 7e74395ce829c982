"""Shared test helpers.

Tests that use the real captures in ``../shared/data`` get their paths from
:func:`shared_files`. When the folder is absent they skip — unless
``MOCAPFIX_REQUIRE_DATA=1`` (CI sets it), in which case they fail.
"""
from __future__ import annotations

import contextlib
import os
import signal
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MOCAPFIX_DATA", REPO.parent / "shared" / "data"))
REQUIRE_DATA = os.environ.get("MOCAPFIX_REQUIRE_DATA") == "1"
SAMPLE_DATA = REPO / "sample_data"


def _missing(what: str):
    message = f"shared data not found: {what} (set MOCAPFIX_DATA or place ../shared/data)"
    if REQUIRE_DATA:
        pytest.fail(message)
    pytest.skip(message)


def shared_files(subdir: str, pattern: str = "*") -> list:
    """Parametrisation list of files in ``DATA/subdir`` matching ``pattern``.

    If none are found the list holds one ``None`` entry; the test must call
    :func:`need` on it, which skips or (under MOCAPFIX_REQUIRE_DATA=1) fails.
    """
    folder = DATA / subdir
    files = sorted(p for p in folder.glob(pattern) if p.is_file()) if folder.is_dir() else []
    if not files:
        return [pytest.param(None, id=f"{subdir}-missing")]
    return [pytest.param(p, id=p.name) for p in files]


def need(path) -> Path:
    """Return ``path`` if it exists; otherwise skip or fail (see module docstring)."""
    if path is None or not Path(path).exists():
        _missing(str(path))
    return Path(path)


def shared(relpath: str) -> Path:
    """One named file of the shared data, with the skip/fail rule applied."""
    return need(DATA / relpath)


class Hang(BaseException):
    """Raised by :func:`hang_guard`. A BaseException, not TimeoutError: TimeoutError is an
    OSError, which readers turn into "malformed file" errors, hiding the hang."""


@contextlib.contextmanager
def hang_guard(seconds: int = 10):
    """Fail instead of hanging forever (a generous guard, not a timing assertion)."""
    if not hasattr(signal, "SIGALRM"):
        yield
        return

    def _timeout(signum, frame):
        raise Hang(f"no answer within {seconds} s")

    previous = signal.signal(signal.SIGALRM, _timeout)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)
