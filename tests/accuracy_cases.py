"""Multi-seed accuracy cases shared by tests/config/test_default_accuracy.py,
tests/cleaners/test_tsmc.py, benchmarks/accuracy_bounds.py (prints the measured mean / worst
seed per case, to re-set the bounds) and benchmarks/mutation_check.py.

A case is a gap-free real capture (a slice small enough for CI; its markers, without
HDM05's unlabelled ``*0``-``*2``, which no pipeline cleans by default), one ``occlusion``
scenario and a seed; every pipeline's RMSE (mm) on it is computed once per process
(``lru_cache``), so the tests that share a case share its runs.

Baselines:
- ``scipy_linear_gaussian`` and ``scipy_spline`` use numpy/scipy directly (np.interp,
  scipy.ndimage.gaussian_filter1d, scipy.interpolate.CubicSpline) — independent of
  mocapfix's own ``fill``/``gaussian`` code, so a regression there cannot make a ratio
  check easier;
- ``classical`` (best of three interpolation + filter pipelines) and ``pca`` (spikes →
  fill_pca → PCHIP → Butterworth) are mocapfix's own strongest simple pipelines.
In the ``swap`` scenario every baseline gets the ``swaps`` cleaner first (a swap is not an
outlier to a smoother), as the default does.
"""
from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]

#: name -> (shared path, frames kept or None)
CAPTURES = {
    "85_02": ("c3d/cmu_85_02.c3d", None),                    # breakdance, 810 frames
    "hdm05": ("c3d/hdm05_HDM_mm_01-02_03_120.c3d", 1500),    # frames 0–1500 of 3990
}
SCENARIOS = ("gaps", "noise", "mixed", "swap")
SEEDS = tuple(int(s) for s in os.environ.get("MOCAPFIX_ACCURACY_SEEDS", "0,1,2").split(","))

CLASSICAL = {
    "pchip": [("fill", {"method": "pchip", "max_gap": None})],
    "spikes+pchip+bw12": [("spikes", {}), ("fill", {"method": "pchip", "max_gap": None}),
                          ("butterworth", {"cutoff": "12 Hz"})],
    "spikes+pchip+bw6": [("spikes", {}), ("fill", {"method": "pchip", "max_gap": None}),
                         ("butterworth", {"cutoff": "6 Hz"})],
}
WITH_PCA = [("spikes", {}), ("fill_pca", {}), ("fill", {"method": "pchip", "max_gap": None}),
            ("butterworth", {"cutoff": "12 Hz"})]
#: tsmc as its own filler (the default before fill_ensemble): what pins its PCA prior
TSMC_ALONE = [("swaps", {}), ("trust", {}), ("tsmc", {})]


@lru_cache(maxsize=None)
def truth(capture: str):
    from conftest import shared
    from mocapfix import read
    from mocapfix.pipeline.selection import without_unlabelled

    path, frames = CAPTURES[capture]
    motion, _ = without_unlabelled(read(shared(path)))      # HDM05's *0-*2: not markers
    return motion.slice_frames(0, frames) if frames else motion


@lru_cache(maxsize=None)
def corrupted(capture: str, scenario: str, seed: int):
    from mocapfix.bench.corrupt import occlusion

    return occlusion(truth(capture), scenario, seed=seed)[0]


def _steps(steps, motion):
    from mocapfix.cleaners import build

    for name, params in steps:
        motion, _ = build(name, **params).apply(motion)
    return motion


def _channels(fn, positions: np.ndarray) -> np.ndarray:
    T, J, _ = positions.shape
    x = positions.reshape(T, 3 * J)
    out = np.stack([fn(x[:, c]) for c in range(3 * J)], axis=1)
    return out.reshape(T, J, 3)


def _np_linear(col):
    ok = ~np.isnan(col)
    t = np.arange(col.size)
    return np.interp(t, t[ok], col[ok]) if ok.any() else col


