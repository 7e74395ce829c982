"""Unlabelled trajectories are not markers to rebuild (mocapfix/pipeline/unlabelled.py): a Vicon
Plug-in Gait trial given five ``*N`` trajectories seen on one frame each, and ktk's racing
capture, whose Sternum is seen on 3 % of the take, are cleaned with those trajectories
passed through bit-identical (read back with py-c3d), not used as donors, not graded, and
listed with the reason; a config or a rules file can ask for them to be cleaned or judged."""
from __future__ import annotations

import json
import warnings

import c3d
import numpy as np
import pytest
from click.testing import CliRunner

from mocapfix import formats, read
from mocapfix.batch.check import check_motion
from mocapfix.cleaning import clean_file, clean_motion
from mocapfix.cli import main
from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion
from mocapfix.config import default_config_path, load_config, loads_config
from mocapfix.quality.report import build_report, to_html, to_markdown
from mocapfix.quality.rules import default_rules, load_rules, loads_rules
from mocapfix.pipeline.selection import not_cleaned, take
from mocapfix.pipeline.unlabelled import name_convention

from conftest import shared

PIG = "c3d/btk_PiG_Motion-FlatFoot-Hole.c3d"     # Vicon Nexus Plug-in Gait, float storage
EXTRAS = ["*3", "*4", "*8", "*9", "*10"]
DEFAULT = default_config_path().read_text()
#: the default with every fill written (its fill gate off)
EVERY_FILL = DEFAULT.replace("max_fill_error: 20 mm", "max_fill_error: null", 1)


def _with_extras(motion: Motion) -> Motion:
    """``motion``'s markers (not its model outputs, which a fresh C3D could not list as
    such) and the five trajectories, each seen on one frame 30 mm off a marker."""
    markers = np.array([k == "marker" for k in motion.kinds or ["marker"] * motion.n_joints])
    named = take(motion, markers)
    T = named.n_frames
    extra = np.full((T, len(EXTRAS), 3), np.nan)
    for k, frame in enumerate(np.linspace(0.15, 0.85, len(EXTRAS)) * T):
        frame = int(frame)
        extra[frame, k] = named.positions[frame, k] + [30.0, -20.0, 15.0]
    # no C3D source: the writer writes a fresh file with every point (a source describes
    # the file that was read, and is kept only for the same points and frames)
    return named.replace(positions=np.concatenate([named.positions, extra], axis=1),
                         names=named.names + EXTRAS, kinds=None, confidence=None, source=None)


@pytest.fixture(scope="module")
def pig(tmp_path_factory):
    """(the PiG trial as read, the path of the file with the five trajectories)."""
    original = read(shared(PIG))
    path = tmp_path_factory.mktemp("pig") / "pig_unlabelled.c3d"
    formats.write(_with_extras(original), path)
    return original, path


def _py_c3d(path):
    """(T, P, 5) records as py-c3d reads them (x, y, z, residual, camera mask) and labels."""
    with open(path, "rb") as handle, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = c3d.Reader(handle)
        frames = np.stack([points for _, points, _ in reader.read_frames()])
        labels = [s.strip() for s in reader.point_labels]
    return frames, labels


def test_the_written_file_holds_the_trajectories_as_built(pig):
    original, path = pig
    records, labels = _py_c3d(path)
    assert labels[-5:] == EXTRAS
    seen = records[:, -5:, 3] >= 0
    assert seen.sum(axis=0).tolist() == [1] * 5
    markers = [k == "marker" for k in original.kinds]
    # the named markers are the trial's, value for value (float storage: no rounding)
    assert np.array_equal(read(path).positions[:, :-5], original.positions[:, markers])


