"""Corruption protocols do exactly what they claim, metrics match hand computations, and
``mocapfix bench`` runs end to end."""
from __future__ import annotations

import json
import shutil
import time

import numpy as np
import pytest
from click.testing import CliRunner

from mocapfix import bench
from mocapfix.bench import corrupt
from mocapfix.core import metrics
from mocapfix.bench.cli import bench as bench_cmd
from mocapfix.cli import main
from mocapfix.core.gaps import runs
from mocapfix.core.motion import Motion, Skeleton

from conftest import SAMPLE_DATA, cut_amc, no_traceback

SAMPLE = SAMPLE_DATA


def make_motion(T=600, J=31, units="mm", mpu=1e-3, seed=7):
    """A smooth synthetic capture: each marker a random offset plus slow sines, in metres
    ×1/mpu (so the same motion can be expressed in any unit)."""
    rng = np.random.default_rng(seed)
    t = np.arange(T)[:, None, None] / 120.0
    offsets = rng.uniform(-0.8, 0.8, size=(1, J, 3))
    freq = rng.uniform(0.3, 2.0, size=(1, J, 3))
    pos_m = offsets + 0.2 * np.sin(2 * np.pi * freq * t) + np.array([0.5, 0.0, 0.0]) * t
    parents = np.r_[-1, np.arange(J - 1)]
    return Motion(pos_m / mpu, [f"m{j}" for j in range(J)], 120.0, units=units,
                  metres_per_unit=mpu, format="c3d", skeleton=Skeleton(parents))


# -- corruption protocols --------------------------------------------------------------

def test_random_missing_exact_fraction_and_reproducible():
    m = make_motion()
    c, mask = corrupt.random_missing(m, np.random.default_rng(3), 0.40)
    assert mask.sum() == round(0.40 * mask.size)
    assert np.array_equal(np.isnan(c.positions).any(axis=2), mask)
    assert np.isnan(c.positions[mask]).all()             # whole samples go missing
    assert np.array_equal(c.positions[~mask], m.positions[~mask])
    c2, mask2 = corrupt.random_missing(m, np.random.default_rng(3), 0.40)
    assert np.array_equal(mask, mask2)
    _, mask3 = corrupt.random_missing(m, np.random.default_rng(4), 0.40)
    assert not np.array_equal(mask, mask3)
    assert not np.isnan(m.positions).any()               # input untouched


@pytest.mark.parametrize("units,mpu", [("mm", 1e-3), ("in/0.45", corrupt.ASF_UNIT_M), ("m", 1.0)])
def test_uniform_outliers_fraction_and_size_in_any_unit(units, mpu):
    m = make_motion(units=units, mpu=mpu)
    c, mask = corrupt.uniform_outliers(m, np.random.default_rng(0), 0.15, 25.0)
    assert mask.sum() == round(0.15 * mask.size)
    delta_cm = (c.positions - m.positions) * mpu * 100
    assert np.allclose(delta_cm[~mask], 0.0)
    d = delta_cm[mask]
    assert np.abs(d).max() <= 25.0 + 1e-9
    assert np.all(np.abs(d).max(axis=1) > 0)               # every chosen sample moved
    # U(-25, 25): mean |x| = 12.5 cm, var = 625/3 cm²
    assert abs(np.abs(d).mean() - 12.5) < 0.3
    assert abs(d.var() - 625 / 3) < 6


@pytest.mark.parametrize("snr", [30, 10, 5])
def test_gaussian_snr_computed_back(snr):
    m = make_motion()
    c, mask = corrupt.gaussian_snr(m, np.random.default_rng(1), snr)
    assert mask.all()
    noise = c.positions - m.positions
    centred = m.positions - m.positions.mean(axis=0)
    measured = 10 * np.log10(np.mean(centred ** 2) / np.mean(noise ** 2))
    assert abs(measured - snr) < 0.05
    # unit-free: the same motion in metres gets the same SNR and noise ×1e-3
    m_m = make_motion(units="m", mpu=1.0)
    c_m, _ = corrupt.gaussian_snr(m_m, np.random.default_rng(1), snr)
    assert np.allclose((c_m.positions - m_m.positions) * 1000, noise, rtol=1e-6, atol=1e-6)


