"""One contract, run over every registered cleaner (scikit-learn style): shapes kept,
input untouched, NaN handled, deterministic, independent of the file's length unit."""
from __future__ import annotations

import numpy as np
import pytest

from mocapfix.cleaners import registry
from mocapfix.cleaners.base import FittedCleaner
from mocapfix.core.motion import Motion, Skeleton

CLEANERS = sorted(registry())
# fitted cleaners need a model for a skeleton they know: tests/cleaners/test_fitted_contract.py runs
# this same contract (shapes, no mutation, determinism, units) on them after fitting
UNFITTED = sorted(n for n, c in registry().items() if not issubclass(c, FittedCleaner))


def _walking_markers(seed: int = 3) -> Motion:
    """12 markers on a 4-segment chain swinging like a leg and an arm, in mm at 100 Hz,
    with 0.5 mm noise, a few spikes and gaps: small, realistic, and not low-rank by luck."""
    rng = np.random.default_rng(seed)
    T = 400
    t = np.arange(T) / 100.0
    root = np.stack([300 * t, 20 * np.sin(2 * np.pi * t), 900 + 10 * np.cos(4 * np.pi * t)], axis=1)
    angles = [0.4 * np.sin(2 * np.pi * t), 0.3 + 0.5 * np.sin(2 * np.pi * t - 1.0),
              -0.5 * np.sin(2 * np.pi * t + 0.5), 0.2 * np.sin(4 * np.pi * t)]
    lengths = [420, 400, 300, 250]
    pts, base, heading = [], root, np.zeros(T)
    for n, (a, length) in enumerate(zip(angles, lengths)):
        heading = heading + a
        direction = np.stack([np.sin(heading), np.zeros(T), -np.cos(heading)], axis=1)
        normal = np.stack([np.cos(heading), np.zeros(T), np.sin(heading)], axis=1)
        end = base + length * direction
        pts += [base + 0.5 * length * direction + 40 * normal, end,
                end + np.array([0.0, 60.0 + 10 * n, 0.0])]
        base = end
    pos = np.stack(pts, axis=1) + rng.normal(0, 0.5, (T, 12, 3))
    pos[rng.integers(5, T - 5, 4), rng.integers(0, 12, 4)] += 60.0
    pos[100:130, 4] = np.nan
    pos[250:262, 9] = np.nan
    pos[:6, 11] = np.nan
    parents = [-1, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10]
    return Motion(pos, [f"M{k}" for k in range(12)], 100.0, units="mm", metres_per_unit=0.001,
                  format="c3d", skeleton=Skeleton(np.array(parents)))


def _equal_nan(a, b, rtol=1e-9, atol=1e-9) -> bool:
    return a.shape == b.shape and bool(np.all(np.isnan(a) == np.isnan(b))) and \
        np.allclose(np.nan_to_num(a), np.nan_to_num(b), rtol=rtol, atol=atol)


def test_registry_is_not_empty():
    assert len(CLEANERS) >= 8, CLEANERS


@pytest.mark.parametrize("name", UNFITTED)
def test_contract(name):
    cls = registry()[name]
    assert cls.name == name and cls.summary, f"{name} needs a name and a one-line summary"
    motion = _walking_markers()
    snapshot = motion.positions.copy()
    out, info = cls().apply(motion)
    # shapes kept, metadata carried through, input untouched
    assert isinstance(out, Motion) and out.positions.shape == motion.positions.shape
    assert out.names == motion.names and out.fps == motion.fps and out.units == motion.units
    assert np.array_equal(motion.positions, snapshot, equal_nan=True), "input was mutated"
    assert isinstance(info, dict)
    # NaN handled: nothing new goes missing unless this cleaner's job is to flag samples
    new_nan = np.isnan(out.positions).any(-1) & ~np.isnan(snapshot).any(-1)
    if not getattr(cls, "flags_samples", False):
        assert not new_nan.any(), f"{name} made {new_nan.sum()} observed samples missing"
    assert np.isfinite(out.positions[~np.isnan(out.positions)]).all()
    # deterministic
    again, _ = cls().apply(motion)
    assert _equal_nan(out.positions, again.positions, rtol=0, atol=0)
    # unit invariance: the same capture in metres gives the same result / 1000
    metres = motion.replace(positions=motion.positions / 1000.0, units="m", metres_per_unit=1.0)
    out_m, _ = cls().apply(metres)
    assert _equal_nan(out_m.positions * 1000.0, out.positions, rtol=1e-6, atol=1e-5), \
        f"{name} depends on the length unit"


@pytest.mark.parametrize("name", CLEANERS)
def test_contract_all_missing_and_tiny_inputs(name):
    """Degenerate inputs give a result or a clear MocapfixError, never a crash."""
    from mocapfix.core.errors import MocapfixError

    cls = registry()[name]
    for pos in (np.full((50, 3, 3), np.nan), np.zeros((1, 2, 3)), np.zeros((3, 1, 3))):
        m = Motion(pos, [f"M{k}" for k in range(pos.shape[1])], 100.0, format="c3d")
        try:
            out, _ = cls().apply(m)
        except MocapfixError:
            continue
        assert out.positions.shape == pos.shape
