"""An AMC is written beside a copy of the ASF it was read with: two AMCs never share an
output skeleton they do not have in common (other bones, other letter case, an ASF
named as an input), an edited ASF replaces its old copy only when no other output
there uses it, and a copy missing after a killed run is written again."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from mocapfix.cli import main

from conftest import SAMPLE_DATA, config_file, md5_tree, no_traceback, shared


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
    before = md5_tree(tmp_path)
    cfg = config_file(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
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
    assert md5_tree(x.parent) == {k: v for k, v in before.items() if k.parent == x.parent}
    assert md5_tree(y.parent) == {k: v for k, v in before.items() if k.parent == y.parent}


@pytest.mark.slow
def test_an_edited_asf_is_written_over_its_old_copy_that_only_this_amc_uses(tmp_path):
    # x_01 cleaned, then its ASF edited (longer bones) and x_01 cleaned again with
    # --overwrite: the run stopped on "out/walker.asf holds another ASF, which other AMC
    # files there use", though the only AMC there was x_01's own earlier output
    import re

    from mocapfix import formats

    x, _ = _two_subjects(tmp_path)
    cfg = config_file(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
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
    kept = md5_tree(out)
    r = CliRunner().invoke(main, ["clean", str(x), "-o", str(out), "-c", cfg, "--overwrite"])
    no_traceback(r)
    assert r.exit_code == 2 and "holds another ASF" in r.output and "x_02.amc" in r.output, r.output
    assert md5_tree(out) == kept        # refused before any work: x_01's earlier output stays
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
    kept = md5_tree(out)
    r = CliRunner().invoke(main, ["clean", str(x), str(x.parent / "x_02.amc"), "-o", str(out),
                                  "-c", cfg, "--skip-existing"])
    no_traceback(r)
    assert r.exit_code == 2 and "holds another ASF" in r.output and "x_02.amc" in r.output, r.output
    assert md5_tree(out) == kept


@pytest.mark.slow
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
    cfg = config_file(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
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
    cfg = config_file(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(x), str(y), "-o", str(out), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2 and "differ" in r.output, r.output
    assert CliRunner().invoke(main, ["clean", str(x), "-o", str(out), "-c", cfg]).exit_code == 0
    kept = md5_tree(out)
    r = CliRunner().invoke(main, ["clean", str(y), "-o", str(out), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2 and "could not be read back" in r.output, r.output
    assert md5_tree(out) == kept
    assert abs(formats.read(out / x.name).positions - formats.read(x).positions).max() < 1e-6
    # another name altogether, in one run: each AMC found the only .asf of its folder, and
    # with both copies side by side neither output could be read back
    (y.parent / "WALKER.ASF").rename(y.parent / "runner.asf")
    r = CliRunner().invoke(main, ["clean", str(x), str(y), "-o", str(tmp_path / "o3"), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2 and "could not be read back" in r.output, r.output
    assert not (tmp_path / "o3").exists()


@pytest.mark.slow
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
    cfg = config_file(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
    out = tmp_path / "out"
    assert CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", cfg]).exit_code == 0
    (out / "05.asf").unlink()
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", cfg, "--overwrite"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    for amc in ("05_01.amc", "13_39.amc"):
        got, want = formats.read(out / amc), formats.read(src / amc)
        assert got.n_joints == want.n_joints and abs(got.positions - want.positions).max() < 1e-6


@pytest.mark.slow
def test_one_asf_in_two_letter_cases_with_the_same_content_is_not_refused(tmp_path):
    # a/05.ASF and b/05.asf hold the same skeleton: the plan let them share one copy, and
    # then refused 05_10 because out/05.ASF, a copy not written yet, could not be read
    from mocapfix import formats

    for sub, asf, amc in (("a", "05.ASF", "05_01.amc"), ("b", "05.asf", "05_10.amc")):
        (tmp_path / sub).mkdir()
        shutil.copy(shared("asfamc/05.asf"), tmp_path / sub / asf)
        shutil.copy(shared(f"asfamc/{amc}"), tmp_path / sub / amc)
    cfg = config_file(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
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
    cfg = config_file(tmp_path, "version: 1\npipeline: []\n", "none.yaml")
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
    kept = md5_tree(out)
    for extra in (["--dry-run"], []):
        r = CliRunner().invoke(main, ["clean", str(other), "-o", str(out), "-c", cfg, *extra])
        no_traceback(r)
        assert r.exit_code == 2 and "05_01.amc (read with 05.asf)" in r.output, r.output
    assert md5_tree(out) == kept
    # the writer alone (the Python API) refuses it too
    from mocapfix import formats
    from mocapfix.core.errors import WriteError

    with pytest.raises(WriteError, match="read with 05.asf"):
        formats.write(formats.read(other), out / "05_01.asf")
    assert md5_tree(out) == kept