def test_gaussian_on_fraction_sigma_is_two_asf_units():
    m = make_motion(units="mm", mpu=1e-3)
    c, mask = corrupt.gaussian_on_fraction(m, np.random.default_rng(2), 0.30, 2.0)
    assert mask.sum() == round(0.30 * mask.size)
    d = c.positions - m.positions
    assert np.allclose(d[~mask], 0)
    sigma_mm = d[mask].std()
    assert abs(sigma_mm - 112.89) < 2.5                  # 2 × 56.444 mm


def test_regular_gaps_ten_markers_sixty_frames():
    m = make_motion(T=610, J=31)
    c, mask = corrupt.regular_gaps(m, np.random.default_rng(5), 0.30, 10, 60)
    per_frame = mask.sum(axis=1)
    assert set(np.unique(per_frame)) <= {0, 10}
    col, start, length = runs(mask)
    assert np.all((length == 60) | (start + length == m.n_frames))
    assert np.all(start % 60 == 0)
    # closest achievable fraction: windows hold 600 samples (the last 100) of 18910
    assert abs(mask.mean() - 0.30) <= 600 / mask.size / 2 + 1e-12
    assert np.array_equal(np.isnan(c.positions).any(axis=2), mask)
    with pytest.raises(ValueError):
        corrupt.regular_gaps(make_motion(J=8), np.random.default_rng(0))


def test_feng2014_mixed_missing_then_noise_on_the_rest():
    m = make_motion()
    c, mask = corrupt.apply_protocol(m, "feng2014", "mixed", seed=0)
    missing = np.isnan(c.positions).any(axis=2)
    noisy = ~missing & (np.abs(c.positions - m.positions).max(axis=2) > 0)
    assert missing.sum() == round(0.30 * mask.size)
    assert noisy.sum() == round(0.30 * (~missing).sum())
    assert np.array_equal(mask, missing | noisy)


def test_feng2015_mixed_and_protocol_table():
    m = make_motion()
    c, mask = corrupt.apply_protocol(m, "feng2015", "snr20+out10", seed=0)
    assert mask.all()
    assert list(corrupt.PROTOCOLS["yang2019"]) == ["5%", "10%", "15%", "20%", "80%"]
    assert len(corrupt.PROTOCOLS["feng2015"]) == 16
    c2, _ = corrupt.apply_protocol(m, "feng2015", "snr20+out10", seed=0)
    assert np.array_equal(c.positions, c2.positions)
    o1, k1 = corrupt.apply_protocol(m, "occlusion", "gaps", seed=4)
    o2, k2 = corrupt.occlusion(m, "gaps", seed=4)
    assert np.array_equal(k1, k2)
    with pytest.raises(ValueError):
        corrupt.apply_protocol(m, "feng2015", "snr99")


def test_protocols_leave_originally_missing_samples_alone():
    m = make_motion()
    pos = m.positions.copy()
    pos[100:150, 3] = np.nan
    m = m.replace(positions=pos)
    for proto, settings in corrupt.PROTOCOLS.items():
        if proto in ("occlusion", "rotations"):   # rotations: needs channels (test_mssa_rotations)
            continue
        for s in settings:
            _, mask = corrupt.apply_protocol(m, proto, s, seed=1)
            assert not mask[100:150, 3].any(), (proto, s)


# -- metrics -----------------------------------------------------------------------------

def test_metrics_hand_computed():
    truth = np.zeros((2, 2, 3))
    est = np.zeros((2, 2, 3))
    est[0, 0] = [3, 4, 0]        # error 5
    est[1, 1] = [0, 0, 1]        # error 1
    est[1, 0] = np.nan           # unfilled
    assert metrics.rmse(est, truth) == pytest.approx(np.sqrt((25 + 0 + 1) / 3))
    mask = np.array([[True, False], [True, True]])
    assert metrics.rmse(est, truth, mask) == pytest.approx(np.sqrt((25 + 1) / 2))
    assert metrics.max_error(est, truth) == pytest.approx(5.0)
    assert metrics.unfilled_fraction(est, truth) == pytest.approx(0.25)
    assert metrics.mean_joint_error(est, truth) == pytest.approx(6 / 3)
    # bones: truth length 1 along x; estimate lengths 2 (frame 0) and 1.5 (frame 1)
    t = np.zeros((2, 2, 3)); t[:, 1, 0] = 1.0
    e = np.zeros((2, 2, 3)); e[0, 1, 0] = 2.0; e[1, 1, 0] = 1.5
    assert metrics.mean_bone_error(e, t, [(0, 1)]) == pytest.approx(0.75)


