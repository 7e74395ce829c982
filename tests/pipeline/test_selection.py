"""Only markers are cleaned: C3D model outputs (POINT:ANGLES, FORCES, MOMENTS, POWERS, ...)
pass through `mocapfix clean` bit-identical, and `markers:`/`exclude:` in a config keep the
named markers as they were, for one step or the whole pipeline."""
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from mocapfix import read
from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion
from mocapfix.config import loads_config
from mocapfix.cli import main

from conftest import SAMPLE_DATA, config_file, shared

C3D = SAMPLE_DATA / "walk_markers.c3d"
PIG = ["c3d/c3dorg_s09_PlugInC3D.c3d", "c3d/btk_PiG_Motion-FlatFoot-Hole.c3d"]


@pytest.mark.slow
@pytest.mark.parametrize("rel", PIG)
def test_model_outputs_are_bit_identical_after_clean(rel, tmp_path):
    path = shared(rel)
    before = read(path)
    assert before.kinds is not None
    model = np.array([k != "marker" for k in before.kinds])
    assert {"angle", "force", "moment", "power"} <= set(before.kinds)
    subprocess.run([sys.executable, "-m", "mocapfix.cli", "clean", str(path), "-o", str(tmp_path)],
                   check=True, capture_output=True)
    after = read(next(tmp_path.glob("*.c3d")))
    assert after.names == before.names
    # the stored point records (x, y, z, residual word) of every model output are unchanged
    assert np.array_equal(after.source.points[:, model].view(np.uint8),
                          before.source.points[:, model].view(np.uint8))
    # their gaps (which the marker fillers used to fill) are still gaps
    assert before.missing[:, model].any()
    assert np.array_equal(after.missing[:, model], before.missing[:, model])
    # while marker gaps, where the file has some, were filled
    if before.missing[:, ~model].any():
        assert (before.missing[:, ~model] & ~after.missing[:, ~model]).any()


def test_model_outputs_do_not_feed_the_marker_models():
    """A cleaner sees only the markers: its result on the markers is the same whether the
    file's model outputs hold their values or garbage."""
    m = read(shared(PIG[0]))
    model = np.array([k != "marker" for k in m.kinds])
    pipe = loads_config("pipeline:\n  - {cleaner: fill_pca, fill_ends: true}\n")
    out1, _ = pipe.run(m)
    noisy = m.positions.copy()
    noisy[:, model] = np.random.default_rng(0).normal(0, 1e4, noisy[:, model].shape)
    out2, _ = pipe.run(m.replace(positions=noisy))
    assert np.array_equal(out1.positions[:, ~model], out2.positions[:, ~model], equal_nan=True)
    assert np.array_equal(out2.positions[:, model], noisy[:, model])


def _gapped(T=120, J=6):
    t = np.linspace(0, 4 * np.pi, T)[:, None]
    pos = np.stack([100 * np.sin(t + np.arange(J)), 100 * np.cos(t + np.arange(J)),
                    np.tile(np.arange(J) * 50.0, (T, 1))], axis=2)
    pos[40:60, :] = np.nan
    names = ["LASI", "RASI", "Probe1", "Probe2", "LKNE", "RKNE"][:J]
    return Motion(pos, names, fps=100.0, format="c3d")


@pytest.mark.parametrize("where", ["pipeline", "step"])
def test_exclude_by_glob_keeps_markers_as_they_were(where):
    m = _gapped()
    step = "  - {cleaner: fill, method: linear, max_gap: 1 s"
    # every fill written: a straight line across a fifth of these sines' period is ~40 mm
    # off, which the default fill gate (max_fill_error) would rightly leave as a gap
    if where == "pipeline":
        text = f"max_fill_error: null\nexclude: ['Probe*']\npipeline:\n{step}}}\n"
    else:
        text = f"max_fill_error: null\npipeline:\n{step}, exclude: ['Probe*']}}\n"
    out, records = loads_config(text).run(m)
    probes = [2, 3]
    assert np.isnan(out.positions[40:60, probes]).all()
    others = [0, 1, 4, 5]
    assert not np.isnan(out.positions[:, others]).any()
    assert records[0].info["points_not_cleaned"] == 2


