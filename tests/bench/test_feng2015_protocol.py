"""The feng2015 protocol's SNR definitions give the noise power they state, and the
oracle-tuned baselines pick the best grid value (issue 10, calibration against Feng 2015)."""
from __future__ import annotations

import numpy as np
import pytest

from mocapfix import bench
from mocapfix.bench import corrupt
from mocapfix.core import metrics
from mocapfix.bench.oracle import OracleMethod, TUNED, tuned_method
from mocapfix.core.motion import Motion, Skeleton
from mocapfix.solvers import segments

from conftest import shared


def _motion(pos_m, mpu=1.0, units="m"):
    T, J, _ = pos_m.shape
    return Motion(pos_m / mpu, [f"j{j}" for j in range(J)], 120.0, units=units,
                  metres_per_unit=mpu, format="asfamc", skeleton=Skeleton(np.r_[-1, np.arange(J - 1)]))


def _known_positions(T=3600, J=4):
    """Channel j, axis a: a constant level c[j, a] (m) plus a 1 Hz sine (whole periods) of amplitude
    s[j, a]: uncentred power c² + s²/2, centred power s²/2 — known by hand."""
    c = np.array([[1.0, 2.0, -1.0], [0.5, 1.5, 0.0], [-2.0, 1.0, 1.0], [0.0, 1.0, 3.0]])[:J]
    s = np.array([[0.2, 0.1, 0.4], [0.3, 0.0, 0.2], [0.1, 0.1, 0.1], [0.5, 0.2, 0.3]])[:J]
    t = np.arange(T)[:, None, None] / 120.0
    return c + s * np.sin(2 * np.pi * t), c, s


@pytest.mark.parametrize("snr", [30, 20, 10, 5])
def test_uncentred_snr_gives_the_stated_noise_power(snr):
    pos, c, s = _known_positions()
    power = np.mean(c ** 2 + s ** 2 / 2)                 # by hand, over all channels
    m = _motion(pos)
    noisy, mask = corrupt.feng2015_gaussian(m, np.random.default_rng(3), snr, "uncentred")
    assert mask.all()
    noise = noisy.positions - pos
    # one σ for every channel, σ² = P / 10^(SNR/10)
    expected_var = power / 10 ** (snr / 10)
    per_channel = noise.var(axis=0)
    assert np.allclose(per_channel, expected_var, rtol=0.1)
    assert abs(10 * np.log10(power / np.mean(noise ** 2)) - snr) < 0.05
    # unit-free: the same motion in mm gets the same SNR, noise ×1000
    m_mm = _motion(pos, mpu=1e-3, units="mm")
    noisy_mm, _ = corrupt.feng2015_gaussian(m_mm, np.random.default_rng(3), snr, "uncentred")
    assert np.allclose((noisy_mm.positions - m_mm.positions) * 1e-3, noise, atol=1e-9)


def test_other_snr_definitions_by_hand():
    pos, c, s = _known_positions()
    snr = 10.0
    k = 10 ** (snr / 10)
    sig = {d: corrupt.feng2015_noise_sigma(pos, snr, d)[0] for d in corrupt.FENG2015_SNR_DEFINITIONS}
    assert np.allclose(sig["uncentred"], np.sqrt(np.mean(c ** 2 + s ** 2 / 2) / k), rtol=1e-3)
    assert np.allclose(sig["uncentred-per-channel"], np.sqrt((c ** 2 + s ** 2 / 2) / k), rtol=2e-3)
    assert np.allclose(sig["centred"], np.sqrt(np.mean(s ** 2 / 2) / k), rtol=2e-3)
    assert np.allclose(sig["centred-per-channel"], np.sqrt(s ** 2 / 2 / k), rtol=2e-3)
    # root-relative: joint j minus joint 0 (both sines in phase): amplitude s_j − s_0
    rel = np.mean((s - s[0]) ** 2 / 2)
    assert np.allclose(sig["root-relative"], np.sqrt(rel / k), rtol=2e-3)
    # the old gaussian_snr is the centred definition
    assert np.isclose(corrupt.signal_power(pos), np.mean(s ** 2 / 2), rtol=2e-3)
    with pytest.raises(ValueError, match="unknown SNR definition"):
        corrupt.feng2015_noise_sigma(pos, snr, "peak")


def test_protocol_uses_the_chosen_definition_and_outlier_size():
    pos, c, s = _known_positions(T=2400)
    m = _motion(pos)
    power = np.mean(c ** 2 + s ** 2 / 2)
    noisy, mask = corrupt.apply_protocol(m, "feng2015", "snr20", seed=4)
    noise = noisy.positions - pos
    assert corrupt.FENG2015_SNR_DEFINITION == "uncentred"
    assert abs(10 * np.log10(power / np.mean(noise ** 2)) - 20) < 0.1
    out, mask = corrupt.apply_protocol(m, "feng2015", "out20", seed=4)
    d = (out.positions - pos)[mask] * 100
    assert mask.sum() == round(0.2 * mask.size)
    h = corrupt.FENG2015_OUTLIER_CM
    assert np.abs(d).max() <= h and np.abs(d).max() > 0.95 * h