def test_evaluate_units_and_protocol_metrics():
    truth = make_motion(T=4, J=2, units="mm", mpu=1e-3)
    est = truth.positions.copy()
    est[0, 0] += [3, 4, 0]          # 5 mm
    est[2, 1] = np.nan
    mask = np.zeros((4, 2), bool); mask[0, 0] = True; mask[2, 1] = True
    ev = bench.evaluate("feng2014", truth, est, mask)
    assert ev["rmse_corrupted_cm"] == pytest.approx(0.5)
    assert ev["rmse_cm"] == pytest.approx(np.sqrt(25 / 7) / 10)
    assert ev["unfilled_pct"] == pytest.approx(12.5)
    ev = bench.evaluate("occlusion", truth, est, mask)
    assert ev["max_mm"] == pytest.approx(5.0) and ev["rmse_corrupted_mm"] == pytest.approx(5.0)
    ev = bench.evaluate("yang2019", truth, est, mask)
    assert ev["aje_m"] == pytest.approx(0.005 / 7)
    assert "abe_m" in ev
    ev = bench.evaluate("feng2015", truth, est, mask)
    assert ev["rmse_cm"] == pytest.approx(np.sqrt(25 / 7) / 10)


# -- runner ------------------------------------------------------------------------------

def test_run_statistics_over_seeds_hand_computed():
    """A method whose k-th run returns the truth moved by k × (3, 4, 0) mm everywhere:
    RMSE 5, 10, 15 mm = 0.5, 1.0, 1.5 cm over the three seeds, so mean 1.0 cm and
    sample standard deviation 0.5 cm, whatever the corruption was."""
    m = make_motion(T=300, J=12)
    calls = []

    class Shifted(bench.Method):
        def run(self, motion):
            calls.append(1)
            return m.replace(positions=m.positions + len(calls) * np.array([3.0, 4.0, 0.0])), None

    res = bench.run([m], "feng2015", [Shifted("shifted", "cleaner", None)], seeds=3,
                    settings=["out10"])
    assert len(calls) == 3
    row = res.summary()[0]
    assert row["metrics"]["rmse_cm"]["mean"] == pytest.approx(1.0)
    assert row["metrics"]["rmse_cm"]["std"] == pytest.approx(0.5)
    assert row["metrics"]["unfilled_pct"]["mean"] == 0.0
    json.loads(res.to_json())


def test_run_none_is_the_corruption():
    """``none`` returns its input: the corrupted samples of ``out10`` (10 % of samples
    moved, the rest untouched) make its error, and the seeds differ."""
    m = make_motion(T=300, J=12)
    methods, _ = bench.resolve_methods([])
    none = [x for x in methods if x.name == "none"]
    row = bench.run([m], "feng2015", none, seeds=3, settings=["out10"]).summary()[0]
    assert row["metrics"]["rmse_cm"]["mean"] > 0 and row["metrics"]["rmse_cm"]["std"] > 0


def test_methods_see_positions_without_rig_and_failures_are_recorded():
    from mocapfix import formats

    amc = formats.read(SAMPLE / "walker_01.amc")
    c, _ = corrupt.apply_protocol(amc, "yang2019", "5%", 0)
    inp = bench.cleaner_input(amc, c)
    assert inp.rig is None and inp.channels is None and inp.skeleton is not None
    assert np.array_equal(inp.positions, c.positions, equal_nan=True)

    class Boom(bench.Method):
        def run(self, motion):
            raise RuntimeError("kaboom")

    res = bench.run([amc], "yang2019", [Boom("boom", "cleaner", None)], seeds=1, settings=["5%"])
    assert "kaboom" in res.runs[0]["error"]
    assert "ERR" in res.to_markdown()


