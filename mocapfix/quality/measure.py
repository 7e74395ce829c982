"""Quality measurements, shared by ``info``, ``check`` and ``clean``'s report.

This module only measures; :mod:`mocapfix.quality.rules` judges the figures and
:mod:`mocapfix.quality.render` prints them. Two sets:

- :func:`measure_input` — what a capture is like as read (``info``, ``check``): per joint
  missing fraction, gaps, longest gap (s), outlier fraction (the Hampel identifier of the
  ``spikes`` cleaner with its defaults), jitter (RMS acceleration, m/s²), bone-length
  variation (std/mean), never-seen flag; per file also dropped frames and timestamp jumps
  (from the file's time stamps), marker swaps suspected (events the ``swaps`` cleaner
  repairs, optical marker data only), frame rate.
- :func:`measure_cleaning` — what a pipeline did (``clean``'s report): missing before and
  after, which step filled each gap, samples flagged (made missing or rebuilt in place),
  correction size and what caused the largest, jitter and bone
  variation before and after, rotation write-back residual, and how much of each joint
  is left *uncertain* (not measured in the input, weighted by the fill's confidence when
  the cleaned motion carries one).

Lengths are in mm, times in s, accelerations in m/s², whatever the file's units.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocapfix.formats import MARKER_FORMATS
from mocapfix.cleaners import build
from mocapfix.cleaners.base import REJECTED_FILLS
from mocapfix.solvers.spikes import hampel_flags
from mocapfix.solvers.fill_error import FillIndex
from mocapfix.core.gaps import LONG_FILL_S, runs, take_frames
from mocapfix.core.metrics import add_rows, bone_lengths, rms_acceleration
from mocapfix.core.motion import Motion, missing_samples
from mocapfix.pipeline.selection import DEFAULT_POLICY, not_cleaned, take
from mocapfix.pipeline.unlabelled import Unlabelled, is_unlabelled
from mocapfix.pipeline.cuts import cut_frames
from mocapfix.pipeline.held import HeldFrames

#: an interval longer than this many times the median is a dropped-frame gap
GAP_FACTOR = 1.5


def finite(x, digits: int = 6) -> float | None:
    """A JSON-safe float: None for NaN/inf."""
    x = float(x)
    return None if not np.isfinite(x) else round(x, digits)


@dataclass
class CleanResult:
    """Everything the report needs about one cleaned file."""

    original: Motion
    cleaned: Motion
    records: list
    writeback_residual: np.ndarray | None = None
    seconds: float = 0.0
    #: per point, why the pipeline left it alone (None: cleaned); see selection.not_cleaned
    not_cleaned: list | None = None
    #: what the output format cannot carry (:func:`mocapfix.formats.losses`), when the
    #: take is written in another format than it was read from
    not_carried: list = field(default_factory=list)


def bones_of(motion: Motion) -> np.ndarray:
    """The bones whose length the report judges: the skeleton's, less those whose child
    joint has translation channels that change over the take — there the file animates
    the bone's vector by design (a root-motion node at the floor with the hips moving
    about it, as in the Bandai BVH files: "varies by 45 %"), so its length is data, not
    a segment that should keep its length."""
    if motion.skeleton is None or not motion.skeleton.bones:
        return np.zeros((0, 2), dtype=np.intp)
    bones = motion.skeleton.bone_array
    rig, channels = motion.rig, motion.channels
    if rig is None or channels is None or not len(channels):
        return bones
    cols = np.asarray(rig.trans_columns)
    animated = np.zeros(len(cols), dtype=bool)
    for j in np.flatnonzero((cols >= 0).any(axis=1)):
        c = cols[j][cols[j] >= 0]
        if c.max() < channels.shape[1]:
            animated[j] = bool((np.ptp(channels[:, c], axis=0) > 0).any())
    return bones[~animated[bones[:, 1]]] if animated.any() else bones


def bone_variation(positions: np.ndarray, bones: np.ndarray) -> np.ndarray:
    """std/mean of each bone's length (B,), NaN where a bone is seen on fewer than two
    frames. One bone's lengths over the take at a time: the (T, B) lengths and
    ``np.nanstd``'s temporaries of them were the peak of a long take's report."""
    out = np.full(len(bones), np.nan)
    for b, (parent, child) in enumerate(np.asarray(bones, dtype=np.intp).reshape(-1, 2).tolist()):
        lengths = bone_lengths(positions, [(parent, child)])[:, 0]
        if np.count_nonzero(np.isfinite(lengths)) > 1:
            with np.errstate(invalid="ignore", divide="ignore"):
                out[b] = np.nanstd(lengths) / np.nanmean(lengths)
    return out


def per_joint_bone_variation(var: np.ndarray, bones: np.ndarray, J: int) -> np.ndarray:
    """(J,) the largest variation of the bones ending at each joint (NaN: none)."""
    out = np.full(J, np.nan)
    for (_, child), v in zip(bones, var):
        if np.isfinite(v) and not (v <= out[child]):
            out[child] = v
    return out


def jitter(motion: Motion) -> np.ndarray:
    """RMS acceleration per joint (J,) in m/s²."""
    if motion.n_frames <= 2:
        return np.full(motion.n_joints, np.nan)
    return rms_acceleration(motion.positions, motion.fps) * motion.metres_per_unit


def timing(motion: Motion) -> dict:
    """Dropped frames and irregular time stamps, from ``motion.times`` (uniform without)."""
    out = {"dropped_frames": 0, "timestamp_jumps": 0, "repeated_frames": 0, "backward_steps": 0,
           "longest_interval_s": None}
    times = motion.times
    if times is None or len(times) < 2:
        return out
    dt = np.diff(np.asarray(times, dtype=np.float64))
    positive = dt[dt > 0]
    if not len(positive):
        return out
    median = float(np.median(positive))
    late = dt > GAP_FACTOR * median
    out["dropped_frames"] = int(np.sum(np.maximum(np.round(dt[late] / median) - 1, 1)))
    out["repeated_frames"] = int(np.sum(dt == 0))
    out["backward_steps"] = int(np.sum(dt < 0))
    out["timestamp_jumps"] = int(late.sum()) + out["repeated_frames"] + out["backward_steps"]
    out["longest_interval_s"] = finite(dt.max())
    return out


def outlier_flags(motion: Motion, cuts=()) -> np.ndarray:
    """(T, J) samples the ``spikes`` cleaner with its default settings would flag, on each
    take between ``cuts`` (the frames where the take jumps as a whole,
    :mod:`mocapfix.pipeline.cuts`) as ``clean`` cleans them: a join is no outlier."""
    T, J = motion.positions.shape[:2]
    flags = np.zeros((T, J), bool)
    if J == 0:
        return flags
    det = build("spikes")
    half = max(1, int(round(det.frames("window", motion) / 2.0)))
    edges = [0, *cuts, T]
    for a, b in zip(edges[:-1], edges[1:]):
        if b - a >= 5:
            flags[a:b], _ = hampel_flags(motion.positions[a:b], half, det["k"],
                                         det.length("min_jump", motion), det["passes"])
    return flags & ~motion.missing


#: the swap search is quadratic in the number of points: files with more points than this
#: (C3D files carrying model outputs as points) are not searched, and say so
MAX_SWAP_POINTS = 120


def suspected_swaps(motion: Motion) -> list[dict] | None:
    """Label swaps the ``swaps`` cleaner finds (optical marker data without a rig);
    None when not searched (not marker data, or more than MAX_SWAP_POINTS points)."""
    if motion.rig is not None or motion.format not in (*MARKER_FORMATS, "unknown") or motion.n_joints < 3:
        return []
    if motion.n_joints > MAX_SWAP_POINTS:
        return None
    _, info = build("swaps").apply(motion)
    return list(info.get("swaps", []))


def gap_runs(missing: np.ndarray):
    """Per joint: gap count and longest gap (frames) of a (T, J) mask."""
    T, J = missing.shape
    col, start, length = runs(missing)
    count = np.bincount(col, minlength=J) if len(col) else np.zeros(J, int)
    longest = np.zeros(J, int)
    if len(col):
        np.maximum.at(longest, col, length)
    return count, longest, (col, start, length)


def measure_input(motion: Motion, *, swaps: bool = True, outliers: bool = True,
                  unlabelled: Unlabelled = DEFAULT_POLICY) -> dict:
    """Measurements of a capture as read: ``{"file": {...}, "joints": [{...}]}``. Model
    outputs a C3D file lists (``Motion.kinds``) and unlabelled trajectories (by the policy
    ``unlabelled``, a rules file's) are measured but carry ``"skipped"`` (the rules pass
    them over) and are left out of the file figures; ``file["unlabelled"]`` lists the
    latter with the reason."""
    T, J = motion.positions.shape[:2]
    why = not_cleaned(motion, unlabelled=unlabelled)
    marker = np.array([w is None for w in why], bool)
    fps = float(motion.fps) if motion.fps and np.isfinite(motion.fps) else float("nan")
    missing = motion.missing
    span = take_frames(missing, marker)
    count, longest, (col, start, length) = gap_runs(missing[span])
    start = start + span.start
    held = HeldFrames.find(motion)
    cuts = cut_frames(motion, held)
    # the outlier test on the points the rules judge: a raw export's hundreds of
    # unlabelled fragments (skipped) cost most of a check and were reported, not judged
    flags = np.zeros((T, J), bool)
    if outliers and marker.any():
        flags[:, marker] = outlier_flags(motion if marker.all() else take(motion, marker), cuts)
    observed = (~missing).sum(axis=0)
    T_take = span.stop - span.start
    jit = jitter(motion)
    bones = bones_of(motion)
    bvar = bone_variation(motion.positions, bones)
    jbvar = per_joint_bone_variation(bvar, bones, J)
    joints = []
    for j in range(J):
        joints.append({
            "name": motion.names[j],
            "missing": finite(missing[span, j].mean()) if T_take else 0.0,
            "gaps": int(count[j]),
            "longest_gap_s": finite(longest[j] / fps) if longest[j] else 0.0,
            "longest_gap_frames": int(longest[j]),
            "never_seen": bool(T and observed[j] == 0),
            "outliers": (None if why[j] else
                         finite(flags[:, j].sum() / observed[j]) if observed[j] else 0.0),
            "jitter": finite(jit[j]),
            "bone_variation": finite(jbvar[j]),
            **({"skipped": why[j]} if why[j] else {}),
        })
    swap_list = suspected_swaps(motion if marker.all() else take(motion, marker)) if swaps else []
    notes = list(motion.notes)
    if swap_list is None:
        notes.append(f"marker swaps not searched ({int(marker.sum())} points > {MAX_SWAP_POINTS})")
        swap_list = []
    if not marker.all():                    # the file figures: markers only
        missing, flags, observed, jit = missing[:, marker], flags[:, marker], observed[marker], jit[marker]
        start, length = start[marker[col]], length[marker[col]]
    empty = _empty_frames(missing, observed)
    missing = missing[span]
    names = [n for n, m in zip(motion.names, marker) if m]
    file = {
        "path": motion.path,
        "format": motion.format,
        "frames": T,
        "fps": finite(fps),
        "duration_s": finite(motion.duration),
        "joints": int(marker.sum()),
        "units": motion.units,
        "missing": finite(missing.mean()) if missing.size else 0.0,
        "gaps": int(len(length)),
        "interior_gaps": int(np.sum((start > span.start) & (start + length < span.stop))),
        "longest_gap_s": finite(length.max() / fps) if len(length) else 0.0,
        "longest_gap_frames": int(length.max()) if len(length) else 0,
        "never_seen": [names[j] for j in range(len(names)) if T and observed[j] == 0],
        "empty_frames": empty,
        "outliers": finite(flags.sum() / max(int(observed.sum()), 1)),
        "jitter": finite(np.nanmedian(jit)) if np.isfinite(jit).any() else None,
        "bone_variation": finite(np.nanmax(bvar)) if np.isfinite(bvar).any() else None,
        "swaps": swap_list,
        **timing(motion),
        "held_frames": 0 if held is None else T - len(held.kept),
        "cuts": len(cuts), "cut_frames": cuts,
        "notes": notes,
    }
    if not marker.all():
        file["points_not_cleaned"] = int((~marker).sum())
    _list_unlabelled(file, motion.names, why)
    _mark_outside_take(file, span, T)
    if motion.confidence is not None and motion.confidence.size:
        conf = motion.confidence
        file["tracking"] = {
            "tracked": float(np.mean(conf >= 1.0)),
            "inferred": float(np.mean((conf > 0) & (conf < 1.0))),
            "not_tracked": float(np.mean(conf <= 0)),
        }
    return {"file": file, "joints": joints}


# -- what a pipeline did ------------------------------------------------------------------

def who_filled(records, T: int, J: int) -> np.ndarray:
    """(T, J) index into ``records`` of the step that filled each sample (-1: none)."""
    who = np.full((T, J), -1, dtype=np.int16 if len(records) < 2 ** 15 else np.intp)
    for n, rec in enumerate(records):
        who[rec.filled & (who < 0)] = n
        who[rec.flagged] = -1          # flagged later → a later filler takes over
    return who


def _rejected_fills(records, names) -> dict:
    """Per point index, the fills steps made and did not write (their ``info``'s
    :data:`~mocapfix.cleaners.base.REJECTED_FILLS`): ``[(start, length, step, why, error_mm,
    bound_mm, uncertain, extrapolated), ...]`` (``uncertain``: left as too uncertain to
    fill, with the fill's estimate and bound, None where it had none; ``extrapolated``:
    that estimate came from windows shorter than the gap)."""
    index = {n: i for i, n in enumerate(names)}
    out: dict = {}
    for rec in records:
        for name, entries in ((rec.info or {}).get(REJECTED_FILLS) or {}).items():
            if name in index:
                out.setdefault(index[name], []).extend(
                    (int(e[0]), int(e[1]), rec.step, str(e[2]),
                     *(e[3:5] if len(e) >= 5 else (None, None)), len(e) >= 5,
                     bool(len(e) > 5 and e[5])) for e in entries)
    return out


def _fill_error(index: FillIndex, name: str, start: int, length: int) -> dict:
    """The estimated error and 90 % bound (mm) of the fill of one gap (the pipeline's
    ``Motion.fill_errors``, :class:`mocapfix.solvers.fill_error.FillIndex`), and whether
    the estimate was extrapolated from windows shorter than the gap; None for the three
    when part of it has no estimate."""
    found = index.error(name, start, length)
    if found is None:
        return {"error_mm": None, "bound_mm": None, "extrapolated": None}
    return {"error_mm": finite(found[0], 3), "bound_mm": finite(found[1], 3),
            "extrapolated": found[2]}


def _left_uncertain(refused: dict, missing_after: np.ndarray) -> np.ndarray:
    """(T, J) the samples still missing that a step left as too uncertain to fill (a
    rejection with an estimate slot: :class:`mocapfix.cleaners.base.FillGate`)."""
    out = np.zeros(missing_after.shape, bool)
    for j, entries in refused.items():
        for a, m, *_, uncertain, _ in entries:
            if uncertain:
                out[a:a + m, j] = True
    return out & missing_after


def _mean_confidence(after: Motion, start: int, length: int, joint: int) -> float | None:
    """Mean per-sample fill confidence over one filled gap (None: the filler gives none)."""
    conf = after.confidence
    if conf is None or conf.shape != after.positions.shape[:2]:
        return None
    return finite(np.nanmean(conf[start:start + length, joint]))


def uncertainty(before: Motion, after: Motion, frames: slice = slice(None)) -> np.ndarray:
    """(J,) fraction of each joint's ``frames`` that rest on no measurement: samples
    missing in the input (filled or not), each counted as ``1 − confidence`` of the cleaned
    motion where it carries a per-sample fill confidence, else as 1. A marker rebuilt from
    3 % of its data is 97 % uncertain, however complete it looks after cleaning."""
    miss_b = before.missing
    rows = range(*frames.indices(miss_b.shape[0]))
    conf = after.confidence
    if conf is None or conf.shape != miss_b.shape:
        # whole numbers: the count is the sum of the 0/1 weights, exactly
        return np.count_nonzero(miss_b[frames], axis=0) / max(len(rows), 1)
    total = np.zeros(miss_b.shape[1])
    for a in range(0, len(rows), MEASURE_CHUNK):
        b = min(a + MEASURE_CHUNK, len(rows))
        taken = slice(rows[a], rows[b - 1] + 1) if rows.step == 1 else rows[a:b]
        total = add_rows(total, miss_b[taken] * _uncertain_weight(after, taken))
    return total / max(len(rows), 1)


#: frames of a take weighed at a time (:func:`uncertainty`)
MEASURE_CHUNK = 16384


def _uncertain_weight(after: Motion, frames) -> np.ndarray:
    """What a sample missing in the input counts for in :func:`uncertainty` on ``frames``:
    1 where the cleaned motion has nothing, else ``1 − confidence``. Worked out a chunk of
    frames at a time: over a long take its temporaries were four (T, J) float arrays."""
    c = np.clip(np.nan_to_num(after.confidence[frames], nan=0.0), 0.0, 1.0)
    return np.where(missing_samples(after.positions[frames]), 1.0, 1.0 - c)


def _correction_cause(outliers: np.ndarray, own: np.ndarray, parents: np.ndarray, names,
                      frame: int, joint: int) -> str | None:
    """Why a joint's largest move happened, when a step judged something wrong there: the
    sample itself (``own``: outliers that move the joint's own position), or a joint up
    its chain (a BVH/AMC rotation spike re-made at a parent moves every joint below it)."""
    if own[frame, joint]:
        return "where it was judged an outlier and rebuilt"
    up, seen = parents[joint], 0
    while up >= 0 and seen < len(parents):
        if outliers[frame, up]:
            return f"where {names[up]} was judged an outlier and rebuilt"
        up, seen = parents[up], seen + 1
    return None


def _empty_frames(missing: np.ndarray, observed: np.ndarray) -> list[list[int]]:
    """``[start, length]`` of every run of frames on which none of the points seen at some
    time is seen (a whole-body dropout, an export's empty first or last frames: nothing
    there to fill from); none when no point is ever seen."""
    seen_somewhere = observed > 0
    if not seen_somewhere.any():
        return []
    _, start, length = runs(missing[:, seen_somewhere].all(axis=1)[:, None])
    return [[int(s), int(n)] for s, n in zip(start, length)]


def _list_unlabelled(file: dict, names, why) -> None:
    """``file["unlabelled"]``: the unlabelled trajectories, ``[{"name", "why"}]`` (nothing
    when there are none)."""
    found = [{"name": n, "why": w} for n, w in zip(names, why) if is_unlabelled(w)]
    if found:
        file["unlabelled"] = found


def _mark_outside_take(file: dict, span: slice, T: int) -> None:
    """Record in the file figures which frames lie before and after the take ``span``
    (``frames_outside_take``: ``[start, length]``), with a note; nothing when none do."""
    outside = [[a, b - a] for a, b in ((0, span.start), (span.stop, T)) if b > a]
    if outside:
        where = " and ".join(f"{n} at the {'start' if a == 0 else 'end'}" for a, n in outside)
        file["frames_outside_take"] = outside
        file["notes"].append(f"frames where no point is seen: {where} (of {T}); outside the "
                             "take, not graded")


def measure_cleaning(result: CleanResult) -> dict:
    """Per-joint and per-file figures of a cleaned file (no status: see rules). Only the
    points the pipeline cleaned are measured and counted; the others (model outputs,
    unlabelled trajectories, points the config excludes) are listed under ``not_cleaned``
    with the reason (``file["points_unlabelled"]`` counts the unlabelled ones)."""
    before, after, records = result.original, result.cleaned, result.records
    T, J = before.positions.shape[:2]
    # without the pipeline's own selection (a result built by hand): the model outputs
    why = not_cleaned(before) if result.not_cleaned is None else result.not_cleaned
    graded = np.array([w is None for w in why], bool)
    mm = before.metres_per_unit * 1000.0
    # the measures with whole-take temporaries of their own first, before the per-sample
    # masks below are held: the report's peak is then theirs alone
    jitter_b, jitter_a = jitter(before), jitter(after)
    bones = bones_of(before)
    # the kinematic chain (a marker set's rigid pairs in ``bones`` are not one)
    parents = before.skeleton.parents if before.skeleton is not None else np.full(J, -1, np.intp)
    var_b, var_a = bone_variation(before.positions, bones), bone_variation(after.positions, bones)
    miss_b, miss_a = before.missing, after.missing
    flagged = np.zeros((T, J), bool)
    made_missing = np.zeros((T, J), bool)
    for rec in records:
        flagged |= rec.outliers
        made_missing |= rec.flagged
    # a sample judged wrong moves its own point, except a BVH joint's re-made rotation,
    # which moves the joints below it only (an ASF/AMC bone's rotation moves its end too)
    rig = before.rig
    own = flagged if rig is None else made_missing | (flagged & np.asarray(rig.offset_in_own_frame, bool)[None, :J])
    who = who_filled(records, T, J)
    who[miss_a] = -1                   # filled by a step, dropped by the writer (storable)
    span = take_frames(miss_b, graded)
    T_take = span.stop - span.start
    unc = uncertainty(before, after, span)
    col, start, length = runs(miss_b[span])
    start = start + span.start
    counted = graded[col]
    col, start, length = col[counted], start[counted], length[counted]
    labels = [r.step for r in records]
    refused = _rejected_fills(records, before.names)
    left_uncertain = _left_uncertain(refused, miss_a)
    fills = FillIndex(after.fill_errors)
    joints = []
    for j in np.flatnonzero(graded):
        sel = col == j
        gaps_filled, gaps_left = [], []
        for s, n in zip(start[sel], length[sel]):
            span_who = who[s:s + n, j]
            if (span_who >= 0).all():
                steps = np.unique(span_who)
                gaps_filled.append({"start": int(s), "length": int(n),
                                    "seconds": finite(n / before.fps),
                                    "long": bool(n / before.fps > LONG_FILL_S),
                                    "confidence": _mean_confidence(after, s, n, j),
                                    **_fill_error(fills, before.names[j], s, n),
                                    "filled_by": ", ".join(labels[k] for k in steps)})
            else:
                left = {"start": int(s), "length": int(n),
                        "filled_frames": int((span_who >= 0).sum())}
                refusals = [{"step": step, "why": reason,
                             **({"error_mm": err, "bound_mm": bound, "extrapolated": far}
                                if err is not None else {})}
                            for a, m, step, reason, err, bound, _, far in refused.get(j, ())
                            if a < s + n and s < a + m]
                if refusals:
                    left["rejected_by"] = refusals
                gaps_left.append(left)
        removed = [{"start": int(s), "length": int(n),
                    "removed_by": ", ".join(dict.fromkeys(
                        r.step for r in records if r.flagged[s:s + n, j].any()))}
                   for s, n in zip(*runs((~miss_b & miss_a)[:, j:j + 1])[1:])]
        mv = np.linalg.norm(after.positions[:, j] - before.positions[:, j], axis=-1) * mm
        mv[miss_b[:, j] | miss_a[:, j]] = np.nan
        has_mv = np.isfinite(mv).any()
        correction = {"mean": finite(np.nanmean(mv)) if has_mv else 0.0,
                      "max": finite(np.nanmax(mv)) if has_mv else 0.0}
        if has_mv and (correction["max"] is None or correction["max"] > 0):   # None: overflow
            frame = int(np.nanargmax(mv))
            correction["frame"] = frame
            cause = _correction_cause(flagged, own, parents, before.names, frame, j)
            if cause:
                correction["cause"] = cause
        bounds = [g["bound_mm"] for g in gaps_filled if g["bound_mm"] is not None]
        entry = {
            "name": before.names[j],
            "missing_before": finite(miss_b[span, j].mean()) if T_take else 0.0,
            "missing_after": finite(miss_a[span, j].mean()) if T_take else 0.0,
            "uncertain": finite(unc[j]),
            "gaps": {"count": int(sel.sum()),
                     "longest_frames": int(length[sel].max()) if sel.any() else 0,
                     "filled": gaps_filled, "unfilled": gaps_left},
            "fill_bound_mm": max(bounds, default=None),
            "left_uncertain": finite(left_uncertain[span, j].mean()) if T_take else 0.0,
            # samples seen in the input, judged wrong and left missing (no fill trusted)
            "removed": removed,
            "outliers_flagged": int(flagged[:, j].sum()),
            "correction_mm": correction,
            "jitter_before": finite(jitter_b[j]),
            "jitter_after": finite(jitter_a[j]),
        }
        if len(bones):
            mine = bones[:, 1] == j
            if mine.any() and np.isfinite(var_b[mine]).any():
                entry["bone_variation_before"] = finite(np.nanmax(var_b[mine]))
            if mine.any() and np.isfinite(var_a[mine]).any():
                entry["bone_variation_after"] = finite(np.nanmax(var_a[mine]))
        if result.writeback_residual is not None:
            res = result.writeback_residual[:, j] * mm
            entry["writeback_residual_mm"] = {"mean": finite(np.nanmean(res)), "max": finite(np.nanmax(res))}
        joints.append(entry)
    filled_samples = int((miss_b & ~miss_a)[:, graded].sum())
    miss_b, miss_a, flagged = miss_b[span][:, graded], miss_a[span][:, graded], flagged[:, graded]
    file = {
        "path": before.path,
        "format": before.format,
        "frames": T,
        "fps": finite(before.fps),
        "joints": int(graded.sum()),
        "units": before.units,
        "missing_before": finite(miss_b.mean()) if miss_b.size else 0.0,
        "missing_after": finite(miss_a.mean()) if miss_a.size else 0.0,
        "samples_filled": filled_samples,
        "samples_flagged": int(flagged.sum()),
        "gaps_before": int(len(length)),
        "gaps_unfilled": int(sum(len(j["gaps"]["unfilled"]) for j in joints)),
        "gaps_after": int(len(runs(miss_a)[0])),
        "long_fills": int(sum(g["long"] for j in joints for g in j["gaps"]["filled"])),
        "fill_bound_max_mm": max((j["fill_bound_mm"] for j in joints
                                  if j["fill_bound_mm"] is not None), default=None),
        "fills_without_estimate": int(sum(g["bound_mm"] is None for j in joints
                                          for g in j["gaps"]["filled"])),
        "fills_extrapolated": int(sum(bool(g["extrapolated"]) for j in joints
                                      for g in j["gaps"]["filled"])),
        "samples_left_uncertain": int(left_uncertain[:, graded].sum()),
        "seconds": finite(result.seconds),
        "notes": list(before.notes) + [n for n in after.notes if n not in before.notes],
    }
    _mark_outside_take(file, span, T)
    steps = [{"step": r.step, "cleaner": r.cleaner, "seconds": finite(r.seconds),
              "filled": int(r.filled.sum()), "flagged": int(r.outliers.sum()),
              "moved_mean_mm": finite(r.mean_moved() * mm),
              **({"skipped": r.skipped} if r.skipped else {}), "info": r.info,
              **_judged_wrong(r, before.names)}
             for r in records]
    out = {"file": file, "steps": steps, "joints": joints}
    if not graded.all():
        file["points_not_cleaned"] = int((~graded).sum())
        out["not_cleaned"] = [{"name": before.names[j], "why": why[j]}
                              for j in np.flatnonzero(~graded)]
        unlabelled = sum(is_unlabelled(w) for w in why)
        if unlabelled:
            file["points_unlabelled"] = unlabelled
    if len(bones):
        out["bones"] = [{"bone": f"{before.names[a]}-{before.names[b]}",
                         "variation_before": finite(vb), "variation_after": finite(va)}
                        for (a, b), vb, va in zip(bones, var_b, var_a)]
    if result.writeback_residual is not None:
        file["writeback_residual_mm"] = _mean_and_max(result.writeback_residual, mm)
    return out


def _mean_and_max(values: np.ndarray, scale: float) -> dict:
    """``{"mean", "max"}`` of ``values × scale`` less its NaN entries, a chunk of frames
    at a time (a whole-take copy of a long take's residuals, and ``np.nanmean``'s copy of
    that, were the peak of its report)."""
    total, count, peak = 0.0, 0, -np.inf
    for a in range(0, len(values), MEASURE_CHUNK):
        part = values[a:a + MEASURE_CHUNK] * scale
        seen = ~np.isnan(part)
        total += float(part[seen].sum())
        count += int(seen.sum())
        peak = max(peak, float(part[seen].max())) if seen.any() else peak
    return {"mean": finite(total / count) if count else None,
            "max": finite(peak) if count else None}


def _judged_wrong(record, names) -> dict:
    """``{"judged_wrong": [[point, start, length], ...]}``: the runs of samples the step
    judged wrong (:attr:`StepRecord.outliers`), so that ``mocapfix view REPORT.json`` can
    colour them by step as the report's own viewer does; empty when there are none."""
    col, start, length = runs(record.outliers)
    if not col.size:
        return {}
    return {"judged_wrong": [[names[c], s, n] for c, s, n in
                             zip(col.tolist(), start.tolist(), length.tolist())]}