def test_cli_clean_passes_the_trajectories_through_bit_identical(pig, tmp_path):
    _, path = pig
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(path), "-o", str(out), "--report", "json,md,html"])
    assert r.exit_code == 0, r.output
    assert r.output.startswith("OK "), r.output
    before, labels = _py_c3d(path)
    after, labels_after = _py_c3d(out / path.name)
    assert labels_after == labels
    assert np.array_equal(after[:, -5:], before[:, -5:])        # values, residuals, masks
    report = json.loads((out / f"{path.name}.report.json").read_text())
    unlabelled = {p["name"]: p["why"] for p in report["not_cleaned"]}
    assert unlabelled == dict.fromkeys(EXTRAS, "unlabelled trajectory (Vicon *N name)")
    assert report["file"]["points_unlabelled"] == 5
    assert not set(EXTRAS) & {j["name"] for j in report["joints"]}
    md = (out / f"{path.name}.report.md").read_text()
    assert "## Unlabelled trajectories" in md and "| *10 | unlabelled trajectory (Vicon *N name) |" in md
    assert "<td>*10</td><td>unlabelled trajectory (Vicon *N name)</td>" in \
        (out / f"{path.name}.report.html").read_text()


@pytest.mark.slow
def test_named_markers_are_cleaned_as_without_the_trajectories(pig, tmp_path):
    """The Python path: the named markers come out of clean_file exactly as a clean of the
    original trial gives them, and the status is the original's."""
    original, path = pig
    pipe = load_config(default_config_path())
    plain = clean_motion(original, pipe)
    reference, ref_positions = build_report(plain, pipe.report), plain.cleaned.positions
    summary = clean_file(path, tmp_path / "out.c3d", pipe, reports=("json",))
    cleaned = read(tmp_path / "out.c3d")
    markers = [k == "marker" for k in original.kinds]
    assert np.array_equal(cleaned.positions[:, :-5], ref_positions[:, markers], equal_nan=True)
    assert summary["status"] == reference["file"]["status"] == "OK"
    report = json.loads((tmp_path / "out.c3d.report.json").read_text())
    assert report["file"]["joints_by_status"] == reference["file"]["joints_by_status"]
    reasons = " ".join(r for j in report["joints"] for r in j["reasons"])
    assert not any(name in reasons for name in EXTRAS)


@pytest.mark.slow
def test_unlabelled_trajectories_are_no_donors():
    """fill_pca rebuilds gaps from every marker it is given: the named markers of c3d.org's
    pc_real (7 % missing) come out the same whether the trajectories sit near the body or
    metres away (before, they moved the fills by up to 229 mm)."""
    m = read(shared("c3d/c3dorg_s02_pc_real.c3d"))
    near = _with_extras(m)
    far = near.replace(positions=near.positions.copy())
    far.positions[:, -5:] += [3000.0, -2000.0, 1500.0]
    # every fill written: fill_pca gives no error estimate, so the default fill gate
    # (max_fill_error) would leave its fills out
    pipe = loads_config("max_fill_error: null\npipeline:\n  - {cleaner: fill_pca, fill_ends: true}\n")
    out_near, out_far, alone = pipe.run(near)[0], pipe.run(far)[0], pipe.run(m)[0]
    assert (m.missing & ~out_near.missing[:, :-5]).sum() > 100           # it filled gaps
    assert np.array_equal(out_near.positions[:, :-5], out_far.positions[:, :-5], equal_nan=True)
    assert np.array_equal(out_near.positions[:, :-5], alone.positions, equal_nan=True)
    assert np.array_equal(out_far.positions[:, -5:], far.positions[:, -5:], equal_nan=True)


@pytest.mark.slow
def test_check_and_info_pass_over_them(pig):
    original, path = pig
    r = CliRunner().invoke(main, ["check", str(path), "-v"])
    assert r.exit_code == 0, r.output
    plain = check_motion(original, default_rules())["status"]
    assert r.output.split()[0] == plain == "OK"
    assert "not judged: 5 unlabelled trajectories (*3, *4, *8, *9, *10)" in r.output
    result = check_motion(read(path), default_rules())
    assert [u["name"] for u in result["file"]["unlabelled"]] == EXTRAS
    assert {j["name"] for j in result["joints"] if j.get("skipped")} == set(EXTRAS)
    info = CliRunner().invoke(main, ["info", str(path)])
    assert info.exit_code == 0
    assert "+ 5 unlabelled trajectories" in info.output
    assert "unlabelled  not cleaned or judged by default: *3 (Vicon *N name)" in info.output


