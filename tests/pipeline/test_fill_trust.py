"""A fill is written as data only when it can be trusted (``max_fill_error``): every fill
gets an error estimate from synthetic gaps of its length and a calibrated 90 % bound
(:mod:`mocapfix.solvers.fill_error`); a fill whose bound exceeds the threshold is left
as a gap (C3D residual −1), reported with its estimate and bound in the report and the
MOCAPFIX parameter group, and no later step fills it. Real captures, gaps cut where the
truth is known."""
from __future__ import annotations

import json
import warnings

import c3d
import numpy as np
import pytest

from mocapfix import formats
from mocapfix.cleaning import clean_file
from mocapfix.bench.corrupt import occlusion_gaps
from mocapfix.core.errors import ConfigError
from mocapfix.config import UNIT_WARNINGS, default_config_path, load_config, loads_config, parse_config
from mocapfix.core.yamlsafe import load_marked_yaml as load_yaml
from mocapfix.solvers import fill_error
from conftest import shared

#: CMU 85_02 (breakdance): the right hand marker loses 1.5 s while the body turns
CAPTURE, MARKER, START, LENGTH = "c3d/cmu_85_02.c3d", "Male:RFIN", 300, 180


def _with_gap(tmp_path):
    """CMU 85_02 written with a 1.5 s gap of the right hand's finger marker (residual −1),
    and the true positions there."""
    motion = formats.read(shared(CAPTURE))
    j = motion.names.index(MARKER)
    truth = motion.positions[START:START + LENGTH, j].copy()
    pos = motion.positions.copy()
    pos[START:START + LENGTH, j] = np.nan
    path = tmp_path / "gap.c3d"
    formats.write(motion.replace(positions=pos), path)
    return path, j, truth


def _config(max_fill_error):
    data = load_yaml(default_config_path().read_text())
    data["max_fill_error"] = max_fill_error
    return parse_config(data)


def _residuals(path, j):
    with open(path, "rb") as handle, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        frames = [points for _, points, _ in c3d.Reader(handle).read_frames()]
    pts = np.stack(frames)
    return pts[:, j, :3], pts[:, j, 3]


def _group(path, prefix):
    with open(path, "rb") as handle, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        get = c3d.Reader(handle).get
        if get(f"MOCAPFIX:{prefix}_POINTS") is None:
            return []
        names = [s.strip() for s in get(f"MOCAPFIX:{prefix}_POINTS").string_array]
        first = get(f"MOCAPFIX:{prefix}_FIRST").float_array.astype(int)
        last = get(f"MOCAPFIX:{prefix}_LAST").float_array.astype(int)
        error = get(f"MOCAPFIX:{prefix}_ERROR").float_array
        bound = get(f"MOCAPFIX:{prefix}_BOUND").float_array
    return list(zip(names, first, last, error, bound))


