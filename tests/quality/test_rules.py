"""The rule engine on known answers: thresholds with units, scope, format filters,
include/exclude, validation errors with line numbers, the report section of configs."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from mocapfix.quality.measure import CleanResult
from mocapfix.pipeline.steps import StepRecord
from mocapfix.core.errors import ConfigError
from mocapfix.quality.measure import measure_input
from mocapfix.core.motion import Motion
from mocapfix.config import loads_config
from mocapfix.quality.report import build_report
from mocapfix.quality.rules import default_rules, load_rules, loads_rules, preset_names, RULES_DIR


def _motion(fmt="c3d"):
    T, fps = 300, 100.0
    t = np.arange(T) / fps
    pos = np.stack([np.stack([1000 * t, np.full(T, 100.0 * j), np.full(T, 900.0)], 1)
                    for j in range(3)], axis=1)
    pos[100:160, 1] = np.nan          # B: one 0.6 s gap, 20 % missing
    pos[:, 2] = np.nan                # C: never seen
    return Motion(pos, ["A", "B", "C"], fps, units="mm", metres_per_unit=0.001, format=fmt)


def test_measure_input_known_answers():
    m = measure_input(_motion())
    a, b, c = m["joints"]
    assert a["missing"] == 0 and b["missing"] == pytest.approx(0.2) and c["missing"] == 1.0
    assert b["gaps"] == 1 and b["longest_gap_s"] == pytest.approx(0.6)
    assert c["never_seen"] and m["file"]["never_seen"] == ["C"]
    assert a["outliers"] == 0 and a["jitter"] == pytest.approx(0.0, abs=1e-9)   # a straight line


def test_thresholds_scope_and_filters():
    rules = loads_rules("""
rules:
  - metric: missing
    warn: 10 %
    fail: 50 %
    exclude: [C]
  - metric: longest_gap
    fail: 50 frames
  - metric: never_seen
    scope: file
    fail: 0
    formats: [kinect]