@pytest.mark.slow
def test_a_config_can_clean_them_and_rules_can_judge_them(pig, tmp_path):
    _, path = pig
    cfg = tmp_path / "clean_unlabelled.yaml"
    # every fill written: a trajectory seen on 0.3 % of the take has no fill the default
    # fill gate (max_fill_error) would trust
    cfg.write_text(EVERY_FILL + "unlabelled:\n  clean: true\n")
    r = CliRunner().invoke(main, ["clean", str(path), "-o", str(tmp_path / "out"), "-c", str(cfg)])
    assert r.exit_code == 0, r.output
    before, after = read(path), read(tmp_path / "out" / path.name)
    assert before.missing[:, -5:].mean() > 0.99
    assert not after.missing[:, -5:].any()                       # filled again, as before
    report = json.loads((tmp_path / "out" / f"{path.name}.report.json").read_text())
    assert set(EXTRAS) <= {j["name"] for j in report["joints"]}
    assert report["file"]["status"] == "FAIL"                     # 99.7 % rebuilt
    rules = tmp_path / "judge.yaml"
    rules.write_text("version: 1\nextends: [default]\nunlabelled: {judge: true}\n")
    r = CliRunner().invoke(main, ["check", str(path), "-r", str(rules)])
    assert r.exit_code == 1 and "*3: 99.7 % missing" in r.output, r.output


@pytest.mark.slow
def test_rarely_seen_marker_is_left_alone_and_listed():
    """ktk's racing capture: Sternum is seen on 21 of its 700 frames; the default used to
    rebuild it over runs of 4.1 s. It is passed through as read and listed with its share;
    ``min_seen: 2 %`` makes it a marker to clean again."""
    motion = read(shared("c3d/ktk_racing_full.c3d"))
    j = motion.names.index("Sternum")
    seen = int((~motion.missing[:, j]).sum())
    assert seen == 21 and (~motion.missing).any(axis=1).all()   # the take: all 700 frames
    pipe = load_config(default_config_path())
    result = clean_motion(motion, pipe)
    assert np.array_equal(result.cleaned.positions[:, j], motion.positions[:, j], equal_nan=True)
    report = build_report(result, pipe.report)
    why = {p["name"]: p["why"] for p in report["not_cleaned"]}
    assert why == {"Sternum": "unlabelled trajectory (seen on 21 of 700 frames of the take, "
                              "3.0 % < 10 %)"}
    assert "| Sternum | unlabelled trajectory (seen on 21 of 700 frames" in to_markdown(report)
    assert "<td>Sternum</td>" in to_html(report, result)
    assert "Sternum" not in {j["name"] for j in report["joints"]}
    lower = loads_config(EVERY_FILL + "unlabelled: {min_seen: 2 %}\n")
    refilled = lower.run(motion)[0]
    assert refilled.missing[:, j].mean() < motion.missing[:, j].mean()
    # as shipped (the fill gate on), a marker seen on 3 % of the take gets no fill it can
    # trust: cleaned as a marker, it stays as missing as it was
    gated = loads_config(DEFAULT + "unlabelled: {min_seen: 2 %}\n").run(motion)[0]
    assert gated.missing[:, j].mean() == motion.missing[:, j].mean()