@pytest.mark.slow
def test_a_long_uncertain_fill_is_left_reported_and_written_when_the_threshold_allows(tmp_path):
    path, j, truth = _with_gap(tmp_path)
    # as shipped: the hand through 1.5 s of breakdance cannot be trusted to 20 mm
    out = tmp_path / "gated.c3d"
    clean_file(path, out, load_config(default_config_path()))
    report = json.loads((tmp_path / "gated.c3d.report.json").read_text())
    joint = next(x for x in report["joints"] if x["name"] == MARKER)
    left = [g for g in joint["gaps"]["unfilled"] if g["start"] == START]
    assert left and left[0]["length"] == LENGTH and left[0]["filled_frames"] == 0
    refusal = next(r for r in left[0]["rejected_by"] if "too uncertain" in r["why"])
    error, bound = refusal["error_mm"], refusal["bound_mm"]
    assert 0 < error < bound and bound > 20.0
    assert f"estimated error {error:.0f} mm (90 % bound {bound:.0f} mm)" in refusal["why"]
    assert report["file"]["samples_left_uncertain"] >= LENGTH
    assert joint["left_uncertain"] > 0 and joint["status"] != "OK"
    # the file: residual −1 on every sample of the gap (py-c3d), listed as left with its
    # estimate and bound in the MOCAPFIX group (C3D frame numbers start at 1 here)
    _, residual = _residuals(out, j)
    assert (residual[START:START + LENGTH] == -1).all()
    first_frame = formats.read(shared(CAPTURE)).source.first_frame
    listed = [r for r in _group(out, "LEFT") if r[0] == MARKER and r[1] == first_frame + START]
    assert listed and listed[0][2] == first_frame + START + LENGTH - 1
    assert listed[0][3] == pytest.approx(error, abs=1e-3)
    assert listed[0][4] == pytest.approx(bound, abs=1e-3)
    assert not [r for r in _group(out, "FILL") if r[0] == MARKER and r[1] == first_frame + START]

    # a threshold just above its bound: the same fill is written (residual 0), with the
    # same estimate and bound in the report and the group, and no longer reported left
    raised = tmp_path / "raised.c3d"
    clean_file(path, raised, _config(f"{bound + 1.0:.1f} mm"))
    report = json.loads((tmp_path / "raised.c3d.report.json").read_text())
    joint = next(x for x in report["joints"] if x["name"] == MARKER)
    filled = [g for g in joint["gaps"]["filled"] if g["start"] == START]
    assert filled and filled[0]["bound_mm"] == pytest.approx(bound, abs=1e-3)
    assert filled[0]["error_mm"] == pytest.approx(error, abs=1e-3)
    assert not [g for g in joint["gaps"]["unfilled"] if g["start"] == START]
    xyz, residual = _residuals(raised, j)
    assert (residual[START:START + LENGTH] == 0).all()
    written = [r for r in _group(raised, "FILL") if r[0] == MARKER and r[1] == first_frame + START]
    assert written and written[0][4] == pytest.approx(bound, abs=1e-3)
    # the truth is known here: the bound was the right call either way (not asserted as
    # a coverage: one gap), but the fill must be the fill the estimate describes
    true = np.sqrt(np.mean(np.sum((xyz[START:START + LENGTH] - truth) ** 2, axis=1)))
    assert true > 1.0


def _coverage(runs, extrapolated_only: bool = False):
    """Every fill written (gate off, so the fills are not selected by their bound) on each
    ``(capture, frames, longest gap s, seed)`` of ``runs`` with ``occlusion`` gaps:
    whether each fill of the cut gaps (only the extrapolated ones with
    ``extrapolated_only``) lies within its 90 % bound, and its bound over its true RMS
    error (at least 0.5 mm)."""
    config = _config(None)
    covered, ratio = [], []
    for name, frames, max_s, seed in runs:
        truth = formats.read(shared(name)).slice_frames(0, frames)
        truth = truth.replace(source=None, confidence=None)
        mm = truth.metres_per_unit * 1e3
        corrupted, mask = occlusion_gaps(truth, np.random.default_rng(seed), max_s=max_s)
        out, _ = config.run(corrupted)
        for marker, entries in out.fill_errors.items():
            j = out.names.index(marker)
            for s, n, _, bound, _, written, far in entries:
                if not (written and mask[s:s + n, j].all()) or (extrapolated_only and not far):
                    continue
                d = np.linalg.norm(out.positions[s:s + n, j] - truth.positions[s:s + n, j], axis=1)
                true = float(np.sqrt(np.mean(d ** 2))) * mm
                covered.append(true <= bound)
                ratio.append(bound / max(true, 0.5))
    n = len(covered)
    share = float(np.mean(covered))
    print(f"{n} fills, {100 * share:.1f} % covered, median bound / true {np.median(ratio):.2f}")
    return n, share, 2 * np.sqrt(0.9 * 0.1 / n), float(np.median(ratio))


