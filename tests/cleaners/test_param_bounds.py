"""Every physical parameter has an upper bound, and the kernels sized from time
parameters are cut at the signal length, so no value a config accepts can allocate more
than O(T): ``gaussian sigma: 1e6 s`` used to build a 6 GB kernel, ``spikes window: 1e9 s``
to ask for 373 GiB."""
from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
from scipy import ndimage

from mocapfix.cleaners import build, registry
from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion
from mocapfix.config import loads_config
from mocapfix.solvers import segments
from mocapfix.solvers.localfit import local_polyfit, moving_median
from conftest import hang_guard


def _walk(T=300, J=4, fps=100.0, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(T)[:, None, None] / fps
    pos = 0.5 * np.sin(2 * np.pi * 0.7 * t + rng.uniform(0, 6, (1, J, 3))) + rng.normal(0, 0.002, (T, J, 3))
    pos[T // 3:T // 3 + 5, 1] = np.nan
    return Motion(pos, [f"m{j}" for j in range(J)], fps, units="m", metres_per_unit=1.0, format="c3d")


def test_every_physical_parameter_has_an_upper_bound():
    for name, cls in registry().items():
        for p in cls.params:
            if p.kind in ("length", "time", "frequency"):
                assert p.upper() is not None and np.isfinite(p.upper()), (name, p.name)
                assert p.max_frames() <= 1e6


@pytest.mark.parametrize("step, pattern", [
    ("{cleaner: gaussian, sigma: 1e6 s}", "'sigma'.*out of range"),
    ("{cleaner: spikes, window: 1e9 s}", "'window'.*out of range"),
    ("{cleaner: spikes, window: 1e9 frames}", "'window'.*frames"),
    ("{cleaner: spikes, window: 5 s}", "'window'.*<= 2"),
    ("{cleaner: fill, max_gap: 1e7 ms}", "'max_gap'.*out of range"),
    ("{cleaner: butterworth, cutoff: 1e9 Hz}", "'cutoff'.*out of range"),
    ("{cleaner: spikes, min_jump: 1e6 m}", "'min_jump'.*out of range"),
    ("{cleaner: kalman, measurement_noise: 5e5 mm}", "'measurement_noise'.*out of range"),
    ("{cleaner: rotation_smooth, sigma: 2e7 frames}", "'sigma'.*frames"),
    # two plain numbers that overflowed (kalman: OverflowError) or broke an
    # eigendecomposition (tsmc: LinAlgError) on a 60-frame motion
    ("{cleaner: kalman, accel_noise: 1.0e+300}", "'accel_noise'.*out of range"),
    ("{cleaner: tsmc, penalty0: 1.0e-300}", "'penalty0'.*out of range"),
])
def test_absurd_physical_values_are_config_errors(step, pattern):
    with pytest.raises(ConfigError, match=pattern) as err:
        loads_config(f"pipeline: [{step}]", "big.yaml")
    assert "big.yaml" in str(err.value) and "allowed" in str(err.value)


def _peak_bytes(func):
    tracemalloc.start()
    try:
        with hang_guard(60):
            result = func()
        return result, tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


@pytest.mark.parametrize("step", [
    "{cleaner: gaussian, sigma: 3600 s}",
    "{cleaner: gaussian, sigma: 1000000 frames}",
    "{cleaner: spikes, window: 2 s}",
    "{cleaner: spikes, window: 20000 frames}",
    "{cleaner: fill, max_gap: 3600 s}",
    "{cleaner: kalman, max_gap: 3600 s, fill: true}",
    "{cleaner: fill_pca, max_gap: 3600 s}",
])
def test_largest_accepted_values_run_in_memory_of_order_T(step):
    motion = _walk()
    pipe = loads_config(f"pipeline: [{step}]")
    (out, _), peak = _peak_bytes(lambda: pipe.run(motion))
    assert out.positions.shape == motion.positions.shape
    # the motion is 29 kB; allow generous per-sample working memory, far below the
    # gigabytes the unclipped kernels asked for
    assert peak < 2000 * motion.positions.nbytes, f"{peak / 1e6:.1f} MB"


def test_gaussian_with_a_cut_kernel_equals_the_full_kernel():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(size=(40, 3)), axis=0)
    for sigma in (15.0, 60.0, 400.0):  # kernel radius 60, 240, 1600 > the padded 79 samples
        padded, p = segments.extend(x, int(np.ceil(4 * sigma)))
        full = ndimage.gaussian_filter1d(padded, sigma, axis=0, mode="constant", truncate=4.0)
        norm = ndimage.gaussian_filter1d(np.ones(len(padded)), sigma, mode="constant", truncate=4.0)
        expected = (full / norm[:, None])[p:p + len(x)]
        assert np.allclose(segments.gaussian(x, sigma, gaps="segments"), expected, atol=1e-9)
    # a huge sigma is a flat kernel: every sample becomes the mean of the odd-extended
    # segment, which for a straight line is its midpoint
    line = np.linspace(0, 1, 50)[:, None] * np.ones((1, 2))
    assert np.allclose(segments.gaussian(line, 3.6e5), 0.5, atol=1e-6)


def test_moving_median_and_local_fit_are_unchanged_by_the_cut():
    rng = np.random.default_rng(4)
    x = rng.normal(size=(30, 2))
    x[5:8, 0] = np.nan
    for half in (40, 10_000):
        got = moving_median(x, half)
        expected = np.array([[np.nanmedian(x[:, c]) for c in range(2)]] * 30)
        assert np.allclose(got, expected, equal_nan=True)
    pos = rng.normal(size=(30, 2, 3))
    w = np.ones((30, 2))
    a = local_polyfit(pos, w, 29)
    # a window wider than the signal is the window of the whole signal
    wide = local_polyfit(pos, w, 5000)
    for u, v in zip(wide, a):
        assert np.allclose(u, v, equal_nan=True)


@pytest.mark.slow
def test_moving_median_memory_is_bounded_for_wide_windows(monkeypatch):
    from mocapfix.solvers import localfit

    x = np.random.default_rng(5).normal(size=(1000, 4))
    x[::7, 1] = np.nan
    whole = moving_median(x, 900)   # one block: 1000 x 4 x 1801 values, 58 MB sorted at once
    monkeypatch.setattr(localfit, "_MEDIAN_BLOCK", 1 << 16)
    blocked, peak = _peak_bytes(lambda: moving_median(x, 900))
    assert peak < 8e6, f"{peak / 1e6:.0f} MB"
    assert np.array_equal(blocked, whole, equal_nan=True)


def test_spikes_window_of_frames_clipped_to_the_signal_still_finds_a_spike():
    # straight-line movement with 2 mm noise: a quadratic over the whole clip follows it
    motion = _walk(T=120)
    rng = np.random.default_rng(6)
    pos = np.linspace(0, 1, 120)[:, None, None] * np.ones((1, 4, 3)) + rng.normal(0, 0.002, (120, 4, 3))
    pos[60, 2] += 0.1  # a 10 cm spike
    cleaner = build("spikes", window="20000 frames")
    out, info = cleaner.apply(motion.replace(positions=pos))
    assert np.isnan(out.positions[60, 2]).all() and info["flagged"] >= 1
