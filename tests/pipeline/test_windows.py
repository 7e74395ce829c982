"""Cleaning long takes in overlapping windows (mocapfix.pipeline.windows)."""
from __future__ import annotations

import numpy as np
import pytest

from mocapfix import Motion, read
from mocapfix.bench.corrupt import occlusion
from mocapfix.cleaning import clean_motion
from mocapfix.config import load_config, loads_config
from mocapfix.core.errors import ConfigError
from mocapfix.core.presets import resolve_config
from mocapfix.pipeline.windows import (MIN_WINDOW_S, Windows, merge_info, over_budget,
                                       parse_memory_budget, point_cuts, window_for)
from mocapfix.quality.report import build_report
from tests.conftest import shared


@pytest.mark.parametrize("value, expected", [("1 GB", 10 ** 9), ("512 MiB", 512 * 2 ** 20),
                                             ("1.5GiB", int(1.5 * 2 ** 30)), (2 * 10 ** 9, 2 * 10 ** 9),
                                             (None, None)])
def test_memory_budget_sizes(value, expected):
    assert parse_memory_budget(value, "x: memory_budget") == expected


@pytest.mark.parametrize("value", ["lots", "1 GHz", "-1 GB", "10 MB", "2 PB", True])
def test_memory_budget_refused(value):
    with pytest.raises(ConfigError, match="x: memory_budget"):
        parse_memory_budget(value, "x: memory_budget")


def test_config_memory_budget(tmp_path):
    assert loads_config("version: 1\npipeline: []\nmemory_budget: 2 GB\n").memory_budget == 2 * 10 ** 9
    assert loads_config("version: 1\npipeline: []\nmemory_budget: null\n").memory_budget is None
    default = loads_config("version: 1\npipeline: []\n")
    assert default.memory_budget == 10 ** 9
    again = loads_config(default.dump())          # the effective config reads back the same
    assert again.memory_budget == default.memory_budget
    path = tmp_path / "c.yaml"
    path.write_text("version: 1\npipeline: []\nmemory_budget: plenty\n")
    with pytest.raises(ConfigError, match=r"c\.yaml \(line 3\): memory_budget"):
        load_config(path)


def test_window_for_budget():
    assert window_for(None, 10 ** 6, 40, 120.0) is None
    assert window_for(10 ** 9, 4500, 41, 120.0) is None            # fits whole
    w = window_for(10 ** 9, 500_000, 41, 120.0)
    assert w is not None and w.frames >= MIN_WINDOW_S * 120 and w.overlap == 720
    bigger = window_for(3 * 10 ** 9, 100_000, 41, 120.0)
    smaller = window_for(15 * 10 ** 8, 100_000, 41, 120.0)
    assert bigger.frames > smaller.frames                          # more budget, longer windows
    assert window_for(10 ** 9, 50_000, 41, 120.0) == window_for(10 ** 9, 500_000, 41, 120.0)
    assert over_budget(10 ** 9, 5 * 10 ** 8) is None
    assert "need about 1.3 GB" in over_budget(10 ** 9, 1_312_000_000)


def test_the_over_budget_note_counts_the_arrays_held(tmp_path):
    """The note of a take whose own arrays are more than half the budget gives their
    size: the input's and the output's positions when the input is held, the output's
    alone when it was kept on disk (the 500,000-frame C3D's note said 3.1 GB, from a
    per-sample estimate, where the whole clean peaked at 2.06 GB)."""
    motion = _smooth_take(T=150_000, J=10)
    pipeline = loads_config("version: 1\nmemory_budget: 64 MB\npipeline:\n  - cleaner: fill\n")
    size = motion.positions.nbytes                           # 36 MB
    held = clean_motion(motion, pipeline)
    assert (f"the take's own arrays (input and output) need about {2 * size / 1e9:.2g} GB, "
            "more than half the memory_budget (0.064 GB)") in held.cleaned.notes[-1]
    kept = clean_motion(motion.copy(), pipeline, keep_input_on_disk=tmp_path)
    assert (f"the cleaned take's arrays (its input kept on disk) need about {size / 1e9:.2g} "
            "GB") in kept.cleaned.notes[-1]
    np.testing.assert_array_equal(kept.cleaned.positions, held.cleaned.positions)