@pytest.mark.slow
def test_the_bound_covers_the_true_error_of_nine_fills_in_ten_on_a_real_capture():
    """Calibration on real captures (CMU 85_02 and HDM05, the first 1,200 frames), the
    ``occlusion`` gaps of 0.1–1.5 s, seeds 0–5, every fill written (gate off, so the
    fills are not selected by their bound): the true RMS error of a fill is within its
    90 % bound for 85–95 % of the fills, within two binomial standard errors; and the
    bounds are not vacuous (the median bound is within 6× the median true error)."""
    n, share, slack, ratio = _coverage(
        [(name, 1200, 1.5, seed) for name in ("c3d/cmu_85_02.c3d",
                                              "c3d/hdm05_HDM_mm_01-02_03_120.c3d")
         for seed in range(6)])
    assert n >= 100
    assert 0.85 - slack <= share <= 0.95 + slack
    assert ratio < 6.0


def test_a_step_without_estimates_has_its_fills_dropped_and_no_later_step_fills_them(tmp_path):
    """``kalman`` (fill: true) gives no error estimate: under the gate its fills are put
    back as missing and reported; the ``fill`` step after it leaves those samples alone
    (it is told they were left as too uncertain) though they are within its max_gap."""
    motion = formats.read(shared("c3d/hdm05_HDM_mm_01-02_03_120.c3d")).slice_frames(0, 600)
    pos = motion.positions.copy()
    j = 5
    pos[200:230, j] = np.nan                                  # 0.25 s
    motion = motion.replace(positions=pos, source=None)
    text = ("max_fill_error: 20 mm\npipeline:\n  - cleaner: kalman\n    fill: true\n"
            "  - cleaner: fill\n    method: pchip\n    max_gap: 0.5 s\n")
    out, records = loads_config(text).run(motion)
    assert out.missing[200:230, j].all()
    kalman, pchip = records                   # (a record's ``filled``: what the step kept)
    assert not kalman.filled[200:230, j].any() and not pchip.filled[200:230, j].any()
    refusal = kalman.info["rejected_fills"][motion.names[j]][0]
    assert refusal[:2] == [200, 30] and "kalman gives no error estimate" in refusal[2]
    # without the gate the same pipeline writes the kalman fill
    out, _ = loads_config(text.replace("20 mm", "null")).run(motion)
    assert not out.missing[200:230, j].any()


def test_tsmc_under_the_gate_fills_nothing_and_runs_no_completion():
    motion = formats.read(shared("c3d/hdm05_HDM_mm_01-02_03_120.c3d")).slice_frames(0, 600)
    pos = motion.positions.copy()
    pos[100:160, 3] = np.nan
    motion = motion.replace(positions=pos, source=None)
    out, records = loads_config("pipeline:\n  - cleaner: tsmc\n").run(motion)
    assert out.missing[100:160, 3].all() and records[0].info["iterations"] == 0
    assert "no error estimate" in records[0].info["skipped_fills"]
    out, records = loads_config("max_fill_error: null\npipeline:\n  - cleaner: tsmc\n").run(motion)
    assert not out.missing[100:160, 3].any() and records[0].info["iterations"] > 0


def test_max_fill_error_is_validated_and_round_trips():
    assert load_config(default_config_path()).max_fill_error.si == pytest.approx(0.02)
    p = loads_config("max_fill_error: 3 cm\npipeline: []\n")
    assert p.max_fill_error.si == pytest.approx(0.03)
    again = parse_config(load_yaml(p.dump()))
    assert again.max_fill_error.si == pytest.approx(0.03) and again.config() == p.config()
    off = loads_config("max_fill_error: null\npipeline: []\n")
    assert off.max_fill_error is None and off.config()["max_fill_error"] is None
    assert parse_config(load_yaml(off.dump())).max_fill_error is None
    for bad in ("-5 mm", "0 mm", "fast", "3 Hz", "[1]"):
        with pytest.raises(ConfigError) as err:
            loads_config(f"version: 1\npipeline: []\nmax_fill_error: {bad}\n", "my.yaml")
        assert "my.yaml (line 3): max_fill_error" in str(err.value)
    UNIT_WARNINGS.clear()
    loads_config("max_fill_error: 25\npipeline: []\n", "bare.yaml")
    assert UNIT_WARNINGS and "max_fill_error: 25 has no unit; read as '25 mm'" in UNIT_WARNINGS[0]
    UNIT_WARNINGS.clear()


