"""Usage errors: a command line that cannot be what the user meant (an absurd ``--fps``,
an empty path, config, rules or report list, options that exclude each other or do
not apply) is refused with exit 2 and one line naming the option, before any file is
read or written."""
from __future__ import annotations

import shutil

from click.testing import CliRunner

from mocapfix.cli import main

from conftest import SAMPLE_DATA, config_file, md5_tree, no_traceback

BVH, C3D, KIN = SAMPLE_DATA / "walk.bvh", SAMPLE_DATA / "walk_markers.c3d", SAMPLE_DATA / "walk_kinect_v2.csv"


def test_absurd_fps_is_a_usage_error_for_every_command(tmp_path):
    # --fps nan/inf used to be taken (an AMC "cleaned" at nan Hz, exit 0), 0 silently
    # meant the default and -1 failed each file separately (exit 1): all are usage errors
    amc = SAMPLE_DATA / "walker_01.amc"
    for value in ("nan", "inf", "-inf", "0", "-1", "1e308"):
        for args in (["info", str(amc)], ["check", str(amc)],
                     ["clean", str(amc), "-o", str(tmp_path / "out"), "-c", config_file(tmp_path)],
                     ["train-dictionary", str(amc), "--method", "mssa", "-o", str(tmp_path / "m.npz")]):
            r = CliRunner().invoke(main, [*args, "--fps", value])
            no_traceback(r)
            assert r.exit_code == 2, (args[0], value, r.output)
            assert "--fps" in r.output and "is not a frame rate" in r.output
    assert not (tmp_path / "out").exists() and not (tmp_path / "m.npz").exists()
    r = CliRunner().invoke(main, ["info", str(amc), "--fps", "60", "--json"])
    assert r.exit_code == 0 and '"fps": 60.0' in r.output


def test_overwrite_and_skip_existing_together_are_a_usage_error(tmp_path):
    # the two shared one option: given both, the last one silently decided whether the
    # existing outputs were replaced or kept
    out = tmp_path / "out"
    cfg = config_file(tmp_path)
    assert CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg]).exit_code == 0
    before = md5_tree(out)
    for flags in (["--overwrite", "--skip-existing"], ["--skip-existing", "--overwrite"]):
        r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg, *flags])
        assert r.exit_code == 2 and "exclude each other" in r.output, r.output
    assert md5_tree(out) == before
    r = CliRunner().invoke(main, ["clean", str(BVH), "-o", str(out), "-c", cfg, "--overwrite"])
    assert r.exit_code == 0 and "cleaned 1 of 1" in r.output


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
