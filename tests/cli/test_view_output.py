"""`mocapfix view -o`: the page never replaces a capture it shows (or one beside it), and
is written as every other output is (atomically, usual permissions)."""
from __future__ import annotations

import os
import shutil

import pytest
from click.testing import CliRunner

from conftest import SAMPLE_DATA, hang_guard
from mocapfix.cli import main
from mocapfix.core.fileio import current_umask

BVH, C3D = SAMPLE_DATA / "walk.bvh", SAMPLE_DATA / "walk_markers.c3d"


def _copies(tmp_path):
    bvh, c3d = tmp_path / "walk.bvh", tmp_path / "walk_markers.c3d"
    shutil.copy(BVH, bvh)
    shutil.copy(C3D, c3d)
    return bvh, c3d


@pytest.mark.parametrize("target", ["the input", "beside"])
def test_view_refuses_an_output_that_is_a_capture_it_reads(tmp_path, target):
    bvh, c3d = _copies(tmp_path)
    before = {p: p.read_bytes() for p in (bvh, c3d)}
    out = bvh if target == "the input" else c3d
    r = CliRunner().invoke(main, ["view", str(bvh), "-o", str(out)])
    assert r.exit_code == 2, r.output
    assert "Traceback" not in r.output and r.output.count("\n") == 1, r.output
    assert f"-o {out}: would overwrite" in r.output, r.output
    assert {p: p.read_bytes() for p in (bvh, c3d)} == before
    assert sorted(os.listdir(tmp_path)) == ["walk.bvh", "walk_markers.c3d"]


def test_view_of_a_report_refuses_to_overwrite_the_input_it_names(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    bvh, _ = _copies(src)
    r = CliRunner().invoke(main, ["clean", str(bvh), "-o", str(tmp_path / "out"), "-q"])
    assert r.exit_code == 0, r.output
    original = bvh.read_bytes()
    r = CliRunner().invoke(main, ["view", str(tmp_path / "out" / "walk.bvh.report.json"),
                                  "-o", str(bvh)])
    assert r.exit_code == 2 and f"would overwrite the input {bvh}" in r.output, r.output
    assert bvh.read_bytes() == original


def test_the_page_is_written_atomically_with_the_usual_permissions(tmp_path):
    bvh, _ = _copies(tmp_path)
    out = tmp_path / "v.html"
    os.symlink(tmp_path / "elsewhere.html", out)         # replaced, not written through
    r = CliRunner().invoke(main, ["view", str(bvh), "-o", str(out)])
    assert r.exit_code == 0, r.output
    assert not out.is_symlink() and not (tmp_path / "elsewhere.html").exists()
    assert out.stat().st_mode & 0o777 == 0o666 & ~current_umask()
    assert not [n for n in os.listdir(tmp_path) if n.endswith(".part")]


@pytest.mark.parametrize("budget", ["nan", "NaN", "-nan"])
def test_a_budget_that_is_not_a_number_is_a_usage_error_naming_the_option(tmp_path, budget):
    # nan passed click's range check (every comparison with it is false) and the error
    # was "cannot convert float NaN to integer", naming neither option nor value
    out = tmp_path / "v.html"
    r = CliRunner().invoke(main, ["view", str(BVH), "-o", str(out), "--budget", budget])
    assert r.exit_code == 2 and "--budget" in r.output and "not a number" in r.output, r.output
    assert not out.exists()


@pytest.mark.parametrize("kind", ["fifo", "device"])
@pytest.mark.parametrize("how", ["file", "after", "report"])
def test_view_refuses_a_fifo_or_device_as_an_input_at_once(tmp_path, kind, how):
    # info and check refuse them (discovery); view read a FIFO, waiting for a writer
    # forever, and a link to /dev/zero without end
    special = tmp_path / ("take.report.json" if how == "report" else "take.bvh")
    if kind == "fifo":
        os.mkfifo(special)
    else:
        special.symlink_to("/dev/null")     # (a link to /dev/zero: no end, no memory left)
    args = {"file": [str(special)], "report": [str(special)],
            "after": ["--before", str(BVH), "--after", str(special)]}[how]
    out = tmp_path / "v.html"
    with hang_guard(20):
        r = CliRunner().invoke(main, ["view", *args, "-o", str(out)])
    assert r.exit_code == 2 and "Traceback" not in r.output, r.output
    assert f"{special}: cannot read: a " in r.output, r.output
    assert not out.exists()
