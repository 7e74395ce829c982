"""How a method's output is scored against the truth in the corruption protocols of
``mocapfix bench`` (:mod:`mocapfix.bench.run`, steps 3 and 4 of its docstring): what the
methods see, and the protocols' metrics."""
from __future__ import annotations

import numpy as np

from mocapfix.core import metrics
from mocapfix.core.motion import Motion


def cleaner_input(clean: Motion, corrupted: Motion) -> Motion:
    """The Motion the methods see: the file's Motion with the corrupted positions and
    no rotation channels or rig (see the module docstring, step 3)."""
    return clean.replace(positions=corrupted.positions.copy(), rig=None, channels=None,
                         confidence=None)


def evaluate(protocol: str, truth: Motion, estimate: np.ndarray, mask: np.ndarray) -> dict:
    """The protocol's metrics of ``estimate`` (T, J, 3) against ``truth`` (see the module
    docstring, step 4). ``mask`` is the (T, J) mask of corrupted samples."""
    true = truth.positions
    m = truth.metres_per_unit
    out = {"unfilled_pct": 100.0 * metrics.unfilled_fraction(estimate, true)}
    if protocol == "feng2015":
        out["rmse_cm"] = 100.0 * m * metrics.rmse(estimate, true)
    elif protocol == "yang2019":
        out["aje_m"] = m * metrics.mean_joint_error(estimate, true)
        if truth.skeleton is not None and len(truth.skeleton.bones):
            with np.errstate(invalid="ignore"):
                out["abe_m"] = m * metrics.mean_bone_error(estimate, true, truth.skeleton.bone_array)
    elif protocol == "feng2014":
        out["rmse_corrupted_cm"] = 100.0 * m * metrics.rmse(estimate, true, mask)
        out["rmse_cm"] = 100.0 * m * metrics.rmse(estimate, true)
    elif protocol == "occlusion":
        out["rmse_mm"] = 1000.0 * m * metrics.rmse(estimate, true)
        out["rmse_corrupted_mm"] = 1000.0 * m * metrics.rmse(estimate, true, mask)
        out["max_mm"] = 1000.0 * m * metrics.max_error(estimate, true)
    else:
        raise ValueError(f"unknown protocol {protocol!r}")
    return {k: float(v) for k, v in out.items()}
