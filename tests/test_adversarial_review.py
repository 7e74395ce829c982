"""Findings of an adversarial review through the command line: each test fails without
its fix (a named pipe replaced by a regular file, misleading messages, …)."""
from __future__ import annotations

import os
import re
import shutil
import stat
import threading

from click.testing import CliRunner

from mocapfix.cli import main
from conftest import SAMPLE_DATA, shared

KIN = SAMPLE_DATA / "walk_kinect_v2.csv"


def _no_traceback(r):
    assert "Traceback" not in r.output
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)


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
        with open(fifo, "wb"):
            pass
    reader.join(10)
    _no_traceback(r)
    assert r.exit_code in (0, 1), r.output
    assert stat.S_ISFIFO(os.stat(fifo).st_mode), "the pipe was replaced by a file"
    assert got and got[0].startswith(b"<?xml") and b"walk_kinect_v2.csv" in got[0]


def test_junit_into_a_pipe_nobody_reads_is_an_error_not_a_hang(tmp_path):
    fifo = tmp_path / "junit.pipe"
    os.mkfifo(fifo)
    r = CliRunner().invoke(main, ["check", str(KIN), "--junit", str(fifo), "-q"])
    _no_traceback(r)
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
    _no_traceback(r)
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
        _no_traceback(r)
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
        fifo.read_bytes()
    writer.join(10)
    _no_traceback(r)
    assert r.exit_code == 0, r.output
    assert "max_gap: 0.5 s" in (tmp_path / "out" / "mocapfix-config.yaml").read_text()


def _cut_amc(src, dst, frames: int):
    """``src`` AMC with its first ``frames`` frames only, beside a copy of its ASF."""
    parts = re.split(r"(?m)^(?=\d+\s*$)", src.read_text())
    dst.write_text("".join(parts[:1 + frames]))
    return dst


def test_bench_kinect_on_short_takes_names_the_file_or_runs(tmp_path):
    # a 1.25 s CMU take crashed the kinect protocol (IndexError in the leg-swap placement:
    # an internal error); a 0.67 s one failed with SciPy's "padlen" message naming no file
    shutil.copy(shared("asfamc/05.asf"), tmp_path / "05.asf")
    amc = shared("asfamc/05_01.amc")
    ok = _cut_amc(amc, tmp_path / "05_90.amc", 150)
    short = _cut_amc(amc, tmp_path / "05_91.amc", 80)
    r = CliRunner().invoke(main, ["bench", str(ok), "--protocol", "kinect", "--seeds", "3", "-q"])
    _no_traceback(r)
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(main, ["bench", str(ok), str(short), "--protocol", "kinect", "-q"])
    _no_traceback(r)
    assert r.exit_code == 2, r.output
    assert f"{short}: 20 frames at 30 fps; the kinect protocol needs at least 30" in r.output


def test_bench_occlusion_on_a_three_frame_take_says_why(tmp_path):
    # it said "occlusion/mixed: low >= high" (NumPy's message for an empty random range)
    shutil.copy(SAMPLE_DATA / "walker.asf", tmp_path / "walker.asf")
    short = _cut_amc(SAMPLE_DATA / "walker_01.amc", tmp_path / "walker_02.amc", 3)
    r = CliRunner().invoke(main, ["bench", str(short), "--protocol", "occlusion", "--seeds", "1",
                                  "--methods", "fill", "-q"])
    _no_traceback(r)
    assert r.exit_code == 2, r.output
    assert "low >= high" not in r.output
    assert f"{short}: occlusion/" in r.output and "3 frames; the occlusion protocol needs at least 4" in r.output