def test_resolve_methods_baselines_and_unknown():
    from mocapfix.core.errors import ConfigError

    methods, notes = bench.resolve_methods(["gaussian"])
    names = [m.name for m in methods]
    assert names[:2] == ["none", "linear+gaussian"] and "gaussian" in names
    assert ("pca+butterworth" in names) or any("pca+butterworth" in n for n in notes)
    with pytest.raises(ConfigError, match="named pipeline"):
        bench.resolve_methods(["no_such_cleaner"])


def test_named_svt_baseline_is_plain_low_rank_completion():
    """``svt`` (the TSMC paper's comparison) is matrix completion: on an exactly rank-2,
    temporally rough motion with 20 % of the samples missing at random it recovers them
    (interpolation cannot), and leaves the observed samples as they are."""
    from mocapfix.core.motion import Motion

    methods, _ = bench.resolve_methods(["svt", "trust+tsmc", "linear", "spline"])
    named = {m.name: m for m in methods}
    assert {"svt", "trust+tsmc", "linear", "spline"} <= set(named)
    rng = np.random.default_rng(0)
    pos = (rng.normal(size=(400, 2)) @ rng.normal(0, 100, (2, 60))).reshape(400, 20, 3) + 500.0
    truth = Motion(pos, [f"M{j}" for j in range(20)], 100.0, format="c3d")
    holed = pos.copy()
    holed[rng.random((400, 20)) < 0.2] = np.nan
    gap = np.isnan(holed).any(axis=2)
    out, _ = named["svt"].run(truth.replace(positions=holed))
    lin, _ = named["linear"].run(truth.replace(positions=holed))
    assert np.array_equal(out.positions[~gap], pos[~gap])
    filled = gap & ~np.isnan(out.positions).any(axis=2)
    assert filled.sum() > 0.99 * gap.sum()      # frames with < half the markers are left
    err = np.linalg.norm(out.positions - pos, axis=2)[filled]
    lin_err = np.linalg.norm(lin.positions - pos, axis=2)[filled]
    # measured: svt RMSE 0.03 mm (max 0.5), linear 227 mm on this ±880 mm motion
    assert np.sqrt(np.mean(err ** 2)) < 0.1 and err.max() < 2.0
    assert np.sqrt(np.mean(err ** 2)) < 0.01 * np.sqrt(np.nanmean(lin_err ** 2))


# -- CLI ---------------------------------------------------------------------------------

def test_cli_end_to_end_c3d(tmp_path):
    out_json, out_md = tmp_path / "b.json", tmp_path / "b.md"
    result = CliRunner().invoke(bench_cmd, [
        str(SAMPLE / "walk_markers.c3d"), "--protocol", "occlusion", "--methods",
        "gaussian,fill", "--seeds", "1", "--settings", "noise,swap", "--json", str(out_json),
        "--markdown", str(out_md)])
    assert result.exit_code == 0, result.output
    data = json.loads(out_json.read_text())
    methods = {r["method"] for r in data["summary"]}
    assert {"none", "linear+gaussian", "gaussian", "fill"} <= methods
    assert {r["setting"] for r in data["summary"]} == {"noise", "swap"}
    assert "RMSE mm" in out_md.read_text() and "RMSE mm" in result.output


def test_cli_end_to_end_amc_config(tmp_path):
    cfg = tmp_path / "mine.yaml"
    cfg.write_text("version: 1\npipeline:\n  - cleaner: butterworth\n    cutoff: 8 Hz\n")
    result = CliRunner().invoke(bench_cmd, [
        str(SAMPLE / "walker_01.amc"), "--protocol", "yang2019", "--configs", str(cfg),
        "--seeds", "1", "--settings", "10%", "-q", "--json", str(tmp_path / "y.json")])
    assert result.exit_code == 0, result.output
    data = json.loads((tmp_path / "y.json").read_text())
    row = [r for r in data["summary"] if r["method"] == "config:mine"][0]
    assert 0 < row["metrics"]["aje_m"]["mean"] < 0.1 and "abe_m" in row["metrics"]


def test_cli_errors_are_one_line(tmp_path):
    r = CliRunner().invoke(bench_cmd, [str(SAMPLE / "walk_markers.c3d"), "--protocol",
                                       "occlusion", "--methods", "nope", "--seeds", "1"])
    assert r.exit_code == 2 and "unknown method 'nope'" in r.output
    r = CliRunner().invoke(bench_cmd, [str(tmp_path / "missing.c3d"), "--protocol",
                                       "occlusion", "--seeds", "1", "-q"])
    assert r.exit_code == 2 and "no such file" in r.output