def test_conformal_factor_is_the_finite_sample_quantile():
    # 19 scores 1..19: the 90 % conformal quantile is the ⌈20 × 0.9⌉ = 18th smallest
    assert fill_error.conformal_factor(np.arange(1.0, 20.0), minimum=10) == (18.0, True)
    # too few scores for the level: the prior, marked as such
    assert fill_error.conformal_factor(np.arange(1.0, 6.0), minimum=2, prior=2.5) == (2.5, False)
    # a gap's estimate is the geometric mean of its windows; a window's score its error
    # over the other window's (floored)
    errors = np.array([[3.0, 4.0], [1.0, np.nan]])
    assert fill_error.estimates(errors)[0] == pytest.approx(np.sqrt(12.0))
    assert fill_error.estimates(errors)[1] == pytest.approx(1.0)
    assert sorted(fill_error.scores(errors, 0.5)) == pytest.approx([0.75, 4 / 3])


#: the HDM05 marker the extrapolation tests take stretches from
ELBOW = "meinard:RELB"


def _short_seen(motion, j, seen, hole, long_gaps):
    """``motion`` with marker ``j`` seen only in stretches of ``seen`` frames between holes
    of ``hole`` frames, and missing on each ``(start, length)`` of ``long_gaps``: its
    longest validation window is ``seen − 2`` frames."""
    pos = motion.positions.copy()
    for t in range(seen, motion.n_frames, seen + hole):
        pos[t:t + hole, j] = np.nan
    for s, n in long_gaps:
        pos[s:s + n, j] = np.nan
    return pos


def test_a_gap_longer_than_any_seen_stretch_of_its_marker_gets_an_extrapolated_estimate(tmp_path):
    """HDM05 (120 Hz): the right elbow marker is seen in stretches of 54 frames at most
    (holes of 10 frames: longer than the ensemble's cubic Hermite holes, so they stay
    holes) and loses 150 frames at once — no window of the gap's length exists, 2.9× the
    longest one. Its fill gets an estimate extrapolated from the 52-frame windows, with
    a calibrated bound (at least the 1 mm physical floor), marked as extrapolated in the
    JSON report and the C3D MOCAPFIX group; the marker's 10-frame holes are not."""
    motion = formats.read(shared("c3d/hdm05_HDM_mm_01-02_03_120.c3d")).slice_frames(0, 600)
    j = motion.names.index(ELBOW)
    pos = _short_seen(motion, j, 54, 10, [(200, 150)])
    assert fill_error.longest_windows(~np.isnan(pos).any(axis=2))[j] == 52
    path = tmp_path / "short.c3d"
    formats.write(motion.replace(positions=pos, source=None), path)
    out = tmp_path / "out.c3d"
    clean_file(path, out, _config(None))
    report = json.loads((tmp_path / "out.c3d.report.json").read_text())
    joint = next(x for x in report["joints"] if x["name"] == ELBOW)
    gap = next(g for g in joint["gaps"]["filled"] if g["start"] == 200)
    assert gap["length"] == 150 and gap["extrapolated"] is True
    assert 0 < gap["error_mm"] <= gap["bound_mm"] and gap["bound_mm"] >= 1.0
    holes = [g for g in joint["gaps"]["filled"] if g["length"] == 10]
    assert holes and all(g["extrapolated"] is False and g["bound_mm"] is not None for g in holes)
    assert report["file"]["fills_extrapolated"] >= 1
    first = formats.read(path).source.first_frame
    with open(out, "rb") as handle, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        get = c3d.Reader(handle).get
        names = [s.strip() for s in get("MOCAPFIX:FILL_POINTS").string_array]
        starts = get("MOCAPFIX:FILL_FIRST").float_array.astype(int)
        flags = get("MOCAPFIX:FILL_EXTRAPOLATED").int8_array
    listed = {(n, s): f for n, s, f in zip(names, starts, flags) if n == ELBOW}
    assert listed[(ELBOW, first + 200)] == 1
    assert sum(listed.values()) == 1


