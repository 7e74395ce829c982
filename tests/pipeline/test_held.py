"""Held frames (mocapfix.pipeline.held): a take whose frames repeat the frame before them is
cleaned on its distinct frames, and every held frame comes out as the frame it repeats."""
from __future__ import annotations

import numpy as np

from mocapfix import Motion, read
from mocapfix.bench.corrupt import occlusion
from mocapfix.cleaners.base import FILL_ERRORS, REJECTED_FILLS, REPLACED_FRAMES, map_frames
from mocapfix.cleaning import clean_motion
from mocapfix.config import load_config
from mocapfix.core.presets import resolve_config
from mocapfix.pipeline.held import HeldFrames, held_frames
from mocapfix.quality.report import build_report
from tests.conftest import shared


def _doubled(motion: Motion) -> Motion:
    """Every frame written twice (a 30 Hz stream saved at 60 Hz)."""
    pick = np.repeat(np.arange(motion.n_frames), 2)
    return motion.replace(positions=motion.positions[pick], source=None, confidence=None,
                          channels=None if motion.channels is None else motion.channels[pick])


def test_held_frames_known_answers():
    rng = np.random.default_rng(0)
    P = rng.normal(size=(8, 3, 3))
    P[2] = P[1]                         # held
    P[3] = P[2]                         # held again (a run)
    P[4, 0] = np.nan
    P[5] = P[4]                         # held, missing where frame 4 was missing
    P[6] = P[5]
    P[6, 1] = np.nan                    # a point lost: a new frame
    P[7] = np.nan                       # an empty frame is never held
    conf = np.ones((8, 3))
    motion = Motion(P.copy(), ["a", "b", "c"], 100.0, confidence=conf.copy())
    assert held_frames(motion).tolist() == [False, False, True, True, False, True, False, False]
    conf[5, 2] = 0.5                    # the tracker's state changed: a new report
    assert not held_frames(Motion(P, ["a", "b", "c"], 100.0, confidence=conf))[5]
    P[7] = P[6] = np.nan                # two empty frames in a row stay as they are
    assert not held_frames(Motion(P, ["a", "b", "c"], 100.0))[7]
    frames = HeldFrames.find(motion)
    assert frames.kept.tolist() == [0, 1, 4, 6, 7]
    assert frames.of.tolist() == [0, 1, 1, 1, 2, 2, 3, 4]
    assert frames.stop.tolist() == [1, 4, 6, 7, 8]


def test_map_frames_makes_the_distinct_frames_numbers_the_takes():
    first, stop = np.array([0, 1, 4, 6]), np.array([1, 4, 6, 9])
    info = {REPLACED_FRAMES: {"a": [1, 3]},
            FILL_ERRORS: {"a": [[1, 2, 3.0, 6.0, False]]},
            REJECTED_FILLS: {"b": [[2, 1, "too uncertain", 9.0, 20.0, False]]},
            "swaps": [{"markers": ["a", "b"], "start": 1, "end": 3, "frames": 2}],
            "gaps": 4}
    out = map_frames(info, first, stop)
    assert out[REPLACED_FRAMES] == {"a": [1, 2, 3, 6, 7, 8]}
    assert out[FILL_ERRORS] == {"a": [[1, 5, 3.0, 6.0, False]]}
    assert out[REJECTED_FILLS] == {"b": [[4, 2, "too uncertain", 9.0, 20.0, False]]}
    assert out["swaps"] == [{"markers": ["a", "b"], "start": 1, "end": 6, "frames": 5}]
    assert out["gaps"] == 4


def test_a_take_with_every_frame_held_comes_out_as_it_went_in():
    """CMU 85_02 (clean: the default changes nothing in it) with every frame written
    twice. Cleaned as 1,620 frames the default judged 2,998 samples wrong, left 1,078
    missing and moved a toe marker by 1.1 m; now nothing moves."""
    motion = _doubled(read(shared("c3d/cmu_85_02.c3d")))
    pipeline = load_config(resolve_config("default"))
    result = clean_motion(motion, pipeline)
    np.testing.assert_array_equal(result.cleaned.positions, motion.positions)
    report = build_report(result, pipeline.report)
    assert report["file"]["samples_flagged"] == 0 and report["file"]["status"] == "OK"
    assert any("810 distinct frames" in n for n in report["file"]["notes"])