def _scipy_spline(col):
    from scipy.interpolate import CubicSpline

    ok = ~np.isnan(col)
    t = np.arange(col.size)
    if ok.sum() < 4:
        return _np_linear(col)
    out = col.copy()
    inside = ~ok & (t > t[ok][0]) & (t < t[ok][-1])
    out[inside] = CubicSpline(t[ok], col[ok])(t[inside])
    return _np_linear(out)                          # ends held


def run(pipeline: str, motion):
    """Positions (T, J, 3) of ``pipeline`` applied to ``motion``. ``default`` is the
    shipped config with its fill gate off (``max_fill_error: null``): these cases pin how
    well the default's steps repair when every fill is written; ``default_gated`` is the
    config as shipped (samples whose fill could not be trusted stay NaN)."""
    from mocapfix.config import load_config

    if pipeline in ("default", "default_gated"):
        config = load_config(REPO / "configs" / "default.yaml")
        if pipeline == "default":
            config.max_fill_error = None
        return config.run(motion)[0].positions
    if pipeline == "scipy_linear_gaussian":
        from scipy.ndimage import gaussian_filter1d
        return gaussian_filter1d(_channels(_np_linear, motion.positions), 2.0, axis=0,
                                 mode="nearest")
    if pipeline == "scipy_spline":
        return _channels(_scipy_spline, motion.positions)
    raise KeyError(pipeline)


@lru_cache(maxsize=None)
def rmse_mm(pipeline: str, capture: str, scenario: str, seed: int) -> float:
    """RMSE in mm over every sample of the capture. ``pipeline``: 'default' (the shipped
    configs/default.yaml), 'scipy_linear_gaussian', 'scipy_spline', 'classical' (best of
    CLASSICAL), 'pca' (WITH_PCA), 'tsmc' (TSMC_ALONE).

    With MOCAPFIX_BASELINE_CACHE set to a folder, the baselines' values (not the
    default's or tsmc's) are kept there across processes — for benchmarks/mutation_check.py, whose
    mutants never touch the baselines; the tests do not set it."""
    cache = os.environ.get("MOCAPFIX_BASELINE_CACHE")
    if not cache or pipeline in ("default", "default_gated", "tsmc"):
        return _rmse_mm(pipeline, capture, scenario, seed)
    path = Path(cache) / f"{pipeline}-{capture}-{scenario}-{seed}.txt"
    if path.exists():
        return float(path.read_text())
    value = _rmse_mm(pipeline, capture, scenario, seed)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(repr(value))
    return value


def _rmse_mm(pipeline: str, capture: str, scenario: str, seed: int) -> float:
    from mocapfix.core.metrics import rmse

    ref = truth(capture)
    bad = corrupted(capture, scenario, seed)
    if scenario == "swap" and pipeline != "default":
        bad = _steps([("swaps", {})], bad)
    mm = ref.metres_per_unit * 1000.0
    if pipeline == "classical":
        return min(rmse(_steps(s, bad).positions, ref.positions) for s in CLASSICAL.values()) * mm
    if pipeline == "pca":
        return rmse(_steps(WITH_PCA, bad).positions, ref.positions) * mm
    if pipeline == "tsmc":
        return rmse(_steps(TSMC_ALONE, bad).positions, ref.positions) * mm
    out = run(pipeline, bad)
    if pipeline == "default_gated":                  # over what it writes
        err = np.linalg.norm(out - ref.positions, axis=2)
        return float(np.sqrt(np.nanmean(err ** 2))) * mm
    if np.isnan(out).any():
        return float("inf")                          # unfilled samples fail every bound
    return rmse(out, ref.positions) * mm


def over_seeds(pipeline: str, capture: str, scenario: str) -> np.ndarray:
    return np.array([rmse_mm(pipeline, capture, scenario, s) for s in SEEDS])


def ratios(pipeline: str, baseline: str, capture: str, scenario: str) -> np.ndarray:
    """Per-seed RMSE ratio pipeline / baseline (NaN where both are exact, 0 / 0)."""
    ours, theirs = over_seeds(pipeline, capture, scenario), over_seeds(baseline, capture, scenario)
    with np.errstate(invalid="ignore", divide="ignore"):
        return ours / theirs