def test_extrapolation_stops_at_the_cap():
    """A marker seen in stretches of 22 frames at most (windows of 20): a gap of 120
    frames (6× the window, :data:`MAX_RATIO`) gets an extrapolated estimate; one of 126
    (6.3×) gets none, and under the gate it is left as a gap, saying why."""
    assert fill_error.MAX_RATIO == 6.0
    motion = formats.read(shared("c3d/hdm05_HDM_mm_01-02_03_120.c3d")).slice_frames(0, 720)
    j = motion.names.index(ELBOW)
    pos = _short_seen(motion, j, 22, 10, [(150, 120), (450, 126)])
    corrupted = motion.replace(positions=pos, source=None)
    out, _ = _config(None).run(corrupted)
    entries = {e[0]: e for e in out.fill_errors[ELBOW]}
    assert entries[150][1] == 120 and entries[150][6] is True and entries[150][3] > 0
    assert 450 not in entries and not out.missing[450:576, j].any()      # filled, unestimated
    gated, records = load_config(default_config_path()).run(corrupted)
    assert gated.missing[450:576, j].all()
    left = [e for r in records for e in ((r.info or {}).get("rejected_fills") or {}).get(ELBOW, [])
            if e[0] == 450]
    assert left and "as long as 1/6 of the gap" in left[0][2] and left[0][3] is None


@pytest.mark.slow
def test_extrapolated_bounds_cover_the_true_error_at_about_the_stated_rate():
    """The extrapolated estimates, on many cut gaps whose truth is known: Qualisys (340
    frames at 200 Hz: most 0.1–3 s gaps are longer than any stretch their marker keeps)
    and CMU 85_02 (3 s gaps), ``occlusion`` gaps, every fill written. The 90 % bounds of
    the extrapolated fills cover their true RMS error for 85–95 % of them within two
    binomial standard errors (benchmarks/fill_calibration.py: 94.9 % of 273), and they
    are not vacuous (median bound within 8× the true error)."""
    runs = [("c3d/ezc3d_Qualisys.c3d", 340, s, seed) for s in (1.5, 3.0) for seed in range(6)]
    runs += [("c3d/cmu_85_02.c3d", 810, 3.0, seed) for seed in range(4)]
    n, share, slack, ratio = _coverage(runs, extrapolated_only=True)
    assert n >= 60
    assert 0.85 - slack <= share <= 0.95 + slack
    assert ratio < 8.0


def test_growth_exponent_and_extrapolated_bounds_on_a_known_law():
    # windows 2× their probes, errors exactly ∝ length^0.8: the exponent is found, the
    # gap (3× its windows) is estimated by it, and every score is 1
    span = np.log(np.full(6, 2.0))
    rise = 0.8 * span
    slope, own, loo = fill_error.growth_exponent(rise, span)
    assert own and slope == pytest.approx(0.8) and loo == pytest.approx(np.full(6, 0.8))
    assert fill_error.growth_exponent(rise[:2], span[:2]) == (fill_error.PRIOR_SLOPE, False,
                                                              pytest.approx([0.6, 0.6]))
    probes = np.full((6, 2), 1.0)
    windows = np.full((6, 2), 2.0 ** 0.8)
    est, bound, factor, own, slope, _ = fill_error.extrapolated_bounds(
        windows, probes, np.full(6, 3.0), np.full(6, 2.0), 1e-3)
    assert own and factor == pytest.approx(1.0) and slope == pytest.approx(0.8)
    assert est == pytest.approx(2.0 ** 0.8 * 3.0 ** 0.8) and bound == pytest.approx(est)
    # a gap whose windows grow faster than the others' probes says so in its score
    windows[0] *= 3.0
    scores = fill_error.extrapolation_scores(windows, probes[:, 0], span, np.full(6, 0.8), 1e-3)
    assert sorted(scores)[-2:] == pytest.approx([3.0, 3.0])
