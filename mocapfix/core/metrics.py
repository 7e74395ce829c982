"""Error metrics against ground truth and quality metrics without it (the papers'
definitions, cited per function). All take (T, J, 3) arrays in the same unit and ignore samples where the truth
is missing."""
from __future__ import annotations

import numpy as np


def joint_errors(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Euclidean error per sample, (T, J); NaN where either is missing."""
    return np.linalg.norm(np.asarray(estimate) - np.asarray(truth), axis=-1)


def rmse(estimate, truth, mask=None) -> float:
    """sqrt(mean ||P − P̃||²) over samples (Feng 2015 eq. 19 when over all samples;
    Feng 2014 eq. 27 when ``mask`` selects the corrupted ones). Missing estimates are
    excluded — see :func:`unfilled_fraction`."""
    err = joint_errors(estimate, truth)
    sel = np.isfinite(err) if mask is None else (np.isfinite(err) & mask)
    return float(np.sqrt(np.mean(err[sel] ** 2))) if sel.any() else float("nan")


def max_error(estimate, truth, mask=None) -> float:
    err = joint_errors(estimate, truth)
    sel = np.isfinite(err) if mask is None else (np.isfinite(err) & mask)
    return float(err[sel].max()) if sel.any() else float("nan")


def mean_joint_error(estimate, truth) -> float:
    """AJE (Yang 2019): mean Euclidean joint error."""
    err = joint_errors(estimate, truth)
    return float(np.nanmean(err))


def bone_lengths(positions: np.ndarray, bones: np.ndarray) -> np.ndarray:
    """(T, B) lengths of the bones (pairs of joint indices)."""
    bones = np.asarray(bones, dtype=np.intp).reshape(-1, 2)
    out = np.empty((positions.shape[0], len(bones)))
    for b, (parent, child) in enumerate(bones.tolist()):     # no (T, B, 3) temporaries
        out[:, b] = np.linalg.norm(positions[:, parent] - positions[:, child], axis=-1)
    return out


def mean_bone_error(estimate, truth, bones) -> float:
    """ABE (Yang 2019): mean |bone length − true bone length|."""
    return float(np.nanmean(np.abs(bone_lengths(estimate, bones) - bone_lengths(truth, bones))))


def bone_length_variation(positions, bones) -> np.ndarray:
    """std/mean of each bone's length over time (B,), ignoring missing frames."""
    lengths = bone_lengths(positions, bones)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.nanstd(lengths, axis=0) / np.nanmean(lengths, axis=0)


#: frames of a take whose accelerations are worked out at a time (:func:`rms_acceleration`)
ACCELERATION_CHUNK = 16384


def add_rows(total: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``total`` plus the sum of ``rows`` over their first axis, added in order: a sum
    over frames taken a chunk at a time this way is the sum ``np.sum(axis=0)`` gives over
    the whole array, bit for bit (that adds row after row), without the whole array."""
    both = np.empty((len(rows) + 1, *rows.shape[1:]))
    both[0], both[1:] = total, rows
    return np.sum(both, axis=0)


def rms_acceleration(positions: np.ndarray, fps: float) -> np.ndarray:
    """RMS of the second difference per joint (J,), in units/s² — a jitter measure.

    The squared accelerations are worked out a chunk of frames at a time and added to a
    running sum per joint, NaN left out: on a long take a (T − 2, J) array of them and
    ``np.nansum``'s copy of it were the peak of the report. The running sum adds the
    frames in order, as a sum over the frames of the whole array does, so every result
    is the same bit for bit."""
    T = positions.shape[0]
    total = np.zeros(positions.shape[1:-1])
    counted = np.zeros(positions.shape[1:-1], dtype=np.intp)
    for a in range(0, max(T - 2, 0), ACCELERATION_CHUNK):
        b = min(a + ACCELERATION_CHUNK, T - 2)
        part = positions[a:b + 2]
        power = np.empty((b - a, *positions.shape[1:-1]))
        for c in range(positions.shape[-1]):
            square = (np.diff(part[..., c], n=2, axis=0) * fps * fps) ** 2
            if c == 0:
                power[:] = square
            else:
                power += square
        counted += np.isfinite(power).sum(axis=0)
        np.copyto(power, 0.0, where=np.isnan(power))
        total = add_rows(total, power)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(np.where(counted > 0, total / np.maximum(counted, 1), np.nan))


def unfilled_fraction(estimate, truth) -> float:
    """Fraction of samples with a truth but no estimate."""
    est_missing = np.isnan(np.asarray(estimate)).any(axis=-1)
    truth_ok = ~np.isnan(np.asarray(truth)).any(axis=-1)
    return float(np.mean(est_missing[truth_ok])) if truth_ok.any() else 0.0