def test_no_named_marker_of_the_shared_captures_is_caught():
    """On every shared C3D file the rules catch HDM05's ``*0``-``*2`` by name and ktk's
    Sternum by its share, nothing else (the next-least-seen marker seen at all is seen on
    17.8 % of its take; markers never seen are left to the never_seen rule)."""
    from conftest import expected_names

    caught = {}
    for name in expected_names("c3d"):
        motion = read(shared(f"c3d/{name}"))
        for point, why in zip(motion.names, not_cleaned(motion)):
            if why and why.startswith("unlabelled"):
                caught[(name, point)] = why
    assert sorted(caught) == [("hdm05_HDM_mm_01-02_03_120.c3d", p) for p in ("*0", "*1", "*2")] \
        + [("ktk_racing_full.c3d", "Sternum")]
    # markers seen on 10-20 % of their take stay markers (numediart's LR_FME: 17.8 %)
    rolling = read(shared("c3d/numediart_03_rolling.c3d"))
    assert 0.1 < (~rolling.missing[:, rolling.names.index("LR_FME")]).mean() < 0.2


@pytest.mark.parametrize("name, convention", [
    ("*3", "Vicon *N name"), ("*12", "Vicon *N name"), ("Matt:*3", "Vicon *N name"),
    ("Unidentified 0007", "QTM Unidentified N name"), ("unidentified_12", "QTM Unidentified N name"),
    ("Unlabeled 1001", "Motive Unlabeled N name"), ("Unlabeled:1001", "Motive Unlabeled N name"),
    ("Unlabeled_1001", "Motive Unlabeled N name"), ("Unlabelled2", "Motive Unlabeled N name"),
    ("Rig:Unlabeled 5", "Motive Unlabeled N name"),
])
def test_vendor_names_are_recognised(name, convention):
    assert name_convention(name) == convention


@pytest.mark.parametrize("name", ["C7", "*", "*3a", "3", "LASI*", "Unlabeled", "Marker_1",
                                  "marker40", "Unidentified", "Matt:C7", "Channel101"])
def test_marker_names_are_not_taken_for_unlabelled(name):
    assert name_convention(name) is None


def _joints_renamed(motion: Motion) -> Motion:
    """``motion`` with its first joint named ``*3`` and its second seen on one frame."""
    positions = motion.positions.copy()
    positions[1:, 1] = np.nan
    return motion.replace(names=["*3", *motion.names[1:]], positions=positions)


@pytest.mark.parametrize("rel", ["kinect/kv2_laban_Ges01_wavehand.csv",
                                 "bvh/bvhpython_test_mocapbank.bvh", "asfamc/05_01.amc"])
def test_skeleton_joints_are_never_unlabelled(rel):
    """A Kinect body or a BVH/AMC rig has joints, not trajectories: a joint named like a
    Vicon trajectory or seen on one frame is still a joint to clean."""
    motion = _joints_renamed(read(shared(rel)))
    assert not any(w and w.startswith("unlabelled") for w in not_cleaned(motion))


def test_unlabelled_config_round_trips_and_bad_values_name_the_line():
    pipe = loads_config("unlabelled:\n  clean: true\n  min_seen: 5 %\npipeline: []\n")
    assert pipe.config()["unlabelled"] == {"clean": True, "min_seen": "5 %"}
    assert loads_config(pipe.dump()).config() == pipe.config()
    assert loads_config("pipeline: []\n").config()["unlabelled"] == {"clean": False,
                                                                      "min_seen": "10 %"}
    assert loads_config("unlabelled: {min_seen: 0.25}\npipeline: []\n").unlabelled.min_seen == 0.25
    bad = {
        "unlabelled:\n  clean: yes please\npipeline: []\n": r"cfg: unlabelled \(line 2\): 'clean' must be true or false",
        "unlabelled:\n  min_seen: 150 %\npipeline: []\n": r"cfg: unlabelled \(line 2\): min_seen must be a share",
        "pipeline: []\nunlabelled:\n  min_seen: -0.1\n": r"\(line 3\): min_seen must be",
        "unlabelled:\n  judge: true\npipeline: []\n": r"\(line 2\): unknown key\(s\) 'judge' \(known: clean, min_seen\)",
        "unlabelled: true\npipeline: []\n": r"'unlabelled' must be a mapping",
        "unlabeled: {clean: true}\npipeline: []\n": r"unknown top-level key\(s\) 'unlabeled'.*unlabelled",
    }
    for text, message in bad.items():
        with pytest.raises(ConfigError, match=message):
            loads_config(text, "cfg")


