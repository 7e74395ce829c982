"""`mocapfix check` on the shared archive and on constructed cases: JUnit XML read back by
a real JUnit consumer (junitparser), one testcase per file, the known-bad files fail,
nothing is written into the input folder, exit codes 0/1/2/3."""
from __future__ import annotations

import hashlib
import json
import shutil

import junitparser
import numpy as np
import pytest
from click.testing import CliRunner

from mocapfix.cli import main
from mocapfix.formats import MOTION_SUFFIXES, write
from mocapfix.core.motion import Motion
from conftest import DATA, SAMPLE_DATA, need, shared

BVH = SAMPLE_DATA / "walk.bvh"


def _tree(folder):
    return {p.relative_to(folder): (hashlib.sha256(p.read_bytes()).hexdigest(), p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def archive_run(tmp_path_factory):
    data = need(DATA)
    before = _tree(data)
    junit = tmp_path_factory.mktemp("check") / "check.xml"
    result = CliRunner().invoke(main, ["check", str(data), "-j", "2", "--junit", str(junit), "--json"])
    return data, before, junit, result


@pytest.mark.slow
def test_archive_junit_is_valid_one_testcase_per_file(archive_run):
    data, before, junit, result = archive_run
    assert result.exit_code == 1, result.output          # some rules fail, every file readable
    xml = junitparser.JUnitXml.fromfile(str(junit))
    cases = [case for suite in xml for case in suite]
    motion_files = [p for p in data.rglob("*") if p.is_file() and p.suffix.lower() in MOTION_SUFFIXES]
    assert len(cases) == len(motion_files) > 40
    assert len({c.name for c in cases}) == len(cases)
    failed = {c.name.split("/")[-1]: c for c in cases if not c.is_passed}
    summary = json.loads(result.stdout)["summary"]
    assert summary["FAIL"] == len(failed) and summary["ERROR"] == 0
    # a capture with never-seen markers (34 of 114 in sub_labels) fails on that rule
    sub = failed["c3dorg_s04_sub_labels.c3d"].result[0]
    assert isinstance(sub, junitparser.Failure)
    assert sub.type == "never_seen" and "34 never-seen" in sub.message
    # a Kinect file with dropped frames (2 timestamp gaps, SOURCES.md) fails on that rule
    ges = failed["kv2_laban_Ges01_wavehand.csv"].result[0]
    assert ges.type == "dropped_frames" and "2 dropped frames" in ges.message
    # a complete optical capture passes
    assert "cmu_85_02.c3d" not in failed and "hdm05_HDM_mm_01-02_03_120.c3d" not in failed


@pytest.mark.slow
def test_archive_check_writes_nothing_into_the_input(archive_run):
    data, before, _, _ = archive_run
    assert _tree(data) == before


def _motion(T=200, J=4, fps=100.0):
    t = np.arange(T) / fps
    pos = np.stack([np.stack([1000 * t + 100 * j, np.sin(t + j) * 100, np.full(T, 900.0 + j)], 1)
                    for j in range(J)], axis=1)
    return Motion(pos, [f"M{j}" for j in range(J)], fps, units="mm", metres_per_unit=0.001, format="c3d")


def test_exit_codes_pass_fail_unreadable_usage(tmp_path):
    good = tmp_path / "good.c3d"
    write(_motion(), good)
    runner = CliRunner()
    r = runner.invoke(main, ["check", str(good), "-r", "optical-gait"])
    assert r.exit_code == 0, r.output
    assert r.stdout.startswith("OK ")                    # complete, 100 Hz, smooth
    gappy = _motion()
    gappy.positions[20:120, 1] = np.nan                              # 1 s gap, 50 % missing
    write(gappy, tmp_path / "gappy.c3d")
    r = runner.invoke(main, ["check", str(tmp_path / "gappy.c3d"), "-r", "optical-gait"])
    assert r.exit_code == 1 and "FAIL" in r.output and "M1: 50.0 % missing" in r.output
    r = runner.invoke(main, ["check", str(tmp_path / "gappy.c3d"), "--exit-zero"])
    assert r.exit_code == 0
    # a relaxed threshold from the command line lets it pass
    r = runner.invoke(main, ["check", str(tmp_path / "gappy.c3d"), "-r", "optical-gait",
                             "--fail-on", "missing=60%", "--fail-on", "longest_gap=2 s"])
    assert r.exit_code == 0, r.output
    (tmp_path / "broken.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
    r = runner.invoke(main, ["check", str(good), str(tmp_path / "broken.bvh")])
    assert r.exit_code == 3 and "ERROR" in r.output and "broken.bvh" in r.output
    bad_rules = tmp_path / "rules.yaml"
    bad_rules.write_text("rules:\n  - metric: missing\n    warn_missing: 5 %\n")
    r = runner.invoke(main, ["check", str(good), "-r", str(bad_rules)])
    assert r.exit_code == 2 and "warn_missing" in r.output and "line 3" in r.output
    r = runner.invoke(main, ["check", str(good), "--fail-on", "missing"])
    assert r.exit_code == 2 and "RULE=VALUE" in r.output
    r = runner.invoke(main, ["check", str(good), "--fail-on", "missing=200%"])
    assert r.exit_code == 2 and "above 100 %" in r.output


def test_a_would_clean_pipeline_that_cannot_clean_a_file_fails_it_not_errors(tmp_path):
    """The marker C3D is readable; a partlet pipeline has no model for a marker set. The
    gate reports a failed check (exit 1, a JUnit failure naming the cause), not an
    unreadable input (exit 3), and the other file is judged as usual."""
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(SAMPLE_DATA / "walk_markers.c3d", src / "walk.c3d")
    shutil.copy(SAMPLE_DATA / "walk_kinect_v2.csv", src / "kinect.csv")
    cfg = tmp_path / "partlet.yaml"
    cfg.write_text("version: 1\npipeline:\n  - cleaner: partlet_dictionary\n")
    junit = tmp_path / "out.xml"
    r = CliRunner().invoke(main, ["check", str(src), "--junit", str(junit), "--json", "--exit-zero",
                                  "--would-clean", str(cfg)])
    assert r.exit_code == 0, r.output
    files = {f["name"]: f for f in json.loads(r.stdout)["files"]}
    c3d = files["in/walk.c3d"]
    assert c3d["status"] == "FAIL" and c3d["findings"][0]["rule"] == "would_clean"
    assert "train" in c3d["findings"][0]["message"] and "error" in c3d["would_clean"]
    assert "samples_filled" in files["in/kinect.csv"]["would_clean"]
    cases = {c.name: c for suite in junitparser.JUnitXml.fromfile(str(junit)) for c in suite}
    assert isinstance(cases["in/walk.c3d"].result[0], junitparser.Failure)
    r = CliRunner().invoke(main, ["check", str(src / "walk.c3d"), "-v", "--would-clean", str(cfg)])
    assert r.exit_code == 1 and "FAIL" in r.output and "cannot clean this file" in r.output, r.output


def test_quiet_keeps_the_fail_and_error_lines_a_ci_log_needs(tmp_path):
    """``check -q`` prints the FAIL and ERROR lines and the summary, not OK, WARN or SKIP
    lines; its --help said "Only errors and the summary", as for the other commands."""
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(shared("c3d/c3dorg_s06_MACsample.c3d"), src)     # 8 markers never seen: FAIL
    shutil.copy(SAMPLE_DATA / "walk.bvh", src)                      # WARN
    (src / "broken.c3d").write_bytes(b"x")                          # ERROR
    (src / "notes.txt").write_text("subject 3, second session\n")  # not motion: a note
    shutil.copy(SAMPLE_DATA / "walk.bvh", src / "old_walk.bvh")     # excluded: a SKIP line
    args = ["check", str(src), "--exclude", "old_*"]
    r = CliRunner().invoke(main, args)
    assert sorted(line.split()[0] for line in r.output.splitlines()) == [
        "ERROR", "FAIL", "SKIP", "WARN", "checked", "note:"], r.output
    r = CliRunner().invoke(main, [*args, "-q"])
    assert r.exit_code == 3
    lines = r.output.splitlines()
    assert lines[0].startswith(f"ERROR {src / 'broken.c3d'}: ")
    assert lines[1].startswith(f"FAIL  {src / 'c3dorg_s06_MACsample.c3d'}  (")
    assert lines[2:] == ["checked 3 files: 0 OK, 1 WARN, 1 FAIL, 1 ERROR"]
    help_text = " ".join(CliRunner().invoke(main, ["check", "--help"]).output.split())
    assert "-q, --quiet Only FAIL and ERROR lines and the summary." in help_text


def test_junit_error_for_unreadable_and_would_clean(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(SAMPLE_DATA / "walk_markers.c3d", src / "walk.c3d")
    (src / "bad.c3d").write_bytes(b"\x02\x50" + b"\x00" * 100)
    before = _tree(src)
    junit = tmp_path / "out.xml"
    r = CliRunner().invoke(main, ["check", str(src), "--junit", str(junit), "--json",
                                  "--would-clean", "default"])
    assert r.exit_code == 3
    cases = {c.name: c for suite in junitparser.JUnitXml.fromfile(str(junit)) for c in suite}
    assert isinstance(cases["in/bad.c3d"].result[0], junitparser.Error)
    files = {f["name"]: f for f in json.loads(r.stdout)["files"]}
    wc = files["in/walk.c3d"]["would_clean"]
    measured = files["in/walk.c3d"]["file"]
    # the sample C3D has gaps; the default pipeline fills them all in memory
    assert measured["gaps"] >= 4 and wc["samples_filled"] > 0 and wc["missing_after"] == 0
    assert 0 < wc["uncertain"] < measured["missing"] + 1e-9
    assert _tree(src) == before and not list(src.rglob("*.report.*"))


def test_frames_where_no_marker_is_seen_at_the_ends_are_not_graded():
    """btk's gait trial sees its markers on frames 133-326 of 487 (the force plates record
    on while the subject is out of view); the OptiTrack export has 229 empty last frames.
    Graded on the take, both pass the default rules (they failed on 60 % missing and on a
    2.3 s gap), and the measurement says which frames it left out."""
    from mocapfix import read
    from mocapfix.quality.measure import measure_input

    gait = need(DATA / "c3d" / "btk_Gait.c3d")
    opti = need(DATA / "c3d" / "btk_mocap36_optitrack.c3d")
    m = measure_input(read(gait), swaps=False, outliers=False)
    assert m["file"]["frames_outside_take"] == [[0, 133], [327, 160]]
    assert m["file"]["empty_frames"] == [[0, 133], [327, 160]]
    assert max(j["missing"] for j in m["joints"]) < 0.05
    assert measure_input(read(opti), swaps=False, outliers=False)["file"][
        "frames_outside_take"] == [[1151, 229]]
    r = CliRunner().invoke(main, ["check", str(gait), str(opti)])
    assert r.exit_code == 0, r.output
    assert [line.split()[0] for line in r.output.splitlines()[:2]] == ["OK", "OK"], r.output


def test_a_worker_that_dies_is_an_error_line_naming_its_file(tmp_path, monkeypatch):
    """``check -j 2``: a worker process killed while it checks a file (out of memory, a
    crash in a native library) gives that file an ERROR line naming it and exit 3; the
    record the pool returns for it names the file under another key, and the line
    builder stopped the run with an internal error."""
    import os
    import mocapfix.batch.check as check_module

    for name in ("a.c3d", "b.c3d"):
        shutil.copy(SAMPLE_DATA / "walk_markers.c3d", tmp_path / name)
    real = check_module.check_motion

    def dies_on_b(motion, *args, **kwargs):
        if motion.path.endswith("b.c3d"):
            os._exit(9)
        return real(motion, *args, **kwargs)

    monkeypatch.setattr(check_module, "check_motion", dies_on_b)
    res = CliRunner().invoke(main, ["check", str(tmp_path), "-j", "2", "--json"])
    assert res.exit_code == 3, res.output
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("ERROR")]
    assert lines and all(str(tmp_path) in ln and "worker failed" in ln for ln in lines)
    assert "internal error" not in res.output + res.stderr


def test_check_names_an_unreadable_file_once(tmp_path):
    # "ERROR /x/bad.bvh: /x/bad.bvh:1: expected 'HIERARCHY'...": the path came twice
    bad = tmp_path / "bad.bvh"
    bad.write_text("not a bvh\n")
    r = CliRunner().invoke(main, ["check", str(bad), str(BVH)])
    assert r.exit_code == 3
    line = next(x for x in r.output.splitlines() if x.startswith("ERROR"))
    assert line.count(str(bad)) == 1 and line.startswith(f"ERROR {bad}:1: "), line


def test_check_counts_held_frames_and_a_rule_can_fail_on_them(tmp_path):
    """A take with every frame written twice: ``check`` says how many frames repeat the
    one before (``held_frames``), and a rule on it fails that file and not the original."""
    from mocapfix import read
    base = read(shared("c3d/cmu_85_02.c3d"))
    doubled = base.replace(positions=base.positions.repeat(2, axis=0), source=None,
                           confidence=None)
    folder = tmp_path / "in"
    folder.mkdir()
    write(base.replace(source=None, confidence=None), folder / "once.c3d")
    write(doubled, folder / "twice.c3d")
    rules = tmp_path / "rules.yaml"
    rules.write_text("version: 1\nrules:\n  - metric: held_frames\n    fail: 0\n")
    result = CliRunner().invoke(main, ["check", str(folder), "-r", str(rules), "--json"])
    assert result.exit_code == 1, result.output
    files = {f["path"].split("/")[-1]: f for f in json.loads(result.stdout)["files"]}
    assert files["twice.c3d"]["file"]["held_frames"] == base.n_frames
    assert files["twice.c3d"]["status"] == "FAIL"
    assert files["once.c3d"]["file"]["held_frames"] == 0 and files["once.c3d"]["status"] == "OK"


def test_check_counts_a_takes_cuts_and_a_rule_can_fail_on_them(tmp_path):
    """CMU 85_02's halves joined with the second 50 cm away: ``check`` finds the one frame
    where the take jumps as a whole (``cuts``; ``info`` lists it), and a rule on it fails
    that file and not the capture."""
    from mocapfix import read
    base = read(shared("c3d/cmu_85_02.c3d")).replace(source=None, confidence=None)
    half = base.n_frames // 2
    P = np.concatenate([base.positions[:half], base.positions[half:2 * half] + [500.0, 0, 0]])
    folder = tmp_path / "in"
    folder.mkdir()
    write(base, folder / "once.c3d")
    write(base.replace(positions=P), folder / "joined.c3d")
    rules = tmp_path / "rules.yaml"
    rules.write_text("version: 1\nrules:\n  - metric: cuts\n    fail: 0\n")
    result = CliRunner().invoke(main, ["check", str(folder), "-r", str(rules), "--json"])
    assert result.exit_code == 1, result.output
    files = {f["path"].split("/")[-1]: f for f in json.loads(result.stdout)["files"]}
    assert files["joined.c3d"]["file"]["cuts"] == 1
    assert files["joined.c3d"]["file"]["cut_frames"] == [half]
    assert files["joined.c3d"]["status"] == "FAIL"
    assert files["once.c3d"]["file"]["cuts"] == 0 and files["once.c3d"]["status"] == "OK"
    info = CliRunner().invoke(main, ["info", str(folder / "joined.c3d")])
    assert f"the take jumps as a whole at frames {half}" in info.output