def test_cuts_join_a_short_last_window():
    assert Windows(4, 2).cuts(10) == [0, 4, 8, 10]
    assert Windows(4, 2).cuts(9) == [0, 4, 9]          # a last frame alone joins the window before
    assert Windows(10, 2).cuts(10) == [0, 10]


def test_point_cuts_step_around_gaps():
    missing = np.zeros((200, 3), bool)
    missing[95:105, 0] = True           # a gap across the nominal cut at 100
    missing[60:140, 2] = True           # a gap longer than the search range (±20)
    cuts = point_cuts(missing, [0, 100, 200], overlap=40)
    assert cuts[0].tolist() == [0, 0, 0] and cuts[2].tolist() == [200, 200, 200]
    # frames 93 and 94 seen (the first cut before the gap: 6 away; 106 is as far, after it)
    assert cuts[1].tolist() == [94, 100, 100]


def test_merge_info_adds_counts_and_joins_frames():
    merged = merge_info([{"filled": 3, "rank": 4, "replaced_frames": {"A": [1, 2]}, "noise_mm": {"A": 0.5},
                          "swaps": [{"start": 1}]},
                         {"filled": 2, "rank": 5, "replaced_frames": {"A": [700], "B": [9]},
                          "noise_mm": {"A": 0.5}, "swaps": []}])
    assert merged == {"filled": 5, "rank": {"per_window": [4, 5]},
                      "replaced_frames": {"A": [1, 2, 700], "B": [9]}, "noise_mm": {"A": 0.5},
                      "swaps": [{"start": 1}]}


