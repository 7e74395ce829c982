"""Bad or odd input met the way a demanding user meets it, through the command line:
each case is one readable line naming the file and the cause, the documented exit code,
the rest of the batch processed, inputs unchanged, nothing left for a failed file and no
traceback (the developers' guide, "Bad input gets a clear error and loses nothing")."""
from __future__ import annotations

import hashlib
import os
import shutil
import stat
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from click.testing import CliRunner

from mocapfix.cli import main

from conftest import SAMPLE_DATA, no_traceback, shared

BVH, C3D, KIN = SAMPLE_DATA / "walk.bvh", SAMPLE_DATA / "walk_markers.c3d", SAMPLE_DATA / "walk_kinect_v2.csv"
FAST = "version: 1\npipeline:\n  - cleaner: fill\n    max_gap: 0.5 s\n"


def _cfg(tmp_path, text=FAST, name="cfg.yaml") -> str:
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def _md5s(folder: Path) -> dict:
    return {p: hashlib.md5(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_output_subfolder_blocked_by_a_file_fails_that_file_only(tmp_path):
    # in/a/x.bvh must go to out/a/x.bvh, but out/a is a file: that one file fails, the
    # rest of the batch is written and the run ends normally (config record, exit 1)
    src = tmp_path / "in"
    (src / "a").mkdir(parents=True)
    shutil.copy(BVH, src / "a" / "x.bvh")
    shutil.copy(BVH, src / "y.bvh")
    out = tmp_path / "out"
    out.mkdir()
    (out / "a").write_text("not a folder")
    before = _md5s(src)
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _cfg(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 1, r.output
    error = [line for line in r.output.splitlines() if line.startswith("ERROR")]
    assert len(error) == 1 and "x.bvh" in error[0] and "internal error" not in error[0]
    assert (out / "y.bvh").is_file() and (out / "mocapfix-config.yaml").is_file()
    assert (out / "a").read_text() == "not a folder"
    assert _md5s(src) == before


def test_unwritable_report_files_are_refused_before_any_work(tmp_path):
    # --junit, bench --json/--markdown and train-dictionary -o under a path that runs
    # through a file: exit 2 naming the option and the path, before any file is read
    # (it used to be a traceback after checking, benchmarking or training everything)
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    bad = str(blocker / "sub" / "out")
    runs = {
        "--junit": ["check", str(BVH), "--junit", bad + ".xml"],
        "--json": ["bench", str(C3D), "--protocol", "occlusion", "--seeds", "1",
                   "--methods", "fill", "-q", "--json", bad + ".json"],
        "--markdown": ["bench", str(KIN), "--protocol", "kinect", "--seeds", "1", "-q",
                       "--markdown", bad + ".md"],
        "-o": ["train-dictionary", str(BVH), "--method", "mssa", "-o", bad + ".npz"],
    }
    for option, args in runs.items():
        r = CliRunner().invoke(main, args)
        no_traceback(r)
        assert r.exit_code == 2, (option, r.output)
        lines = r.output.strip().splitlines()
        assert len(lines) == 1 and option in lines[0] and str(blocker) in lines[0], r.output
        assert "part of the path is a file" in lines[0]
    assert blocker.read_text() == "x"


def test_junit_into_a_new_folder_is_still_written(tmp_path):
    junit = tmp_path / "reports" / "ci" / "check.xml"
    r = CliRunner().invoke(main, ["check", str(BVH), "--junit", str(junit), "--exit-zero"])
    assert r.exit_code == 0, r.output
    assert junit.read_text().startswith("<?xml")


def test_absurd_fps_is_a_usage_error_for_every_command(tmp_path):
    # --fps nan/inf used to be taken (an AMC "cleaned" at nan Hz, exit 0), 0 silently
    # meant the default and -1 failed each file separately (exit 1): all are usage errors
    amc = SAMPLE_DATA / "walker_01.amc"
    for value in ("nan", "inf", "-inf", "0", "-1", "1e308"):
        for args in (["info", str(amc)], ["check", str(amc)],
                     ["clean", str(amc), "-o", str(tmp_path / "out"), "-c", _cfg(tmp_path)],
                     ["train-dictionary", str(amc), "--method", "mssa", "-o", str(tmp_path / "m.npz")]):
            r = CliRunner().invoke(main, [*args, "--fps", value])
            no_traceback(r)
            assert r.exit_code == 2, (args[0], value, r.output)
            assert "--fps" in r.output and "is not a frame rate" in r.output
    assert not (tmp_path / "out").exists() and not (tmp_path / "m.npz").exists()
    r = CliRunner().invoke(main, ["info", str(amc), "--fps", "60", "--json"])
    assert r.exit_code == 0 and '"fps": 60.0' in r.output


def test_reading_an_amc_at_a_non_finite_rate_is_refused():
    import pytest

    from mocapfix import formats
    from mocapfix.core.errors import UnreadableFileError

    for fps in (float("nan"), float("inf"), 0.0):
        with pytest.raises(UnreadableFileError, match="frame rate must be a positive number"):
            formats.read(SAMPLE_DATA / "walker_01.amc", fps=fps)


def test_a_file_name_that_is_not_utf8_is_cleaned_and_reported(tmp_path):
    # Linux names are bytes; b"take\xff.bvh" reaches Python as "take\udcff.bvh". The
    # Markdown/HTML reports and the JUnit XML could not be encoded: the file failed with
    # "internal error UnicodeEncodeError" and check --junit ended in a traceback
    import os
    import xml.etree.ElementTree as ET

    import pytest

    src = tmp_path / "in"
    src.mkdir()
    try:
        raw = os.path.join(os.fsencode(src), b"take\xff.bvh")
        with open(raw, "wb") as fh:
            fh.write(BVH.read_bytes())
    except (OSError, UnicodeError):
        pytest.skip("this file system refuses names that are not UTF-8")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _cfg(tmp_path),
                                  "--report", "json,md,html"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    names = sorted(os.listdir(os.fsencode(out)))
    for name in (b"take\xff.bvh", b"take\xff.bvh.report.json", b"take\xff.bvh.report.md",
                 b"take\xff.bvh.report.html"):
        assert name in names, names
    md = (out / os.fsdecode(b"take\xff.bvh.report.md")).read_bytes()
    md.decode("utf-8")                                   # the reports stay UTF-8 text
    junit = tmp_path / "check.xml"
    r = CliRunner().invoke(main, ["check", str(src), "--junit", str(junit), "--exit-zero"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    case = ET.parse(junit).getroot().find(".//testcase")
    assert case is not None and "take" in case.get("name")


def test_a_file_whose_content_is_another_format_is_written_back_in_that_format(tmp_path):
    # The reader goes by content, the writer went by the name: a BVH saved as .c3d came
    # out as a real C3D of joint positions (its rotation channels and hierarchy lost) and
    # a C3D saved as .bvh failed with "the motion has no BVH channels to write"
    from mocapfix import formats

    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(BVH, src / "bvh_inside.c3d")
    shutil.copy(C3D, src / "c3d_inside.bvh")
    before = _md5s(src)
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _cfg(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert (out / "bvh_inside.c3d").read_bytes().startswith(b"HIERARCHY")
    assert (out / "c3d_inside.bvh").read_bytes()[1:2] == b"\x50"        # the C3D key
    for name, fmt, original in (("bvh_inside.c3d", "bvh", BVH), ("c3d_inside.bvh", "c3d", C3D)):
        back, first = formats.read(out / name), formats.read(original)
        assert back.format == fmt and back.names == first.names
        assert back.positions.shape == first.positions.shape
    assert _md5s(src) == before


def test_a_key_given_twice_in_a_config_or_rules_file_is_refused(tmp_path):
    # YAML keeps the last of two equal keys without a word: "max_gap: 5 s" after
    # "max_gap: 0.5 s" ran with five seconds, a second "pipeline:" replaced the first
    twice = FAST + "    max_gap: 5 s\n"
    r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(tmp_path / "out"),
                                  "-c", _cfg(tmp_path, twice, "twice.yaml")])
    no_traceback(r)
    assert r.exit_code == 2, r.output
    assert "twice.yaml (line 5): key 'max_gap' appears twice" in r.output and "line 4" in r.output
    assert not (tmp_path / "out").exists()
    two_pipelines = "version: 1\npipeline: []\npipeline:\n  - cleaner: fill\n"
    r = CliRunner().invoke(main, ["check", str(BVH), "--would-clean",
                                  _cfg(tmp_path, two_pipelines, "two.yaml")])
    assert r.exit_code == 2 and "key 'pipeline' appears twice" in r.output, r.output
    rules = "version: 1\nrules:\n  - metric: missing\n    warn: 5 %\n    warn: 50 %\n"
    r = CliRunner().invoke(main, ["check", str(BVH), "-r", _cfg(tmp_path, rules, "rules.yaml")])
    assert r.exit_code == 2 and "rules.yaml (line 5): key 'warn' appears twice" in r.output, r.output


def test_merge_keys_and_equal_keys_in_different_mappings_still_load():
    from mocapfix.config import loads_config

    text = ("version: 1\npipeline:\n  - &f {cleaner: fill, max_gap: 0.5 s}\n"
            "  - <<: *f\n    max_gap: 0.2 s\n  - cleaner: butterworth\n    cutoff: 6 Hz\n")
    pipeline = loads_config(text)
    steps = pipeline.config()["pipeline"]
    assert [s["cleaner"] for s in steps] == ["fill", "fill", "butterworth"]
    assert [s.get("max_gap") for s in steps[:2]] == ["0.5 s", "0.2 s"]


def test_info_on_a_folder_without_motion_files_says_so(tmp_path):
    # clean and check say "no motion files found" (exit 2); info printed nothing, exit 0
    (tmp_path / "notes.txt").write_text("session notes, not motion\n")
    (tmp_path / "sub").mkdir()
    for args in (["info", str(tmp_path)], ["info", str(tmp_path), "--json"],
                 ["check", str(tmp_path)], ["info", str(SAMPLE_DATA), "--include", "*.nothing"]):
        r = CliRunner().invoke(main, args)
        no_traceback(r)
        assert r.exit_code == 2 and "no motion files found in" in r.output, (args, r.output)


def test_a_long_but_legal_file_name_is_cleaned_and_its_stale_temporary_removed(tmp_path):
    # a 244-byte name (the limit is 255) failed with "File name too long": not for the
    # output, whose name is the same, but for its temporary ".NAME.XXXXXXXX.part"
    stem = "take_" + "x" * 235
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(BVH, src / f"{stem}.bvh")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _cfg(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert (out / f"{stem}.bvh").read_bytes().startswith(b"HIERARCHY")
    # its report keeps the stem only: "<name>.bvh.report.json" would pass the 255 bytes
    assert (out / f"{stem}.report.json").is_file()
    # the temporary a killed run leaves for that name is found and removed by the next run
    from mocapfix.core.fileio import NAME_MAX

    leftover = out / f".{(stem + '.bvh')[:NAME_MAX - 15]}.k3j_9x2a.part"
    leftover.write_bytes(b"half")
    other = out / ".someone_else.k3j_9x2a.part"
    other.write_bytes(b"not ours")
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _cfg(tmp_path), "--overwrite"])
    assert r.exit_code == 0, r.output
    assert not leftover.exists() and other.read_bytes() == b"not ours"


def test_a_damaged_manifest_or_config_record_in_the_output_folder(tmp_path):
    # the journal is a text file anyone can edit; a record whose "files" is not a list of
    # names crashed every re-run with a TypeError traceback, a folder in place of the
    # manifest or of the config record with IsADirectoryError (the latter after cleaning)
    import json

    out = tmp_path / "out"
    cfg = _cfg(tmp_path)
    assert CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg]).exit_code == 0
    manifest = out / "mocapfix-manifest.jsonl"
    record = json.loads(manifest.read_text().splitlines()[0])
    for damaged in (5, [None], {"a": 1}, "walk.bvh"):
        manifest.write_text(json.dumps({**record, "files": damaged}) + "\n")
        for policy in ([], ["--skip-existing"]):
            r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg, *policy])
            no_traceback(r)
            if policy:             # the existing output is kept, as the option says
                assert r.exit_code == 0 and "output exists" in r.output, r.output
            else:                  # no trustworthy record: an existing output, refused
                assert r.exit_code == 2 and "exist already" in r.output, r.output
    for name in ("mocapfix-manifest.jsonl", "mocapfix-config.yaml"):
        bad = tmp_path / f"bad_{name}"
        (bad / name).mkdir(parents=True)
        r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(bad), "-c", cfg])
        no_traceback(r)
        assert r.exit_code == 2 and name in r.output, r.output
        assert not (bad / "walk.bvh").exists()


