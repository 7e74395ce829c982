"""The quality report on cases whose answers are known by construction."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
from click.testing import CliRunner

from mocapfix.cleaning import clean_motion
from mocapfix.cli import main
from mocapfix.core.motion import Motion, Skeleton
from mocapfix.config import loads_config
from mocapfix.quality.report import build_report, to_html, to_json, to_markdown

from conftest import SAMPLE_DATA, config_file, no_traceback, shared

BVH = SAMPLE_DATA / "walk.bvh"


def _motion():
    T = 200
    t = np.arange(T) / 100.0
    a = np.stack([1000 * t, np.zeros(T), np.full(T, 900.0)], axis=1)
    b = a + np.array([0.0, 0.0, -400.0])
    pos = np.stack([a, b], axis=1)
    pos[50:60, 1] = np.nan                     # one 10-frame gap on marker B
    return Motion(pos, ["A", "B"], 100.0, units="mm", metres_per_unit=0.001, format="c3d",
                  skeleton=Skeleton(np.array([-1, 0])))


def test_report_names_the_filler_and_counts():
    motion = _motion()
    pipe = loads_config("pipeline:\n  - cleaner: fill\n    method: linear\n")
    result = clean_motion(motion, pipe)
    report = build_report(result)
    json.loads(to_json(report))  # valid JSON, no NaN
    a, b = report["joints"]
    assert b["missing_before"] == 0.05 and b["missing_after"] == 0.0
    assert b["gaps"]["count"] == 1 and b["gaps"]["longest_frames"] == 10
    filled = b["gaps"]["filled"]
    # the straight line is interpolated exactly on its validation windows too: the
    # estimate is the error floor (half a millimetre: below it errors are not told
    # apart), the bound of its order, below the default gate (20 mm), so it is written
    assert len(filled) == 1 and filled[0].pop("error_mm") <= 0.5
    assert 0.0 < filled[0].pop("bound_mm") < 20.0
    assert filled[0].pop("extrapolated") is False      # windows of its own length were cut
    assert filled == [{"start": 50, "length": 10, "seconds": 0.1, "long": False,
                       "confidence": None, "filled_by": "step 1 (fill)"}]
    assert report["file"]["long_fills"] == 0
    assert a["status"] == "OK" and b["status"] == "OK"
    # the straight line is filled exactly, so the bone keeps its length
    assert b["bone_variation_after"] < 1e-12
    assert report["file"]["samples_filled"] == 10 and report["file"]["status"] == "OK"
    md = to_markdown(report)
    assert "| B | OK |" in md and "step 1 (fill)" in md
    assert to_html(report, result).count("<svg") == 1      # B plotted; A, unchanged, not


def test_unfilled_gap_warns_and_fails_over_threshold():
    motion = _motion()
    pipe = loads_config("pipeline:\n  - cleaner: fill\n    max_gap: 5 frames\n")
    report = build_report(clean_motion(motion, pipe))
    b = report["joints"][1]
    assert b["gaps"]["unfilled"] == [{"start": 50, "length": 10, "filled_frames": 0}]
    assert b["status"] == "WARN" and "still missing" in b["reasons"][0]
    strict = build_report(clean_motion(motion, pipe), {"fail_missing_after": 0.01})
    assert strict["joints"][1]["status"] == "FAIL" and strict["file"]["status"] == "FAIL"


def test_html_plots_the_joints_that_changed_most_not_never_seen_ones():
    T = 200
    t = np.arange(T) / 100.0
    a = np.stack([1000 * t, np.zeros(T), np.full(T, 900.0)], axis=1)
    pos = np.stack([a, a + [0, 0, -400.0], a + [0, 300.0, 0], a + [0, 600.0, 0]], axis=1)
    pos[50:60, 1] = np.nan                     # B: a gap the fill closes
    pos[:, 2] = np.nan                         # C: never seen, stays missing
    motion = Motion(pos, ["A", "B", "C", "D"], 100.0, units="mm", metres_per_unit=0.001,
                    format="c3d")
    pipe = loads_config("pipeline:\n  - cleaner: fill\n    method: linear\n"
                        "  - cleaner: spikes\n    formats: [kinect]\n")
    result = clean_motion(motion, pipe)
    report = build_report(result)
    assert report["joints"][2]["status"] == "FAIL"          # C: worst status…
    page = to_html(report, result, n_plots=1)
    assert "<h3>B — OK</h3>" in page and "<h3>C" not in page  # …but B is the one plotted
    assert "<title>" in page and "mocapfix report</title>" in page and "`" not in page
    md = to_markdown(report)
    assert "| step 2 (spikes)" not in md and "Not run for c3d" in md


def test_long_fills_are_listed_with_their_confidence():
    """A 0.8 s gap (longer than the 0.5 s long-fill limit) and a 0.1 s one on a 100 fps
    capture: the ensemble fills both; only the long one is marked long, listed in the
    Markdown, and its confidence is the mean of the filler's per-sample confidence."""
    T, fps = 600, 100.0
    t = np.arange(T) / fps
    rng = np.random.default_rng(3)
    base = np.stack([400 * np.sin(t), 300 * np.cos(0.7 * t), 900 + 50 * np.sin(2 * t)], axis=1)
    offsets = rng.normal(0, 150, size=(6, 3))
    pos = base[:, None, :] + offsets[None]
    pos[100:180, 2] = np.nan                   # 80 frames = 0.8 s
    pos[300:310, 4] = np.nan                   # 10 frames = 0.1 s
    motion = Motion(pos, [f"M{k}" for k in range(6)], fps, units="mm", metres_per_unit=0.001,
                    format="c3d")
    result = clean_motion(motion, loads_config("pipeline:\n  - cleaner: fill_ensemble\n"))
    report = build_report(result)
    json.loads(to_json(report))
    long_gap = report["joints"][2]["gaps"]["filled"]
    short_gap = report["joints"][4]["gaps"]["filled"]
    assert [g["long"] for g in long_gap] == [True] and [g["long"] for g in short_gap] == [False]
    assert long_gap[0]["seconds"] == 0.8 and short_gap[0]["seconds"] == 0.1
    expected = float(np.mean(result.cleaned.confidence[100:180, 2]))
    assert 0.0 < long_gap[0]["confidence"] < 1.0
    assert abs(long_gap[0]["confidence"] - expected) < 1e-6          # rounded to 6 decimals
    assert report["file"]["long_fills"] == 1
    md = to_markdown(report)
    assert "## Long fills" in md and "| M2 | 100–179 | 0.80 |" in md and "| M4 | 300" not in md


