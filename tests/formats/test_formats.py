"""The format table over the readers and writers: a file is read as its content says and
written back in that format whatever its name, and ``--fps`` sets the rate of the
files that store none while stored rates stay."""
from __future__ import annotations

import shutil

from click.testing import CliRunner

from mocapfix.cli import main

from conftest import SAMPLE_DATA, config_file, md5_tree, no_traceback

BVH, C3D, KIN = SAMPLE_DATA / "walk.bvh", SAMPLE_DATA / "walk_markers.c3d", SAMPLE_DATA / "walk_kinect_v2.csv"


def test_a_file_whose_content_is_another_format_is_written_back_in_that_format(tmp_path):
    # The reader goes by content, the writer went by the name: a BVH saved as .c3d came
    # out as a real C3D of joint positions (its rotation channels and hierarchy lost) and
    # a C3D saved as .bvh failed with "the motion has no BVH channels to write"
    from mocapfix import formats

    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(BVH, src / "bvh_inside.c3d")
    shutil.copy(C3D, src / "c3d_inside.bvh")
    before = md5_tree(src)
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", config_file(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    assert (out / "bvh_inside.c3d").read_bytes().startswith(b"HIERARCHY")
    assert (out / "c3d_inside.bvh").read_bytes()[1:2] == b"\x50"        # the C3D key
    for name, fmt, original in (("bvh_inside.c3d", "bvh", BVH), ("c3d_inside.bvh", "c3d", C3D)):
        back, first = formats.read(out / name), formats.read(original)
        assert back.format == fmt and back.names == first.names
        assert back.positions.shape == first.positions.shape
    assert md5_tree(src) == before


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
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", config_file(tmp_path),
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
