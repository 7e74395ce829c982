"""Where a batch writes: output and report paths checked before any work (a path
through a file, a report that would replace a capture or a config the run reads),
names at the 255-byte limit, namesakes of other formats, folders in the way; a file
that cannot be written fails alone, the rest of the batch is written and nothing is
left for the failed file."""
from __future__ import annotations

import shutil

from click.testing import CliRunner

from mocapfix.cli import main

from conftest import SAMPLE_DATA, config_file, md5_tree, no_traceback

BVH, C3D, KIN = SAMPLE_DATA / "walk.bvh", SAMPLE_DATA / "walk_markers.c3d", SAMPLE_DATA / "walk_kinect_v2.csv"


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
    before = md5_tree(src)
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", config_file(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 1, r.output
    error = [line for line in r.output.splitlines() if line.startswith("ERROR")]
    assert len(error) == 1 and "x.bvh" in error[0] and "internal error" not in error[0]
    assert (out / "y.bvh").is_file() and (out / "mocapfix-config.yaml").is_file()
    assert (out / "a").read_text() == "not a folder"
    assert md5_tree(src) == before


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


def test_a_long_but_legal_file_name_is_cleaned_and_its_stale_temporary_removed(tmp_path):
    # a 244-byte name (the limit is 255) failed with "File name too long": not for the
    # output, whose name is the same, but for its temporary ".NAME.XXXXXXXX.part"
    stem = "take_" + "x" * 235
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(BVH, src / f"{stem}.bvh")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", config_file(tmp_path)])
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
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", config_file(tmp_path), "--overwrite"])
    assert r.exit_code == 0, r.output
    assert not leftover.exists() and other.read_bytes() == b"not ours"


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
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", config_file(tmp_path), "--overwrite"])
    no_traceback(r)
    assert r.exit_code == 1, r.output
    error = [line for line in r.output.splitlines() if line.startswith("ERROR")]
    assert len(error) == 1 and "walker_02.amc.report.json: cannot write: Is a directory" in error[0], r.output
    assert (out / "zz_last.csv").is_file()                 # the batch went on
    assert not (out / "walker_02.amc").exists()            # nothing left for the failed file
    assert (out / "walker_02.amc.report.json").is_dir()        # the folder is not ours to remove
    assert formats.read(out / "walker_01.amc").n_frames > 0  # its skeleton is still there


def test_report_files_never_overwrite_the_captures_they_are_about(tmp_path):
    # "check take.c3d --junit take.c3d" replaced the capture with JUnit XML (exit 0); the
    # same for a capture in an input folder, the ASF beside a named AMC, bench --json on
    # its input and train-dictionary -o on a training file
    src = tmp_path / "in"
    src.mkdir()
    for f in (BVH, C3D, SAMPLE_DATA / "walker.asf", SAMPLE_DATA / "walker_01.amc"):
        shutil.copy(f, src / f.name)
    (src / "notes.txt").write_text("session notes\n")
    before = md5_tree(src)
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
    assert md5_tree(src) == before
    # a report file that is not a capture may go beside them, also replacing a text file
    # that is not motion data
    r = CliRunner().invoke(main, ["check", str(src), "--junit", str(src / "notes.txt"), "--exit-zero"])
    assert r.exit_code == 0, r.output
    assert (src / "notes.txt").read_text().startswith("<?xml")


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
        r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", config_file(tmp_path),
                                      "-j", jobs, "--report", "json,md"])
        no_traceback(r)
        assert r.exit_code == 1, r.output                   # take.amc failed
        for name in ("take.bvh", "take.c3d", "take.csv"):
            report = json.loads((out / f"{name}.report.json").read_text())
            assert report["file"]["path"] == str(src / name)
            assert (out / f"{name}.report.md").is_file()
        assert not (out / "take.amc").exists() and not (out / "take.amc.report.json").exists()


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
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", config_file(tmp_path)])
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


def test_skip_existing_does_not_take_a_folder_for_an_output(tmp_path):
    # a folder at out/walk.csv made --skip-existing say "SKIP … output exists" and exit 0
    # with nothing cleaned; without it, "output(s) exist already … pass --overwrite"
    src = tmp_path / "in"
    src.mkdir()
    (src / "walk.csv").write_bytes(KIN.read_bytes())
    out = tmp_path / "out"
    (out / "walk.csv").mkdir(parents=True)
    for extra in (["--skip-existing"], []):
        r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", config_file(tmp_path), *extra])
        no_traceback(r)
        assert r.exit_code == 1, (extra, r.output)
        assert "output exists" not in r.output and "exist already" not in r.output, r.output
        assert f"ERROR {src / 'walk.csv'}" in r.output and "Is a directory" in r.output, r.output
        assert (out / "walk.csv").is_dir()