def _rigid_markers(T: int, fps: float, seed: int) -> np.ndarray:
    """Six markers (mm) on a rigid body moving smoothly, M4 missing on frames 300-309."""
    t = np.arange(T) / fps
    rng = np.random.default_rng(seed)
    base = np.stack([400 * np.sin(t), 300 * np.cos(0.7 * t), 900 + 50 * np.sin(2 * t)], axis=1)
    pos = base[:, None, :] + rng.normal(0, 150, size=(6, 3))[None]
    pos[300:310, 4] = np.nan
    return pos


def test_gaps_left_are_listed_once_per_span_with_the_reasons():
    """Six markers on a rigid body at 100 fps: a 0.1 s gap in one marker (filled) and 50
    frames empty for every marker (nothing is seen: left), and a seventh marker never
    seen. The Markdown lists the empty span once for the six markers with the ensemble's
    reason, the never-seen marker as such, and not the filled gap."""
    T, fps = 600, 100.0
    pos = _rigid_markers(T, fps, seed=3)
    pos[450:500] = np.nan
    pos = np.concatenate([pos, np.full((T, 1, 3), np.nan)], axis=1)      # M6: never seen
    names = [f"M{k}" for k in range(7)]
    names[5] = "M|5"                                    # a pipe in a label stays in its cell
    motion = Motion(pos, names, fps, units="mm", metres_per_unit=0.001, format="c3d")
    report = build_report(clean_motion(motion, loads_config("pipeline:\n  - cleaner: fill_ensemble\n")))
    assert report["file"]["gaps_unfilled"] == 7
    md = to_markdown(report)
    section = md.split("## Gaps left unfilled", 1)[1].split("\n\n", 2)[1]
    rows = [line for line in section.splitlines() if line.startswith("| 4")]
    assert rows == ["| 450–499 | 0.50 | 6: M0, M1, M2, M3, M4, M\\|5 | step 1 (fill_ensemble): no "
                    "other marker is seen through it |"]
    assert "| 300" not in section
    assert "| 0–599 | 6.00 | 1: M6 | never seen in the input |" in section