def _two_subjects(tmp_path) -> tuple[Path, Path]:
    """subjects/a/x_01.amc and subjects/b/y_01.amc, each beside its own walker.asf; b's
    bones are longer."""
    import re

    asf = (SAMPLE_DATA / "walker.asf").read_text()
    longer = re.sub(r"(length\s+)([0-9.]+)", lambda m: f"{m.group(1)}{1.3 * float(m.group(2)):.4f}", asf)
    assert longer != asf
    paths = []
    for sub, text, amc in (("a", asf, "x_01.amc"), ("b", longer, "y_01.amc")):
        folder = tmp_path / "subjects" / sub
        folder.mkdir(parents=True)
        (folder / "walker.asf").write_text(text)
        shutil.copy(SAMPLE_DATA / "walker_01.amc", folder / amc)
        paths.append(folder / amc)
    return paths[0], paths[1]


def test_two_amcs_never_share_an_output_skeleton_they_do_not_have_in_common(tmp_path):
    # an AMC is written beside a copy of its ASF; x (a/walker.asf) and y (b/walker.asf,
    # other bones) named one by one both wrote out/walker.asf: the last one won and
    # out/x_01.amc silently came with y's skeleton
    from mocapfix import formats

    x, y = _two_subjects(tmp_path)
    before = _md5s(tmp_path)
    cfg = _cfg(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(x), str(y), "-o", str(out), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2 and "walker.asf" in r.output and "differ" in r.output, r.output
    assert not out.exists()
    # one at a time into one folder: the second is refused before it runs (exit 2, as
    # --dry-run says), the first keeps its skeleton
    assert CliRunner().invoke(main, ["clean", str(x), "-o", str(out), "-c", cfg]).exit_code == 0
    for extra in (["--dry-run"], []):
        r = CliRunner().invoke(main, ["clean", str(y), "-o", str(out), "-c", cfg, *extra])
        no_traceback(r)
        assert r.exit_code == 2 and "holds another ASF" in r.output and "x_01.amc" in r.output, r.output
    assert (out / "walker.asf").read_bytes() == (x.parent / "walker.asf").read_bytes()
    assert not list(out.glob("y_01*"))
    np_x = formats.read(out / "x_01.amc").positions
    assert abs(np_x - formats.read(x).positions).max() < 1e-6
    # the folder above theirs named instead: mirrored, each with its own skeleton
    r = CliRunner().invoke(main, ["clean", str(x.parent.parent), "-o", str(tmp_path / "o2"), "-c", cfg])
    assert r.exit_code == 0, r.output
    for amc in (x, y):
        got = tmp_path / "o2" / amc.parent.name
        assert (got / "walker.asf").read_bytes() == (amc.parent / "walker.asf").read_bytes()
    assert _md5s(x.parent) == {k: v for k, v in before.items() if k.parent == x.parent}
    assert _md5s(y.parent) == {k: v for k, v in before.items() if k.parent == y.parent}


def test_an_edited_asf_is_written_over_its_old_copy_that_only_this_amc_uses(tmp_path):
    # x_01 cleaned, then its ASF edited (longer bones) and x_01 cleaned again with
    # --overwrite: the run stopped on "out/walker.asf holds another ASF, which other AMC
    # files there use", though the only AMC there was x_01's own earlier output
    import re

    from mocapfix import formats

    x, _ = _two_subjects(tmp_path)
    cfg = _cfg(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
    out = tmp_path / "out"
    assert CliRunner().invoke(main, ["clean", str(x), "-o", str(out), "-c", cfg]).exit_code == 0
    asf = x.parent / "walker.asf"
    asf.write_text(re.sub(r"(length\s+)([0-9.]+)",
                          lambda m: f"{m.group(1)}{1.2 * float(m.group(2)):.4f}", asf.read_text()))
    r = CliRunner().invoke(main, ["clean", str(x), "-o", str(out), "-c", cfg, "--overwrite"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert (out / "walker.asf").read_bytes() == asf.read_bytes()
    assert abs(formats.read(out / x.name).positions - formats.read(x).positions).max() < 1e-6
    # another AMC there read with the old copy: still refused, and named
    shutil.copy(x, x.parent / "x_02.amc")
    assert CliRunner().invoke(main, ["clean", str(x.parent / "x_02.amc"), "-o", str(out),
                                     "-c", cfg]).exit_code == 0
    asf.write_text(re.sub(r"(length\s+)([0-9.]+)",
                          lambda m: f"{m.group(1)}{1.1 * float(m.group(2)):.4f}", asf.read_text()))
    kept = _md5s(out)
    r = CliRunner().invoke(main, ["clean", str(x), "-o", str(out), "-c", cfg, "--overwrite"])
    no_traceback(r)
    assert r.exit_code == 2 and "holds another ASF" in r.output and "x_02.amc" in r.output, r.output
    assert _md5s(out) == kept        # refused before any work: x_01's earlier output stays
    # both cleaned again in one run (with two workers): each one's earlier output is the
    # other's only obstacle, and both are being replaced
    r = CliRunner().invoke(main, ["clean", str(x), str(x.parent / "x_02.amc"), "-o", str(out),
                                  "-c", cfg, "--overwrite", "-j", "2"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert (out / "walker.asf").read_bytes() == asf.read_bytes()
    for amc in (x, x.parent / "x_02.amc"):
        assert abs(formats.read(out / amc.name).positions - formats.read(amc).positions).max() < 1e-6
    # edited once more; x_01's output removed, x_02's kept by --skip-existing: x_02's
    # output is not written again, so its skeleton copy stays and x_01 is refused
    asf.write_text(re.sub(r"(length\s+)([0-9.]+)",
                          lambda m: f"{m.group(1)}{1.1 * float(m.group(2)):.4f}", asf.read_text()))
    (out / x.name).unlink()
    kept = _md5s(out)
    r = CliRunner().invoke(main, ["clean", str(x), str(x.parent / "x_02.amc"), "-o", str(out),
                                  "-c", cfg, "--skip-existing"])
    no_traceback(r)
    assert r.exit_code == 2 and "holds another ASF" in r.output and "x_02.amc" in r.output, r.output
    assert _md5s(out) == kept


def test_skip_existing_redoes_an_output_whose_replacement_was_interrupted(tmp_path):
    # x_01 and x_02 cleaned; their ASF edited; a --overwrite run of both killed after x_01
    # (its output and the new ASF copy written, x_02's old output still there, recorded as
    # started); then --skip-existing kept x_02's old output beside the new skeleton copy
    import json
    import re

    from mocapfix import formats

    x, _ = _two_subjects(tmp_path)
    x2 = x.parent / "x_02.amc"
    shutil.copy(x, x2)
    cfg = _cfg(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
    out = tmp_path / "out"
    assert CliRunner().invoke(main, ["clean", str(x), str(x2), "-o", str(out), "-c", cfg]).exit_code == 0
    old_x2 = (out / x2.name).read_bytes()
    asf = x.parent / "walker.asf"
    asf.write_text(re.sub(r"(length\s+)([0-9.]+)",
                          lambda m: f"{m.group(1)}{1.2 * float(m.group(2)):.4f}", asf.read_text()))
    assert CliRunner().invoke(main, ["clean", str(x), str(x2), "-o", str(out), "-c", cfg,
                                     "--overwrite"]).exit_code == 0
    # what the killed run leaves: x_02's earlier output, and its last record "started"
    (out / x2.name).write_bytes(old_x2)
    manifest = out / "mocapfix-manifest.jsonl"
    done = [json.loads(line) for line in manifest.read_text().splitlines()
            if json.loads(line).get("output") == x2.name][-1]
    started = {k: v for k, v in done.items() if k not in ("quality", "files", "input_sha256",
                                                          "companions_sha256")}
    started["status"] = "started"
    with manifest.open("a") as f:
        f.write(json.dumps(started) + "\n")
    r = CliRunner().invoke(main, ["clean", str(x), str(x2), "-o", str(out), "-c", cfg,
                                  "--skip-existing"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert not any("SKIP" in line and "x_02" in line for line in r.output.splitlines()), r.output
    assert (out / "walker.asf").read_bytes() == asf.read_bytes()
    assert abs(formats.read(out / x2.name).positions - formats.read(x2).positions).max() < 1e-6


def test_an_asf_named_in_other_letter_case_is_not_read_with_the_wrong_amc(tmp_path):
    # a/walker.asf beside x_01.amc and b/WALKER.ASF (longer bones) beside y_01.amc: named
    # one by one they wrote out/walker.asf and out/WALKER.ASF, and out/y_01.amc was read
    # back with walker.asf, the wrong skeleton, without a word
    from mocapfix import formats

    x, y = _two_subjects(tmp_path)
    (y.parent / "walker.asf").rename(y.parent / "WALKER.ASF")
    cfg = _cfg(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(x), str(y), "-o", str(out), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2 and "differ" in r.output, r.output
    assert CliRunner().invoke(main, ["clean", str(x), "-o", str(out), "-c", cfg]).exit_code == 0
    kept = _md5s(out)
    r = CliRunner().invoke(main, ["clean", str(y), "-o", str(out), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2 and "could not be read back" in r.output, r.output
    assert _md5s(out) == kept
    assert abs(formats.read(out / x.name).positions - formats.read(x).positions).max() < 1e-6
    # another name altogether, in one run: each AMC found the only .asf of its folder, and
    # with both copies side by side neither output could be read back
    (y.parent / "WALKER.ASF").rename(y.parent / "runner.asf")
    r = CliRunner().invoke(main, ["clean", str(x), str(y), "-o", str(tmp_path / "o3"), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2 and "could not be read back" in r.output, r.output
    assert not (tmp_path / "o3").exists()


def test_an_amc_output_left_without_its_skeleton_copy_is_written_again(tmp_path):
    # a run killed after writing out/05_01.amc but before its copy out/05.asf: 05_01.amc
    # then read the only .asf there, 13.asf, and every later run (resume, --overwrite,
    # --skip-existing) refused with "would leave 05_01.amc (read with 13.asf) without its
    # skeleton", though 05_01.amc was one of the files it would write again
    from mocapfix import formats

    src = tmp_path / "in"
    src.mkdir()
    for name in ("05.asf", "05_01.amc", "13.asf", "13_39.amc"):
        shutil.copy(shared(f"asfamc/{name}"), src / name)
    cfg = _cfg(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
    out = tmp_path / "out"
    assert CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", cfg]).exit_code == 0
    (out / "05.asf").unlink()
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", cfg, "--overwrite"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    for amc in ("05_01.amc", "13_39.amc"):
        got, want = formats.read(out / amc), formats.read(src / amc)
        assert got.n_joints == want.n_joints and abs(got.positions - want.positions).max() < 1e-6


def test_one_asf_in_two_letter_cases_with_the_same_content_is_not_refused(tmp_path):
    # a/05.ASF and b/05.asf hold the same skeleton: the plan let them share one copy, and
    # then refused 05_10 because out/05.ASF, a copy not written yet, could not be read
    from mocapfix import formats

    for sub, asf, amc in (("a", "05.ASF", "05_01.amc"), ("b", "05.asf", "05_10.amc")):
        (tmp_path / sub).mkdir()
        shutil.copy(shared("asfamc/05.asf"), tmp_path / sub / asf)
        shutil.copy(shared(f"asfamc/{amc}"), tmp_path / sub / amc)
    cfg = _cfg(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(tmp_path / "a" / "05_01.amc"),
                                  str(tmp_path / "b" / "05_10.amc"), "-o", str(out), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    for amc in ("05_01.amc", "05_10.amc"):
        assert formats.read(out / amc).n_joints == formats.read(shared(f"asfamc/{amc}")).n_joints


def test_an_asf_named_as_an_input_is_planned_like_the_copies_beside_amcs(tmp_path):
    # x2/05/05_01.amc (with CMU's 05.asf) and x1/05/05.asf, another skeleton, named
    # together: out/05.asf ended as x1's skeleton and out/05_01.amc was read with it
    for sub, asf in (("x1", "143.asf"), ("x2", "05.asf")):
        (tmp_path / sub / "05").mkdir(parents=True)
        shutil.copy(shared(f"asfamc/{asf}"), tmp_path / sub / "05" / "05.asf")
    shutil.copy(shared("asfamc/05_01.amc"), tmp_path / "x2" / "05" / "05_01.amc")
    cfg = _cfg(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
    r = CliRunner().invoke(main, ["clean", str(tmp_path / "x2" / "05" / "05_01.amc"),
                                  str(tmp_path / "x1" / "05" / "05.asf"), "-o", str(tmp_path / "out"),
                                  "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2 and "differ" in r.output, r.output
    assert not (tmp_path / "out").exists()
    # one run after another: x2's 05_01 cleaned, then an ASF named 05_01.asf, which
    # find_asf reads with out/05_01.amc before 05.asf (by the AMC's own name)
    out = tmp_path / "out"
    assert CliRunner().invoke(main, ["clean", str(tmp_path / "x2" / "05" / "05_01.amc"),
                                     "-o", str(out), "-c", cfg]).exit_code == 0
    other = tmp_path / "x1" / "05" / "05_01.asf"
    (tmp_path / "x1" / "05" / "05.asf").rename(other)
    kept = _md5s(out)
    for extra in (["--dry-run"], []):
        r = CliRunner().invoke(main, ["clean", str(other), "-o", str(out), "-c", cfg, *extra])
        no_traceback(r)
        assert r.exit_code == 2 and "05_01.amc (read with 05.asf)" in r.output, r.output
    assert _md5s(out) == kept
    # the writer alone (the Python API) refuses it too
    from mocapfix import formats
    from mocapfix.core.errors import WriteError

    with pytest.raises(WriteError, match="read with 05.asf"):
        formats.write(formats.read(other), out / "05_01.asf")
    assert _md5s(out) == kept


def test_an_unforeseen_failure_is_one_line_and_the_other_files_go_on(tmp_path, monkeypatch):
    # info caught only mocapfix's own errors: anything else in one file (a bug, an OS
    # error) ended the run with a traceback and the files after it were never shown; any
    # command's unforeseen failure was a traceback. Simulated here, since every known
    # cause is fixed: the guard itself is what is tested
    import mocapfix.quality.info
    import mocapfix.batch.manifest

    real = mocapfix.quality.info.summarise

    def flaky(motion):
        if str(motion.path).endswith(".bvh"):
            raise ValueError("simulated")
        return real(motion)

    monkeypatch.setattr(mocapfix.quality.info, "summarise", flaky)
    r = CliRunner().invoke(main, ["info", str(BVH), str(KIN), "--json"])
    no_traceback(r)
    assert r.exit_code == 3, r.output
    assert "walk.bvh: internal error ValueError: simulated" in r.output
    assert '"frames"' in r.output                        # the Kinect file still summarised

    def broken_close(self, compact=True):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(mocapfix.batch.manifest.Manifest, "close", broken_close)
    args = ["clean", str(KIN), "-o", str(tmp_path / "out"), "-c", _cfg(tmp_path)]
    r = CliRunner().invoke(main, args)
    no_traceback(r)
    assert r.exit_code == 1
    assert r.output.strip().splitlines()[-1] == ("mocapfix: error: internal error OSError: [Errno 28] "
                                                 "No space left on device (--debug shows the traceback)")
    r = CliRunner().invoke(main, ["--debug", *args, "--overwrite"])
    assert isinstance(r.exception, OSError)              # --debug: the real exception


def test_one_absurd_kinect_coordinate_does_not_move_its_joint(tmp_path):
    # one corrupt field (1e9-1e300 m: a flipped exponent bit) steered the first GCV
    # smooth of kinect_skeleton: the whole joint came out 0.3 m (1e9) to 2.6 m (1e12) off
    # in every frame, with no warning. Corrupt a clean take, clean it, bound the error
    # against the clean of the uncorrupted take
    import numpy as np

    from mocapfix import formats
    from mocapfix.config import loads_config

    pipeline = loads_config("version: 1\npipeline:\n  - cleaner: kinect_skeleton\n")
    motion = formats.read(KIN)
    reference, _ = pipeline.run(motion)
    j = motion.names.index("SpineBase")
    for axis, value in ((0, 1e9), (0, 1e12), (0, -1e15), (0, 1e300), (2, -1e20)):
        positions = motion.positions.copy()
        positions[20, j, axis] = value
        cleaned, records = pipeline.run(motion.replace(positions=positions))
        error = np.linalg.norm(cleaned.positions - reference.positions, axis=-1)
        assert np.nanmax(error) < 0.02, (value, float(np.nanmax(error)))
        assert 20 in records[0].info["replaced_frames"]["SpineBase"]
        # known answer: the same as that sample missing (a -1e20 m depth turned the depth
        # model off for the whole file)
        positions[20, j] = np.nan
        as_missing, _ = pipeline.run(motion.replace(positions=positions))
        np.testing.assert_array_equal(cleaned.positions, as_missing.positions)


def test_control_characters_in_file_names_reach_neither_the_terminal_nor_the_junit(tmp_path):
    # a file named "bad\x1b[31m.bvh" recoloured the terminal (any escape sequence went
    # out raw, a "\r" could hide the start of a line) and made the JUnit XML unparsable
    # ("not well-formed (invalid token)"), failing the whole CI report
    import re
    import xml.etree.ElementTree as ET

    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(BVH, src / "a\x01b.bvh")
    (src / "bad\x1b[31mred\r.bvh").write_bytes(b"\x00\x06junk, not a BVH\n")
    junit = tmp_path / "check.xml"
    r = CliRunner().invoke(main, ["check", str(src), "--junit", str(junit)])
    no_traceback(r)
    assert r.exit_code == 3, r.output
    assert not re.search("[\x00-\x08\x0b-\x1f\x7f]", r.output), repr(r.output)
    assert "a\\x01b.bvh" in r.output and "bad\\x1b[31mred\\x0d.bvh" in r.output
    names = [case.get("name") for case in ET.parse(junit).getroot().iter("testcase")]
    assert names == ["in/a\\x01b.bvh", "in/bad\\x1b[31mred\r.bvh"]       # CR is valid XML
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(tmp_path / "out"), "-c", _cfg(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 1 and not re.search("[\x00-\x08\x0b-\x1f\x7f]", r.output), repr(r.output)
    assert (tmp_path / "out" / "a\x01b.bvh").is_file()           # the file itself keeps its name


def test_a_folder_that_cannot_be_listed_is_named_not_passed_over(tmp_path, monkeypatch):
    # os.walk skips a folder it cannot list without a word: the takes in it were silently
    # left out of clean/check/info ("cleaned 2 of 2 files")
    import errno
    import os

    src = tmp_path / "in"
    (src / "locked").mkdir(parents=True)
    shutil.copy(BVH, src / "ok.bvh")
    shutil.copy(BVH, src / "locked" / "take.bvh")
    locked = src / "locked"
    locked.chmod(0)
    if os.geteuid() == 0:                  # root lists anything: refuse as the OS would
        real = os.scandir

        def scandir(path="."):
            if os.fspath(path) == str(locked):
                raise PermissionError(errno.EACCES, "Permission denied", str(locked))
            return real(path)

        monkeypatch.setattr(os, "scandir", scandir)
    try:
        for args in (["clean", str(src), "-o", str(tmp_path / "out"), "-c", _cfg(tmp_path)],
                     ["check", str(src)], ["info", str(src)]):
            r = CliRunner().invoke(main, args)
            no_traceback(r)
            skip = [line for line in r.output.splitlines() if line.startswith("SKIP")]
            assert skip == [f"SKIP  {locked}: cannot read this folder: Permission denied "
                            "(the files in it were not processed)"], (args[0], r.output)
    finally:
        locked.chmod(0o755)


def _six_channel_bvh(glitch: float | None) -> str:
    """A 3-joint BVH whose every joint has 6 channels (as Bandai-Namco's files do),
    120 frames of smooth motion; ``glitch`` goes into Chest.Xposition at frame 60."""
    import numpy as np

    hier = ("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition "
            "Zrotation Xrotation Yrotation\n JOINT Chest\n {\n  OFFSET 0 20 0\n  CHANNELS 6 "
            "Xposition Yposition Zposition Zrotation Xrotation Yrotation\n  JOINT Head\n  {\n"
            "   OFFSET 0 20 0\n   CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
            "Yrotation\n   End Site\n   {\n    OFFSET 0 10 0\n   }\n  }\n }\n}\n"
            "MOTION\nFrames: 120\nFrame Time: 0.0083333\n")
    rows = []
    for f in range(120):
        t = f / 120
        vals = [10 * np.sin(3 * t), 90, 5 * t, 5 * np.sin(5 * t), 3 * np.cos(4 * t), 2 * t,
                0, 20, 0, 4 * np.sin(6 * t), 2 * np.cos(5 * t), 1,
                0, 20, 0, 3 * np.sin(7 * t), np.cos(3 * t), 0]
        if f == 60 and glitch is not None:
            vals[6] = glitch
        rows.append(" ".join(f"{v:.6g}" for v in vals))
    return hier + "\n".join(rows) + "\n"


def test_a_joint_moved_beyond_the_float_range_is_reported_not_an_internal_error(tmp_path):
    # 1e300 in a non-root joint's position channel: the report's largest correction
    # overflowed to inf (written as null) and the comparison "max > 0" raised TypeError,
    # so the file failed with "internal error TypeError" and no output. The rotations are
    # smoothed by a fixed filter (the default leaves this noiseless take as it is), so the
    # joints below the glitch move by 1e300 × a rounding error
    import json

    src = tmp_path / "in"
    src.mkdir()
    (src / "glitch.bvh").write_text(_six_channel_bvh(1e300))
    (src / "clean.bvh").write_text(_six_channel_bvh(None))
    config = tmp_path / "smooth.yaml"
    config.write_text("pipeline:\n  - cleaner: rotation_smooth\n    translations: false\n")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "--report", "json,md,html",
                                  "-c", str(config)])
    no_traceback(r)
    assert r.exit_code == 0 and "internal error" not in r.output, r.output
    report = json.loads((out / "glitch.bvh.report.json").read_text())
    assert any(j["correction_mm"]["max"] is None for j in report["joints"])
    assert (out / "glitch.bvh").read_text().startswith("HIERARCHY")


def test_debug_shows_the_traceback_of_a_file_that_failed_unexpectedly(tmp_path, monkeypatch):
    # README: --debug gives "tracebacks instead of one-line errors"; a file that failed in
    # clean's or check's batch showed only "internal error TYPE: ..." even with --debug,
    # so the bug behind it could not be reported. Simulated failure (every known cause is
    # fixed); without --debug the output stays one line
    import mocapfix.batch.check
    import mocapfix.clean

    def broken(*args, **kwargs):
        raise ValueError("simulated")

    monkeypatch.setattr(mocapfix.clean, "build_report", broken)
    monkeypatch.setattr(mocapfix.batch.check, "check_motion", broken)
    runs = {"clean": ["clean", str(KIN), "-o", str(tmp_path / "out"), "-c", _cfg(tmp_path), "--overwrite"],
            "check": ["check", str(KIN)]}
    for name, args in runs.items():
        r = CliRunner().invoke(main, args)
        assert r.exit_code in (1, 3) and "internal error ValueError: simulated" in r.output
        assert "Traceback" not in r.output, name
        r = CliRunner().invoke(main, [*args, "--debug"])
        assert "Traceback (most recent call last)" in r.output and "in broken" in r.output, name


def test_check_names_an_unreadable_file_once(tmp_path):
    # "ERROR /x/bad.bvh: /x/bad.bvh:1: expected 'HIERARCHY'...": the path came twice
    bad = tmp_path / "bad.bvh"
    bad.write_text("not a bvh\n")
    r = CliRunner().invoke(main, ["check", str(bad), str(BVH)])
    assert r.exit_code == 3
    line = next(x for x in r.output.splitlines() if x.startswith("ERROR"))
    assert line.count(str(bad)) == 1 and line.startswith(f"ERROR {bad}:1: "), line


def test_a_selection_that_matches_nothing_says_why_it_warns(tmp_path):
    # markers: ["NoSuch*"] leaves nothing to clean: the file WARNs (report note), but the
    # line gave no reason, even with -v
    cfg = _cfg(tmp_path, "version: 1\nmarkers: [\"NoSuch*\"]\npipeline:\n  - cleaner: fill\n")
    r = CliRunner().invoke(main, ["clean", str(C3D), "-o", str(tmp_path / "out"), "-c", cfg, "-v"])
    assert r.exit_code == 0, r.output
    lines = r.output.splitlines()
    assert lines[0].startswith("WARN")
    assert "leave none of this file's markers to clean" in lines[1], r.output


def test_overwrite_and_skip_existing_together_are_a_usage_error(tmp_path):
    # the two shared one option: given both, the last one silently decided whether the
    # existing outputs were replaced or kept
    out = tmp_path / "out"
    cfg = _cfg(tmp_path)
    assert CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg]).exit_code == 0
    before = _md5s(out)
    for flags in (["--overwrite", "--skip-existing"], ["--skip-existing", "--overwrite"]):
        r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg, *flags])
        assert r.exit_code == 2 and "exclude each other" in r.output, r.output
    assert _md5s(out) == before
    r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg, "--overwrite"])
    assert r.exit_code == 0 and "cleaned 1 of 1" in r.output


def test_a_model_whose_array_header_lies_is_a_config_error(tmp_path):
    # a model member whose .npy header declares 10^11 floats (a few bytes in the file):
    # np.load first allocates what is declared -> MemoryError (745 GiB), a traceback;
    # now a config error naming the model and the array, before any file is read
    import io
    import zipfile

    import numpy as np

    from mocapfix.core import models

    shipped = models.shipped()["mssa-cmu"]
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(shipped) as zin, zipfile.ZipFile(bomb, "w") as zout:
        for name in zin.namelist():
            data = zin.read(name)
            if name == "bases.npy":
                buf = io.BytesIO()
                np.lib.format.write_array_header_1_0(
                    buf, {"descr": "<f8", "fortran_order": False, "shape": (10 ** 11,)})
                data = buf.getvalue() + bytes(64)
            zout.writestr(name, data)
    cfg = _cfg(tmp_path, "version: 1\npipeline:\n  - cleaner: mssa\n    model: bomb.npz\n")
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA / "walker_01.amc"), "-o",
                                  str(tmp_path / "out"), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2, r.output
    assert "bomb.npz: corrupt model file" in r.output and "'bases' declares" in r.output
    assert not (tmp_path / "out").exists()
    models.load(shipped, "mssa")                        # a sound model still loads


def test_a_model_header_nested_too_deep_is_a_config_error(tmp_path):
    # the JSON header "[[[[...]]]]" 100,000 deep: RecursionError, an internal error
    import numpy as np

    deep = ("[" * 100_000 + "]" * 100_000).encode()
    np.savez(tmp_path / "deep.npz", __header__=np.frombuffer(deep, dtype=np.uint8))
    cfg = _cfg(tmp_path, "version: 1\npipeline:\n  - cleaner: mssa\n    model: deep.npz\n")
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA / "walker_01.amc"), "-o",
                                  str(tmp_path / "out"), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2 and "deep.npz: not a mocapfix model file (RecursionError" in r.output, r.output


def test_a_folder_where_a_report_goes_fails_that_file_only_and_keeps_shared_skeletons(tmp_path):
    # out/walker_02.amc.report.json is a folder: the report cannot be written. The cleanup
    # then tried to unlink that folder (IsADirectoryError): the file became "internal
    # error", the same error in the batch's own cleanup stopped the run (later files never
    # cleaned), and the cleanup also deleted walker.asf, which walker_01.amc, cleaned
    # fine just before, needs: that good output could no longer be read
    from mocapfix import formats

    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(SAMPLE_DATA / "walker.asf", src / "walker.asf")
    for n in ("01", "02"):
        shutil.copy(SAMPLE_DATA / "walker_01.amc", src / f"walker_{n}.amc")
    shutil.copy(KIN, src / "zz_last.csv")
    out = tmp_path / "out"
    (out / "walker_02.amc.report.json").mkdir(parents=True)
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _cfg(tmp_path), "--overwrite"])
    no_traceback(r)
    assert r.exit_code == 1, r.output
    error = [line for line in r.output.splitlines() if line.startswith("ERROR")]
    assert len(error) == 1 and "walker_02.amc.report.json: cannot write: Is a directory" in error[0], r.output
    assert (out / "zz_last.csv").is_file()                 # the batch went on
    assert not (out / "walker_02.amc").exists()            # nothing left for the failed file
    assert (out / "walker_02.amc.report.json").is_dir()        # the folder is not ours to remove
    assert formats.read(out / "walker_01.amc").n_frames > 0  # its skeleton is still there


def test_a_malformed_scheduler_address_is_refused_before_anything_is_written(tmp_path):
    # "--scheduler foo" raised ValueError (a traceback) when the batch started, after the
    # output folder and its manifest had been made; dask is in the dev extra
    out = tmp_path / "out"
    for address in ("foo", "tcp://host-without-port", "tcp://127.0.0.1:x"):
        for args in (["clean", str(BVH), "-o", str(out), "-c", _cfg(tmp_path)], ["check", str(BVH)]):
            r = CliRunner().invoke(main, [*args, "--scheduler", address])
            no_traceback(r)
            assert r.exit_code == 2, r.output
            assert f"--scheduler {address!r} is not a Dask scheduler address" in r.output
    assert not out.exists()


def test_an_unreachable_scheduler_leaves_the_output_folder_as_it_was(tmp_path, monkeypatch):
    # a well-formed address nobody answers: the run used to leave the folders it made and
    # a manifest of "started" records behind (or append them to an existing manifest)
    import distributed                                     # the dev extra has it

    def refuse(*args, **kwargs):
        raise OSError("Timed out trying to connect to tcp://10.0.0.1:8786 after 10 s")
    monkeypatch.setattr(distributed, "Client", refuse)
    fresh = tmp_path / "new" / "out"
    r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(fresh), "-c", _cfg(tmp_path),
                                  "--scheduler", "tcp://10.0.0.1:8786"])
    no_traceback(r)
    assert r.exit_code == 2 and "cannot reach the Dask scheduler" in r.output, r.output
    assert not (tmp_path / "new").exists()
    used = tmp_path / "used"
    r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(used), "-c", _cfg(tmp_path)])
    assert r.exit_code == 0, r.output
    before = _md5s(used)
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA), "-o", str(used), "-c", _cfg(tmp_path),
                                  "--overwrite", "--scheduler", "tcp://10.0.0.1:8786"])
    assert r.exit_code == 2, r.output
    assert _md5s(used) == before                           # the manifest as it was


def test_report_files_never_overwrite_the_captures_they_are_about(tmp_path):
    # "check take.c3d --junit take.c3d" replaced the capture with JUnit XML (exit 0); the
    # same for a capture in an input folder, the ASF beside a named AMC, bench --json on
    # its input and train-dictionary -o on a training file
    src = tmp_path / "in"
    src.mkdir()
    for f in (BVH, C3D, SAMPLE_DATA / "walker.asf", SAMPLE_DATA / "walker_01.amc"):
        shutil.copy(f, src / f.name)
    (src / "notes.txt").write_text("session notes\n")
    before = _md5s(src)
    cases = [
        (["check", str(src / "walk.bvh"), "--junit", str(src / "walk.bvh")], "the input"),
        (["check", str(src), "--junit", str(src / "walk_markers.c3d")], "a capture in the input folder"),
        (["check", str(src / "walker_01.amc"), "--junit", str(src / "walker.asf")], "a capture beside the input"),
        (["bench", str(src / "walk_markers.c3d"), "--protocol", "occlusion", "--seeds", "1",
          "--methods", "fill", "-q", "--json", str(src / "walk_markers.c3d")], "the input"),
        (["train-dictionary", str(src / "walk.bvh"), "--method", "mssa", "-o", str(src / "walk.bvh")], "the input"),
    ]
    for args, what in cases:
        r = CliRunner().invoke(main, args)
        no_traceback(r)
        assert r.exit_code == 2 and f"would overwrite {what}" in r.output, (args[0], r.output)
    assert _md5s(src) == before
    # a report file that is not a capture may go beside them, also replacing a text file
    # that is not motion data
    r = CliRunner().invoke(main, ["check", str(src), "--junit", str(src / "notes.txt"), "--exit-zero"])
    assert r.exit_code == 0, r.output
    assert (src / "notes.txt").read_text().startswith("<?xml")


def test_an_empty_path_is_a_usage_error_not_the_current_folder(tmp_path, monkeypatch):
    # -o "" (an unset $OUT) wrote the outputs into the current folder; an input "" made
    # the whole current tree the input; --junit "" silently wrote no report
    work = tmp_path / "cwd"
    work.mkdir()
    shutil.copy(BVH, work / "take.bvh")
    monkeypatch.chdir(work)
    before = sorted(p.name for p in work.iterdir())
    runs = [["clean", "take.bvh", "-o", ""], ["clean", "", "-o", str(tmp_path / "out")],
            ["info", ""], ["check", ""], ["check", "take.bvh", "--junit", ""],
            ["train-dictionary", "take.bvh", "--method", "mssa", "-o", ""],
            ["bench", "", "--protocol", "rotations", "--seeds", "1"],
            ["bench", "take.bvh", "--protocol", "rotations", "--seeds", "1", "--json", ""]]
    for args in runs:
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 2 and "is empty" in r.output, (args, r.output)
    assert sorted(p.name for p in work.iterdir()) == before and not (tmp_path / "out").exists()


def test_an_empty_config_or_rules_name_is_a_usage_error_not_the_default(tmp_path):
    # -c "" ran the default config (and recorded it) instead of the user's, -r "" the
    # default rules, --would-clean "" nothing: an unset variable went unnoticed
    runs = [["clean", str(BVH), "-o", str(tmp_path / "out"), "-c", ""],
            ["check", str(BVH), "-r", ""], ["check", str(BVH), "--would-clean", ""]]
    for args in runs:
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 2 and "is empty" in r.output, (args, r.output)
    assert not (tmp_path / "out").exists()


def test_a_closed_pipe_on_stdout_ends_the_run_quietly(tmp_path):
    # `mocapfix info DIR | head -1`: every later file was reported as "internal error
    # BrokenPipeError" (and before the last guard a traceback); now the run stops
    # quietly as a pipe's writer does (exit 1)
    import subprocess
    import sys

    src = tmp_path / "in"
    src.mkdir()
    for n in range(3):
        shutil.copy(BVH, src / f"take{n}.bvh")
    for args in (["info", str(src)], ["check", str(src)]):
        proc = subprocess.Popen([sys.executable, "-m", "mocapfix.cli", *args],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        proc.stdout.close()                     # the reader is gone before the first line
        _, err = proc.communicate(timeout=120)
        err = err.decode()
        assert proc.returncode == 1, (args[0], proc.returncode, err)
        assert "Traceback" not in err and "internal error" not in err and "BrokenPipe" not in err, err


def test_version_true_is_not_version_1():
    # YAML's true is Python's True, which equals 1: "version: true" passed as version 1
    import pytest

    from mocapfix.core.errors import ConfigError
    from mocapfix.config import loads_config
    from mocapfix.quality.rules import loads_rules

    with pytest.raises(ConfigError, match="unsupported config version True"):
        loads_config("version: true\npipeline: []\n", "c.yaml")
    with pytest.raises(ConfigError, match="unsupported rules version True"):
        loads_rules("version: true\nrules: []\n", "r.yaml")
    assert loads_config("version: 1\npipeline: []\n").steps == []


def test_training_mssa_on_a_bvh_and_a_c3d_says_one_model_per_skeleton(tmp_path):
    # the first file (BVH) made the model learn rotations; the C3D has none:
    # "internal error AttributeError: 'NoneType' object has no attribute 'rot_axes'"
    out = tmp_path / "m.npz"
    r = CliRunner().invoke(main, ["train-dictionary", str(BVH), str(C3D), "--method", "mssa", "-o", str(out)])
    no_traceback(r)
    assert r.exit_code == 2, r.output
    assert f"{C3D}: has no rotation channels" in r.output and "one model per skeleton" in r.output
    assert not out.exists()


def test_partlet_training_on_unusable_takes_is_one_clear_error(tmp_path):
    # a Kinect take then an AMC (other joint names: no body frame) failed with "internal
    # error ValueError: no frame has enough torso points"; takes shorter than one window
    # (an ASF alone is a one-frame rest pose) with "need at least one array to concatenate"
    asf, amc = SAMPLE_DATA / "walker.asf", SAMPLE_DATA / "walker_01.amc"
    for files, message in (([KIN, amc], f"{amc}: lacks body-frame joints of {KIN}"),
                           ([asf], "no training motion has a complete window of 16 samples")):
        r = CliRunner().invoke(main, ["train-dictionary", *map(str, files), "--atoms", "4",
                                      "--iterations", "1", "-o", str(tmp_path / "m.npz")])
        no_traceback(r)
        assert r.exit_code == 2 and message in r.output, r.output
    assert not (tmp_path / "m.npz").exists()


def test_a_link_to_a_folder_inside_an_input_folder_is_named_not_passed_over(tmp_path):
    # os.walk does not follow links to folders: the takes behind "session -> /data/s2"
    # were left out without a word (links to files are read)
    import os

    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.copy(BVH, elsewhere / "behind_the_link.bvh")
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(BVH, src / "here.bvh")
    os.symlink(elsewhere, src / "session")
    for args in (["check", str(src)], ["info", str(src)],
                 ["clean", str(src), "-o", str(tmp_path / "out"), "-c", _cfg(tmp_path)]):
        r = CliRunner().invoke(main, args)
        no_traceback(r)
        assert r.exit_code == 0, r.output
        assert f"SKIP  {src / 'session'}: a link to a folder, not followed" in r.output, (args[0], r.output)


def test_a_kinect_time_column_of_absurd_steps_is_refused_by_the_reader(tmp_path):
    # a headed CSV whose time stamps are 1e300 apart read as "90 frames at 0 fps" and
    # cleaning died in the smoother: "internal error OverflowError"
    import math

    joints = ["Head", "Neck", "SpineShoulder", "SpineMid", "SpineBase", "ShoulderLeft",
              "ElbowLeft", "WristLeft", "ShoulderRight", "ElbowRight", "WristRight", "HipLeft",
              "KneeLeft", "AnkleLeft", "HipRight", "KneeRight", "AnkleRight"]
    header = "time," + ",".join(f"{j}_X,{j}_Y,{j}_Z" for j in joints)

    def take(step):
        rows = [",".join([f"{step * (t + 1):.6g}"] + [f"{v:.4f}" for k in range(len(joints))
                 for v in (0.1 * k + 0.01 * math.sin(t / 5), 1.0 - 0.05 * k, 2.5 + 0.01 * math.cos(t / 7))])
                for t in range(90)]
        return header + "\n" + "\n".join(rows) + "\n"

    src = tmp_path / "in"
    src.mkdir()
    (src / "absurd.csv").write_text(take(1e300))
    (src / "fine.csv").write_text(take(1 / 30))
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(tmp_path / "out"), "-c", "kinect"])
    no_traceback(r)
    assert r.exit_code == 1, r.output
    error = [line for line in r.output.splitlines() if line.startswith("ERROR")]
    assert len(error) == 1 and error[0].startswith(f"ERROR {src / 'absurd.csv'}: the time column gives ")
    assert error[0].endswith("frames per second, outside 0.001-100000 Hz (a corrupt time column?)")
    assert (tmp_path / "out" / "fine.csv").is_file() and not list((tmp_path / "out").glob("absurd*"))