def _smooth_case():
    """A constant pose plus white noise of 2 cm: the truth is flat, so the widest kernel
    of a grid is the best one (known answer)."""
    pos = np.ones((1200, 3, 3))
    m = _motion(pos)
    noisy = m.replace(positions=pos + np.random.default_rng(0).normal(0, 0.02, pos.shape))
    return m, noisy


def test_oracle_picks_the_best_grid_value():
    truth, noisy = _smooth_case()
    grid = [(f"{f} frames", {"sigma": f"{f} frames"}) for f in (0.5, 4, 32)]
    oracle = OracleMethod("gaussian(test)", "gaussian", grid)
    out, _ = oracle.run(bench.cleaner_input(truth, noisy), truth=truth)
    assert oracle.last_choice == "32 frames"
    assert min(oracle.last_errors, key=oracle.last_errors.get) == "32 frames"
    assert oracle.last_errors["32 frames"] < oracle.last_errors["0.5 frames"] / 5
    assert np.isclose(metrics.rmse(out.positions, truth.positions), oracle.last_errors["32 frames"])
    # a noise-free fast signal: the narrowest kernel wins
    t = np.arange(600) / 120.0
    fast = _motion(np.sin(2 * np.pi * 8 * t)[:, None, None] * np.ones((1, 2, 3)))
    oracle.run(bench.cleaner_input(fast, fast), truth=fast)
    assert oracle.last_choice == "0.5 frames"
    with pytest.raises(ValueError, match="oracle"):
        oracle.run(noisy)


@pytest.mark.slow
def test_tuned_baselines_in_bench_beat_their_defaults():
    truth, _ = _smooth_case()
    truth = truth.replace(positions=truth.positions + np.sin(np.arange(1200) / 120.0)[:, None, None])
    methods, _ = bench.resolve_methods(["gaussian", "gaussian(tuned)", "wavelet(tuned)",
                                        "kalman(tuned)"])
    res = bench.run([truth], "feng2015", methods, seeds=1, settings=["snr20"])
    err = {r["method"]: r["metrics"]["rmse_cm"] for r in res.runs}
    assert err["gaussian(tuned)"] < err["gaussian"] < err["none"]
    assert err["wavelet(tuned)"] < err["none"] and err["kalman(tuned)"] < err["none"]
    tuned = {r["method"]: r.get("tuned") for r in res.runs}
    assert all(tuned[n] for n in TUNED)
    assert "| gaussian(tuned) |" in res.to_markdown()


def test_linear_wavelet_threshold_is_a_low_pass():
    t = np.arange(1024) / 120.0
    slow = np.sin(2 * np.pi * 0.5 * t)[:, None]
    noise = np.random.default_rng(1).normal(0, 0.1, slow.shape)
    out = segments.wavelet_denoise(slow + noise, "sym8", 4, threshold="linear")
    assert np.sqrt(np.mean((out - slow) ** 2)) < 0.1 / 3      # noise cut, slow sine kept
    with pytest.raises(ValueError, match="threshold"):
        segments.wavelet_denoise(slow, threshold="hard")


@pytest.mark.slow
@pytest.mark.parametrize("name,paper_cm", [("gaussian(tuned)", 6.65), ("wavelet(tuned)", 8.60),
                                           ("kalman(tuned)", 7.24)])
def test_tuned_baselines_on_cmu_dance_match_the_paper_at_10_db(name, paper_cm):
    """Feng 2015 Table I, dance, 10 dB (their trial 05_15, not shared): Gaussian 6.65,
    wavelet 8.60, Kalman 7.24 cm. On 05_02 with the protocol's SNR the oracle-tuned
    baselines are within ±25 % (measured 1.22, 0.99, 0.94 × the paper, seed 0); with the
    old centred SNR they were at about half."""
    from mocapfix import formats

    m = formats.read(shared("asfamc/05_02.amc"))
    noisy, _ = corrupt.apply_protocol(m, "feng2015", "snr10", seed=0)
    method = tuned_method(name)
    out, _ = method.run(bench.cleaner_input(m, noisy), truth=m)
    err_cm = 100 * m.metres_per_unit * metrics.rmse(out.positions, m.positions)
    assert 0.75 * paper_cm <= err_cm <= 1.25 * paper_cm
    old, _ = corrupt.gaussian_snr(m, np.random.default_rng(0), 10)
    out_old, _ = method.run(bench.cleaner_input(m, old), truth=m)
    assert 100 * m.metres_per_unit * metrics.rmse(out_old.positions, m.positions) < 0.7 * paper_cm