def test_empty_frames_at_the_ends_are_outside_the_take_and_not_graded():
    """An export with its last 0.5 s empty (no marker seen: the recording ran on after the
    take) and a marker with a real 0.1 s gap in the take: the markers are graded on the
    take, frames 0-549 (the gap counts, the empty end does not), and the report says which
    frames it left out. The same empty frames in the middle are a whole-body dropout: every
    marker's gap, left unfilled."""
    T, fps = 600, 100.0
    pos = _rigid_markers(T, fps, seed=5)
    config = loads_config("pipeline:\n  - cleaner: fill\n    max_gap: 0.05 s\n")
    end = pos.copy()
    end[T - 50:] = np.nan
    report = build_report(clean_motion(Motion(end, [f"M{k}" for k in range(6)], fps, units="mm",
                                              metres_per_unit=0.001, format="c3d"), config))
    f = report["file"]
    assert f["frames_outside_take"] == [[550, 50]]
    assert any("50 at the end" in n for n in f["notes"])
    j4 = next(j for j in report["joints"] if j["name"] == "M4")
    assert j4["missing_before"] == pytest.approx(10 / 550, abs=1e-6) == j4["missing_after"]
    assert [j["missing_after"] for j in report["joints"] if j["name"] != "M4"] == [0.0] * 5
    assert f["gaps_before"] == 1 and f["gaps_unfilled"] == 1
    middle = pos.copy()
    middle[400:450] = np.nan
    report = build_report(clean_motion(Motion(middle, [f"M{k}" for k in range(6)], fps,
                                              units="mm", metres_per_unit=0.001, format="c3d"),
                                       config))
    assert "frames_outside_take" not in report["file"]
    assert report["file"]["gaps_unfilled"] == 7                # six dropouts and M4's gap
    assert all(j["missing_after"] == pytest.approx(50 / 600, abs=1e-6) for j in report["joints"]
               if j["name"] != "M4")


def _fill_config(tmp_path) -> str:
    path = tmp_path / "fill.yaml"
    path.write_text("version: 1\npipeline:\n  - cleaner: fill\n    max_gap: 0.5 s\n")
    return str(path)


def test_marker_name_with_a_pipe_keeps_its_report_row_whole(tmp_path):
    # a C3D label "a|b" split its row of the Markdown and HTML joint tables in two cells
    from malformed_corpus import c3d_bytes, small_c3d_points

    src = tmp_path / "in" / "pipes.c3d"
    src.parent.mkdir()
    src.write_bytes(c3d_bytes(small_c3d_points(T=200, P=3), ["a|b", "C", "D"]))
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "--report", "md,html",
                                  "-c", _fill_config(tmp_path)])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    md = (out / "pipes.c3d.report.md").read_text().splitlines()
    header = next(line for line in md if line.startswith("| joint |"))
    row = next(line for line in md if line.startswith("| a"))
    border = re.compile(r"(?<!\\)\|")
    assert len(border.findall(row)) == len(border.findall(header)), row
    html_text = (out / "pipes.c3d.report.html").read_text()
    assert "<td>a|b</td>" in html_text and "<td>a</td>" not in html_text


def test_plot_ticks_are_round_inside_the_range_and_at_least_two():
    """A span whose step rounds up from 2 to 5 held a single multiple (0.5-8.54 mm: only
    5), and the browser test found a Kinect panel with one y tick."""
    from hypothesis import given, strategies as st

    from mocapfix.quality.plots import ticks as _ticks

    assert _ticks(0.5, 8.54) == [2.0, 4.0, 6.0, 8.0]
    assert _ticks(0.0, 100.0) == [0.0, 50.0, 100.0]

    @given(st.floats(-1e4, 1e4), st.floats(1e-3, 1e4))
    def check(lo, span):
        ticks = _ticks(lo, lo + span)
        assert len(ticks) >= 2
        assert lo - 1e-9 * span <= ticks[0] and ticks[-1] <= lo + span + 1e-9 * span
        steps = np.diff(ticks)
        np.testing.assert_allclose(steps, steps[0], rtol=1e-6)
        assert len(ticks) <= 11

    check()