def test_fps_sets_the_rate_of_files_that_store_none_and_leaves_stored_rates_alone(tmp_path):
    # --fps 60 meant for the AMC files of a mixed folder rewrote the C3D file's rate, the
    # BVH file's Frame Time and the Kinect CSV's time base as well
    import json

    from conftest import shared
    from mocapfix import formats

    src = tmp_path / "in"
    src.mkdir()
    for f in (BVH, C3D, KIN, SAMPLE_DATA / "walker.asf", SAMPLE_DATA / "walker_01.amc",
              shared("kinect/kv1_msr3d_a01_s01_e01_skeleton3D.txt")):
        shutil.copy(f, src / f.name)
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _cfg(tmp_path),
                                  "--fps", "60"])
    no_traceback(r)
    assert r.exit_code in (0, 1), r.output
    rates = {p.name.split(".")[0]: json.loads(p.read_text())["file"]["fps"]
             for p in out.glob("*.report.json")}
    stored = {f.stem: formats.read(f).fps for f in (BVH, C3D, KIN)}
    assert rates["walker_01"] == 60.0                       # AMC: no stored rate
    assert rates["kv1_msr3d_a01_s01_e01_skeleton3D"] == 60.0  # MSR text: no timing
    for stem, fps in stored.items():
        assert abs(rates[stem] - fps) < 1e-9 * fps, stem      # stored rates are kept
        assert abs(formats.read(out / (stem + {"walk": ".bvh", "walk_markers": ".c3d",
                                               "walk_kinect_v2": ".csv"}[stem])).fps - fps) < 1e-6 * fps
    note = json.loads((out / "walk_markers.c3d.report.json").read_text())["file"]["notes"]
    assert any("--fps 60 not used: the file stores its rate" in n for n in note)
    note = json.loads((out / "kv1_msr3d_a01_s01_e01_skeleton3D.txt.report.json").read_text())["file"]["notes"]
    assert any("fps 60 given by the user (the file stores no rate)" in n for n in note)
    assert not any("assumed" in n for n in note), note
    r = CliRunner().invoke(main, ["info", str(src / "walker_01.amc"), "--fps", "60"])
    assert "at 60 fps" in r.output, r.output


