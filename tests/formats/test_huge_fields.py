"""Huge fields (issue 40, item 6): text readers refuse a field longer than MAX_FIELD with
one short line naming the file and line; no message quotes more than an excerpt."""
from __future__ import annotations

import shutil

from click.testing import CliRunner

from mocapfix.cli import main
from mocapfix.core.errors import MAX_FIELD, MAX_REASON, UnreadableFileError

from conftest import SAMPLE_DATA, config_file, no_traceback


def test_a_5mb_number_in_a_kinect_csv_fails_that_file_with_a_short_line(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    rows = (SAMPLE_DATA / "walk_kinect_v2.csv").read_text().split("\n")
    cells = rows[3].split(",")
    cells[2] = "1" * 5_000_000
    rows[3] = ",".join(cells)
    (src / "huge.csv").write_text("\n".join(rows))
    shutil.copy(SAMPLE_DATA / "walk.bvh", src / "ok.bvh")
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(tmp_path / "o"),
                                  "-c", config_file(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 1, r.output[:2000]
    line = next(x for x in r.output.splitlines() if "huge.csv:" in x)
    assert f"huge.csv:4: a field longer than {MAX_FIELD:,} characters: '1111" in line
    assert "(5,000,000 characters)" in line and len(line) < 300
    assert "MemoryError" not in r.output and "cleaned 1 of 2 files" in r.output


def test_a_bvh_full_of_garbage_gets_an_excerpt_not_the_garbage(tmp_path):
    from mocapfix import formats

    junk = bytes(range(33, 127)) * 2_000
    for name, data in {
            "name.bvh": b"HIERARCHY\nROOT " + junk + b"\n{\n",
            "garbage.bvh": b"HIERARCHY\n" + junk.replace(b"{", b" ").replace(b"}", b" "),
            "frames.bvh": (SAMPLE_DATA / "walk.bvh").read_bytes().replace(
                b"Frames:", b"Frames: " + b"7" * 4_000 + b"\nX:", 1)}.items():
        path = tmp_path / name
        path.write_bytes(data)
        try:
            formats.read(path)
        except UnreadableFileError as exc:
            assert len(str(exc)) < 400, (name, len(str(exc)), str(exc)[:200])
            assert str(exc).startswith(str(path))
        else:
            raise AssertionError(f"{name} was read")


def test_no_unreadable_file_error_keeps_a_reason_longer_than_the_cap():
    exc = UnreadableFileError("x.bvh", "y" * 100_000)
    assert len(exc.reason) <= MAX_REASON and exc.reason.endswith("(cut: 100,000 characters in all)")