def test_markers_list_selects_names_and_patterns():
    m = _gapped()
    out, _ = loads_config("max_fill_error: null\nmarkers: [LASI, '*KNE']\npipeline:\n"
                          "  - {cleaner: fill, method: linear, max_gap: 1 s}\n").run(m)
    filled = ~np.isnan(out.positions[50]).any(axis=1)
    assert filled.tolist() == [True, False, False, False, True, True]
    assert loads_config("markers: [LASI]\npipeline:\n  - {cleaner: fill}\n").config()["markers"] == ["LASI"]


def test_bad_selection_is_a_config_error():
    with pytest.raises(ConfigError, match="'exclude' must be"):
        loads_config("pipeline:\n  - {cleaner: fill, exclude: 3}\n")


# -- the report grades only what was cleaned ------------------------------------------------

def _clean_report(path, config=None):
    from mocapfix.cleaning import clean_motion
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config
    from mocapfix.quality.report import build_report

    pipe = loads_config(config) if config else load_config(resolve_config("default"))
    motion = read(path)
    return motion, build_report(clean_motion(motion, pipe), pipe.report)


@pytest.mark.slow
@pytest.mark.parametrize("rel", PIG)
def test_report_lists_model_outputs_as_not_cleaned_and_grades_markers_only(rel):
    motion, report = _clean_report(shared(rel))
    model = [n for n, k in zip(motion.names, motion.kinds) if k != "marker"]
    markers = [n for n, k in zip(motion.names, motion.kinds) if k == "marker"]
    assert [j["name"] for j in report["joints"]] == markers
    assert [p["name"] for p in report["not_cleaned"]] == model
    kinds = dict(zip(motion.names, motion.kinds))
    assert all(p["why"] == f"model output ({kinds[p['name']]})" for p in report["not_cleaned"])
    f = report["file"]
    assert f["joints"] == len(markers) and f["points_not_cleaned"] == len(model)
    is_marker = np.array([k == "marker" for k in motion.kinds])
    # over the take: from the first to the last frame where a marker is seen
    seen = np.flatnonzero((~motion.missing[:, is_marker]).any(axis=1))
    take = motion.missing[seen[0]:seen[-1] + 1, is_marker]
    assert f["missing_before"] == pytest.approx(take.mean(), abs=1e-6)
    # no finding names a model output, however much of it is missing
    assert motion.missing[:, ~is_marker].mean(axis=0).max() > 0.2
    reasons = " ".join(r for j in report["joints"] for r in j["reasons"])
    assert not any(n in reasons for n in model)


@pytest.mark.slow
def test_pig_walk_with_complete_markers_is_ok():
    """btk's PiG walk: every marker complete, forces/moments/powers missing outside the
    force-plate contacts. It used to FAIL on 'LAnkleForce 24.1 % still missing'."""
    motion, report = _clean_report(shared(PIG[1]))
    is_marker = np.array([k == "marker" for k in motion.kinds])
    assert not motion.missing[:, is_marker].any()
    assert report["file"]["status"] == "OK"
    assert report["file"]["joints_by_status"] == {"OK": int(is_marker.sum()), "WARN": 0, "FAIL": 0}


@pytest.mark.slow
def test_pipeline_exclude_takes_markers_out_of_the_grading():
    """ktk's racing capture has six calibration probes never seen in the trial: excluded
    for the whole pipeline they are listed as such, not rebuilt, and do not fail the file."""
    path = shared("c3d/ktk_racing_full.c3d")
    motion, plain = _clean_report(path)
    probes = [f"Probe{k}" for k in range(1, 7)]
    assert all(motion.missing[:, motion.names.index(p)].all() for p in probes)
    failing = {j["name"] for j in plain["joints"] if j["status"] == "FAIL"}
    assert set(probes) <= failing
    _, excluded = _clean_report(path, "exclude: ['Probe*']\npipeline:\n"
                                "  - {cleaner: fill, method: linear, max_gap: 0.5 s}\n")
    why = {p["name"]: p["why"] for p in excluded["not_cleaned"]}
    assert {n: why[n] for n in probes} == dict.fromkeys(probes, "excluded by the config")
    # the file's other point left alone: Sternum, seen on 3 % of the take (tests/pipeline/test_unlabelled.py)
    assert set(why) - set(probes) == {"Sternum"}
    assert not set(why) & {j["name"] for j in excluded["joints"]}
    assert excluded["file"]["joints"] == motion.n_joints - 7


