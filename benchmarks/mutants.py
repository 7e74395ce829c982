"""pytest plugin for benchmarks/mutation_check.py: applies the mutant named by the
environment variable MOCAPFIX_MUTANT to mocapfix before the tests import it.

    MOCAPFIX_MUTANT=no_lowrank PYTHONPATH=benchmarks python -m pytest -p mutants tests/...
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

#: the C3D part of the default before tsmc (commit 77ffd92^): swaps, spikes, PCA fill with
#: ends, PCHIP, wavelet — the other formats as now
PREVIOUS_DEFAULT = """version: 1
pipeline:
  - {cleaner: swaps, formats: [c3d]}
  - {cleaner: spikes, formats: [c3d, kinect]}
  - {cleaner: fill_pca, fill_ends: true}
  - {cleaner: fill, method: pchip, max_gap: 0.5 s}
  - {cleaner: wavelet}
"""

MUTANTS = {
    "none": "unchanged code (control: every test passes)",
    "linear_fill": "tsmc fills with linear interpolation of its trusted samples",
    "no_pca_prior": "tsmc prior: none (the paper's model alone)",
    "no_lowrank": "tsmc without its low-rank + smooth completion (PCA prediction + bridge)",
    "one_iteration": "tsmc stopped after one ALM iteration",
    "no_swaps": "default config without the swaps step",
    "previous_default": "previous default (swaps, spikes, fill_pca, PCHIP, wavelet)",
    "no_ensemble": "default without fill_ensemble (swaps, trust, tsmc: the default before issue 16)",
}


def _override(name: str, value):
    from mocapfix.cleaners import tsmc

    original = tsmc.TSMC.__getitem__
    tsmc.TSMC.__getitem__ = lambda self, key: value if key == name else original(self, key)


def _config_text(edit):
    from mocapfix import config as pipeline

    original = pipeline.load_config

    def load_config(path):
        if Path(path).name == "default.yaml":
            text = Path(path).read_text()
            if edit(text) == text:
                raise RuntimeError(f"mutant left {path} unchanged")
            return pipeline.loads_config(edit(text), str(path))
        return original(path)
    pipeline.load_config = load_config


def _without_swaps(text: str) -> str:
    return text.replace("  - cleaner: swaps\n    formats: [c3d]\n", "")


def _without_ensemble(text: str) -> str:
    return text.replace("  - cleaner: fill_ensemble\n    formats: [c3d]\n", "")


def apply(mutant: str) -> None:
    from mocapfix.cleaners import tsmc
    from mocapfix.solvers.segments import linear_bridge

    if mutant == "none":
        return
    if mutant == "linear_fill":
        def _complete(self, motion, trusted, rows, p):
            T, J, _ = motion.positions.shape
            cols = np.repeat(rows, 3)
            omega = np.repeat(trusted, 3, axis=1)[:, cols]
            x = motion.positions.reshape(T, 3 * J)[:, cols]
            return linear_bridge(np.where(omega, x, np.nan)), \
                {"iterations": 0, "residual": 0.0, "converged": True, "rank": None}
        tsmc.TSMC._complete = _complete
    elif mutant == "no_pca_prior":
        _override("prior", "none")
    elif mutant == "no_lowrank":
        from mocapfix.solvers import tsmc as tsmc_kernels

        tsmc_kernels.tsmc_solve = lambda x, omega, *a, **k: (
            np.zeros_like(x), np.zeros_like(x),
            {"iterations": 0, "residual": 0.0, "converged": True, "rank": 0})
    elif mutant == "one_iteration":
        _override("max_iter", 1)
    elif mutant == "no_swaps":
        _config_text(_without_swaps)
    elif mutant == "no_ensemble":
        _config_text(_without_ensemble)
    elif mutant == "previous_default":
        _config_text(lambda text: PREVIOUS_DEFAULT)
    else:
        raise KeyError(f"unknown mutant {mutant!r} (known: {', '.join(MUTANTS)})")


def pytest_configure(config):
    apply(os.environ.get("MOCAPFIX_MUTANT", "none"))
