"""Cuts (mocapfix.pipeline.cuts): a take that jumps as a whole, as one take ends and another
begins, is cleaned as the takes between its cuts."""
from __future__ import annotations

import numpy as np
import pytest

from mocapfix import Motion, read
from mocapfix.bench.corrupt import occlusion
from mocapfix.cleaning import clean_motion
from mocapfix.config import load_config
from mocapfix.core.presets import resolve_config
from mocapfix.pipeline.cuts import cut_frames, jumps, take_cuts
from mocapfix.pipeline.held import HeldFrames
from mocapfix.pipeline.windows import Windows, pieces
from mocapfix.quality.measure import outlier_flags
from mocapfix.quality.report import build_report
from tests.conftest import need, shared, shared_files


def _walkers(T: int = 1200, J: int = 12, seed: int = 0) -> np.ndarray:
    """(T, J, 3) points (m) on smooth curves at 120 Hz with 0.2 mm noise: a body walking."""
    rng = np.random.default_rng(seed)
    t = np.arange(T)[:, None, None] / 120.0
    phase = rng.uniform(0, 2 * np.pi, (1, J, 3))
    base = rng.normal(0, 0.3, (1, J, 3))
    walk = np.array([1.2, 0.0, 0.0]) * t
    return base + walk + 0.05 * np.sin(2 * np.pi * 1.1 * t + phase) + rng.normal(0, 2e-4, (T, J, 3))


def test_jumps_known_answers():
    P = np.zeros((8, 2, 3))
    P[:, 0, 0] = np.arange(8) * 0.01                # constant speed: no jump
    P[:, 1, 0] = np.arange(8) * 0.01
    P[5:, 1, 0] += 0.3                              # a step of 0.3 into frame 5
    P[2, 0] = np.nan
    e = jumps(P)
    assert np.isnan(e[0]).all()
    assert np.isnan(e[2, 0]) and np.isnan(e[3, 0])  # no step into or out of a missing frame
    assert np.isnan(e[1, 0])                        # a step with none either side to compare
    assert e[4, 0] == pytest.approx(0.0, abs=1e-7)  # the step after only
    assert e[5, 1] == pytest.approx(0.3, rel=1e-6)  # the step, in full
    assert e[4, 1] == pytest.approx(0.15, rel=1e-6) and e[6, 1] == pytest.approx(0.15, rel=1e-6)
    assert e[7, 1] == pytest.approx(0.0, abs=1e-7)  # the last frame: the step before only
    assert e[3, 1] == pytest.approx(0.0, abs=1e-7)


def test_take_cuts_finds_a_whole_body_jump_and_nothing_else():
    P = _walkers() * 1000.0                         # mm, the Motion's default unit
    m = Motion(P.copy(), [f"m{j}" for j in range(P.shape[1])], 120.0)
    assert take_cuts(m).size == 0
    joined = P.copy()
    joined[700:] += np.array([0.0, 120.0, 0.0])     # another take, 12 cm away, from frame 700
    assert take_cuts(m.replace(positions=joined)).tolist() == [700]
    some = P.copy()
    some[700:, :4] += np.array([0.0, 120.0, 0.0])   # a third of the points: markers, not the take
    assert take_cuts(m.replace(positions=some)).size == 0
    for size in (80.0, 120.0, 400.0):               # one frame of the whole body off, then back
        spike = P.copy()
        spike[700] += np.array([0.0, size, 0.0])
        assert take_cuts(m.replace(positions=spike)).size == 0
    burst = joined.copy()
    burst[720:] -= np.array([0.0, 120.0, 0.0])      # jumps 20 frames apart: a glitch, no take
    assert take_cuts(m.replace(positions=burst)).size == 0
    small = P.copy()
    small[700:] += np.array([0.0, 30.0, 0.0])       # 3 cm: below MIN_JUMP_M
    assert take_cuts(m.replace(positions=small)).size == 0
    gap = joined.copy()
    gap[650:760, :3] = np.nan                       # points missing across it: the rest decide
    assert take_cuts(m.replace(positions=gap)).tolist() == [700]
    metres = m.replace(positions=joined / 1000.0, units="m", metres_per_unit=1.0)
    assert take_cuts(metres).tolist() == [700]      # in the take's own unit


def test_pieces_cut_at_the_takes_cuts_with_no_overlap():
    assert pieces(100, None, []) is None
    assert pieces(100, Windows(200, 10), []) is None
    plan = pieces(100, None, [40])
    assert plan.cuts == (0, 40, 100) and plan.overlaps == (0, 0, 0) and plan.windows is None
    plan = pieces(100, Windows(30, 5), [50])
    assert plan.cuts == (0, 30, 50, 80, 100) and plan.overlaps == (0, 5, 0, 5, 0)
    assert [plan.bounds(k) for k in range(4)] == [(0, 35), (25, 50), (50, 85), (75, 100)]