def _smooth_take(T=6000, J=6, fps=100.0, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(T) / fps
    freq = rng.uniform(0.2, 1.5, (J, 3))
    phase = rng.uniform(0, 2 * np.pi, (J, 3))
    positions = 300 * np.sin(2 * np.pi * freq[None] * t[:, None, None] + phase[None])
    positions += 1000 * np.arange(J)[None, :, None]
    return Motion.from_arrays(positions, [f"M{j}" for j in range(J)], fps)


def test_local_steps_give_the_whole_take_result():
    """A step that only looks at a gap's neighbourhood (PCHIP) cleans the take in windows
    exactly as whole, gaps across the nominal cuts included (the cut steps around them),
    and the report counts the same gaps filled."""
    motion = _smooth_take()
    positions = motion.positions.copy()
    for j, (s, n) in enumerate([(995, 20), (1990, 30), (2998, 4), (4010, 25), (5, 40), (3500, 10)]):
        positions[s:s + n, j] = np.nan
    motion = motion.replace(positions=positions)
    pipeline = loads_config("version: 1\nmax_fill_error: null\npipeline:\n"
                            "  - cleaner: fill\n    method: pchip\n    max_gap: 1 s\n")
    whole = clean_motion(motion, pipeline, windows=None)
    cut = clean_motion(motion, pipeline, windows=Windows(1000, 200))
    assert not whole.cleaned.missing.any()
    np.testing.assert_array_equal(cut.cleaned.positions, whole.cleaned.positions)
    a, b = build_report(whole, pipeline.report), build_report(cut, pipeline.report)
    assert [j["gaps"]["filled"][0]["start"] for j in a["joints"]] == \
           [j["gaps"]["filled"][0]["start"] for j in b["joints"]]
    assert b["file"]["samples_filled"] == a["file"]["samples_filled"] == 129
    assert b["steps"][0]["info"]["windows"] == 6
    assert any("cleaned in 6 windows" in n for n in b["file"]["notes"])


def test_budget_decides_the_windows(monkeypatch):
    # a take cleaned in windows hands the windows' freed memory back once, after the last
    # window (before the records and the report are made); a take cleaned whole does not
    import mocapfix.cleaning

    released = []
    monkeypatch.setattr(mocapfix.cleaning, "release_freed_memory", lambda: released.append(1))
    motion = _smooth_take(T=30_000, J=10)
    pipeline = loads_config("version: 1\nmemory_budget: 64 MB\npipeline:\n  - cleaner: fill\n")
    result = clean_motion(motion, pipeline)
    assert any(n.startswith("cleaned in ") for n in result.cleaned.notes)
    assert released == [1]
    roomy = loads_config("version: 1\nmemory_budget: 4 GB\npipeline:\n  - cleaner: fill\n")
    assert not any(n.startswith("cleaned in ") for n in clean_motion(motion, roomy).cleaned.notes)
    assert released == [1]


def test_default_in_windows_on_a_real_capture():
    """The default config on CMU 85_02 played forwards and backwards to 5,000 frames with
    the mixed corruption, whole and in two windows: the samples seen in the input stay
    within 1.5 mm of the whole-take clean at the 99th percentile (per-window estimates of
    the subspace and the noise), every gap is filled or listed as left, and no sample the
    whole clean wrote is missing because of a seam more than a few gaps' worth."""
    base = read(shared("c3d/cmu_85_02.c3d"))
    positions = np.concatenate([base.positions, base.positions[::-1]] * 3)[:5000]
    motion, _ = occlusion(base.replace(positions=positions, source=None, confidence=None), "mixed", 0)
    pipeline = load_config(resolve_config("default"))
    whole = clean_motion(motion, pipeline, windows=None)
    cut = clean_motion(motion, pipeline, windows=Windows(2500, 720))
    seen = ~motion.missing
    d = np.linalg.norm(cut.cleaned.positions - whole.cleaned.positions, axis=-1)[seen]
    assert np.nanpercentile(d, 99) < 1.5
    report = build_report(cut, pipeline.report)
    for joint in report["joints"]:
        gaps = joint["gaps"]
        assert len(gaps["filled"]) + len(gaps["unfilled"]) == gaps["count"]
    lost = (cut.cleaned.missing & ~whole.cleaned.missing).sum()
    assert lost <= 0.01 * motion.missing.sum()


def test_windowed_records_hold_a_replaced_mask_only_where_replaced():
    """In windows, a step's mask of the samples it re-made in place is made only when a
    window re-made some (an empty one pasted window by window touched a whole-take array
    per step: 100 MB for a 500,000-frame C3D): the rotation step that re-made the spiked
    rotations has the mask of exactly the frames its info lists, the steps that re-made
    nothing have none."""
    from mocapfix.pipeline.steps import replaced_mask

    motion = read(shared("bvh/cmu_cgspeed_131_01.bvh"))
    channels = motion.channels.copy()
    knee = motion.rig.rot_columns[motion.names.index("RightKnee")][0]
    spikes = [150, 480, 800]
    channels[spikes, knee] += 70.0
    motion = motion.replace(channels=channels, positions=motion.rig.positions(channels))
    pipeline = load_config(resolve_config("default"))
    cut = clean_motion(motion, pipeline, windows=Windows(250, 60))
    by_step = {r.cleaner: r for r in cut.records}
    outliers = by_step["rotation_outliers"]
    assert outliers.info["windows"] > 2
    expected = replaced_mask(outliers.info, motion.names, motion.positions.shape[:2])
    assert outliers.replaced is not None and outliers.replaced.any()
    np.testing.assert_array_equal(outliers.replaced, expected)
    assert set(spikes) <= set(np.flatnonzero(outliers.replaced.any(axis=1)).tolist())
    assert by_step["fill_pca"].replaced is None and by_step["swaps"].replaced is None