@pytest.mark.slow
def test_markdown_report_names_what_was_not_cleaned():
    from mocapfix.quality.report import to_markdown

    _, report = _clean_report(shared(PIG[0]))
    md = to_markdown(report)
    assert "## Not cleaned (passed through unchanged, not graded)" in md
    assert "8 × model output (force): LGroundReactionForce" in md
    assert "(32 more points not cleaned: see below)" in md


@pytest.mark.slow
def test_check_passes_over_model_outputs_whatever_their_names():
    """`check` judges markers: a rule without name patterns does not see the model outputs
    (the shipped optical-gait rules also exclude them by name, for files that do not list
    them in POINT:ANGLES/...)."""
    from mocapfix.batch.check import check_motion
    from mocapfix.quality.rules import loads_rules

    motion = read(shared(PIG[1]))
    rules = loads_rules("version: 1\nrules:\n  - {metric: missing, fail: 0 %}\n"
                        "  - {metric: missing, scope: file, fail: 0 %, name: file-missing}\n")
    result = check_motion(motion, rules)
    assert result["status"] == "OK", result["findings"][:2]
    skipped = [j["name"] for j in result["joints"] if j.get("skipped")]
    assert skipped == [n for n, k in zip(motion.names, motion.kinds) if k != "marker"]
    assert result["file"]["missing"] == 0.0
    # the same rule does fail a marker that misses samples
    gappy = motion.positions.copy()
    gappy[:10, motion.kinds.index("marker")] = np.nan
    assert check_motion(motion.replace(positions=gappy), rules)["status"] == "FAIL"


@pytest.mark.slow
def test_a_result_built_without_the_pipeline_still_skips_model_outputs():
    """measure_cleaning works the model outputs out from the motion when the caller did
    not say what the pipeline left alone (library users, benchmark scripts)."""
    from mocapfix.quality.measure import CleanResult
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config
    from mocapfix.quality.report import build_report

    motion = read(shared(PIG[1]))
    pipe = load_config(resolve_config("default"))
    report = build_report(CleanResult(motion, *pipe.run(motion)), pipe.report)
    markers = [n for n, k in zip(motion.names, motion.kinds) if k == "marker"]
    assert [j["name"] for j in report["joints"]] == markers
    assert report["file"]["status"] == "OK"


def test_a_selection_that_picks_no_marker_warns():
    """A mistyped markers: list must not read as a clean pass."""
    _, report = _clean_report(shared("c3d/c3dorg_s02_pc_real.c3d"),
                              "markers: ['NoSuchMarker*']\npipeline:\n  - {cleaner: fill}\n")
    assert report["file"]["joints"] == 0 and report["file"]["status"] == "WARN"
    assert any("leave none of this file's markers" in n for n in report["file"]["notes"])


# -- BVH/AMC rigs: a joint left out keeps its own curves ------------------------------------

def _spiked_bandai():
    """The Bandai walk with 20° glitches on the left hand's and the left lower arm's first
    rotation channel (frames 40 and 80)."""
    motion = read(shared("bvh/bandai_dataset-1_walk_normal_001.bvh"))
    ch = motion.channels.copy()
    rig = motion.rig
    for name in ("Hand_L", "LowerArm_L"):
        col = rig.rot_columns[rig.names.index(name)][0]
        ch[[40, 80], col] += 20.0
    return motion.replace(channels=ch, positions=rig.positions(ch)), ch


@pytest.mark.parametrize("where", ["pipeline", "step"])
def test_a_rig_joint_left_out_keeps_its_channels_and_the_others_are_cleaned(where):
    # selections were refused on BVH/AMC ("select markers of marker data, not joints of a
    # bvh rig"): an animator could not keep the hands' curves out of the cleaning
    motion, ch = _spiked_bandai()
    rig = motion.rig
    step = "  - {cleaner: rotation_outliers, threshold: 16"
    text = (f"exclude: ['Hand_*']\npipeline:\n{step}}}\n" if where == "pipeline"
            else f"pipeline:\n{step}, exclude: ['Hand_*']}}\n")
    out, records = loads_config(text).run(motion)
    hand = list(rig.rot_columns[rig.names.index("Hand_L")])
    arm = list(rig.rot_columns[rig.names.index("LowerArm_L")])
    assert np.array_equal(out.channels[:, hand], ch[:, hand])          # glitches and all
    clean = read(shared("bvh/bandai_dataset-1_walk_normal_001.bvh")).channels
    assert np.abs(out.channels[[40, 80], arm[0]] - clean[[40, 80], arm[0]]).max() < 2.0
    assert np.allclose(out.positions, rig.positions(out.channels))
    assert "Hand_L" not in records[0].info.get("replaced_frames", {})
    assert "LowerArm_L" in records[0].info["replaced_frames"]
    assert records[0].info["points_not_cleaned"] == 4                  # Hand_L/R and their ends