def test_time_budget_stops_a_method_after_whole_runs():
    m = make_motion(T=200, J=10)

    class Busy(bench.Method):
        def run(self, motion):
            end = time.process_time() + 0.01          # burn 10 ms of CPU
            while time.process_time() < end:
                pass
            return motion.copy(), None

    methods = [Busy("busy", "cleaner", None), Busy("busy2", "cleaner", None)]
    res = bench.run([m], "yang2019", methods, seeds=2, settings=["5%", "10%"], method_budget_s=0.005)
    counts = {}
    for r in res.runs:
        counts[r["method"]] = counts.get(r["method"], 0) + 1
    assert set(counts.values()) == {1}                     # each ran once, then stopped
    assert any("CPU budget" in n and "ran 1 of 4" in n for n in res.notes)
    assert "[1/2 seeds]" in res.to_markdown()


def test_bench_occlusion_on_a_three_frame_take_says_why(tmp_path):
    # it said "occlusion/mixed: low >= high" (NumPy's message for an empty random range)
    shutil.copy(SAMPLE_DATA / "walker.asf", tmp_path / "walker.asf")
    short = cut_amc(SAMPLE_DATA / "walker_01.amc", tmp_path / "walker_02.amc", 3)
    r = CliRunner().invoke(main, ["bench", str(short), "--protocol", "occlusion", "--seeds", "1",
                                  "--methods", "fill", "-q"])
    no_traceback(r)
    assert r.exit_code == 3, r.output          # the only file, left out: nothing benchmarked
    assert "low >= high" not in r.output
    assert f"{short}: occlusion/" in r.output and "3 frames; the occlusion protocol needs at least 4" in r.output


def test_a_file_named_twice_is_benchmarked_once(tmp_path):
    # `bench walk.bvh walk.bvh` scored it twice: double weight in every mean, and no word
    src = SAMPLE_DATA / "walk.bvh"
    link = tmp_path / "again.bvh"
    link.symlink_to(src)
    args = ["--protocol", "feng2015", "--seeds", "1", "--settings", "snr20", "--methods", "none"]
    once = CliRunner().invoke(main, ["bench", str(src), *args, "--json", str(tmp_path / "1.json")])
    twice = CliRunner().invoke(main, ["bench", str(src), str(link), str(src), *args,
                                      "--json", str(tmp_path / "2.json")])
    no_traceback(twice)
    assert once.exit_code == twice.exit_code == 0, twice.output
    assert "2 file(s) given more than once (benchmarked once)" in twice.output
    runs = [json.loads((tmp_path / n).read_text())["runs"] for n in ("1.json", "2.json")]
    assert len(runs[1]) == len(runs[0]) > 0


def _unreadable(tmp_path):
    """A truncated C3D, a text file of no format and a folder, in ``tmp_path``."""
    cut = tmp_path / "cut.c3d"
    cut.write_bytes((SAMPLE / "walk_markers.c3d").read_bytes()[:3000])
    garbage = tmp_path / "garbage.bvh"
    garbage.write_text("not a motion file\n")
    folder = tmp_path / "folder.c3d"
    folder.mkdir()
    return [cut, garbage, folder]


_QUICK = ["--protocol", "occlusion", "--methods", "none", "--seeds", "1", "--settings", "noise",
          "-q"]


def test_an_unreadable_file_is_named_and_left_out_the_others_benchmarked(tmp_path):
    # one truncated file stopped the whole bench before any work (exit 2)
    good = SAMPLE / "walk_markers.c3d"
    bad = _unreadable(tmp_path)
    out_json, out_md = tmp_path / "b.json", tmp_path / "b.md"
    r = CliRunner().invoke(main, ["bench", str(bad[0]), str(good), *map(str, bad[1:]), *_QUICK,
                                  "--json", str(out_json), "--markdown", str(out_md)])
    no_traceback(r)
    assert r.exit_code == 1, r.output
    for f in bad:
        lines = [line for line in r.stderr.splitlines() if line.startswith(f"mocapfix: error: {f}:")]
        assert len(lines) == 1, r.stderr
    data = json.loads(out_json.read_text())
    assert data["files"] == [str(good)]
    assert data["runs"] and {run["file"] for run in data["runs"]} == {str(good)}
    left_out = [n for n in data["notes"] if n.endswith("(left out of the benchmark)")]
    assert [n.split(":")[0] for n in left_out] == list(map(str, bad))
    assert f"- note: {bad[2]}: is a directory, not a file (left out of the benchmark)" \
        in out_md.read_text()


