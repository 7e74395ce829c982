"""Huge fields (issue 40, item 6): text readers refuse a field longer than MAX_FIELD with
one short line naming the file and line; no message quotes more than an excerpt."""
from __future__ import annotations

import shutil

import numpy as np
from click.testing import CliRunner
from conftest import SAMPLE_DATA, config_file, no_traceback

from mocapfix.cli import main
from mocapfix.core.errors import MAX_FIELD, MAX_REASON, UnreadableFileError


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


def test_a_long_number_within_the_cap_does_not_size_the_kinect_writer(tmp_path):
    # each cell was copied into one fixed-width string array as wide as the longest token:
    # 139 numbers of 999 characters made 47 MB of it (a 5 MB one: 211 GiB)
    import tracemalloc

    from mocapfix import formats

    rows = (SAMPLE_DATA / "walk_kinect_v2.csv").read_text().split("\n")
    for n in range(1, 140):
        cells = rows[n].split(",")
        cells[2] = cells[2] + "0" * (MAX_FIELD - 1 - len(cells[2]))
        rows[n] = ",".join(cells)
    (tmp_path / "long.csv").write_text("\n".join(rows))
    motion = formats.read(tmp_path / "long.csv")
    moved = motion.replace(positions=motion.positions + 0.001)
    tracemalloc.start()
    try:
        formats.write(moved, tmp_path / "out.csv")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 15e6, f"{peak / 1e6:.0f} MB to write a 500 KB file"
    again = formats.read(tmp_path / "out.csv")
    np.testing.assert_allclose(again.positions, moved.positions, atol=1e-6)


def test_a_huge_field_in_an_amc_or_its_asf_is_refused_with_an_excerpt(tmp_path):
    from mocapfix import formats

    for damaged in ("walker_01.amc", "walker.asf"):
        folder = tmp_path / damaged.replace(".", "_")
        folder.mkdir()
        for name in ("walker.asf", "walker_01.amc"):
            data = (SAMPLE_DATA / name).read_bytes()
            if name == damaged:
                lines = data.split(b"\n")
                lines[10] += b" " + b"5" * 5_000_000
                data = b"\n".join(lines)
            (folder / name).write_bytes(data)
        try:
            formats.read(folder / "walker_01.amc")
        except UnreadableFileError as exc:
            assert str(exc).startswith(f"{folder / damaged}:11: a field longer than 1,000 characters")
            assert len(str(exc)) < 300
        else:
            raise AssertionError(f"a 5 MB field in {damaged} was read")
