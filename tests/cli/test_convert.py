"""`mocapfix convert` and `clean --to`: the samples written are the samples read (a
missing one stays missing), what the output format cannot carry is named per file and in
the report, a conversion that cannot be made fails that file alone with a clear error,
and runs resume like `clean`."""
from __future__ import annotations

import hashlib
import json

import numpy as np
import pytest
from click.testing import CliRunner

from mocapfix import formats
from mocapfix.cli import main
from conftest import SAMPLE_DATA, no_traceback, shared

C3D, BVH, KIN = SAMPLE_DATA / "walk_markers.c3d", SAMPLE_DATA / "walk.bvh", SAMPLE_DATA / "walk_kinect_v2.csv"


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_convert_writes_the_samples_read_and_leaves_gaps_as_gaps(tmp_path):
    before = _digest(C3D)
    r = CliRunner().invoke(main, ["convert", str(C3D), "-o", str(tmp_path / "o"), "--to", "kinect"])
    assert r.exit_code == 0, r.output
    assert "converted 1 of 1 files" in r.output
    assert _digest(C3D) == before
    out = tmp_path / "o" / "walk_markers.csv"
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == [
        "mocapfix-config.yaml", "mocapfix-manifest.jsonl", "walk_markers.csv"]   # no report by default
    src, got = formats.read(C3D), formats.read(out)
    assert got.names == src.names and got.units == src.units
    assert abs(got.fps - src.fps) < 1e-6 * src.fps        # times printed to 1e-9 s
    assert np.array_equal(got.missing, src.missing) and src.missing.any()   # gaps kept, not filled
    seen = ~src.missing
    assert np.abs(got.positions[seen] - src.positions[seen]).max() < 1e-5


def test_what_the_output_cannot_carry_is_named_on_the_line_and_in_the_report(tmp_path):
    r = CliRunner().invoke(main, ["convert", str(BVH), str(KIN), "-o", str(tmp_path / "o"), "--to", "c3d",
                                  "--report", "json"])
    assert r.exit_code == 0, r.output
    assert "not carried into c3d: the joint rotations" in r.output
    assert "not carried into c3d: the tracking state of each sample" in r.output
    report = json.loads((tmp_path / "o" / "walk.c3d.report.json").read_text())
    assert any("joint rotations" in n for n in report["file"]["notes"])
    src, got = formats.read(BVH), formats.read(tmp_path / "o" / "walk.c3d")
    assert got.names == src.names
    assert np.abs(got.positions - src.positions).max() < 1e-3 * np.abs(src.positions).max()


def test_a_conversion_that_cannot_be_made_fails_that_file_alone(tmp_path):
    r = CliRunner().invoke(main, ["convert", str(C3D), str(BVH), "-o", str(tmp_path / "o"), "--to", "bvh"])
    no_traceback(r)
    assert r.exit_code == 1, r.output
    assert "ERROR" in r.output and "BVH output needs a motion read from a BVH file" in r.output
    assert not (tmp_path / "o" / "walk_markers.bvh").exists()      # nothing left of it
    assert (tmp_path / "o" / "walk.bvh").exists()                   # the other file written
    r = CliRunner().invoke(main, ["convert", str(C3D), "-o", str(tmp_path / "p"), "--to", "xyz"])
    assert r.exit_code == 2 and "unknown output format 'xyz'" in r.output
    assert not (tmp_path / "p").exists()


def test_clean_to_another_format_cleans_then_writes_it(tmp_path):
    r = CliRunner().invoke(main, ["clean", str(KIN), "-o", str(tmp_path / "o"), "--to", "c3d"])
    assert r.exit_code == 0, r.output
    cleaned = formats.read(tmp_path / "o" / "walk_kinect_v2.c3d")
    src = formats.read(KIN)
    assert cleaned.n_frames == src.n_frames and cleaned.names == src.names
    assert not np.allclose(cleaned.positions, src.positions, equal_nan=True)   # it was cleaned


def test_convert_resumes_and_a_new_format_is_a_new_run(tmp_path):
    args = ["convert", str(C3D), "-o", str(tmp_path / "o"), "--to", "kinect"]
    assert CliRunner().invoke(main, args).exit_code == 0
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 0 and "finished earlier" in r.output
    r = CliRunner().invoke(main, ["convert", str(C3D), "-o", str(tmp_path / "o"), "--to", "c3d"])
    assert r.exit_code == 0 and (tmp_path / "o" / "walk_markers.c3d").exists(), r.output


def _trc_empty(path):
    """(names, (T, M) empty) of a TRC, read with plain string splitting: a sample is empty
    when its three fields are."""
    lines = path.read_text().split("\n")
    names = [n.strip() for n in lines[3].split("\t")[2::3] if n.strip()]
    rows = [line.split("\t") for line in lines[5:] if line.strip() and line.split("\t")[0].strip().isdigit()]
    empty = np.array([[all(not (row[2 + 3 * m + k].strip() if 2 + 3 * m + k < len(row) else "")
                           for k in range(3)) for m in range(len(names))] for row in rows])
    return names, empty


