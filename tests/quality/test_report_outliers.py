"""Samples a step judges wrong and rebuilds in place (a BVH rotation spike re-made, a
Kinect glitch replaced) are counted as outliers in the report, and a large move they
cause is explained: on real files with one glitch put in by hand."""
from __future__ import annotations

import numpy as np
import pytest

from mocapfix import formats
from mocapfix.cleaning import clean_motion
from mocapfix.config import loads_config
from mocapfix.quality.report import build_report
from conftest import shared


def _joint(report, name):
    return next(j for j in report["joints"] if j["name"] == name)


@pytest.mark.slow
def test_a_rotation_spike_is_an_outlier_of_its_joint_and_explains_the_move_below_it():
    m = formats.read(shared("bvh/cmu_cgspeed_131_01.bvh"))
    elbow = m.names.index("LeftElbow")
    ch = m.channels.copy()
    ch[500:502, m.rig.rot_columns[elbow][0]] += 40.0          # a 2-frame 40° glitch
    spiked = m.replace(channels=ch, positions=m.rig.positions(ch))
    pipe = loads_config("pipeline:\n  - cleaner: rotation_outliers\n")
    before = build_report(clean_motion(m, pipe), pipe.report)      # its own re-makes
    assert "LeftElbow" not in before["steps"][0]["info"]["joints"]
    report = build_report(clean_motion(spiked, pipe), pipe.report)
    step = report["steps"][0]
    assert step["info"]["joints"]["LeftElbow"] == 2
    assert step["info"]["replaced_frames"]["LeftElbow"] == [500, 501]
    assert step["flagged"] == before["steps"][0]["flagged"] + 2
    assert report["file"]["samples_flagged"] == before["file"]["samples_flagged"] + 2
    assert _joint(report, "LeftElbow")["outliers_flagged"] == 2
    wrist = _joint(report, "LeftWrist")
    assert wrist["outliers_flagged"] == 0
    assert wrist["correction_mm"]["frame"] in (500, 501) and wrist["correction_mm"]["max"] > 50
    assert wrist["status"] == "WARN"
    assert "where LeftElbow was judged an outlier and rebuilt" in " ".join(wrist["reasons"])


@pytest.mark.slow
def test_a_kinect_glitch_replaced_in_place_is_counted_and_named():
    m = formats.read(shared("kinect/kv2_laban_Ges03_drawlines.csv"))
    pipe = loads_config("pipeline:\n  - cleaner: kinect_skeleton\n")
    before = build_report(clean_motion(m, pipe), pipe.report)
    elbow = m.names.index("ElbowLeft")
    frame = int(np.flatnonzero(m.confidence[:, elbow] >= 1.0)[100])   # a Tracked sample
    pos = m.positions.copy()
    pos[frame, elbow] += np.array([0.0, 0.35, 0.0]) / m.metres_per_unit   # 35 cm up
    report = build_report(clean_motion(m.replace(positions=pos), pipe), pipe.report)
    glitched = _joint(report, "ElbowLeft")
    assert frame in report["steps"][0]["info"]["replaced_frames"]["ElbowLeft"]
    assert glitched["outliers_flagged"] == _joint(before, "ElbowLeft")["outliers_flagged"] + 1
    assert glitched["correction_mm"]["frame"] == frame
    assert glitched["correction_mm"]["cause"] == "where it was judged an outlier and rebuilt"
    assert report["file"]["samples_flagged"] == before["file"]["samples_flagged"] + 1


def test_replaced_frames_map_to_samples_by_name_and_skip_what_cannot_be_placed():
    from mocapfix.pipeline.steps import replaced_mask

    info = {"replaced_frames": {"A": [0, 5, 99, -1], "B": [1], "C": [2], "Z": [3]}}
    mask = replaced_mask(info, ["A", "B", "B", "C"], (10, 4))
    # frames outside the clip, an unknown name and a label two points share are skipped
    assert np.argwhere(mask).tolist() == [[0, 0], [2, 3], [5, 0]]
    assert not replaced_mask({}, ["A"], (3, 1)).any()


@pytest.mark.slow
def test_a_bvh_joint_re_made_where_its_parent_was_is_moved_by_the_parent():
    """In BVH a joint's own rotation turns the joints below it, not itself: when a joint
    and its parent are both re-made at a frame, the parent is named as the cause of the
    joint's move (bvh-python's test file with a 35° glitch put by hand on LeftFoot and
    LeftToeBase at frames 40-41; the file as read has none the limb's path contradicts)."""
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config

    m = formats.read(shared("bvh/bvhpython_test_freebvh.bvh"))
    pipe = load_config(resolve_config("default"))
    as_read = build_report(clean_motion(m, pipe), pipe.report)
    step = next(s for s in as_read["steps"] if s["cleaner"] == "rotation_outliers")
    assert not step["info"].get("replaced_frames")
    ch = m.channels.copy()
    for name in ("mixamorig:LeftFoot", "mixamorig:LeftToeBase"):
        j = m.names.index(name)              # about X: the toe's end sits on its Z axis
        ch[40:42, m.rig.rot_columns[j][m.rig.rot_axes[j].upper().index("X")]] += 35.0
    report = build_report(clean_motion(m.replace(channels=ch, positions=m.rig.positions(ch)), pipe),
                          pipe.report)
    replaced = next(s for s in report["steps"] if s["cleaner"] == "rotation_outliers")["info"]["replaced_frames"]
    toe = _joint(report, "mixamorig:LeftToeBase")
    frame = toe["correction_mm"]["frame"]
    assert frame in (40, 41) and toe["correction_mm"]["max"] > 10
    assert frame in replaced["mixamorig:LeftToeBase"] and frame in replaced["mixamorig:LeftFoot"]
    assert toe["correction_mm"]["cause"] == "where mixamorig:LeftFoot was judged an outlier and rebuilt"