def test_bench_with_no_readable_file_writes_nothing(tmp_path):
    out_json = tmp_path / "b.json"
    r = CliRunner().invoke(main, ["bench", *map(str, _unreadable(tmp_path)), *_QUICK,
                                  "--json", str(out_json)])
    no_traceback(r)
    assert r.exit_code == 3, r.output
    assert "no file could be read and used: nothing benchmarked, nothing written" in r.stderr
    assert not out_json.exists()
    # a path that does not exist is a usage error, before any work, as in clean and check
    r = CliRunner().invoke(main, ["bench", str(SAMPLE / "walk_markers.c3d"),
                                  str(tmp_path / "missing.c3d"), *_QUICK, "--json", str(out_json)])
    assert r.exit_code == 2 and f"mocapfix: error: {tmp_path / 'missing.c3d'}: no such file" in r.stderr
    assert not out_json.exists()


def _three_frames(tmp_path):
    shutil.copy(SAMPLE / "walker.asf", tmp_path / "walker.asf")
    return cut_amc(SAMPLE / "walker_01.amc", tmp_path / "walker_02.amc", 3)


def _eight_markers(tmp_path):
    from mocapfix import formats
    from mocapfix.pipeline.selection import take

    c3d = formats.read(SAMPLE / "walk_markers.c3d")
    return formats.write(take(c3d, np.arange(c3d.n_joints) < 8), tmp_path / "eight.c3d")[0]


def _no_sample(tmp_path):
    from mocapfix import formats

    c3d = formats.read(SAMPLE / "walk_markers.c3d")
    return formats.write(c3d.replace(positions=np.full_like(c3d.positions, np.nan)),
                         tmp_path / "dark.c3d")[0]


@pytest.mark.parametrize("protocol,setting,unusable,cause", [
    ("occlusion", "noise", _three_frames,
     "occlusion/noise: 3 frames; the occlusion protocol needs at least 4"),
    ("rotations", "jitter", lambda tmp_path: SAMPLE / "walk_markers.c3d",
     "rotations/jitter: the rotations protocol needs rotation channels (BVH or ASF/AMC)"),
    ("feng2014", "regular-gaps", _eight_markers,
     "feng2014/regular-gaps: regular gaps need at least 10 markers, the motion has 8"),
    ("harm", "as-read", _no_sample, "no sample present, nothing to benchmark"),
], ids=["too-short", "no-channels", "too-few-markers", "no-sample"])
def test_a_file_the_protocol_cannot_use_is_named_and_left_out(tmp_path, protocol, setting,
                                                             unusable, cause):
    # a readable file the protocol cannot use stopped the whole bench (exit 2)
    good, bad = SAMPLE / "walk.bvh", unusable(tmp_path)
    out_json = tmp_path / "b.json"
    args = ["--protocol", protocol, "--settings", setting, "--methods", "none", "--seeds", "1",
            "-q", "--json", str(out_json)]
    r = CliRunner().invoke(main, ["bench", str(bad), str(good), *args])
    no_traceback(r)
    assert r.exit_code == 1, r.output
    assert r.stderr.splitlines() == [f"mocapfix: error: {bad}: {cause}"]
    data = json.loads(out_json.read_text())
    assert data["files"] == [str(good)]
    assert data["runs"] and {run["file"] for run in data["runs"]} == {str(good)}
    assert f"{bad}: {cause} (left out of the benchmark)" in data["notes"]
    out_json.unlink()
    r = CliRunner().invoke(main, ["bench", str(bad), *args])      # no file usable
    no_traceback(r)
    assert r.exit_code == 3, r.output
    assert f"mocapfix: error: {bad}: {cause}" in r.stderr and not out_json.exists()