def test_held_frames_come_out_as_the_frame_they_repeat_with_the_reports_frames():
    """85_02 with the mixed corruption (gaps, jitter, spikes), every frame then written
    twice: the output is the corrupted take's output with each frame twice, bit for bit,
    and the report counts the file's samples and gives its gaps at the file's frames, each
    filled gap with the error estimate of the same gap of the distinct take."""
    base = read(shared("c3d/cmu_85_02.c3d"))
    corrupted, _ = occlusion(base, "mixed", 3)
    corrupted = corrupted.replace(source=None, confidence=None)
    pipeline = load_config(resolve_config("default"))
    once = clean_motion(corrupted, pipeline)
    twice = clean_motion(_doubled(corrupted), pipeline)
    np.testing.assert_array_equal(twice.cleaned.positions, once.cleaned.positions.repeat(2, axis=0))
    a, b = build_report(once, pipeline.report), build_report(twice, pipeline.report)
    assert b["file"]["samples_filled"] == 2 * a["file"]["samples_filled"] > 0
    assert b["file"]["samples_flagged"] == 2 * a["file"]["samples_flagged"] > 0
    assert b["file"]["gaps_before"] == a["file"]["gaps_before"]
    filled = 0
    for ja, jb in zip(a["joints"], b["joints"]):
        for ga, gb in zip(ja["gaps"]["filled"], jb["gaps"]["filled"]):
            assert (gb["start"], gb["length"]) == (2 * ga["start"], 2 * ga["length"])
            assert gb["bound_mm"] == ga["bound_mm"] and gb["error_mm"] == ga["error_mm"]
            filled += 1
        assert len(ja["gaps"]["unfilled"]) == len(jb["gaps"]["unfilled"])
    assert filled > 10


def test_a_few_held_frames_stay_held_in_the_output():
    """Dropped frames padded with the frame before (3 % of the frames, at random) in a
    capture with gaps, jitter and spikes: each held frame comes out equal to the frame it
    repeats, and the report says how many there were."""
    base, _ = occlusion(read(shared("c3d/cmu_85_02.c3d")), "mixed", 5)
    rng = np.random.default_rng(1)
    held = np.zeros(base.n_frames, bool)
    held[rng.choice(np.arange(1, base.n_frames), base.n_frames // 33, replace=False)] = True
    pick = np.arange(base.n_frames)
    for t in np.flatnonzero(held):
        pick[t] = pick[t - 1]
    motion = base.replace(positions=base.positions[pick], source=None, confidence=None)
    assert (held_frames(motion) == held).all()
    pipeline = load_config(resolve_config("default"))
    result = clean_motion(motion, pipeline)
    t = np.flatnonzero(held)
    np.testing.assert_array_equal(result.cleaned.positions[t], result.cleaned.positions[t - 1])
    notes = build_report(result, pipeline.report)["file"]["notes"]
    assert any(n.startswith(f"{len(t)} of {base.n_frames} frames repeat") for n in notes)


def test_held_frames_in_a_take_cleaned_in_windows():
    """The windows are cut in the distinct frames: a doubled take cleaned in windows gives
    the distinct take's windowed output with every frame twice, and its report the file's
    frames."""
    from mocapfix.pipeline.windows import Windows

    base = read(shared("c3d/cmu_85_02.c3d"))
    corrupted, _ = occlusion(base, "mixed", 4)
    corrupted = corrupted.replace(source=None, confidence=None)
    pipeline = load_config(resolve_config("default"))
    windows = Windows(300, 40)
    once = clean_motion(corrupted, pipeline, windows=windows)
    twice = clean_motion(_doubled(corrupted), pipeline, windows=windows)
    np.testing.assert_array_equal(twice.cleaned.positions, once.cleaned.positions.repeat(2, axis=0))
    a, b = build_report(once, pipeline.report), build_report(twice, pipeline.report)
    assert b["file"]["samples_filled"] == 2 * a["file"]["samples_filled"] > 0
    assert any("cleaned in 3 windows" in n for n in b["file"]["notes"])