def test_files_that_share_a_name_but_not_a_format_keep_their_own_reports(tmp_path):
    # take.bvh, take.c3d and take.csv in one folder all wrote take.report.json: two of
    # the three reports were lost (which one survived depended on -j), and a failed
    # file's cleanup removed the report of a namesake that had been cleaned
    import json

    src = tmp_path / "in"
    src.mkdir()
    for f, name in ((BVH, "take.bvh"), (C3D, "take.c3d"), (KIN, "take.csv")):
        shutil.copy(f, src / name)
    (src / "take.amc").write_text("not an AMC\n")           # fails to read
    for jobs in ("1", "2"):
        out = tmp_path / f"out{jobs}"
        r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _cfg(tmp_path),
                                      "-j", jobs, "--report", "json,md"])
        no_traceback(r)
        assert r.exit_code == 1, r.output                   # take.amc failed
        for name in ("take.bvh", "take.c3d", "take.csv"):
            report = json.loads((out / f"{name}.report.json").read_text())
            assert report["file"]["path"] == str(src / name)
            assert (out / f"{name}.report.md").is_file()
        assert not (out / "take.amc").exists() and not (out / "take.amc.report.json").exists()


def test_a_file_named_again_inside_its_folder_is_cleaned_once(tmp_path):
    """``clean in in/walk.bvh`` (or one file named twice) cleans that file once and says so;
    two different files that would write one output are still refused."""
    src = tmp_path / "in"
    shutil.copytree(SAMPLE_DATA, src)
    take = next(p for p in sorted(src.iterdir()) if p.suffix == ".bvh")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), str(take), str(take), "-o", str(out),
                                  "-c", _cfg(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert r.output.count(f"SKIP  {take}: given more than once") == 2
    assert r.output.count(f"{take} ->") == 1
    sub = src / "sub"
    sub.mkdir()
    shutil.copy(take, sub / take.name)
    r = CliRunner().invoke(main, ["clean", str(src), str(sub / take.name), "-o", str(tmp_path / "o2"),
                                  "-c", _cfg(tmp_path)])
    assert r.exit_code == 2 and "would both be written" in r.output, r.output
    assert not (tmp_path / "o2" / take.name).exists()



def _release_reader(fifo):
    """Let a thread blocked opening ``fifo`` to read go on (EOF), never blocking here: a
    blocking open for writing hung the test when the reader had just finished."""
    try:
        os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
    except OSError:                 # ENXIO: nobody is reading (any more)
        pass


def _release_writer(fifo):
    """Let a thread blocked opening ``fifo`` to write go on and drain what it writes,
    never blocking here (with no writer left the read ends at once, on EOF)."""
    fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    os.set_blocking(fd, True)
    with os.fdopen(fd, "rb") as fh:
        fh.read()


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


def test_output_folder_equal_to_the_input_folder_says_so(tmp_path):
    # `clean in -o in --allow-inside-input` said "no motion files found in in" although
    # the folder holds captures: they are all inside the output folder, and that is why
    src = tmp_path / "in"
    src.mkdir()
    (src / "walk.csv").write_bytes(KIN.read_bytes())
    before = (src / "walk.csv").read_bytes()
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(src), "--allow-inside-input",
                                  "-c", "kinect"])
    no_traceback(r)
    assert r.exit_code == 2, r.output
    assert "no motion files found" not in r.output
    assert f"inside the output folder {src}" in r.output
    assert (src / "walk.csv").read_bytes() == before
    assert sorted(p.name for p in src.iterdir()) == ["walk.csv"]


