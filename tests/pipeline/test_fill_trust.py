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
from mocapfix.clean import clean_file
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


@pytest.mark.slow
def test_the_bound_covers_the_true_error_of_nine_fills_in_ten_on_a_real_capture():
    """Calibration on real captures (CMU 85_02 and HDM05, the first 1,200 frames), the
    ``occlusion`` gaps of 0.1–1.5 s, seeds 0–5, every fill written (gate off, so the
    fills are not selected by their bound): the true RMS error of a fill is within its
    90 % bound for 85–95 % of the fills, within two binomial standard errors; and the
    bounds are not vacuous (the median bound is within 6× the median true error)."""
    config = _config(None)
    covered, ratio = [], []
    for name in ("c3d/cmu_85_02.c3d", "c3d/hdm05_HDM_mm_01-02_03_120.c3d"):
        truth = formats.read(shared(name)).slice_frames(0, 1200)
        truth = truth.replace(source=None, confidence=None)
        mm = truth.metres_per_unit * 1e3
        for seed in range(6):
            corrupted, mask = occlusion_gaps(truth, np.random.default_rng(seed), max_s=1.5)
            out, _ = config.run(corrupted)
            for marker, entries in out.fill_errors.items():
                j = out.names.index(marker)
                for s, n, _, bound, _, written in entries:
                    if not written or not mask[s:s + n, j].all():
                        continue
                    d = np.linalg.norm(out.positions[s:s + n, j] - truth.positions[s:s + n, j], axis=1)
                    true = float(np.sqrt(np.mean(d ** 2))) * mm
                    covered.append(true <= bound)
                    ratio.append(bound / max(true, 0.5))
    n = len(covered)
    share = float(np.mean(covered))
    slack = 2 * np.sqrt(0.9 * 0.1 / n)
    print(f"{n} fills, {100 * share:.1f} % covered, median bound / true {np.median(ratio):.2f}")
    assert n >= 100
    assert 0.85 - slack <= share <= 0.95 + slack
    assert np.median(ratio) < 6.0


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