def test_rules_files_take_the_judge_knob(tmp_path):
    rules = loads_rules("version: 1\nunlabelled: {judge: true, min_seen: 1 %}\nrules: []\n")
    assert rules.unlabelled.clean and rules.unlabelled.min_seen == 0.01
    assert not default_rules().unlabelled.clean
    parent = tmp_path / "judging.yaml"
    parent.write_text("version: 1\nunlabelled: {judge: true}\nrules: []\n")
    child = tmp_path / "child.yaml"
    child.write_text(f"version: 1\nextends: [{parent}]\nrules: []\n")
    assert load_rules(child).unlabelled.clean                     # inherited
    child.write_text(f"version: 1\nextends: [{parent}]\nunlabelled: {{judge: false}}\n")
    assert not load_rules(child).unlabelled.clean                 # the file's own wins
    assert load_rules(parent).with_fail_on(["missing=20%"]).unlabelled.clean  # --fail-on keeps it
    with pytest.raises(ConfigError, match=r"rules: unlabelled \(line 3\): unknown key\(s\) 'clean'"):
        loads_rules("version: 1\nunlabelled:\n  clean: true\nrules: []\n", "rules")


def test_benchmarks_leave_unlabelled_trajectories_out_of_the_truth():
    """HDM05's *0-*2 are no markers any pipeline cleans by default: the bench (and the
    accuracy cases) measure methods on its 41 named markers, and say so."""
    from mocapfix import bench
    from mocapfix.pipeline.selection import without_unlabelled

    hdm = read(shared("c3d/hdm05_HDM_mm_01-02_03_120.c3d")).slice_frames(0, 240)
    named, dropped = without_unlabelled(hdm)
    assert dropped == ["*0", "*1", "*2"]
    assert named.names == hdm.names[3:] and np.array_equal(named.positions, hdm.positions[:, 3:])
    again, none_dropped = without_unlabelled(named)
    assert again is named and none_dropped == []
    none = [m for m in bench.resolve_methods([])[0] if m.name == "none"]
    result = bench.run([hdm], "occlusion", none, seeds=1, settings=["gaps"])
    assert any("3 unlabelled trajectories left out of the truth (*0, *1, *2)" in n
               for n in result.notes), result.notes


def test_the_steps_records_are_those_of_the_whole_take(pig):
    """What each step did is measured on the points the pipeline cleans alone when others
    sit beside them (a raw export's fragments: every step compared all 1,041 points of a
    take to clean 41); the records are the ones the whole take gives: each step's masks and
    distances against StepRecord.compare over every point, and nothing on the fragments."""
    from mocapfix.pipeline.steps import StepRecord

    _, path = pig
    motion = read(path)
    P = motion.positions.copy()
    P[100:130, 3] = P[200:206, 7] = np.nan            # gaps to fill, a spike to judge
    P[300, 5] += [80.0, 0.0, 0.0]
    motion = motion.replace(positions=P, source=None)
    pipe = load_config(default_config_path())
    kept = np.array([w is None for w in pipe.not_cleaned(motion)])
    assert not kept[-5:].any() and kept[:-5].all()
    before = motion
    for step in pipe.steps:
        if not step.applies(before):
            continue
        after, info = pipe._apply_step(step, before, kept)
        whole = StepRecord.compare(step, before, after, info, 0.0)
        alone = StepRecord.compare(step, before, after, info, 0.0, np.flatnonzero(kept))
        for key in ("filled", "flagged", "moved", "replaced"):
            assert np.array_equal(getattr(alone, key), getattr(whole, key)), (step.label, key)
        assert not whole.moved[:, -5:].any() and not whole.filled[:, -5:].any()
        before = after
    cleaned, records = pipe.run(motion)
    assert sum(int(r.filled.sum()) for r in records) >= 36   # the steps did something
    assert sum(int(r.outliers[300, 5]) for r in records) == 1
