"""Text files in a folder that match no layout: a table of numbers is data in a layout we
do not read (named, a skipped JUnit testcase, an ERROR under ``check --strict``); prose is
a note, passed over quietly."""
from __future__ import annotations

import junitparser
from click.testing import CliRunner

from mocapfix.batch.discovery import discover_inputs, unknown_layout
from mocapfix.cli import main
from conftest import SAMPLE_DATA

TABLE = "time;fx;fy;fz\n0.00;1.5;2.5;3.5\n0.01;1.6;2.6;3.6\n0.02;1.7;2.7;3.7\n0.03;1.8;2.8;3.8\n"
NOTE = "Session 3\nSubject walked 3 times at 1.2 m/s, 2 m/s and 3 m/s.\nMarkers re-taped.\n"


def _folder(tmp_path):
    (tmp_path / "walk.bvh").write_bytes((SAMPLE_DATA / "walk.bvh").read_bytes())
    (tmp_path / "forces.csv").write_text(TABLE)
    (tmp_path / "notes.txt").write_text(NOTE)
    return tmp_path


def test_a_table_of_numbers_is_data_and_prose_is_a_note(tmp_path):
    _folder(tmp_path)
    assert unknown_layout(tmp_path / "forces.csv") == "not a known layout (first line: 'time;fx;fy;fz')"
    assert unknown_layout(tmp_path / "notes.txt") is None      # numbers, but not three a row
    found = discover_inputs([str(tmp_path)])
    assert [f.path.name for f in found.files] == ["walk.bvh"]
    assert [(f.path.name, why.split(" (")[0]) for f, why in found.unknown] == [
        ("forces.csv", "not a known layout")]
    assert {p.rsplit("/", 1)[-1] for p, _ in found.skipped} == {"forces.csv", "notes.txt"}


def test_check_lists_unknown_layouts_as_skipped_testcases_and_strict_fails(tmp_path):
    (tmp_path / "in").mkdir()
    src = _folder(tmp_path / "in")
    junit = tmp_path / "check.xml"
    r = CliRunner().invoke(main, ["check", str(src), "--junit", str(junit)])
    assert r.exit_code == 0, r.output
    assert "1 SKIP (not a known layout" in r.output and "checked 1 files" in r.output
    suite = next(iter(junitparser.JUnitXml.fromfile(str(junit))))
    assert (suite.tests, suite.skipped, suite.failures, suite.errors) == (2, 1, 0, 0)
    cases = {c.name: c for c in suite}
    assert set(cases) == {"in/walk.bvh", "in/forces.csv"}            # the note is no testcase
    skipped = cases["in/forces.csv"].result
    assert len(skipped) == 1 and isinstance(skipped[0], junitparser.Skipped)
    assert skipped[0].message.startswith("not a known layout")

    r = CliRunner().invoke(main, ["check", str(src), "--strict", "--junit", str(junit)])
    assert r.exit_code == 3, r.output                                  # an input not readable
    assert "ERROR" in r.output and "forces.csv" in r.output and "SKIP  " not in r.output
    suite = next(iter(junitparser.JUnitXml.fromfile(str(junit))))
    assert (suite.tests, suite.skipped, suite.errors) == (2, 0, 1)


def test_a_folder_of_notes_only_still_says_no_motion_files(tmp_path):
    (tmp_path / "notes.txt").write_text(NOTE)
    r = CliRunner().invoke(main, ["check", str(tmp_path)])
    assert r.exit_code == 2 and "no motion files found" in r.output