def _looped(base: Motion, seconds: float = 2.0, n_frames: int = 3000) -> tuple[Motion, np.ndarray]:
    pick = np.arange(n_frames) % int(seconds * base.fps)
    return base.replace(positions=base.positions[pick], source=None, confidence=None,
                        channels=None if base.channels is None else base.channels[pick],
                        times=None), pick


def test_a_looped_capture_comes_out_as_the_capture_does():
    """CMU 85_02's first 2 s played over and over: every loop point is a cut, each loop is
    cleaned as the take it is, and the default — which leaves 85_02 as it is — leaves the
    loop as it is too (before the cuts it judged 888 samples wrong at the loop points and
    moved them up to 133 mm)."""
    base = read(shared("c3d/cmu_85_02.c3d"))
    loop, pick = _looped(base)
    pipeline = load_config(resolve_config("default"))
    result = clean_motion(loop, pipeline)
    assert take_cuts(loop).tolist() == list(range(240, 3000, 240))
    alone = clean_motion(base.replace(source=None), pipeline).cleaned.positions[pick]
    np.testing.assert_array_equal(result.cleaned.positions, alone)
    np.testing.assert_array_equal(result.cleaned.positions, loop.positions)
    report = build_report(result)
    assert report["file"]["samples_flagged"] == 0
    assert any(n.startswith("the take jumps as a whole at 12 frames (240, 480,")
               for n in report["file"]["notes"])


def test_cuts_are_found_on_the_distinct_frames_of_a_take_with_held_frames():
    """The 85_02 loop with every frame written twice: the cuts are found as ``clean``
    finds them, on its distinct frames, and given in the file's frames; the output is the
    loop's output with every frame twice."""
    base = read(shared("c3d/cmu_85_02.c3d"))
    loop, _ = _looped(base)
    doubled = loop.replace(positions=loop.positions.repeat(2, axis=0))
    assert cut_frames(doubled, HeldFrames.find(doubled)) == [2 * f for f in range(240, 3000, 240)]
    pipeline = load_config(resolve_config("default"))
    result = clean_motion(doubled, pipeline)
    once = clean_motion(loop, pipeline).cleaned.positions
    np.testing.assert_array_equal(result.cleaned.positions, once.repeat(2, axis=0))
    assert any(n.startswith("the take jumps as a whole at 12 frames (480, 960,")
               for n in result.cleaned.notes)


def test_joined_takes_are_repaired_each_on_its_own_and_no_fill_crosses_the_cut():
    """Two corrupted takes of one marker set joined (HDM05, its first and second halves, the
    second 50 cm away, a gap across the join): the output is each take's output cleaned
    alone, so nothing is filled, smoothed or judged across the join."""
    base = read(shared("c3d/hdm05_HDM_mm_01-02_03_120.c3d")).replace(source=None, confidence=None)
    half = base.n_frames // 2
    first = occlusion(base.slice_frames(0, half), "mixed", 0)[0].replace(confidence=None)
    second = occlusion(base.slice_frames(half, 2 * half), "mixed", 1)[0].replace(confidence=None)
    moved = second.positions + np.array([500.0, 0.0, 0.0]) / 1000.0 / base.metres_per_unit
    P = np.concatenate([first.positions, moved])
    j = 5
    P[half - 30:half + 30, j] = np.nan                  # a gap across the join
    joined = base.replace(positions=P)
    assert take_cuts(joined).tolist() == [half]
    pipeline = load_config(resolve_config("default"))
    out = clean_motion(joined, pipeline).cleaned
    alone = [clean_motion(joined.slice_frames(a, b), pipeline).cleaned.positions
             for a, b in ((0, half), (half, 2 * half))]
    np.testing.assert_array_equal(out.positions, np.concatenate(alone), strict=True)


