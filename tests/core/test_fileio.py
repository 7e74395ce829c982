"""Atomic writes into what is not a regular file: a report written to a named pipe
(``--junit /dev/stdout`` in CI) goes into the pipe instead of replacing it, and a pipe
nothing reads is an error, not a hang."""
from __future__ import annotations

import os
import stat
import threading

from click.testing import CliRunner

from mocapfix.cli import main

from conftest import SAMPLE_DATA, no_traceback

KIN = SAMPLE_DATA / "walk_kinect_v2.csv"


def _release_reader(fifo):
    """Let a thread blocked opening ``fifo`` to read go on (EOF), never blocking here: a
    blocking open for writing hung the test when the reader had just finished."""
    try:
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
    except OSError:                 # ENXIO: nobody is reading (any more)
        pass


def test_junit_into_a_pipe_is_written_into_it_not_replaced(tmp_path):
    # `--junit /dev/null` or `--junit /dev/stdout` in a CI container run as root replaced
    # the device (the link) with a regular XML file: the temporary-then-rename of an
    # atomic write renamed over it. A pipe (here a FIFO with a reader) is written into.
    fifo = tmp_path / "junit.pipe"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(fifo.read_bytes()), daemon=True)
    reader.start()
    r = CliRunner().invoke(main, ["check", str(KIN), "--junit", str(fifo), "-q"])
    if reader.is_alive():           # without the fix nobody opens the pipe to write
        _release_reader(fifo)
    reader.join(10)
    no_traceback(r)
    assert r.exit_code in (0, 1), r.output
    assert stat.S_ISFIFO(os.stat(fifo).st_mode), "the pipe was replaced by a file"
    assert got and got[0].startswith(b"<?xml") and b"walk_kinect_v2.csv" in got[0]


def test_junit_into_a_pipe_nobody_reads_is_an_error_not_a_hang(tmp_path):
    fifo = tmp_path / "junit.pipe"
    os.mkfifo(fifo)
    r = CliRunner().invoke(main, ["check", str(KIN), "--junit", str(fifo), "-q"])
    no_traceback(r)
    assert r.exit_code == 2, r.output
    assert f"{fifo}: cannot write: a named pipe (FIFO) that nothing reads" in r.output
    assert stat.S_ISFIFO(os.stat(fifo).st_mode)