@pytest.mark.parametrize("name", ["ktk_racing_full.c3d", "c3dorg_s28_dynamic.C3D"])
def test_clean_to_trc_leaves_empty_exactly_what_the_report_lists_as_left(name, tmp_path):
    """An IK solver reads the TRC: every empty field is a sample the report lists as left
    (a gap not filled, or a point not cleaned), and every sample the report lists as left
    is empty — nothing forward-filled, nothing left unsaid."""
    src = shared(f"c3d/{name}")
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(tmp_path / "o"), "--to", "trc"])
    assert r.exit_code in (0, 1) and "ERROR" not in r.output, r.output
    out = tmp_path / "o" / (src.stem + ".trc")
    report = json.loads((tmp_path / "o" / (src.stem + ".trc.report.json")).read_text())
    names, empty = _trc_empty(out)
    listed = np.zeros_like(empty)
    read = formats.read(src)
    for joint in report["joints"]:
        m = names.index(joint["name"])
        for run in joint["gaps"]["unfilled"]:
            assert run["filled_frames"] == 0, run
            listed[run["start"]:run["start"] + run["length"], m] = True
        for run in joint["removed"]:                   # judged wrong, no fill trusted
            listed[run["start"]:run["start"] + run["length"], m] = True
    for point in report.get("not_cleaned", []):          # left as read, gaps included
        if point["name"] in names:
            listed[:, names.index(point["name"])] = read.missing[:, read.names.index(point["name"])]
    assert empty.any() and report["file"]["samples_filled"] > 0
    assert np.array_equal(empty, listed), np.argwhere(empty != listed)[:5]


def test_a_trc_is_cleaned_as_its_c3d_is(tmp_path):
    """The shipped configs name the ``markers`` family: a TRC converted from a C3D gets the
    same steps, fills, flags and gaps left as the C3D itself."""
    src = shared("c3d/c3dorg_s28_dynamic.C3D")
    assert CliRunner().invoke(main, ["convert", str(src), "-o", str(tmp_path / "t"), "--to", "trc"]).exit_code == 0
    trc = tmp_path / "t" / "c3dorg_s28_dynamic.trc"
    for given, out in ((src, "a"), (trc, "b")):
        r = CliRunner().invoke(main, ["clean", str(given), "-o", str(tmp_path / out)])
        assert "ERROR" not in r.output, r.output
    a = json.loads((tmp_path / "a" / "c3dorg_s28_dynamic.C3D.report.json").read_text())
    b = json.loads((tmp_path / "b" / "c3dorg_s28_dynamic.trc.report.json").read_text())
    assert [s["skipped"] if "skipped" in s else None for s in b["steps"]] == \
        [s["skipped"] if "skipped" in s else None for s in a["steps"]]
    for key in ("samples_filled", "samples_flagged", "samples_left_uncertain", "missing_after"):
        assert a["file"][key] == b["file"][key], key
    assert a["file"]["samples_filled"] > 0
    ca, cb = formats.read(tmp_path / "a" / "c3dorg_s28_dynamic.C3D"), formats.read(tmp_path / "b" / "c3dorg_s28_dynamic.trc")
    assert np.array_equal(ca.missing, cb.missing)
    assert np.nanmax(np.abs(ca.positions - cb.positions)) < 0.01      # mm: float32 and %.5f


def test_only_what_the_format_cannot_carry_is_listed_as_not_carried(tmp_path):
    """A take whose clean adds notes of its own (two CMU takes joined: "the take jumps as a
    whole") lists under "not carried into c3d" only what C3D cannot hold; the cleaning's
    notes stay in the report, not in those lines."""
    a, b = (formats.read(shared(f"bvh/cmu_cgspeed_131_0{k}.bvh")) for k in (1, 3))
    joined = a.replace(channels=np.concatenate([a.channels[:600], b.channels[:600]]),
                       positions=np.concatenate([a.positions[:600], b.positions[:600]]))
    take = tmp_path / "in" / "joined.bvh"
    formats.write(joined, take)
    r = CliRunner().invoke(main, ["convert", str(take), "-o", str(tmp_path / "o"), "--to", "c3d",
                                  "--report", "json"])
    assert r.exit_code == 0, r.output
    carried = [line for line in r.output.splitlines() if "not carried into c3d" in line]
    assert carried and all("joint rotations" in line for line in carried), r.output
    notes = json.loads((tmp_path / "o" / "joined.c3d.report.json").read_text())["file"]["notes"]
    assert any("jumps as a whole" in n for n in notes) and any("joint rotations" in n for n in notes)