def test_config_or_rules_path_that_is_a_folder_says_so(tmp_path):
    # a folder given to -c / -r / --would-clean was "no such config file or preset"
    folder = tmp_path / "my.yaml"
    folder.mkdir()
    for args, what in ((["clean", str(KIN), "-o", str(tmp_path / "out"), "-c", str(folder)], "config"),
                       (["check", str(KIN), "--would-clean", str(folder)], "config"),
                       (["check", str(KIN), "-r", str(folder)], "rules")):
        r = CliRunner().invoke(main, args)
        no_traceback(r)
        assert r.exit_code == 2, (args, r.output)
        assert f"{folder}: is a folder, not a {what} file" in r.output, (args, r.output)
    assert not (tmp_path / "out").exists()


def test_config_from_a_pipe_is_read(tmp_path):
    # `-c <(…)` (a pipe, not a regular file) was "no such config file or preset"
    fifo = tmp_path / "cfg.pipe"
    os.mkfifo(fifo)
    text = b"version: 1\npipeline:\n  - cleaner: fill\n    max_gap: 0.5 s\n"
    writer = threading.Thread(target=lambda: fifo.write_bytes(text), daemon=True)
    writer.start()
    r = CliRunner().invoke(main, ["clean", str(KIN), "-o", str(tmp_path / "out"), "-c", str(fifo)])
    if writer.is_alive():           # without the fix nobody opens the pipe to read
        _release_writer(fifo)
    writer.join(10)
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert "max_gap: 0.5 s" in (tmp_path / "out" / "mocapfix-config.yaml").read_text()


