"""Faults around a batch (issue 40): links planted in the output folder, a full disk, an
output that is a device or a pipe. Each file that cannot be written fails alone with one
line naming it and the cause; the run ends with its summary and the right exit code."""
from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import stat
import subprocess

import pytest
from click.testing import CliRunner
from conftest import SAMPLE_DATA, config_file, md5_tree, no_traceback

from mocapfix.cli import main
from mocapfix.core import fileio
from mocapfix.core.errors import WriteError

BVH, KIN, C3D = (SAMPLE_DATA / "walk.bvh", SAMPLE_DATA / "walk_kinect_v2.csv",
                 SAMPLE_DATA / "walk_markers.c3d")


def _inputs(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(BVH, src / "a.bvh")
    shutil.copy(KIN, src / "b.csv")
    return src


def _clean(tmp_path, src, out, *more):
    return CliRunner().invoke(main, ["clean", str(src), "-o", str(out),
                                     "-c", config_file(tmp_path), *more])


def _clean_with_link(tmp_path, name: str, target: str):
    """Clean two files into a folder where ``name`` is a symbolic link to ``target``:
    (the folder, the CliRunner result)."""
    out = tmp_path / "o"
    out.mkdir()
    (out / name).symlink_to(target)
    r = _clean(tmp_path, _inputs(tmp_path), out)
    no_traceback(r)
    return out, r


# -- 1. the manifest never follows a link -------------------------------------------------

@pytest.mark.parametrize("dangling", [False, True])
def test_a_manifest_link_is_refused_and_its_target_left_alone(tmp_path, dangling):
    victim = tmp_path / "victim.txt"
    if not dangling:
        victim.write_text("precious\n")
    out, r = _clean_with_link(tmp_path, "mocapfix-manifest.jsonl", "../victim.txt")
    assert r.exit_code == 2, r.output
    assert "mocapfix-manifest.jsonl: the output folder's manifest is a symbolic link" in r.output
    if dangling:
        assert not victim.exists(), "the dangling link created its target"
    else:
        assert victim.read_text() == "precious\n"
    assert os.path.islink(out / "mocapfix-manifest.jsonl")
    assert sorted(p.name for p in out.iterdir()) == ["mocapfix-manifest.jsonl"]


def test_a_manifest_link_planted_during_the_run_is_not_written_through(tmp_path):
    # checked at the start, and opened with O_NOFOLLOW: a link that appears after the
    # check is a write error, not an append to its target
    from mocapfix.batch.manifest import Manifest

    out = tmp_path / "o"
    out.mkdir()
    manifest = Manifest(out, {"config_sha256": "x", "models_sha256": {}, "reports": [],
                              "read_options": {}, "version": "0"})
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    (out / "mocapfix-manifest.jsonl").symlink_to(victim)
    with pytest.raises(WriteError, match="cannot write the manifest: is a link"):
        manifest.record({"input": "/x", "output": str(out / "x"), "status": "ERROR", "error": "e"})
    assert victim.read_text() == "precious\n"


# -- 2. a full disk -----------------------------------------------------------------------

@contextlib.contextmanager
def small_disk(path, size: str):
    """A real tmpfs of ``size`` mounted at ``path`` (this test suite runs as root in CI;
    elsewhere the test is skipped and the injected-error tests below still run)."""
    path.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                       capture_output=True, check=False)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.decode().strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=True)


def _fill(folder, leave: int):
    """Fill the file system of ``folder`` up to ``leave`` bytes free."""
    st = os.statvfs(folder)
    free = st.f_bavail * st.f_frsize
    with open(folder / "filler", "wb") as fh, contextlib.suppress(OSError):
        fh.write(b"\0" * max(0, free - leave))


def test_a_full_disk_fails_each_file_with_its_path_and_the_run_ends_with_its_summary(tmp_path):
    src = _inputs(tmp_path)
    shutil.copy(C3D, src / "c.c3d")          # its writer writes inside atomic_open
    before = md5_tree(src)
    with small_disk(tmp_path / "disk", "2m") as disk:
        _fill(disk, 8192)                   # room for the manifest's first lines, no output
        out = disk / "o"
        r = _clean(tmp_path, src, out)
        no_traceback(r)
        assert r.exit_code == 1, r.output
        assert "internal error" not in r.output
        for name in ("a.bvh", "b.csv", "c.c3d"):
            assert f"{out / name}: cannot write: No space left on device" in r.output
        assert "cleaned 0 of 3 files; 3 failed (ERROR)" in r.output
        left = sorted(p.name for p in out.iterdir())
        assert not [n for n in left if n.endswith(".part") or n.startswith(("a.", "b.", "c."))], left
        # space again: the same command finishes the batch
        (disk / "filler").unlink()
        r = _clean(tmp_path, src, out)
        assert r.exit_code == 0, r.output
        assert (out / "a.bvh").is_file() and (out / "mocapfix-config.yaml").is_file()
    assert md5_tree(src) == before


