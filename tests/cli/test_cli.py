"""The command line end to end: info, clean on files and folders, failure isolation,
exit codes, reports, atomic outputs and untouched inputs."""
from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys

import pytest
from click.testing import CliRunner

from mocapfix.cli import main
from mocapfix.formats import read
from conftest import SAMPLE_DATA, need, shared, shared_files

ALL_SHARED = [p for sub in ("c3d", "bvh", "asfamc", "kinect")
              for p in shared_files(sub, "*.amc" if sub == "asfamc" else "*")]


def _digest(folder):
    return {p.relative_to(folder): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_info_json_on_sample_data():
    files = sorted(str(p) for p in SAMPLE_DATA.iterdir() if p.suffix != ".asf")
    result = CliRunner().invoke(main, ["info", "--json", *files])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.stdout)
    assert len(rows) == len(files)
    for row in rows:
        for key in ("path", "format", "frames", "fps", "joints", "units", "missing_fraction",
                    "gaps", "longest_gap_frames"):
            assert key in row
    by_name = {r["path"].split("/")[-1]: r for r in rows}
    c3d = by_name["walk_markers.c3d"]
    assert c3d["format"] == "c3d" and c3d["frames"] == 600 and c3d["fps"] == 120
    assert c3d["gaps"] >= 4 and c3d["longest_gap_frames"] == 60   # the gaps the script made
    assert by_name["walk.bvh"]["frames"] == 300 and by_name["walk.bvh"]["fps"] == pytest.approx(60, rel=1e-4)
    assert by_name["walker_01.amc"]["frames"] == 240
    kin = by_name["walk_kinect_v2.csv"]
    assert kin["joints"] == 25 and kin["longest_gap_frames"] == 6 and "tracking" in kin
    assert any("drop" in n.lower() for n in kin["notes"])


def test_info_text_and_unreadable_exit_code(tmp_path):
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n")
    result = CliRunner().invoke(main, ["info", str(SAMPLE_DATA / "walk.bvh"), str(bad)])
    assert result.exit_code == 3            # unreadable input (docs/commands.md "Exit codes")
    assert "walk.bvh" in result.output and "broken.bvh" in result.output
    assert "Traceback" not in result.output


def test_info_names_the_frames_where_no_marker_is_seen():
    """The OptiTrack export ends with 229 frames holding no marker (frames 1151-1379 at
    100 Hz) and c3d.org s06 starts and ends with such runs: info lists them, the JSON as
    [start, length]; a capture seen throughout (CMU 85_02) has none."""
    files = [shared(f"c3d/{name}") for name in
             ("btk_mocap36_optitrack.c3d", "c3dorg_s06_MACsample.c3d", "cmu_85_02.c3d")]
    rows = json.loads(CliRunner().invoke(main, ["info", "--json", *map(str, files)]).stdout)
    assert [r["empty_frames"] for r in rows] == [[[1151, 229]], [[0, 16], [111, 69]], []]
    text = CliRunner().invoke(main, ["info", str(files[0])]).output
    assert "empty       229 frames with no marker seen: 1151–1379 (2.29 s)" in text


@pytest.mark.slow
@pytest.mark.parametrize("path", ALL_SHARED)
def test_info_reads_every_shared_file(path):
    result = CliRunner().invoke(main, ["info", "--json", str(need(path))])
    assert result.exit_code == 0, result.output
    row = json.loads(result.stdout)[0]
    assert row["frames"] > 0 and row["joints"] > 0 and 0.0 <= row["missing_fraction"] <= 1.0


@pytest.mark.slow
def test_clean_sample_folder_end_to_end(tmp_path):
    src = tmp_path / "in"
    shutil.copytree(SAMPLE_DATA, src)
    before = _digest(src)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "--report", "json,md,html",
                                       "--json"])
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["failed"] == 0 and summary["cleaned"] == 4
    assert _digest(src) == before, "inputs were modified"
    assert (out / "mocapfix-config.yaml").exists()
    for name in ("walk.bvh", "walker_01.amc", "walk_markers.c3d", "walk_kinect_v2.csv"):
        cleaned = read(out / name)
        original = read(src / name)
        assert cleaned.positions.shape == original.positions.shape
        assert cleaned.missing.sum() <= original.missing.sum()
        stem = name                           # reports: take.c3d.report.json
        report = json.loads((out / f"{stem}.report.json").read_text())
        assert report["schema"] == "mocapfix.report/1"
        assert len(report["joints"]) == original.n_joints
        assert (out / f"{stem}.report.md").read_text().startswith("# mocapfix report")
        assert "<svg" in (out / f"{stem}.report.html").read_text()
    assert (out / "walker.asf").exists()
    assert not list(out.rglob("*.part"))
    # the gaps of the sample C3D were filled and their filler named
    rep = json.loads((out / "walk_markers.c3d.report.json").read_text())
    wrist = next(j for j in rep["joints"] if j["name"] == "LEFTWRIST")
    assert wrist["missing_before"] > 0 and wrist["missing_after"] == 0
    assert wrist["gaps"]["filled"] and wrist["gaps"]["filled"][0]["filled_by"]


def test_batch_with_a_corrupt_file_cleans_the_rest(tmp_path):
    src = tmp_path / "in"
    (src / "sub").mkdir(parents=True)
    shutil.copy(SAMPLE_DATA / "walk_markers.c3d", src / "sub" / "good.c3d")
    shutil.copy(SAMPLE_DATA / "walk.bvh", src / "good.bvh")
    (src / "bad.c3d").write_bytes(b"\x02\x50" + b"\x00" * 100)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-j", "2", "--json"])
    assert result.exit_code == 1
    summary = json.loads(result.stdout if hasattr(result, "stdout") else result.output)
    assert summary["cleaned"] == 2 and summary["failed"] == 1
    bad = [f for f in summary["files"] if f["status"] == "ERROR"]
    assert len(bad) == 1 and "bad.c3d" in bad[0]["error"]
    assert (out / "sub" / "good.c3d").exists() and (out / "good.bvh").exists()
    assert not (out / "bad.c3d").exists()


def test_usage_errors_exit_2(tmp_path):
    runner = CliRunner()
    cfg = tmp_path / "bad.yaml"
    cfg.write_text("pipeline:\n  - cleaner: nope\n")
    r = runner.invoke(main, ["clean", str(SAMPLE_DATA / "walk.bvh"), "-o", str(tmp_path / "o"), "-c", str(cfg)])
    assert r.exit_code == 2 and "nope" in r.output and "Traceback" not in r.output
    r = runner.invoke(main, ["clean", str(SAMPLE_DATA), "-o", str(SAMPLE_DATA / "out")])
    assert r.exit_code == 2 and "inside input folder" in r.output
    r = runner.invoke(main, ["clean", str(tmp_path / "missing.c3d"), "-o", str(tmp_path / "o")])
    assert r.exit_code == 2


def test_console_script_runs():
    out = subprocess.run([sys.executable, "-m", "mocapfix.cli", "--help"], capture_output=True, text=True)
    assert out.returncode == 0 and "clean" in out.stdout