def test_train_dictionary_names_the_option_that_does_not_apply(tmp_path):
    # --iterations / --max-windows with --method mssa said "unknown parameter(s)
    # 'max_windows', 'train_iterations' for cleaner 'mssa'": names no option has
    model = tmp_path / "m.npz"
    for args, message in (
            (["--method", "mssa", "--iterations", "2", "--max-windows", "200"],
             "--iterations, --max-windows do not apply to --method mssa (only to partlet and ksvd)"),
            (["--method", "partlet", "--bases", "5"], "--bases does not apply to --method partlet (only to mssa)")):
        r = CliRunner().invoke(main, ["train-dictionary", str(SAMPLE_DATA / "walk.bvh"), "-o", str(model),
                                      *args])
        no_traceback(r)
        assert r.exit_code == 2, r.output
        assert message in r.output and "train_iterations" not in r.output, r.output
        assert not model.exists()


def test_a_255_byte_file_name_fails_alone_with_a_readable_error(tmp_path):
    # its report name passes the 255-byte limit: the WriteError was replaced by an OSError
    # of the clean-up (Path.is_dir on the too-long name), "internal error", and the same
    # clean-up in the CLI then ended the whole batch (files after it were never cleaned)
    src = tmp_path / "in"
    src.mkdir()
    long_name = "a" * 251 + ".csv"
    (src / long_name).write_bytes(KIN.read_bytes())
    (src / "b.csv").write_bytes(KIN.read_bytes())
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _cfg(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 1, r.output
    error = [line for line in r.output.splitlines() if line.startswith("ERROR")]
    assert len(error) == 1 and long_name in error[0] and "internal error" not in error[0], r.output
    assert "File name too long" in error[0]
    assert (out / "b.csv").is_file() and not (out / long_name).exists()
    assert "cleaned 1 of 2 files" in r.output


def test_report_outputs_never_replace_the_configs_the_run_reads(tmp_path):
    # check -r R --junit R, check --would-clean C --junit C and bench --configs C --json C
    # replaced the user's rules or config with the report; --json F --markdown F kept
    # only the Markdown
    config = tmp_path / "my.yaml"
    config.write_text("version: 1\npipeline:\n  - cleaner: fill\n    max_gap: 0.5 s\n")
    rules = tmp_path / "rules.yaml"
    rules.write_text("version: 1\nrules:\n  - metric: missing\n    warn: 10%\n")
    before = {p: p.read_bytes() for p in (config, rules)}
    runs = [
        (["check", str(KIN), "-r", str(rules), "--junit", str(rules)], f"would overwrite the config {rules}"),
        (["check", str(KIN), "--would-clean", str(config), "--junit", str(config)],
         f"would overwrite the config {config}"),
        (["bench", str(KIN), "--protocol", "occlusion", "--seeds", "1", "--configs", str(config),
          "--json", str(config), "-q"], f"would overwrite the config {config}"),
        (["bench", str(KIN), "--protocol", "occlusion", "--seeds", "1", "--methods", "fill",
          "--json", str(tmp_path / "r.out"), "--markdown", str(tmp_path / "r.out"), "-q"],
         "--json and --markdown both name"),
    ]
    for args, message in runs:
        r = CliRunner().invoke(main, args)
        no_traceback(r)
        assert r.exit_code == 2, (args, r.output)
        assert message in r.output, (args, r.output)
    assert {p: p.read_bytes() for p in (config, rules)} == before
    assert not (tmp_path / "r.out").exists()


def test_clean_json_dry_run_prints_json(tmp_path):
    # --json --dry-run printed nothing on stdout (the WOULD lines go to stderr with --json)
    import json

    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(KIN), "-o", str(out), "--json", "--dry-run"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    data = json.loads(r.stdout)
    assert data["dry_run"] is True
    assert data["files"] == [{"input": str(KIN), "output": str(out / KIN.name), "replaces": False}]
    assert not out.exists()


def test_an_input_that_changes_while_it_is_cleaned_is_not_recorded_as_finished(tmp_path, monkeypatch):
    # the manifest took the input's sha256 after the clean: a file still being written
    # was recorded with its new content against an output of the old one, and the next
    # run skipped it as "finished earlier", keeping the stale output
    import mocapfix.clean as clean_module

    src = tmp_path / "in"
    src.mkdir()
    take = src / "walk.csv"
    take.write_bytes(KIN.read_bytes())
    real = clean_module.clean_motion

    def clean_while_the_file_grows(motion, pipeline):
        with open(take, "ab") as fh:            # the recorder appends a frame meanwhile
            fh.write(KIN.read_bytes().splitlines(keepends=True)[-1])
        return real(motion, pipeline)

    monkeypatch.setattr(clean_module, "clean_motion", clean_while_the_file_grows)
    out = tmp_path / "out"
    args = ["clean", str(src), "-o", str(out), "-c", _cfg(tmp_path)]
    r = CliRunner().invoke(main, args)
    no_traceback(r)
    assert r.exit_code == 1, r.output
    assert f"ERROR {take}: the file changed while it was being cleaned" in r.output
    assert not (out / "walk.csv").exists()
    monkeypatch.setattr(clean_module, "clean_motion", real)
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0 and "finished earlier" not in r.output, r.output
    assert (out / "walk.csv").is_file()


def test_a_folder_named_like_a_preset_does_not_hide_the_preset(tmp_path, monkeypatch):
    # `mocapfix clean kinect -c kinect` beside a data folder named kinect keeps the preset
    monkeypatch.chdir(tmp_path)
    (tmp_path / "kinect").mkdir()
    (tmp_path / "kinect" / "walk.csv").write_bytes(KIN.read_bytes())
    r = CliRunner().invoke(main, ["clean", "kinect", "-c", "kinect", "-o", "out", "--dry-run"])
    no_traceback(r)
    assert r.exit_code == 0 and "configs/kinect.yaml" in r.output, r.output
    r = CliRunner().invoke(main, ["check", "kinect", "-r", "kinect", "--exit-zero"])
    no_traceback(r)
    assert r.exit_code == 0 and "is a folder" not in r.output, r.output


def test_one_file_found_through_two_given_paths_resumes(tmp_path):
    # `clean in in/sub/x.csv -o out` writes out/sub/x.csv and out/x.csv; the manifest kept
    # one record per input, so the same command run again stopped with exit 2, "1 output(s)
    # exist already … made with another config, report kinds, --fps, version or input"
    src = tmp_path / "in"
    (src / "sub").mkdir(parents=True)
    (src / "sub" / "x.csv").write_bytes(KIN.read_bytes())
    out = tmp_path / "out"
    args = ["clean", str(src), str(src / "sub" / "x.csv"), "-o", str(out), "-c", _cfg(tmp_path)]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    assert (out / "sub" / "x.csv").is_file() and (out / "x.csv").is_file()
    r = CliRunner().invoke(main, args)
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert r.output.count("finished earlier") >= 2 and "exist already" not in r.output, r.output


def test_check_counts_a_file_found_through_two_given_paths_once(tmp_path):
    # `check in in/sub/x.csv` checked x.csv twice: "checked 2 files" for one, two JUnit
    # testcases (info listed it twice, train-dictionary trained on it twice)
    import json
    import xml.etree.ElementTree as ET

    src = tmp_path / "in"
    (src / "sub").mkdir(parents=True)
    (src / "sub" / "x.csv").write_bytes(KIN.read_bytes())
    junit = tmp_path / "j.xml"
    r = CliRunner().invoke(main, ["check", str(src), str(src / "sub" / "x.csv"), "--junit", str(junit),
                                  "--exit-zero"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert "checked 1 files" in r.output and "given more than once" in r.output, r.output
    assert len(ET.parse(junit).getroot().findall(".//testcase")) == 1
    r = CliRunner().invoke(main, ["info", str(src), str(src / "sub" / "x.csv"), "--json"])
    assert r.exit_code == 0, r.output
    assert len(json.loads(r.stdout)) == 1


def test_skip_existing_does_not_take_a_folder_for_an_output(tmp_path):
    # a folder at out/walk.csv made --skip-existing say "SKIP … output exists" and exit 0
    # with nothing cleaned; without it, "output(s) exist already … pass --overwrite"
    src = tmp_path / "in"
    src.mkdir()
    (src / "walk.csv").write_bytes(KIN.read_bytes())
    out = tmp_path / "out"
    (out / "walk.csv").mkdir(parents=True)
    for extra in (["--skip-existing"], []):
        r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _cfg(tmp_path), *extra])
        no_traceback(r)
        assert r.exit_code == 1, (extra, r.output)
        assert "output exists" not in r.output and "exist already" not in r.output, r.output
        assert f"ERROR {src / 'walk.csv'}" in r.output and "Is a directory" in r.output, r.output
        assert (out / "walk.csv").is_dir()


def test_a_line_break_in_a_file_name_does_not_split_its_line(tmp_path):
    """Files named 'a<newline>b.bvh' (readable) and 'bad<newline>x.bvh' (not): clean, check
    and info print each on one line, the break shown as \\n, and clean still writes the
    readable one under its real name."""
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(BVH, src / "a\nb.bvh")
    (src / "bad\nx.bvh").write_text("garbage\n")
    runs = {"clean": ["clean", str(src), "-o", str(tmp_path / "out"), "-c", _cfg(tmp_path)],
            "check": ["check", str(src)], "info": ["info", str(src)]}
    for what, args in runs.items():
        r = CliRunner().invoke(main, args)
        no_traceback(r)
        lines = r.output.splitlines()
        if what == "info":
            lines = [line for line in lines if not line.startswith("  ")]
        named = [line for line in lines if "a\\nb.bvh" in line or "bad\\nx.bvh" in line]
        assert not [line for line in lines if line in ("b.bvh", "x.bvh") or line.startswith(("b.bvh", "x.bvh"))], (what, lines)
        assert any("a\\nb.bvh" in line for line in named) and any("bad\\nx.bvh" in line for line in named), (what, lines)
    assert (tmp_path / "out" / "a\nb.bvh").is_file()


def test_an_empty_report_list_is_a_usage_error_not_no_reports(tmp_path):
    """`--report ""` (an unset shell variable) meant no reports, silently; 'none' says so.
    Now it is refused like an unknown kind, and nothing is written."""
    for value, message in (("", "--report is empty"), (" , ", "--report is empty"),
                           ("pdf", "unknown report kind(s) pdf")):
        out = tmp_path / f"out{len(value)}"
        r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "--report", value])
        no_traceback(r)
        assert r.exit_code == 2 and message in r.output, r.output
        assert not out.exists()
    r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(tmp_path / "none"), "--report", "none"])
    assert r.exit_code == 0 and not list((tmp_path / "none").glob("*.report.*"))


