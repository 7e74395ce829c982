"""Causal joint filters that Kinect applications run frame by frame, used as baselines by
the ``kinect`` bench protocol (:mod:`mocapfix.bench.kinect`).

Both take positions (T, J, 3) without NaN (interpolate missing samples first) and sample
times (T,) in seconds, and are vectorised over joints; the loop is over frames, as in the
original real-time code.
"""
from __future__ import annotations

import math

import numpy as np


def _smoothing_factor(dt: np.ndarray | float, cutoff: np.ndarray | float):
    """alpha = 1 / (1 + tau / Te) with tau = 1 / (2 pi fc) (Casiez et al. 2012, eq. 2)."""
    tau = 1.0 / (2.0 * math.pi * cutoff)
    return 1.0 / (1.0 + tau / dt)


def one_euro(x: np.ndarray, times: np.ndarray, *, min_cutoff: float = 1.0, beta: float = 0.0,
             d_cutoff: float = 1.0) -> np.ndarray:
    """The 1€ filter (Casiez, Roussel & Vogel 2012, "1€ Filter: A Simple Speed-based
    Low-pass Filter for Noisy Input in Interactive Systems", CHI'12, Algorithm 1) on
    every coordinate of ``x`` (T, ...): an exponential low-pass whose cutoff
    ``fc = min_cutoff + beta |dx̂|`` grows with the low-passed speed ``dx̂`` (itself
    low-passed at ``d_cutoff``). ``min_cutoff``, ``d_cutoff`` in Hz, ``beta`` in 1/(unit of
    x); Te = the actual interval between samples (dropped frames lengthen it)."""
    x = np.asarray(x, dtype=np.float64)
    out = np.empty_like(x)
    if len(x) == 0:
        return out
    t = np.asarray(times, dtype=np.float64)
    prev = x[0].copy()
    dprev = np.zeros_like(prev)
    out[0] = prev
    for i in range(1, len(x)):
        dt = max(t[i] - t[i - 1], 1e-6)
        dx = (x[i] - prev) / dt
        a_d = _smoothing_factor(dt, d_cutoff)
        dprev = a_d * dx + (1.0 - a_d) * dprev
        cutoff = min_cutoff + beta * np.abs(dprev)
        a = _smoothing_factor(dt, cutoff)
        prev = a * x[i] + (1.0 - a) * prev
        out[i] = prev
    return out


def holt_joint_filter(x: np.ndarray, inferred: np.ndarray | None = None, *,
                      smoothing: float = 0.5, correction: float = 0.5, prediction: float = 0.5,
                      jitter_radius: float = 0.05, max_deviation_radius: float = 0.04) -> np.ndarray:
    """The Kinect SDK's Holt double-exponential joint filter (``KinectJointFilter`` of the
    Kinect for Windows SDK 2.0 samples, ported from the SDK 1.x
    ``NUI_TRANSFORM_SMOOTH_PARAMETERS`` filter; Holt 1957 double exponential smoothing),
    per joint on 3-D positions ``x`` (T, J, 3) in metres; defaults are the SDK's.

    Per frame and joint, as in the SDK code: radii doubled for inferred joints; frame 0:
    filtered = raw, trend 0; frame 1: filtered = mean of the two raw positions, trend =
    correction · (filtered − previous) ; later: jitter filter (raw blended with the
    previous filtered position in proportion ``|raw − prev| / jitter_radius`` when that
    distance is within the radius), then ``filtered = (1 − smoothing) · jittered +
    smoothing · (prev + trend)``, ``trend = correction · (filtered − prev) + (1 −
    correction) · trend``; output ``filtered + prediction · trend``, pulled back to within
    ``max_deviation_radius`` of the raw position. Radii below 0.1 mm are raised to it
    (the SDK's guard against division by zero).
    """
    x = np.asarray(x, dtype=np.float64)
    T, J, _ = x.shape
    out = np.empty_like(x)
    if T == 0:
        return out
    inferred = np.zeros((T, J), bool) if inferred is None else np.asarray(inferred, bool)
    jit = np.maximum(np.where(inferred, 2.0, 1.0) * jitter_radius, 1e-4)
    dev = np.maximum(np.where(inferred, 2.0, 1.0) * max_deviation_radius, 1e-4)
    filt = x[0].copy()
    trend = np.zeros((J, 3))
    raw_prev = x[0]

    def clamp(pred, raw, radius):
        diff = np.linalg.norm(pred - raw, axis=1)
        over = diff > radius
        w = np.where(over, radius / np.maximum(diff, 1e-12), 1.0)[:, None]
        return np.where(over[:, None], pred * w + raw * (1.0 - w), pred)

    out[0] = clamp(filt + prediction * trend, x[0], dev[0])
    for i in range(1, T):
        raw = x[i]
        if i == 1:
            new = 0.5 * (raw + raw_prev)
            trend = correction * (new - filt) + (1.0 - correction) * trend
        else:
            d = np.linalg.norm(raw - filt, axis=1)
            ratio = (d / jit[i])[:, None]
            jittered = np.where(ratio <= 1.0, raw * ratio + filt * (1.0 - ratio), raw)
            new = jittered * (1.0 - smoothing) + (filt + trend) * smoothing
            trend = correction * (new - filt) + (1.0 - correction) * trend
        filt = new
        raw_prev = raw
        out[i] = clamp(filt + prediction * trend, raw, dev[i])
    return out