def test_truncated_bvh_message_gives_no_python_only_advice(tmp_path):
    # the CLI said "(pass allow_truncated=True to read them)": no option of mocapfix does
    text = (SAMPLE_DATA / "walk.bvh").read_text()
    cut = tmp_path / "cut.bvh"
    cut.write_text(text[: len(text) - len(text.splitlines()[-1]) * 5 // 2])
    before = cut.read_bytes()
    r = CliRunner().invoke(main, ["info", str(cut)])
    _no_traceback(r)
    assert r.exit_code == 3, r.output
    assert f"{cut}" in r.output and "truncated: 'Frames:" in r.output
    assert "allow_truncated" not in r.output and "cut short" in r.output
    assert cut.read_bytes() == before


def test_kinect_stamps_a_tick_apart_are_a_readable_error(tmp_path):
    # rows stamped 100 ns apart made kinect_skeleton's banded Cholesky fail: "internal
    # error LinAlgError: 34th leading minor not positive definite"
    lines = KIN.read_text().split("\n")
    head = next(i for i, line in enumerate(lines) if line[:1].isdigit())
    for i in range(head + 10, head + 100, 3):
        tick = int(lines[i - 1].split(",")[0])
        lines[i] = ",".join([str(tick + 1)] + lines[i].split(",")[1:])
    bad = tmp_path / "in" / "ticks.csv"
    bad.parent.mkdir()
    bad.write_text("\n".join(lines))
    (tmp_path / "in" / "walk.csv").write_bytes(KIN.read_bytes())
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(bad.parent), "-o", str(out), "-c", "kinect"])
    _no_traceback(r)
    assert r.exit_code == 1, r.output
    error = [line for line in r.output.splitlines() if line.startswith("ERROR")]
    assert len(error) == 1 and str(bad) in error[0], r.output
    assert "internal error" not in error[0] and "kinect_skeleton" in error[0]
    assert "shortest time step 1e-07 s" in error[0]
    assert (out / "walk.csv").is_file() and not (out / "ticks.csv").exists()


def test_trust_one_absurd_sample_costs_only_itself():
    # one sample 1 km off (a corrupt field) steered trust's first robust smooth and every
    # sample of its marker came out untrusted and was deleted (CMU 85_02: 810 of 810;
    # 100 m: 731 of 810); now (beyond 100 m) it alone is untrusted, the rest as without it
    import numpy as np

    from mocapfix.formats import read
    from mocapfix.pipeline import loads_config

    motion = read(SAMPLE_DATA / "walk_markers.c3d")
    trust = loads_config("version: 1\npipeline:\n  - cleaner: trust\n")
    plain, _ = trust.run(motion)
    for offset_mm in (2e5, 1e6, 1e30):
        pos = motion.positions.copy()
        pos[300, 4] += offset_mm * 1e-3 / motion.metres_per_unit
        out, records = trust.run(motion.replace(positions=pos))
        lost = np.isnan(out.positions).any(axis=2) & ~np.isnan(plain.positions).any(axis=2)
        assert lost.sum() == 1 and lost[300, 4], (offset_mm, int(lost.sum()))
        same = np.ones(lost.shape, bool)
        same[300, 4] = False
        np.testing.assert_array_equal(out.positions[same], plain.positions[same])
        assert records[0].info["untrusted_gross"] == 1


def test_trust_gross_screen_ignores_mislabelled_units():
    # the gross-error screen is relative to the capture's extent: millimetre data labelled
    # as metres is not one big gross error (an absolute 100 m screen took every sample)
    from mocapfix.formats import read
    from mocapfix.pipeline import loads_config

    motion = read(SAMPLE_DATA / "walk_markers.c3d")
    wrong = motion.replace(metres_per_unit=1.0)
    _, records = loads_config("version: 1\npipeline:\n  - cleaner: trust\n").run(wrong)
    assert records[0].info["untrusted_gross"] == 0


def test_marker_name_with_a_pipe_keeps_its_report_row_whole(tmp_path):
    # a C3D label "a|b" split its row of the Markdown and HTML joint tables in two cells
    from malformed_corpus import c3d_bytes, small_c3d_points

    src = tmp_path / "in" / "pipes.c3d"
    src.parent.mkdir()
    src.write_bytes(c3d_bytes(small_c3d_points(T=200, P=3), ["a|b", "C", "D"]))
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "--report", "md,html",
                                  "-c", _fill_config(tmp_path)])
    _no_traceback(r)
    assert r.exit_code == 0, r.output
    md = (out / "pipes.c3d.report.md").read_text().splitlines()
    header = next(line for line in md if line.startswith("| joint |"))
    row = next(line for line in md if line.startswith("| a"))
    border = re.compile(r"(?<!\\)\|")
    assert len(border.findall(row)) == len(border.findall(header)), row
    html_text = (out / "pipes.c3d.report.html").read_text()
    assert "<td>a|b</td>" in html_text and "<td>a</td>" not in html_text


