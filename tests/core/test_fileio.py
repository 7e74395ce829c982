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


def test_junit_into_stdout_redirected_to_a_file_lands_in_that_file(tmp_path):
    # `check --junit /dev/stdout > report.xml`: /dev/stdout links to /proc/self/fd/1, which
    # is then the regular file report.xml; the temporary-then-rename replaced the link
    # itself (as root: the machine's /dev/stdout) and left report.xml empty. The link here
    # stands in for /dev/stdout (the real one must not be put at risk by a regression).
    import subprocess
    import sys

    link = tmp_path / "stdout"
    link.symlink_to("/proc/self/fd/1")
    report = tmp_path / "report.xml"
    with open(report, "wb") as out:
        r = subprocess.run([sys.executable, "-m", "mocapfix.cli", "check", str(KIN), "--junit",
                            str(link), "-q"], stdout=out, stderr=subprocess.PIPE, text=True,
                           timeout=120)
    assert r.returncode in (0, 1), r.stderr
    assert link.is_symlink() and os.readlink(link) == "/proc/self/fd/1"
    text = report.read_text()
    assert "<?xml" in text and "walk_kinect_v2.csv" in text and "</testsuites>" in text


def test_a_descriptor_path_is_written_in_place_through_a_chain_of_links(tmp_path):
    from mocapfix.core.fileio import atomic_write_text, is_stream

    target = tmp_path / "out.txt"
    target.write_text("printed first\n")
    with open(target, "a") as held:
        first = tmp_path / "a"
        first.symlink_to(f"/proc/self/fd/{held.fileno()}")
        second = tmp_path / "b"
        second.symlink_to("a")                          # a relative link to the link
        assert is_stream(second) and not is_stream(target)
        atomic_write_text(second, "then the page\n")
        assert second.is_symlink() and first.is_symlink()
    assert target.read_text() == "printed first\nthen the page\n"
    loop = tmp_path / "loop"
    loop.symlink_to("loop")
    assert not is_stream(loop)
