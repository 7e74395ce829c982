"""A lab folder as it comes: a Vicon Nexus CSV, a QTM TSV, a C3D and the session's
notes.txt. `info`, `clean` and `check --junit` treat each capture as a capture and the
notes as a note (issue "formats": before, the Nexus export was skipped with the notes and a
CI job went green without checking it)."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import junitparser
from click.testing import CliRunner

from mocapfix import formats
from mocapfix.cli import main
from conftest import SAMPLE_DATA

VENDOR = Path(__file__).resolve().parents[1] / "data" / "vendor"
CAPTURES = {"Trial03.csv": VENDOR / "nexus_sections_doc.csv",
            "Trial04.tsv": VENDOR / "qtm_hand_embodiment_recording.tsv",
            "walk_markers.c3d": SAMPLE_DATA / "walk_markers.c3d"}
FORMAT = {"Trial03.csv": "nexus_csv", "Trial04.tsv": "qtm_tsv", "walk_markers.c3d": "c3d"}


def _session(tmp_path) -> Path:
    folder = tmp_path / "session"
    folder.mkdir()
    for name, src in CAPTURES.items():
        shutil.copyfile(src, folder / name)
    (folder / "notes.txt").write_text("Subject 3, second session.\nMarkers re-taped after trial 2.\n")
    return folder


def test_info_reads_every_capture_and_passes_over_the_note(tmp_path):
    folder = _session(tmp_path)
    r = CliRunner().invoke(main, ["info", str(folder), "--json"])
    assert r.exit_code == 0, r.output
    listed = json.loads(r.stdout)
    assert {Path(s["path"]).name: s["format"] for s in listed} == FORMAT
    assert "1 text file(s) are not motion data" in r.stderr


def test_clean_writes_every_capture_in_its_own_layout_and_fills_the_nexus_gaps(tmp_path):
    folder = _session(tmp_path)
    r = CliRunner().invoke(main, ["clean", str(folder), "-o", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    assert "cleaned 3 of 3 files" in r.output
    out = tmp_path / "out"
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith("mocapfix-")
                  and not p.name.endswith(".json")) == sorted(CAPTURES)
    for name, fmt in FORMAT.items():
        assert formats.detect(out / name) == fmt
    nexus_in, nexus_out = formats.read(folder / "Trial03.csv"), formats.read(out / "Trial03.csv")
    assert nexus_in.missing.sum() == 2                          # two empty samples in the export
    report = json.loads((out / "Trial03.csv.report.json").read_text())
    steps = {s["cleaner"]: s.get("skipped") for s in report["steps"]}
    assert steps["fill_ensemble"] != "not for this format"      # the marker pipeline ran on it
    assert nexus_out.missing.sum() <= nexus_in.missing.sum()
    # the Devices and Model Outputs sections are written back as they were
    text_in, text_out = (folder / "Trial03.csv").read_bytes(), (out / "Trial03.csv").read_bytes()
    assert text_in.split(b"Trajectories")[0] == text_out.split(b"Trajectories")[0]
    assert text_in.split(b"Model Outputs")[1] == text_out.split(b"Model Outputs")[1]


def test_check_junit_has_a_testcase_per_capture_and_none_for_the_note(tmp_path):
    folder = _session(tmp_path)
    junit = tmp_path / "check.xml"
    r = CliRunner().invoke(main, ["check", str(folder), "--junit", str(junit)])
    assert r.exit_code in (0, 1), r.output
    suite = next(iter(junitparser.JUnitXml.fromfile(str(junit))))
    names = {c.name: c.classname for c in suite}
    assert names == {f"session/{n}": f"mocapfix.check.{fmt}" for n, fmt in FORMAT.items()}
    assert suite.skipped == 0 and suite.errors == 0