def test_a_position_step_on_a_rig_keeps_the_left_out_joints_channels():
    from mocapfix.cleaning import clean_motion

    motion, ch = _spiked_bandai()
    rig = motion.rig
    pipe = loads_config("pipeline:\n  - {cleaner: gaussian, sigma: 2 frames, exclude: ['Hand_L']}\n")
    result = clean_motion(motion, pipe)
    hand = list(rig.rot_columns[rig.names.index("Hand_L")])
    arm = list(rig.rot_columns[rig.names.index("LowerArm_L")])
    assert np.array_equal(result.cleaned.channels[:, hand], ch[:, hand])
    assert np.abs(result.cleaned.channels[:, arm] - ch[:, arm]).max() > 1.0   # smoothed


@pytest.mark.slow
@pytest.mark.parametrize("where", ["pipeline", "step", "above", "markers", "child", "child-step"])
def test_flag_then_fill_still_repairs_a_rig_when_joints_are_left_out(where):
    # the first version wrote the flagging step's positions back at once: its flagged
    # (missing) samples became the old rotations' positions again, the fill after it had
    # nothing to fill, and a 60° knee glitch stayed in the file as soon as any joint was
    # excluded
    from mocapfix.cleaning import clean_motion

    truth = read(shared("bvh/cmu_cgspeed_131_01.bvh"))
    rig = truth.rig
    ch = truth.channels.copy()
    ch[500:503, rig.rot_columns[rig.names.index("RightKnee")][0]] += 60.0
    glitched = truth.replace(channels=ch, positions=rig.positions(ch))
    # "above": the glitched knee hangs below the excluded hip; "markers": the root is left
    # out (every joint hangs below it), and the flags below it were lost
    # "child": the joint below the glitched knee is excluded, and its thrown-off samples are
    # the only evidence of the glitch (they were dropped, and the report said OK)
    sel = {"pipeline": "exclude: ['Left*']\n", "above": "exclude: ['RightHip']\n",
           "markers": "markers: ['Right*']\n", "child": "exclude: ['RightAnkle']\n"}.get(where, "")
    step = "['RightAnkle']" if where == "child-step" else "['Left*']"
    text = (f"{sel}pipeline:\n  - cleaner: spikes\n  - cleaner: fill\n" if sel
            else f"pipeline:\n  - {{cleaner: spikes, exclude: {step}}}\n  - cleaner: fill\n")
    plain = clean_motion(glitched, loads_config("pipeline:\n  - cleaner: spikes\n  - cleaner: fill\n"))
    result = clean_motion(glitched, loads_config(text))
    ankle = rig.names.index("RightAnkle")
    before = np.abs(glitched.positions[500:503, ankle] - truth.positions[500:503, ankle]).max()
    after = np.abs(result.cleaned.positions[500:503, ankle] - truth.positions[500:503, ankle]).max()
    assert after < 0.05 * before
    kept = {"above": ("RightHip",), "markers": tuple(n for n in rig.names if not n.startswith("Right")),
            "child": ("RightAnkle",)}
    names = kept.get(where, tuple(n for n in rig.names if n.startswith("Left")))
    left = [int(c) for j, n in enumerate(rig.names) if n in names for c in rig.rot_columns[j]]
    assert np.array_equal(result.cleaned.channels[:, left], ch[:, left])
    if where in ("pipeline", "step"):
        assert np.nanmax(result.writeback_residual) == pytest.approx(np.nanmax(plain.writeback_residual))


def test_a_selection_that_matches_nothing_says_why_it_warns(tmp_path):
    # markers: ["NoSuch*"] leaves nothing to clean: the file WARNs (report note), but the
    # line gave no reason, even with -v
    cfg = config_file(tmp_path, "version: 1\nmarkers: [\"NoSuch*\"]\npipeline:\n  - cleaner: fill\n")
    r = CliRunner().invoke(main, ["clean", str(C3D), "-o", str(tmp_path / "out"), "-c", cfg, "-v"])
    assert r.exit_code == 0, r.output
    lines = r.output.splitlines()
    assert lines[0].startswith("WARN")
    assert "leave none of this file's markers to clean" in lines[1], r.output
