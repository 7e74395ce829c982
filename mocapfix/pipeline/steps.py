"""A pipeline of cleaner steps and its run on a Motion; the YAML that makes one is read by
:mod:`mocapfix.config`.

Running records, per step, which samples it filled, which it flagged (made missing) and
how far it moved the rest: the provenance the quality report is built from.

**Fills are written only when they can be trusted** (``max_fill_error``, default
:data:`DEFAULT_MAX_FILL_ERROR`): on a format that can store a missing sample and would
otherwise store a fill as measured (:data:`GATED_FORMATS`), every step runs under a
:class:`~mocapfix.cleaners.base.FillGate`. A step's fill (a run of samples missing before
it and present after it) is kept when the step gave it an error estimate
(``info["fill_errors"]``, :mod:`mocapfix.solvers.fill_error`) whose calibrated 90 % bound
is at most the threshold; otherwise it is put back as missing, listed under the step's
``rejected_fills`` with its estimate and bound, and no later step fills those samples
(the steps that fill are told, so they do not fill a gap only for it to be dropped). The
cleaned motion carries the estimates of the fills it keeps (``Motion.fill_errors``) for
the report and the C3D writer.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from mocapfix.formats import FAMILIES, FORMATS, MARKER_FORMATS, matches
from mocapfix.cleaners.base import (FILL_ERRORS, REJECTED_FILLS, REPLACED_FRAMES, Cleaner,
                                    FillGate, FittedCleaner, shift_frames)
from mocapfix.core.errors import ConfigError
from mocapfix.core.gaps import runs, take_frames
from mocapfix.core.motion import Motion, missing_samples
from mocapfix.core.quantity import Quantity, parse_quantity
from mocapfix.pipeline.selection import (NO_MARKER_SELECTED, Selection, keep_rig_joints,
                                         moved_channels, not_cleaned, put, take)
from mocapfix.solvers.fill_error import uncertain_reason
from mocapfix.solvers.rigid import norms
from mocapfix.pipeline.unlabelled import Unlabelled
from mocapfix.pipeline.windows import DEFAULT_MEMORY_BUDGET, parse_memory_budget

#: the config schema version this mocapfix reads and writes
CONFIG_VERSION = 1
#: the default of ``max_fill_error``: the size of the soft-tissue artefact of skin markers
#: (10–20 mm; Leardini et al. 2005, Gait Posture 21:212), which inverse-kinematics solvers
#: already absorb; a fill that may be further off than that is not written as data
DEFAULT_MAX_FILL_ERROR = "20 mm"
#: formats where a fill is gated: they store a missing sample (C3D: residual −1; TRC and the
#: vendors' text exports: empty fields) and would store a fill as a valid sample (the
#: ``markers`` family). Kinect files mark fills as Inferred (the sensor's own
#: word for a joint it did not see) and are not gated; BVH/AMC cannot store a missing
#: sample at all
GATED_FORMATS = MARKER_FORMATS



@dataclass
class Step:
    cleaner: Cleaner
    formats: tuple[str, ...] | None = None
    line: int | None = None
    select: Selection | None = None

    @property
    def label(self) -> str:
        return self.cleaner.step

    def applies(self, motion: Motion) -> bool:
        return self.formats is None or matches(motion.format, self.formats)

    def config(self) -> dict:
        out = {"cleaner": self.cleaner.name}
        out.update(self.cleaner.config())
        if self.formats:
            out["formats"] = list(self.formats)
        if self.select is not None:
            out.update(self.select.config())
        return out


def parse_max_fill_error(value, where: str) -> Quantity | None:
    """The ``max_fill_error`` value: a length above 0 and at most 100 m, or None (off)."""
    if value is None:
        return None
    q = parse_quantity(value, "length", "mm", where)
    if q.si is None or not (0.0 < q.si <= 100.0):
        raise ConfigError(f"{where} = {value!r} is out of range (allowed: a length > 0 and "
                          "<= 100 m, or null to write every fill)")
    return q


@dataclass
class Pipeline:
    steps: list[Step]
    report: dict = field(default_factory=dict)
    source: str | None = None
    select: Selection | None = None
    unlabelled: Unlabelled = field(default_factory=Unlabelled)
    #: the largest calibrated 90 % error bound of a fill written (None: every fill)
    max_fill_error: Quantity | None = field(
        default_factory=lambda: parse_max_fill_error(DEFAULT_MAX_FILL_ERROR, "max_fill_error"))
    #: bytes one clean may use; a longer take is cleaned in windows
    #: (:mod:`mocapfix.pipeline.windows`; None: every take whole)
    memory_budget: int | None = field(
        default_factory=lambda: parse_memory_budget(DEFAULT_MEMORY_BUDGET, "memory_budget"))

    def config(self) -> dict:
        """The effective config (every parameter, defaults included) as a plain dict."""
        out = {"version": CONFIG_VERSION, "pipeline": [s.config() for s in self.steps]}
        if self.select is not None:
            out.update(self.select.config())
        out["unlabelled"] = self.unlabelled.config()
        out["max_fill_error"] = None if self.max_fill_error is None else str(self.max_fill_error)
        out["memory_budget"] = None if self.memory_budget is None else f"{self.memory_budget / 1e6:g} MB"
        if self.report:
            out["report"] = dict(self.report)
        return out

    def dump(self) -> str:
        return yaml.safe_dump(self.config(), sort_keys=False)

    def model_files(self) -> list[Path]:
        """Every model file the steps may read, each once, in step order."""
        return list(dict.fromkeys(path for step in self.steps if isinstance(step.cleaner, FittedCleaner)
                                  for path in step.cleaner.model_files()))

    def not_cleaned(self, motion: Motion) -> list[str | None]:
        """Per point, why the whole pipeline leaves it alone (None: cleaned): model outputs,
        its ``markers:``/``exclude:``, unlabelled trajectories by its ``unlabelled:``
        (:func:`mocapfix.pipeline.selection.not_cleaned`)."""
        return not_cleaned(motion, self.select, unlabelled=self.unlabelled)

    def run(self, motion: Motion, points: np.ndarray | None = None) -> tuple[Motion, list["StepRecord"]]:
        """Run the steps in turn. Which points the pipeline cleans is decided once, on the
        motion as given (or ``points``, (J,) bool, decided on a whole take of which
        ``motion`` is a window): a step that flags samples of a marker does not make it a
        rarely seen, unlabelled trajectory for the steps after it."""
        records = []
        cleaned = (np.array([why is None for why in self.not_cleaned(motion)], bool)
                   if points is None else points)
        gated = self.max_fill_error is not None and matches(motion.format, (*GATED_FORMATS, "markers"))
        unmatched = [s for s in self.steps if not s.applies(motion)]
        if unmatched and motion.format not in FORMATS and motion.format not in FAMILIES:
            # a Motion built in Python with no format: say so, or steps vanish silently
            why = (f"Motion.format is {motion.format!r}: {len(unmatched)} of {len(self.steps)} "
                   "steps (limited to formats) do not run; build it with "
                   "Motion.from_arrays(..., kind='markers' or 'skeleton') or set its format")
            warnings.warn(why, UserWarning, stacklevel=2)
            motion = motion.replace(notes=[*motion.notes, why])
        # samples a step left as too uncertain to fill: no later step fills them
        settled = np.zeros(motion.positions.shape[:2], bool) if gated else None
        # the points a step can change, where they are not all (a raw export's hundreds of
        # unlabelled fragments beside the markers): what each step did is measured on them
        # alone. A rig's joints move with their parents', so there every point is measured
        touched = None if cleaned.all() or motion.rig is not None else np.flatnonzero(cleaned)
        for step in self.steps:
            if not step.applies(motion):
                records.append(StepRecord.not_run(step, motion, "not for this format"))
                continue
            started = time.perf_counter()
            out, info = self._apply_step(step, motion, cleaned, settled)
            if gated:
                out, info = self._gate(step, motion, out, info, settled, touched)
            records.append(StepRecord.compare(step, motion, out, info, time.perf_counter() - started,
                                              touched))
            motion = out
        return motion.replace(fill_errors=written_fill_errors(motion, records)), records

    def _gate(self, step: Step, before: Motion, after: Motion, info: dict,
              settled: np.ndarray, touched: np.ndarray | None = None) -> tuple[Motion, dict]:
        """The step's fills without those it gave no estimate for, or whose 90 % bound
        exceeds ``max_fill_error`` (put back as missing and listed in the info's
        :data:`REJECTED_FILLS` with their estimate and bound); marks in ``settled`` (in
        place) every gap left as too uncertain, by the step or here. ``touched``: the
        points the step can change (indices; None: all)."""
        info = dict(info or {})
        limit_mm = self.max_fill_error.si * 1e3
        listed = {(name, int(e[0])): e for name, entries in (info.get(FILL_ERRORS) or {}).items()
                  for e in entries}
        if touched is None:
            col, start, length = runs(before.missing & ~after.missing)
        else:
            col, start, length = runs(missing_samples(before.positions[:, touched])
                                      & ~missing_samples(after.positions[:, touched]))
            col = touched[col]
        drop = []
        for j, s, n in zip(col.tolist(), start.tolist(), length.tolist()):
            entry = listed.get((after.names[j], s))        # the run the step estimated
            if entry is not None and s + n > entry[0] + entry[1]:
                entry = None
            if entry is None or entry[3] > limit_mm:
                drop.append((j, s, n, entry))
        if drop:
            positions = after.positions.copy()
            confidence = None if after.confidence is None else after.confidence.copy()
            rejected = {k: list(v) for k, v in (info.get(REJECTED_FILLS) or {}).items()}
            for j, s, n, entry in drop:
                positions[s:s + n, j] = np.nan
                if confidence is not None:
                    confidence[s:s + n, j] = 0.0
                err, bound = (None, None) if entry is None else (entry[2], entry[3])
                why = uncertain_reason(err, bound, f"{step.cleaner.name} gives no error "
                                       "estimate for its fills")
                rejected.setdefault(after.names[j], []).append([s, n, why, err, bound])
            info[REJECTED_FILLS] = rejected
            after = after.replace(positions=positions, confidence=confidence)
        index = {name: j for j, name in enumerate(after.names)}
        for name, entries in (info.get(REJECTED_FILLS) or {}).items():
            for entry in entries:
                if len(entry) >= 5 and name in index:
                    settled[int(entry[0]):int(entry[0]) + int(entry[1]), index[name]] = True
        return after, info

    def _apply_step(self, step: Step, motion: Motion, cleaned: np.ndarray,
                    settled: np.ndarray | None = None) -> tuple[Motion, dict]:
        """Run one step on the markers it may clean (``cleaned`` (J,): those the pipeline
        cleans, less those the step's own selection leaves out; see
        :mod:`mocapfix.pipeline.selection`) over the frames of the take
        (:func:`~mocapfix.core.gaps.take_frames`: an export's empty first and last frames hold
        nothing to clean, fill or count); the other points and frames come back
        unchanged. ``settled``: the fill gate is on, and these samples were left as too
        uncertain to fill (None: no gate)."""
        cols = cleaned if step.select is None else cleaned & step.select.mask(motion.names)
        if not cols.any():
            return motion.copy(), {"skipped": NO_MARKER_SELECTED}
        span = take_frames(motion.missing, cols)

        def gate(frames: slice) -> FillGate | None:
            if settled is None:
                return None
            leave = settled[frames]
            if not cols.all() and motion.rig is None:
                leave = leave[:, cols]
            return FillGate(self.max_fill_error.si, leave if leave.any() else None)
        if span.stop - span.start == motion.n_frames:
            return self._apply_on_points(step, motion, cols, gate(slice(None)))
        part, info = self._apply_on_points(step, motion.slice_frames(span.start, span.stop), cols,
                                           gate(span))
        return motion.with_frames(span.start, part), shift_frames(info, span.start)

    @staticmethod
    def _apply_on_points(step: Step, motion: Motion, cols: np.ndarray,
                         gate: FillGate | None = None) -> tuple[Motion, dict]:
        if cols.all():
            return step.cleaner.apply(motion, gate)
        if motion.rig is not None and motion.channels is not None:
            out, info = step.cleaner.apply(motion, gate)
            channel_step = moved_channels(motion, out)
            if channel_step:
                # a rotation step: what it did to the excluded joints' channels is undone
                info = _without_points(info, [n for n, c in zip(motion.names, cols) if not c])
            info = dict(info or {})
            info["points_not_cleaned"] = int((~cols).sum())
            return keep_rig_joints(motion, out, ~cols, channel_step), info
        part, info = step.cleaner.apply(take(motion, cols), gate)
        info = dict(info or {})
        info["points_not_cleaned"] = int((~cols).sum())
        return put(motion, cols, part), info


def _without_points(info: dict, names: list[str]) -> dict:
    """A step's ``info`` without what it says of the joints ``names`` (joints of a rig it
    ran on whole, whose channels are then put back): entries keyed by joint name (the
    frames it replaced or rejected, per-joint counts) lose those joints, and the counts of
    what it replaced (``spike_frames``, ``joint_frames_replaced``) are counted again from
    what is left. For a rotation step only: the flags of a position step stay on every
    joint (:func:`mocapfix.pipeline.selection.keep_rig_joints`)."""
    info = dict(info or {})
    drop = set(names)
    for key, value in list(info.items()):
        if isinstance(value, dict) and value and drop & set(value):
            info[key] = {n: v for n, v in value.items() if n not in drop}
    replaced = info.get(REPLACED_FRAMES)
    if isinstance(replaced, dict):
        if "joint_frames_replaced" in info:
            info["joint_frames_replaced"] = sum(len(v) for v in replaced.values())
        if "spike_frames" in info:
            info["spike_frames"] = len({int(f) for v in replaced.values() for f in v})
    return info


def written_fill_errors(motion: Motion, records) -> dict:
    """``{name: [[start, length, error_mm, bound_mm, step, written, extrapolated], ...]}``:
    the estimates the steps gave (:data:`FILL_ERRORS`) of the fills ``motion`` (the
    pipeline's output) holds, the last step's where two estimated the same samples
    (``written`` 1), and the gaps left as too uncertain to fill that are still missing,
    with their estimate and bound when they had one (``written`` 0; from the steps'
    :data:`REJECTED_FILLS`); ``extrapolated``: the estimate was extrapolated from windows
    shorter than the gap (:func:`mocapfix.solvers.fill_error.extrapolated_bounds`)."""
    missing = motion.missing
    index = {name: j for j, name in enumerate(motion.names)}
    out: dict = {}
    taken = np.zeros(missing.shape, bool)           # samples a later step's estimate holds
    for rec in reversed(records):
        for name, entries in ((rec.info or {}).get(FILL_ERRORS) or {}).items():
            j = index.get(name)
            for s, n, err, bound, *far in entries:
                span = slice(int(s), int(s) + int(n))
                if j is None or missing[span, j].any() or taken[span, j].any():
                    continue
                taken[span, j] = True
                out.setdefault(name, []).append([int(s), int(n), err, bound, rec.step, 1,
                                                 bool(far and far[0])])
    for rec in records:
        for name, entries in ((rec.info or {}).get(REJECTED_FILLS) or {}).items():
            j = index.get(name)
            for e in entries:
                if j is not None and len(e) >= 5 and missing[int(e[0]):int(e[0]) + int(e[1]), j].all():
                    out.setdefault(name, []).append([int(e[0]), int(e[1]), e[3], e[4], rec.step, 0,
                                                     bool(len(e) > 5 and e[5])])
    return out


def replaced_mask(info: dict, names, shape) -> np.ndarray:
    """(T, J) mask of the samples a step's ``info[REPLACED_FRAMES]`` lists."""
    mask = np.zeros(shape, bool)
    listed = info.get(REPLACED_FRAMES) or {}
    index: dict = {}
    for j, name in enumerate(names):
        index[name] = j if name not in index else None     # a repeated label: ambiguous
    for name, frames in listed.items():
        j = index.get(name)
        rows = np.asarray(frames, dtype=np.intp).ravel()
        rows = rows[(rows >= 0) & (rows < shape[0])]
        if j is not None and rows.size:
            mask[rows, j] = True
    return mask


@dataclass
class StepRecord:
    """What one step did, per sample: filled (missing → present), flagged (present →
    missing), replaced (judged wrong and rebuilt in place: the step's
    ``info["replaced_frames"]``, :data:`~mocapfix.cleaners.base.REPLACED_FRAMES`) and the displacement of
    samples present before and after."""

    step: str
    cleaner: str
    seconds: float
    filled: np.ndarray
    flagged: np.ndarray
    moved: np.ndarray
    info: dict
    skipped: str | None = None
    replaced: np.ndarray | None = None
    #: the mean of ``moved`` over every sample, where ``moved`` is not kept (a take
    #: cleaned in windows: :mod:`mocapfix.pipeline.windows`; ``moved`` is then empty)
    moved_mean: float | None = None

    def mean_moved(self) -> float:
        """The mean displacement over every sample of the take (file units)."""
        if self.moved_mean is not None:
            return self.moved_mean
        return float(np.mean(self.moved)) if self.moved.size else 0.0

    @property
    def outliers(self) -> np.ndarray:
        """Samples the step judged wrong: flagged (made missing) or replaced in place."""
        return self.flagged if self.replaced is None else self.flagged | self.replaced

    @classmethod
    def compare(cls, step: Step, before: Motion, after: Motion, info: dict, seconds: float,
                touched: np.ndarray | None = None):
        """The record of ``step`` from the motion ``before`` and ``after`` it; ``touched``:
        the points it can change (indices; None: all), the others being the same in both
        (their samples neither filled, flagged, replaced nor moved)."""
        if after.positions.shape != before.positions.shape:
            raise ConfigError(f"{step.label}: cleaner changed the shape of the motion")
        info = info or {}
        if touched is None:
            miss_before, miss_after = before.missing, after.missing
            moved = norms(after.positions - before.positions)
            moved[miss_before | miss_after] = 0.0
            return cls(step.label, step.cleaner.name, seconds, miss_before & ~miss_after,
                       ~miss_before & miss_after, moved, info,
                       replaced=replaced_mask(info, after.names, miss_before.shape) & ~miss_before)
        shape = before.positions.shape[:2]
        b, a = before.positions[:, touched], after.positions[:, touched]
        mb, ma = missing_samples(b), missing_samples(a)
        part = norms(a - b)
        part[mb | ma] = 0.0
        moved, filled, flagged = np.zeros(shape), np.zeros(shape, bool), np.zeros(shape, bool)
        moved[:, touched], filled[:, touched], flagged[:, touched] = part, mb & ~ma, ~mb & ma
        replaced = replaced_mask(info, after.names, shape)
        replaced[:, touched] &= ~mb
        others = np.setdiff1d(np.flatnonzero(replaced.any(axis=0)), touched)
        if len(others):         # listed though the step could not change them: as the whole
            replaced[:, others] &= ~missing_samples(before.positions[:, others])
        return cls(step.label, step.cleaner.name, seconds, filled, flagged, moved, info,
                   replaced=replaced)

    @classmethod
    def not_run(cls, step: Step, motion: Motion, why: str):
        shape = motion.positions.shape[:2]
        return cls(step.label, step.cleaner.name, 0.0, np.zeros(shape, bool),
                   np.zeros(shape, bool), np.zeros(shape), {}, skipped=why)
