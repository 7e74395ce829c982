"""Seeded corruption of clean motions, for tests and ``mocapfix bench``.

The ``occlusion`` scenarios model an optical capture (ALGORITHMS.md, "Corruption
protocols", and issue 3): occlusion gaps of 0.1–1.5 s on a quarter of the markers,
2 mm jitter with 2 % spikes of 20–100 mm, both together, and a marker swap. Physical
sizes are converted to the motion's units. Every function returns the corrupted motion
and a (T, J) mask of the samples it touched; the input is never modified.
"""
from __future__ import annotations

import numpy as np

from mocapfix.motion import Motion


def _mm(motion: Motion, value_mm: float) -> float:
    return value_mm * 1e-3 / motion.metres_per_unit


def occlusion_gaps(motion: Motion, rng: np.random.Generator, marker_fraction: float = 0.25,
                   min_s: float = 0.1, max_s: float = 1.5, gaps_per_marker: tuple[int, int] = (1, 3)):
    """Interior gaps of ``min_s``–``max_s`` seconds on ``marker_fraction`` of the markers."""
    pos = motion.positions.copy()
    T, J, _ = pos.shape
    mask = np.zeros((T, J), dtype=bool)
    observed_markers = np.flatnonzero(~np.isnan(pos).any(axis=2).all(axis=0))
    n_markers = max(1, int(round(marker_fraction * len(observed_markers))))
    chosen = rng.choice(observed_markers, size=min(n_markers, len(observed_markers)), replace=False)
    lo, hi = max(1, int(round(min_s * motion.fps))), max(1, int(round(max_s * motion.fps)))
    for j in chosen:
        for _ in range(rng.integers(gaps_per_marker[0], gaps_per_marker[1] + 1)):
            length = int(rng.integers(lo, hi + 1))
            if length >= T - 2:
                length = T // 3
            start = int(rng.integers(1, T - length - 1))
            mask[start:start + length, j] = True
    pos[mask] = np.nan
    return motion.replace(positions=pos), mask


def jitter_and_spikes(motion: Motion, rng: np.random.Generator, jitter_mm: float = 2.0,
                      spike_fraction: float = 0.02, spike_mm: tuple[float, float] = (20.0, 100.0)):
    """Gaussian jitter of ``jitter_mm`` (per coordinate) on every sample, plus spikes of
    random direction and uniform size in ``spike_mm`` on ``spike_fraction`` of the samples."""
    pos = motion.positions.copy()
    T, J, _ = pos.shape
    pos += rng.normal(0.0, _mm(motion, jitter_mm), size=pos.shape)
    n_spikes = int(round(spike_fraction * T * J))
    flat = rng.choice(T * J, size=n_spikes, replace=False)
    t, j = np.unravel_index(flat, (T, J))
    direction = rng.normal(size=(n_spikes, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    size = rng.uniform(*spike_mm, size=n_spikes)
    pos[t, j] += direction * _mm(motion, 1.0) * size[:, None]
    mask = np.zeros((T, J), dtype=bool)
    mask[t, j] = True
    return motion.replace(positions=pos), mask


def marker_swap(motion: Motion, rng: np.random.Generator, min_s: float = 0.3, max_s: float = 1.5):
    """Two neighbouring markers exchange trajectories for a stretch (a labelling error)."""
    pos = motion.positions.copy()
    T, J, _ = pos.shape
    mean = np.nanmean(pos, axis=0)
    a = int(rng.integers(J))
    dist = np.linalg.norm(mean - mean[a], axis=1)
    dist[a] = np.inf
    dist[np.isnan(dist)] = np.inf
    neighbours = np.argsort(dist)[:3]
    b = int(rng.choice(neighbours))
    length = int(rng.integers(max(1, round(min_s * motion.fps)), max(2, round(max_s * motion.fps)) + 1))
    length = min(length, T // 2)
    start = int(rng.integers(1, T - length))
    span = slice(start, start + length)
    pos[span, a], pos[span, b] = motion.positions[span, b], motion.positions[span, a]
    mask = np.zeros((T, J), dtype=bool)
    mask[span, [a, b]] = True
    return motion.replace(positions=pos), mask


OCCLUSION_SCENARIOS = ("gaps", "noise", "mixed", "swap")


def occlusion(motion: Motion, scenario: str, seed: int = 0):
    """One scenario of the ``occlusion`` protocol; returns (corrupted motion, mask)."""
    rng = np.random.default_rng(seed)
    if scenario == "gaps":
        return occlusion_gaps(motion, rng)
    if scenario == "noise":
        return jitter_and_spikes(motion, rng)
    if scenario == "mixed":
        noisy, m1 = jitter_and_spikes(motion, rng)
        gapped, m2 = occlusion_gaps(noisy, rng)
        return gapped, m1 | m2
    if scenario == "swap":
        return marker_swap(motion, rng)
    raise ValueError(f"unknown occlusion scenario {scenario!r} (known: {', '.join(OCCLUSION_SCENARIOS)})")