def test_a_joined_take_in_windows_is_each_take_in_its_windows():
    """Cuts and memory-budget windows together: the joined take cleaned in windows of 700
    frames is each of its takes cleaned in windows of 700 frames, bit for bit, and the
    report says both."""
    base = read(shared("c3d/hdm05_HDM_mm_01-02_03_120.c3d")).replace(source=None, confidence=None)
    half = base.n_frames // 2
    shift = np.array([500.0, 0.0, 0.0]) / 1000.0 / base.metres_per_unit
    parts = [occlusion(base.slice_frames(0, half), "mixed", 0)[0].replace(confidence=None),
             occlusion(base.slice_frames(half, 2 * half), "mixed", 1)[0].replace(confidence=None)]
    joined = base.replace(positions=np.concatenate([parts[0].positions, parts[1].positions + shift]))
    pipeline = load_config(resolve_config("default"))
    windows = Windows(700, 120)
    result = clean_motion(joined, pipeline, windows=windows)
    alone = [clean_motion(joined.slice_frames(a, b), pipeline, windows=windows).cleaned.positions
             for a, b in ((0, half), (half, 2 * half))]
    np.testing.assert_array_equal(result.cleaned.positions, np.concatenate(alone), strict=True)
    notes = build_report(result)["file"]["notes"]
    assert any(n.startswith("cleaned in 6 windows of 700 frames") and n.endswith(
        "cut with no overlap where the take jumps as a whole (1 frame)") for n in notes)
    assert any(n.startswith("the take jumps as a whole at 1 frame (1995)") for n in notes)


def test_check_counts_no_outlier_at_a_cut():
    """``check``'s outlier figure takes the takes between the cuts as ``clean`` does: at
    the join of 85_02's halves (50 cm apart) the spike test on the whole take flags every
    marker, on the two takes none; the flags are each half's own."""
    base = read(shared("c3d/cmu_85_02.c3d")).replace(source=None, confidence=None)
    half = base.n_frames // 2
    P = np.concatenate([base.positions[:half], base.positions[half:2 * half] + [500.0, 0, 0]])
    joined = base.replace(positions=P)
    around = slice(half - 3, half + 3)
    assert outlier_flags(joined)[around].any(axis=0).mean() > 0.9
    flags = outlier_flags(joined, [half])
    assert not flags[around].any()
    np.testing.assert_array_equal(flags, np.concatenate(
        [outlier_flags(joined.slice_frames(0, half)), outlier_flags(joined.slice_frames(half))]))


def test_cuts_are_looked_for_on_the_labelled_markers_only():
    """A raw export's unlabelled fragments (Vicon ``*N``) are not the take's points: 30 of
    them jumping together at frame 400 beside 12 smooth markers are no cut (they were,
    counted with the markers), a jump of the 12 markers is one whatever the fragments
    do; ``check``'s outlier figure leaves the fragments unmeasured (None), as its rules
    leave them unjudged."""
    rng = np.random.default_rng(3)
    P = _walkers() * 1000.0
    frags = np.full((P.shape[0], 30, 3), np.nan)
    for u in range(30):
        start = int(rng.integers(380, 400))
        frags[start:start + 40, u] = rng.normal(0, 800, 3) + np.arange(40)[:, None] * [1.0, 0, 0]
    frags[400:] += [0.0, 300.0, 0.0]                # every fragment jumps 30 cm into frame 400
    names = [f"m{j}" for j in range(12)] + [f"*{u}" for u in range(30)]
    m = Motion(np.concatenate([P, frags], axis=1), names, 120.0)
    assert take_cuts(m).tolist() == [400]           # all 42 points measured
    assert cut_frames(m, None) == [] and take_cuts(m, np.arange(12)).size == 0
    joined = m.positions.copy()
    joined[700:, :12] += [0.0, 120.0, 0.0]
    assert cut_frames(m.replace(positions=joined), None) == [700]
    report = build_report(clean_motion(m.replace(positions=joined), load_config(resolve_config("default"))))
    assert "1 frame (700)" in " ".join(report["file"]["notes"])
    from mocapfix.quality.measure import measure_input
    measured = measure_input(m)
    assert measured["file"]["cuts"] == 0
    assert [j["outliers"] is None for j in measured["joints"]] == [False] * 12 + [True] * 30


@pytest.mark.parametrize("subdir", ["c3d", "bvh", "asfamc", "kinect"])
def test_the_shared_captures_have_no_cut_but_the_kinect_tracker_jump(subdir):
    """The detector's false alarms on real takes: none of the shared captures jumps as a
    whole but UTKinect s01_e01, whose 20 joints move 37 cm in one frame (15 of 20 past 20
    times their usual jump) at frame 263 (at 7.5 Hz: 5.5 m/s) and go on from there."""
    found = {}
    for param in shared_files(subdir):
        path = need(param.values[0])
        if path.suffix.lower() == ".asf":
            continue
        cuts = take_cuts(read(path)).tolist()
        if cuts:
            found[path.name] = cuts
    expected = {"kv1_utkinect_joints_s01_e01.txt": [263]} if subdir == "kinect" else {}
    assert found == expected