def test_a_disk_that_fills_before_the_manifest_is_a_problem_line_not_an_internal_error(tmp_path):
    src = _inputs(tmp_path)
    with small_disk(tmp_path / "disk", "1m") as disk:
        out = disk / "o"
        out.mkdir()
        _fill(disk, 0)
        r = _clean(tmp_path, src, out)
        no_traceback(r)
        assert r.exit_code == 1, r.output
        assert "internal error" not in r.output
        problem = (f"mocapfix: error: {out / 'mocapfix-manifest.jsonl'}: cannot write the "
                   "manifest: No space left on device")
        assert r.output.count(problem) == 1, r.output
        assert r.output.rstrip().endswith(problem), "not after the summary"
        assert "cleaned 0 of 2 files" in r.output


def test_junit_onto_a_full_disk_exits_2_with_the_cause(tmp_path):
    with small_disk(tmp_path / "disk", "1m") as disk:
        junit = disk / "junit.xml"
        _fill(disk, 0)                      # an empty file (the probe) fits, the XML not
        r = CliRunner().invoke(main, ["check", str(BVH), str(KIN), "--junit", str(junit)])
        no_traceback(r)
        assert r.exit_code == 2, r.output
        assert f"{junit}: cannot write: No space left on device" in r.output
        assert not junit.exists()
        assert not [p for p in disk.iterdir() if p.name.endswith(".part")]


@pytest.mark.parametrize("code", ["ENOSPC", "EDQUOT", "EIO", "EROFS"])
def test_a_refused_write_inside_an_atomic_write_is_a_write_error_naming_the_path(
        tmp_path, monkeypatch, code):
    # the errors a tmpfs cannot produce (quota, I/O, read-only), injected into the
    # writes a caller makes inside atomic_open
    real = os.fdopen

    class Refusing:
        def __init__(self, fh):
            self.fh = fh

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

        def write(self, data):
            raise OSError(getattr(errno, code), os.strerror(getattr(errno, code)))

    monkeypatch.setattr(fileio.os, "fdopen", lambda *a, **k: Refusing(real(*a, **k)))
    target = tmp_path / "x.bvh"
    with pytest.raises(WriteError) as info:
        fileio.atomic_write_bytes(target, b"data" * 100_000)
    assert str(info.value) == f"{target}: cannot write: {os.strerror(getattr(errno, code))}"
    assert list(tmp_path.iterdir()) == []


# -- 8. an output that is a device or a pipe ----------------------------------------------

@pytest.mark.parametrize("kind", ["devnull link", "fifo"])
def test_an_output_that_is_a_device_or_a_pipe_fails_that_file_and_is_not_recorded_done(
        tmp_path, kind):
    src = _inputs(tmp_path)
    out = tmp_path / "o"
    out.mkdir()
    target = out / "a.bvh"
    if kind == "fifo":
        os.mkfifo(target)
    else:
        target.symlink_to("/dev/null")
    r = _clean(tmp_path, src, out, "--overwrite")
    no_traceback(r)
    assert r.exit_code == 1, r.output
    assert f"{target}: cannot write: it is a device or a named pipe (FIFO)" in r.output
    assert "cleaned 1 of 2 files" in r.output
    records = [json.loads(line) for line in (out / "mocapfix-manifest.jsonl").read_text().splitlines()]
    status = {rec["output"]: rec["status"] for rec in records}
    assert status == {"a.bvh": "failed", "b.csv": "done"}
    # left as it was: neither replaced by a file nor removed as a failed output
    mode = os.lstat(target).st_mode
    assert stat.S_ISFIFO(mode) if kind == "fifo" else os.readlink(target) == "/dev/null"


def test_a_config_record_linked_to_dev_null_is_a_problem_not_swallowed(tmp_path):
    out, r = _clean_with_link(tmp_path, "mocapfix-config.yaml", "/dev/null")
    assert r.exit_code == 1, r.output
    assert f"{out / 'mocapfix-config.yaml'}: cannot write: it is a device" in r.output
    assert "cleaned 2 of 2 files" in r.output


def test_an_asf_copy_onto_a_device_fails_its_amc(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    for name in ("walker.asf", "walker_01.amc"):
        shutil.copy(SAMPLE_DATA / name, src / name)
    out = tmp_path / "o"
    out.mkdir()
    (out / "walker.asf").symlink_to("/dev/null")
    r = _clean(tmp_path, src, out, "--overwrite")
    no_traceback(r)
    assert r.exit_code == 1, r.output
    assert f"{out / 'walker.asf'}: cannot write: it is a device or a named pipe (FIFO)" in r.output
    assert os.readlink(out / "walker.asf") == "/dev/null" and not (out / "walker_01.amc").exists()