def test_markdown_says_what_each_step_found():
    """A real Kinect v2 recording (LabanotationSuite Ges01): the Markdown names the joint
    pair ``kinect_skeleton`` found rigid and held, with its counts; per-joint tables of the
    step's info (noise, cut-offs) stay in the JSON only."""
    from mocapfix import read
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config

    motion = read(shared("kinect/kv2_laban_Ges01_wavehand.csv"))
    report = build_report(clean_motion(motion, load_config(resolve_config("kinect"))))
    md = to_markdown(report)
    line = next(x for x in md.splitlines() if x.startswith("- step 1 (kinect_skeleton): "))
    assert "rigid pairs HandLeft-ThumbLeft" in line
    assert "leg swap frames 0" in line and "outliers 0" in line
    assert "noise mm" not in line and "cutoff hz" not in line
    info = report["steps"][0]["info"]
    assert info["rigid_pairs"] == ["HandLeft-ThumbLeft"] and "noise_mm" in info


def _padded(motion: Motion, before: int, after: int) -> Motion:
    """``motion`` with ``before`` / ``after`` empty frames (no point seen) around it, on a
    time axis that goes on at the frame rate."""
    T, J = motion.n_frames, motion.n_joints
    pos = np.full((before + T + after, J, 3), np.nan)
    pos[before:before + T] = motion.positions
    conf = None
    if motion.confidence is not None:
        conf = np.zeros(pos.shape[:2])
        conf[before:before + T] = motion.confidence
    times = None
    if motion.times is not None:
        t = np.asarray(motion.times, float)
        times = np.r_[t[0] - np.arange(before, 0, -1) / motion.fps, t,
                      t[-1] + np.arange(1, after + 1) / motion.fps]
    return motion.replace(positions=pos, confidence=conf, times=times, source=None)


@pytest.mark.slow
@pytest.mark.parametrize("rel, config", [("c3d/hdm05_HDM_mm_01-02_03_120.c3d", "default"),
                                         ("kinect/kv2_laban_Ges02_balancinghands.csv", "kinect")])
def test_empty_frames_around_the_take_change_nothing_a_step_does(rel, config):
    """An export padded with empty frames (a recording left running before and after the
    take) is cleaned as the take alone: the same positions in the take, nothing invented in
    the padding, and every step's findings the same — gap counts that match the report's,
    and outliers rebuilt in place reported on the same frames of the file."""
    from mocapfix import read
    from mocapfix.core.presets import resolve_config
    from mocapfix.config import load_config
    motion = read(shared(rel))
    if motion.n_frames > 900:
        motion = motion.slice_frames(0, 900)
    motion.positions[100:112, 3] = np.nan                  # a gap in the take
    pipeline = load_config(resolve_config(config))
    plain = clean_motion(motion, pipeline)
    padded = clean_motion(_padded(motion, 23, 17), pipeline)
    T = motion.n_frames
    assert np.isnan(padded.cleaned.positions[:23]).all()
    assert np.isnan(padded.cleaned.positions[23 + T:]).all()
    assert np.allclose(padded.cleaned.positions[23:23 + T], plain.cleaned.positions,
                       rtol=0, atol=1e-9, equal_nan=True)
    ran = [(a, b) for a, b in zip(plain.records, padded.records) if a.skipped is None]
    assert ran
    for a, b in ran:
        assert a.info.keys() == b.info.keys()
        counts = {k: v for k, v in a.info.items() if isinstance(v, (int, str))}
        assert counts == {k: b.info[k] for k in counts}, a.step
        assert np.array_equal(a.outliers, b.outliers[23:23 + T]), a.step
        assert not b.outliers[:23].any() and not b.outliers[23 + T:].any()
    rep_plain, rep_padded = build_report(plain), build_report(padded)
    assert rep_padded["file"]["frames_outside_take"] == [[0, 23], [23 + T, 17]]
    for key in ("gaps_before", "gaps_unfilled", "samples_filled", "samples_flagged"):
        assert rep_padded["file"][key] == rep_plain["file"][key], key