def test_values_near_1e300_print_no_numpy_warnings(tmp_path):
    """A Kinect file with one coordinate at 1e300 m: info, check and clean (one process and
    a pool of two) printed a dozen 'RuntimeWarning: overflow encountered in multiply' lines
    naming no file. Run as a user runs it (a process of its own: pytest records warnings
    itself): no warning, and each command still gives its line for the file."""
    lines = KIN.read_text().split("\n")
    k = next(i for i, line in enumerate(lines) if line[:1].isdigit()) + 20
    fields = lines[k].split(",")
    fields[1] = "1e300"
    lines[k] = ",".join(fields)
    path = tmp_path / "huge.csv"
    path.write_text("\n".join(lines))
    for args in (["info", str(path)], ["check", str(path)],
                 ["clean", str(path), "-o", str(tmp_path / "o1")],
                 ["clean", str(path), "-o", str(tmp_path / "o2"), "-j", "2"]):
        r = subprocess.run([sys.executable, "-m", "mocapfix.cli", *args], capture_output=True,
                           text=True, timeout=120)
        assert "Warning" not in r.stdout + r.stderr, (args, r.stderr)
        assert "huge.csv" in r.stdout + r.stderr and "Traceback" not in r.stderr, (args, r.stderr)


def test_dry_run_says_a_folder_at_the_output_path_would_fail(tmp_path):
    # the dry run said "(replaces the existing output)" where the real run fails with
    # "cannot write: Is a directory"
    import json

    out = tmp_path / "out"
    (out / KIN.name).mkdir(parents=True)
    r = CliRunner().invoke(main, ["clean", str(KIN), "-o", str(out), "--dry-run"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert "its output path is a folder: the file would fail" in r.output
    assert "replaces" not in r.output
    r = CliRunner().invoke(main, ["clean", str(KIN), "-o", str(out), "--json", "--dry-run"])
    assert json.loads(r.stdout)["files"][0]["output_is_folder"] is True
    r = CliRunner().invoke(main, ["clean", str(KIN), "-o", str(out)])
    assert r.exit_code != 0 and "Is a directory" in r.output