def _fill_config(tmp_path) -> str:
    path = tmp_path / "fill.yaml"
    path.write_text("version: 1\npipeline:\n  - cleaner: fill\n    max_gap: 0.5 s\n")
    return str(path)


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
        _no_traceback(r)
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
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _fill_config(tmp_path)])
    _no_traceback(r)
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
        _no_traceback(r)
        assert r.exit_code == 2, (args, r.output)
        assert message in r.output, (args, r.output)
    assert {p: p.read_bytes() for p in (config, rules)} == before
    assert not (tmp_path / "r.out").exists()


def test_clean_json_dry_run_prints_json(tmp_path):
    # --json --dry-run printed nothing on stdout (the WOULD lines go to stderr with --json)
    import json

    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(KIN), "-o", str(out), "--json", "--dry-run"])
    _no_traceback(r)
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
    args = ["clean", str(src), "-o", str(out), "-c", _fill_config(tmp_path)]
    r = CliRunner().invoke(main, args)
    _no_traceback(r)
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
    _no_traceback(r)
    assert r.exit_code == 0 and "configs/kinect.yaml" in r.output, r.output
    r = CliRunner().invoke(main, ["check", "kinect", "-r", "kinect", "--exit-zero"])
    _no_traceback(r)
    assert r.exit_code == 0 and "is a folder" not in r.output, r.output


def test_glitch_screen_on_a_take_of_eight_frames_warns_nothing():
    # rotation_outliers on a take of <= 8 frames printed NumPy's "RuntimeWarning: Mean of
    # empty slice" (twice, naming no file) into the terminal
    import warnings

    import numpy as np

    from mocapfix.solvers.glitches import glitches

    x = np.cumsum(np.random.default_rng(0).normal(size=(8, 6)), axis=0)
    x[4, 2] += 50.0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        found = glitches(x)
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in caught]
    assert found.shape == x.shape and found[4, 2]


def test_one_file_found_through_two_given_paths_resumes(tmp_path):
    # `clean in in/sub/x.csv -o out` writes out/sub/x.csv and out/x.csv; the manifest kept
    # one record per input, so the same command run again stopped with exit 2, "1 output(s)
    # exist already … made with another config, report kinds, --fps, version or input"
    src = tmp_path / "in"
    (src / "sub").mkdir(parents=True)
    (src / "sub" / "x.csv").write_bytes(KIN.read_bytes())
    out = tmp_path / "out"
    args = ["clean", str(src), str(src / "sub" / "x.csv"), "-o", str(out), "-c", _fill_config(tmp_path)]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0, r.output
    assert (out / "sub" / "x.csv").is_file() and (out / "x.csv").is_file()
    r = CliRunner().invoke(main, args)
    _no_traceback(r)
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
    _no_traceback(r)
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
        r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", _fill_config(tmp_path), *extra])
        _no_traceback(r)
        assert r.exit_code == 1, (extra, r.output)
        assert "output exists" not in r.output and "exist already" not in r.output, r.output
        assert f"ERROR {src / 'walk.csv'}" in r.output and "Is a directory" in r.output, r.output
        assert (out / "walk.csv").is_dir()


def test_trust_gross_screen_keeps_a_wand_moving_over_a_static_rig():
    # a screen on the capture-wide extent alone took every sample of the one marker that
    # moves (a wand, 1.6 m) when the other 20 stand still: its extent is its own
    import numpy as np

    from mocapfix.formats import read
    from mocapfix.pipeline import loads_config

    base = read(SAMPLE_DATA / "walk_markers.c3d")
    T = base.n_frames
    rng = np.random.default_rng(0)
    pos = np.zeros((T, 21, 3))
    pos[:, :20] = rng.uniform(-500, 500, (1, 20, 3)) + rng.normal(0, 0.1, (T, 20, 3))
    t = np.arange(T) / base.fps
    pos[:, 20] = np.stack([800 * np.sin(t), 800 * np.cos(t), 500 + 0 * t], axis=1)
    rig = base.replace(positions=pos, names=[f"M{i}" for i in range(21)], confidence=None)
    trust = loads_config("version: 1\npipeline:\n  - cleaner: trust\n")
    _, records = trust.run(rig)
    assert records[0].info["untrusted_gross"] == 0
    pos = pos.copy()
    pos[300, 20] += 1e6                 # 1 km: still a gross error
    _, records = trust.run(rig.replace(positions=pos))
    assert records[0].info["untrusted_gross"] == 1
