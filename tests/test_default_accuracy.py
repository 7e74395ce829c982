"""The shipped default config on real gap-free optical captures corrupted with the
``occlusion`` protocol: error bounds set from measurement, and a clear margin over the
linear fill + Gaussian smoothing that users start from."""
from __future__ import annotations

import pytest

from conftest import REPO, shared
from mocapfix import read
from mocapfix.corrupt import occlusion
from mocapfix.metrics import rmse, unfilled_fraction
from mocapfix.pipeline import load_config, loads_config

LINEAR_GAUSSIAN = ("pipeline:\n  - {cleaner: fill, method: linear, max_gap: 1000 s}\n"
                   "  - {cleaner: gaussian, sigma: 2 frames}\n")

# RMSE bounds in mm (seed 0), about 1.3× the measured values (swap: 0.2 mm, a clean
# repair leaves nothing to measure). Measured with swaps → trust → fill_ensemble → tsmc
# (issue 16), seeds 0 / 1 / 2:
# 85_02 (breakdance, 810 frames): gaps 8.88 / 3.18 / 2.54, noise 1.59 / 1.59 / 1.62,
#                                 mixed 4.12 / 3.83 / 3.55, swap 0.000;
# HDM05 (frames 0–1500):          gaps 0.53 / 0.84 / –, noise 1.27 / 1.27 / 1.29,
#                                 mixed 1.50 / 1.91 / 1.69, swap 0.000.
# (The previous default — swaps, trust, tsmc — measured, seed 0: 21.3, 1.59, 12.5, 0.000
# and 1.27, 1.27, 1.80, 0.000.)
BOUNDS = {
    ("c3d/cmu_85_02.c3d", None): {"gaps": 11.5, "noise": 2.1, "mixed": 5.4, "swap": 0.2},
    ("c3d/hdm05_HDM_mm_01-02_03_120.c3d", 1500): {"gaps": 0.7, "noise": 1.65, "mixed": 1.95, "swap": 0.2},
}


@pytest.fixture(scope="module")
def pipelines():
    return load_config(REPO / "configs" / "default.yaml"), loads_config(LINEAR_GAUSSIAN)


@pytest.mark.parametrize("capture,frames", list(BOUNDS))
@pytest.mark.parametrize("scenario", ["gaps", "noise", "mixed", "swap"])
def test_default_config_recovers_corrupted_capture(pipelines, capture, frames, scenario):
    default, baseline = pipelines
    truth = read(shared(capture))
    if frames:
        truth = truth.slice_frames(0, frames)
    corrupted, _ = occlusion(truth, scenario, seed=0)
    cleaned, _ = default.run(corrupted)
    reference, _ = baseline.run(corrupted)
    mm = truth.metres_per_unit * 1000.0
    ours = rmse(cleaned.positions, truth.positions) * mm
    theirs = rmse(reference.positions, truth.positions) * mm
    assert unfilled_fraction(cleaned.positions, truth.positions) == 0.0
    assert ours < BOUNDS[(capture, frames)][scenario]
    assert ours < 0.5 * theirs, f"default {ours:.2f} mm vs linear+gaussian {theirs:.2f} mm"