def test_a_file_name_that_is_not_utf8_is_cleaned_and_reported(tmp_path):
    # Linux names are bytes; b"take\xff.bvh" reaches Python as "take\udcff.bvh". The
    # Markdown/HTML reports and the JUnit XML could not be encoded: the file failed with
    # "internal error UnicodeEncodeError" and check --junit ended in a traceback
    import os
    import xml.etree.ElementTree as ET

    import pytest

    src = tmp_path / "in"
    src.mkdir()
    try:
        raw = os.path.join(os.fsencode(src), b"take\xff.bvh")
        with open(raw, "wb") as fh:
            fh.write(BVH.read_bytes())
    except (OSError, UnicodeError):
        pytest.skip("this file system refuses names that are not UTF-8")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "-c", config_file(tmp_path),
                                  "--report", "json,md,html"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    names = sorted(os.listdir(os.fsencode(out)))
    for name in (b"take\xff.bvh", b"take\xff.bvh.report.json", b"take\xff.bvh.report.md",
                 b"take\xff.bvh.report.html"):
        assert name in names, names
    md = (out / os.fsdecode(b"take\xff.bvh.report.md")).read_bytes()
    md.decode("utf-8")                                   # the reports stay UTF-8 text
    junit = tmp_path / "check.xml"
    r = CliRunner().invoke(main, ["check", str(src), "--junit", str(junit), "--exit-zero"])
    no_traceback(r)
    assert r.exit_code == 0, r.output
    case = ET.parse(junit).getroot().find(".//testcase")
    assert case is not None and "take" in case.get("name")


def _six_channel_bvh(glitch: float | None) -> str:
    """A 3-joint BVH whose every joint has 6 channels (as Bandai-Namco's files do),
    120 frames of smooth motion; ``glitch`` goes into Chest.Xposition at frame 60."""
    import numpy as np

    hier = ("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 6 Xposition Yposition Zposition "
            "Zrotation Xrotation Yrotation\n JOINT Chest\n {\n  OFFSET 0 20 0\n  CHANNELS 6 "
            "Xposition Yposition Zposition Zrotation Xrotation Yrotation\n  JOINT Head\n  {\n"
            "   OFFSET 0 20 0\n   CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
            "Yrotation\n   End Site\n   {\n    OFFSET 0 10 0\n   }\n  }\n }\n}\n"
            "MOTION\nFrames: 120\nFrame Time: 0.0083333\n")
    rows = []
    for f in range(120):
        t = f / 120
        vals = [10 * np.sin(3 * t), 90, 5 * t, 5 * np.sin(5 * t), 3 * np.cos(4 * t), 2 * t,
                0, 20, 0, 4 * np.sin(6 * t), 2 * np.cos(5 * t), 1,
                0, 20, 0, 3 * np.sin(7 * t), np.cos(3 * t), 0]
        if f == 60 and glitch is not None:
            vals[6] = glitch
        rows.append(" ".join(f"{v:.6g}" for v in vals))
    return hier + "\n".join(rows) + "\n"


def test_a_joint_moved_beyond_the_float_range_is_reported_not_an_internal_error(tmp_path):
    # 1e300 in a non-root joint's position channel: the report's largest correction
    # overflowed to inf (written as null) and the comparison "max > 0" raised TypeError,
    # so the file failed with "internal error TypeError" and no output. The rotations are
    # smoothed by a fixed filter (the default leaves this noiseless take as it is), so the
    # joints below the glitch move by 1e300 × a rounding error
    import json

    src = tmp_path / "in"
    src.mkdir()
    (src / "glitch.bvh").write_text(_six_channel_bvh(1e300))
    (src / "clean.bvh").write_text(_six_channel_bvh(None))
    config = tmp_path / "smooth.yaml"
    config.write_text("pipeline:\n  - cleaner: rotation_smooth\n    translations: false\n")
    out = tmp_path / "out"
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "--report", "json,md,html",
                                  "-c", str(config)])
    no_traceback(r)
    assert r.exit_code == 0 and "internal error" not in r.output, r.output
    report = json.loads((out / "glitch.bvh.report.json").read_text())
    assert any(j["correction_mm"]["max"] is None for j in report["joints"])
    assert (out / "glitch.bvh").read_text().startswith("HIERARCHY")
