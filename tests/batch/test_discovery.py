"""Input discovery: what clean, check and info find under the paths they are given — a
folder that cannot be listed and a link to a folder are named, not passed over; a
file found through two given paths is processed once; an output folder equal to the
input folder says why nothing is found."""
from __future__ import annotations

import shutil

from click.testing import CliRunner

from mocapfix.cli import main

from conftest import SAMPLE_DATA, config_file, no_traceback

BVH = SAMPLE_DATA / "walk.bvh"
KIN = SAMPLE_DATA / "walk_kinect_v2.csv"


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
        for args in (["clean", str(src), "-o", str(tmp_path / "out"), "-c", config_file(tmp_path)],
                     ["check", str(src)], ["info", str(src)]):
            r = CliRunner().invoke(main, args)
            no_traceback(r)
            skip = [line for line in r.output.splitlines() if line.startswith("SKIP")]
            assert skip == [f"SKIP  {locked}: cannot read this folder: Permission denied "
                            "(the files in it were not processed)"], (args[0], r.output)
    finally:
        locked.chmod(0o755)


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
                 ["clean", str(src), "-o", str(tmp_path / "out"), "-c", config_file(tmp_path)]):
        r = CliRunner().invoke(main, args)
        no_traceback(r)
        assert r.exit_code == 0, r.output
        assert f"SKIP  {src / 'session'}: a link to a folder, not followed" in r.output, (args[0], r.output)


def test_a_file_named_again_inside_its_folder_is_cleaned_once(tmp_path):
    """``clean in in/walk.bvh`` (or one file named twice) cleans that file once and says so;
    two different files that would write one output are still refused."""
    src = tmp_path / "in"
    shutil.copytree(SAMPLE_DATA, src)
    take = next(p for p in sorted(src.iterdir()) if p.suffix == ".bvh")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), str(take), str(take), "-o", str(out),
                                  "-c", config_file(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert r.output.count(f"SKIP  {take}: given more than once") == 2
    assert r.output.count(f"{take} ->") == 1
    sub = src / "sub"
    sub.mkdir()
    shutil.copy(take, sub / take.name)
    r = CliRunner().invoke(main, ["clean", str(src), str(sub / take.name), "-o", str(tmp_path / "o2"),
                                  "-c", config_file(tmp_path)])
    assert r.exit_code == 2 and "would both be written" in r.output, r.output
    assert not (tmp_path / "o2" / take.name).exists()


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


def test_a_link_beside_the_file_it_names_is_said_to_be_that_file(tmp_path):
    # check/info keep one of a link in a folder and the file it names beside it: the
    # other was "given more than once" though the folder was given once
    src = tmp_path / "in"
    src.mkdir()
    (src / "take.csv").write_bytes(KIN.read_bytes())
    (src / "alias.csv").symlink_to("take.csv")
    for command in (["check", "--exit-zero"], ["info"]):
        r = CliRunner().invoke(main, [command[0], str(src), *command[1:]])
        no_traceback(r)
        assert r.exit_code == 0, r.output
        assert f"SKIP  {src / 'take.csv'}: the same file as {src / 'alias.csv'} (processed once)" \
            in r.output, r.output
        assert "given more than once" not in r.output, r.output