""")
    verdict = rules.judge(measure_input(_motion()))
    got = {(f.rule, f.joint, f.level) for f in verdict.findings}
    # B is 20 % missing → WARN; C excluded from the missing rule; C's longest gap is the
    # whole take (3 s) and B's 0.6 s = 60 frames > 50 frames → FAIL; never_seen only for Kinect
    assert got == {("missing", "B", "WARN"), ("longest_gap", "B", "FAIL"), ("longest_gap", "C", "FAIL")}
    assert verdict.status == "FAIL"
    kin = rules.judge(measure_input(_motion("kinect")))
    assert ("never_seen", None, "FAIL") in {(f.rule, f.joint, f.level) for f in kin.findings}


def test_file_scope_aggregates_selected_joints():
    rules = loads_rules("rules:\n  - {metric: missing, scope: file, fail: 30 %, include: [A, B]}\n")
    assert rules.judge(measure_input(_motion())).status == "OK"      # (0 + 20 %) / 2
    rules = loads_rules("rules:\n  - {metric: missing, scope: file, fail: 30 %}\n")
    assert rules.judge(measure_input(_motion())).status == "FAIL"    # C counts: 40 %


@pytest.mark.parametrize("text, pattern", [
    ("rules:\n  - metric: missing\n    warn_missing: 5 %\n", r"line 3.*unknown key.*warn_missing"),
    ("rules:\n  - metric: nope\n    warn: 1\n", r"line 2.*unknown metric 'nope'"),
    ("rules:\n  - metric: longest_gap\n    warn: 5\n", r"needs a unit"),
    ("rules:\n  - metric: missing\n    warn: .nan\n", r"not a finite number"),
    ("rules:\n  - metric: missing\n    warn: 5\n", r"fraction above 1"),
    ("rules:\n  - metric: missing\n    fail: 200 %\n", r"above 100 %.*could never fire"),
    ("rules:\n  - metric: dropped_frames\n    scope: joint\n    fail: 0\n", r"per file only"),
    ("rules:\n  - metric: missing_after\n    fail: 1 %\n", r"clean's report"),
    ("rules:\n  - metric: missing\n", r"needs 'warn' or 'fail'"),
    ("version: 1\nrule: []\n", r"line 2.*unknown top-level key"),
    ("", r"r.yaml: a rules file is a mapping with 'rules'"),      # empty: judged all OK
    ("# nothing yet\n", r"a rules file is a mapping"),
    ("rules:\n  - metric: missing\n    fail: 1 %\n    formats: [fbx]\n", r"formats"),
])
def test_rules_validation_names_the_line(text, pattern):
    with pytest.raises(ConfigError, match=pattern):
        loads_rules(text, "r.yaml")


def test_rules_with_an_empty_list_judge_nothing():
    assert loads_rules("rules: []\n", "r.yaml").rules == []


def test_shipped_rule_sets_load():
    assert set(preset_names()) >= {"default", "optical-gait", "kinect", "animation-bvh"}
    for name in preset_names():
        assert len(load_rules(RULES_DIR / f"{name}.yaml")) > 0
    from mocapfix.formats import NAMES

    # every format is judged by the default rules (a marker family rule covers TRC too)
    assert {f for f in NAMES if any(r.applies(f) for r in default_rules().rules)} == set(NAMES)
    assert default_rules().rules[0].applies("trc") and not default_rules().rules[0].applies("bvh")


@pytest.mark.parametrize("text, pattern", [
    ("pipeline: []\nreport:\n  warn_missing: 0.1\n", r"line 3.*unknown key 'warn_missing'"),
    ("pipeline: []\nreport:\n  fail_missing_after: .nan\n", r"finite number"),
    ("pipeline: []\nreport:\n  fail_missing_after: 5\n", r"fraction in \[0, 1\]"),
    ("pipeline: []\nreport:\n  rules:\n    - {metric: missing, fail: 1 %}\n", r"belongs to `check`"),
])
def test_config_report_section_is_validated(text, pattern):
    with pytest.raises(ConfigError, match=pattern):
        loads_config(text)


def test_uncertain_rule_grades_a_marker_rebuilt_from_little_data():
    T, fps = 400, 100.0
    t = np.arange(T) / fps
    a = np.stack([1000 * t, np.zeros(T), np.full(T, 900.0)], 1)
    truth = np.stack([a, a + [0, 0, -400.0], a + [0, 200.0, 0]], axis=1)
    pos = truth.copy()
    pos[12:, 1] = np.nan               # B seen in 3 % of frames, then lost
    motion = Motion(pos, ["A", "B", "C"], fps, units="mm", metres_per_unit=0.001, format="c3d")
    # a step that rebuilt B completely (as a PCA fill from A and C would)
    step = loads_config("pipeline:\n  - cleaner: fill\n").steps[0]
    rebuilt = motion.replace(positions=truth.copy())
    # every point cleaned, as with `unlabelled: {clean: true}` (by default a marker seen on
    # 3 % of the take is an unlabelled trajectory, left alone: tests/pipeline/test_unlabelled.py)
    result = CleanResult(motion, rebuilt, [StepRecord.compare(step, motion, rebuilt, {}, 0.0)],
                         not_cleaned=[None] * 3)
    assert not result.cleaned.missing[:, 1].any()         # looks complete after cleaning…
    report = build_report(result)
    b = next(j for j in report["joints"] if j["name"] == "B")
    assert b["missing_after"] == 0.0
    assert b["uncertain"] == pytest.approx(0.97)          # …but 97 % of it was rebuilt
    assert b["status"] == "FAIL" and any("uncertain (missing in the input" in r for r in b["reasons"])
    assert report["joints"][0]["status"] == "OK"
    # a fill confidence on the cleaned motion, where present, lowers the uncertainty
    conf = np.ones((T, 3))
    conf[12:, 1] = 0.9
    result.cleaned.confidence = conf
    assert build_report(result)["joints"][1]["uncertain"] == pytest.approx(0.097)
    assert math.isfinite(b["uncertain"])


ROOT_MOTION_BVH = """HIERARCHY
ROOT Ground
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Hips
  {
    OFFSET 0 90 0
    CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
    JOINT Spine
    {
      OFFSET 0 10 0
      CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 40 0
      }
    }
  }
}
MOTION
Frames: 4
Frame Time: 0.01
0 0 0 0 0 0 0 90 0 0 0 0 0 10 0 0 0 0
0 0 0 0 0 0 50 92 0 0 0 0 0 10 0 30 0 0
0 0 0 0 0 0 100 90 0 0 0 0 0 10 0 60 0 0
0 0 0 0 0 0 150 88 0 0 0 0 0 10 0 90 0 0
"""


def test_bones_a_file_animates_by_translation_are_not_judged(tmp_path):
    # a root-motion node at the floor with the hips travelling 1.5 m about it (the Bandai
    # BVH files): the "bone" from it to the hips grew 90 -> 175 cm and the check WARNed
    # "Hips: bone length varies by 45 %"; the spine, whose position channels hold still,
    # is a segment and is judged
    from mocapfix import formats
    from mocapfix.quality.measure import bone_variation, bones_of

    path = tmp_path / "root_motion.bvh"
    path.write_text(ROOT_MOTION_BVH)
    motion = formats.read(path)
    names = motion.names
    judged = {(names[a], names[b]) for a, b in bones_of(motion)}
    assert ("Ground", "Hips") not in judged
    assert ("Hips", "Spine") in judged and ("Spine", "Spine_End") in judged
    assert np.nanmax(bone_variation(motion.positions, motion.skeleton.bone_array)) > 0.2
    assert np.nanmax(bone_variation(motion.positions, bones_of(motion))) < 1e-9
    result = measure_input(motion)
    assert not (result["file"].get("bone_variation") or 0.0) > 1e-9


def test_bandai_root_motion_is_not_a_varying_bone():
    from conftest import shared
    from mocapfix import formats

    for name in ("bandai_dataset-1_walk_normal_001.bvh", "bandai_dataset-2_run_normal_001.bvh"):
        motion = formats.read(shared(f"bvh/{name}"))
        verdict = default_rules().judge(measure_input(motion))
        assert [f for f in verdict.findings if f.rule == "bone_variation"] == [], name


def test_extends_adds_the_parent_rules_and_refuses_a_circle(tmp_path):
    """'extends' puts a preset's or a file's rules before the file's own; a file that
    extends itself, directly or through another, is an error naming the circle (it said
    "nests too deep"), and so is a chain of more than five files."""
    own = "rules:\n  - {metric: missing, fail: 90 %}\n"
    (tmp_path / "child.yaml").write_text("version: 1\nextends: default\n" + own)
    child = load_rules(tmp_path / "child.yaml")
    assert len(child) == len(default_rules()) + 1
    (tmp_path / "grandchild.yaml").write_text("version: 1\nextends: child.yaml\n" + own)
    assert len(load_rules(tmp_path / "grandchild.yaml")) == len(child) + 1
    (tmp_path / "self.yaml").write_text("version: 1\nextends: self.yaml\n" + own)
    with pytest.raises(ConfigError, match=r"goes round in a circle: .*self.yaml -> .*self.yaml"):
        load_rules(tmp_path / "self.yaml")
    (tmp_path / "a.yaml").write_text("version: 1\nextends: b.yaml\n" + own)
    (tmp_path / "b.yaml").write_text("version: 1\nextends: a.yaml\n" + own)
    with pytest.raises(ConfigError, match=r"circle: .*a.yaml -> .*b.yaml -> .*a.yaml"):
        load_rules(tmp_path / "a.yaml")
    for k in range(7):
        parent = f"extends: r{k + 1}.yaml\n" if k < 6 else ""
        (tmp_path / f"r{k}.yaml").write_text(f"version: 1\n{parent}" + own)
    with pytest.raises(ConfigError, match="nests too deep"):
        load_rules(tmp_path / "r0.yaml")


@pytest.mark.parametrize("text, cause", [
    ("version: 1\nrules:\n  - metric: fps\n    warn: 100 Hz\n    fail: 200 Hz\n",
     "rule 1 (line 3): warn 100 Hz is beyond fail 200 Hz"),
    ("version: 1\nrules:\n  - metric: missing\n    warn: 30%\n    fail: 10%\n",
     "rule 1 (line 3): warn 30.0 % is beyond fail 10.0 %"),
])
def test_a_rule_whose_warn_lies_beyond_its_fail_is_a_config_error(text, cause):
    """FAIL is checked first, so such a rule would silently never warn."""
    with pytest.raises(ConfigError, match=re.escape(cause)):
        loads_rules(text)
    warn, fail = re.findall(r"(?:warn|fail): (.*)", text)
    swapped = text.replace(f"warn: {warn}", "WARN").replace(f"fail: {fail}", f"warn: {fail}")
    assert len(loads_rules(swapped.replace("WARN", f"fail: {warn}"))) == 1


def test_report_thresholds_that_could_never_warn_are_a_config_error():
    head = "version: 1\npipeline: []\nreport:\n"
    with pytest.raises(ConfigError, match="line 4.*warn_missing_after 0.5 is above "
                                          "fail_missing_after 0.01"):
        loads_config(head + "  warn_missing_after: 0.5\n  fail_missing_after: 0.01\n")
    with pytest.raises(ConfigError, match=r"0\.1 \(the default; set fail_missing_after too\)"):
        loads_config(head + "  warn_missing_after: 0.5\n")
    assert loads_config(head + "  warn_missing_after: 0.5\n  fail_missing_after: 0.6\n").report
