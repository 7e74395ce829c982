"""Clean one motion or one file: run the pipeline, write rotations back for hierarchical
formats, write the output and its reports."""
from __future__ import annotations

import contextlib
import os
import stat
import time
from pathlib import Path

import numpy as np

from mocapfix import formats
from mocapfix.core.diskarray import FramesOnDisk
from mocapfix.core.errors import UnreadableFileError
from mocapfix.core.fileio import NAME_MAX, atomic_write_text, is_stream, refuse_stream
from mocapfix.core.memory import release_freed_memory
from mocapfix.core.motion import Motion
from mocapfix.pipeline.held import HeldFrames
from mocapfix.pipeline.steps import Pipeline, StepRecord, written_fill_errors
from mocapfix.pipeline.cuts import note as cuts_note
from mocapfix.pipeline.cuts import cut_points, take_cuts
from mocapfix.pipeline.windows import (Pieces, Windows, merge_info, over_budget, paste, pieces,
                                       point_cuts, shifted_info, window_for)
from mocapfix.quality.render import ranked
from mocapfix.quality.report import CleanResult, build_report, to_html, to_json, to_markdown
from mocapfix.pipeline.selection import own_channels
from mocapfix.core.writeback import write_back

REPORT_KINDS = ("json", "md", "html")


def clean_motion(motion: Motion, pipeline: Pipeline, to: str | None = None,
                 windows: Windows | None | str = "budget",
                 keep_input_on_disk: Path | None = None) -> CleanResult:
    """Run ``pipeline`` on ``motion``. For BVH/AMC the cleaned positions are turned back
    into the file's channels and the written positions are their forward kinematics; a
    value the output file cannot hold is dropped as its writer will drop it
    (:func:`mocapfix.formats.storable`). ``to``: the format it will be written in (None:
    its own); what that format cannot carry is added to the cleaned motion's notes
    (:func:`mocapfix.formats.losses`), so the report says it.

    ``windows``: a take longer than the pipeline's ``memory_budget`` allows is cleaned in
    overlapping windows (:mod:`mocapfix.pipeline.windows`; ``"budget"``, the default);
    :class:`~mocapfix.pipeline.windows.Windows` to choose them, None to clean it whole.
    A take whose frames repeat the frame before them is cleaned on its distinct frames
    (:mod:`mocapfix.pipeline.held`), and a take that jumps as a whole somewhere (takes
    joined) as the takes between its jumps (:mod:`mocapfix.pipeline.cuts`).

    ``keep_input_on_disk``: a folder, for a caller that has no other use for ``motion``
    (``clean_file``): a take over the memory budget (cleaned in windows, or as the takes
    between its cuts) is then cleaned in place, its arrays
    becoming the cleaned motion's, while ``motion`` (the result's ``original``) and its
    source read the values as read from an unlinked file in that folder
    (:class:`~mocapfix.core.diskarray.FramesOnDisk`): the input is not held in memory
    beside the output. Where the file cannot be written the input is copied, as
    without."""
    started = time.perf_counter()
    why = pipeline.not_cleaned(motion)
    held = HeldFrames.find(motion)
    distinct = motion if held is None else held.take(motion)
    if windows == "budget":
        windows = window_for(pipeline.memory_budget, distinct.n_frames, motion.n_joints, motion.fps)
    at = take_cuts(distinct, cut_points(motion))
    plan = pieces(distinct.n_frames, windows, at)
    if plan is None:
        cleaned, records, residual = _clean_span(distinct, pipeline, why)
    else:
        cleaned, records, residual = _clean_windowed(
            distinct, pipeline, why, plan, distances=windows is None,
            disk=keep_input_on_disk if held is None and windows is not None else None)
    if len(at):     # in place: replace() would copy the take's arrays
        cleaned.notes = [*cleaned.notes, cuts_note(at if held is None else held.kept[at])]
    if held is not None:
        cleaned, records, residual = held.expand(motion, cleaned, records, residual)
    losses = [] if to is None or to == motion.format else formats.losses(cleaned, to)
    cleaned.notes = [*cleaned.notes, *losses]       # in place, as the cuts' note
    cleaned = formats.storable(cleaned, to)
    return CleanResult(motion, cleaned, records, residual, time.perf_counter() - started, why,
                       losses)


def _clean_span(motion: Motion, pipeline: Pipeline, why: list, points: np.ndarray | None = None):
    """The pipeline's run and, for a rig, the write-back of its positions into channels:
    ``(cleaned, records, residual)`` (residual None without a rig)."""
    cleaned, records = pipeline.run(motion, points)
    residual = None
    if cleaned.rig is not None and cleaned.channels is not None:
        channels, positions, residual = write_back(cleaned)
        excluded = np.array([w is not None for w in why], bool)
        if excluded.any():
            # the joints the config leaves out keep their channels through the write-back
            # of what later steps filled (selection.keep_rig_joints)
            channels = own_channels(cleaned.rig, channels, motion.channels, excluded)
            positions = cleaned.rig.positions(channels)
            residual = np.linalg.norm(positions - cleaned.positions, axis=-1)
        cleaned = cleaned.replace(channels=channels, positions=positions)
    return cleaned, records, residual


def _clean_windowed(motion: Motion, pipeline: Pipeline, why: list, plan: Pieces,
                    distances: bool = False, disk: Path | None = None):
    """:func:`_clean_span` over the pieces of ``plan`` (overlapping windows, the takes
    between cuts), put together frame by frame (:mod:`mocapfix.pipeline.windows`). The
    points the pipeline cleans are decided once, on the whole take. ``distances``: the
    steps' records keep how far they moved each sample (a take the memory budget lets
    be cleaned whole), not only the mean. ``disk``: :func:`clean_motion`'s
    ``keep_input_on_disk``."""
    T, J = motion.n_frames, motion.n_joints
    cuts = list(plan.cuts)
    per_point = point_cuts(motion.missing, cuts, plan.overlaps)
    points = np.array([w is None for w in why], bool)
    taken, why_held = (None, None) if disk is None else _input_to_disk(motion, disk)
    notes = list(motion.notes) + ([why_held] if why_held else [])
    if taken is None:
        positions = motion.positions.copy()
        confidence = None if motion.confidence is None else motion.confidence.copy()
        channels = None if motion.channels is None else motion.channels.copy()
    else:
        positions, confidence, channels = taken
    residual = None
    masks: list[dict] = []
    infos: list[list] = []
    heads: list = []
    for k in range(len(cuts) - 1):
        lo, hi = plan.bounds(k)
        start, stop = per_point[k], per_point[k + 1]
        part, records, res = _clean_span(motion.slice_frames(lo, hi), pipeline, why, points)
        paste(positions, part.positions, lo, start, stop)
        if part.confidence is not None:
            if confidence is None:
                confidence = (~motion.missing).astype(np.float64)
            paste(confidence, part.confidence, lo, start, stop)
        if channels is not None:
            channels[cuts[k]:cuts[k + 1]] = part.channels[cuts[k] - lo:cuts[k + 1] - lo]
        if res is not None:
            residual = np.zeros((T, J)) if residual is None else residual
            paste(residual, res, lo, start, stop)
        notes += [n for n in part.notes if n not in notes]
        if not masks:
            # what the merged records take from the first window's (not its arrays)
            heads = [(rec.step, rec.cleaner, rec.info) for rec in records]
            # of the distances moved only their sum is kept (the report gives the mean)
            masks = [{"filled": np.zeros((T, J), bool), "flagged": np.zeros((T, J), bool),
                      "moved": 0.0, "replaced": None,
                      "distances": np.zeros((T, J)) if distances else None}
                     for _ in records]
            infos = [[] for _ in records]
        for rec, mask, info in zip(records, masks, infos):
            info.append((shifted_info(rec.info, lo, start, stop, motion.names), rec.seconds,
                         rec.skipped))
            if rec.skipped:
                continue            # nothing to paste: its masks stay zero pages, never touched
            for key in ("filled", "flagged"):
                if getattr(rec, key).any():     # an empty one stays zero pages
                    paste(mask[key], getattr(rec, key), lo, start, stop)
            mask["moved"] += sum(float(rec.moved[a - lo:b - lo, j].sum())
                                 for j, (a, b) in enumerate(zip(start.tolist(), stop.tolist())))
            if mask["distances"] is not None:
                paste(mask["distances"], rec.moved, lo, start, stop)
            # every step's record has a replaced mask, mostly empty: one pasted as it was
            # touched a whole-take array per step (100 MB for a 500,000-frame C3D)
            if rec.replaced is not None and rec.replaced.any():
                if mask["replaced"] is None:
                    mask["replaced"] = np.zeros((T, J), bool)
                paste(mask["replaced"], rec.replaced, lo, start, stop)
        # pasted: the window's output and records go before the next window is cleaned
        # (held, they were one more window's arrays beside its working memory)
        del part, records, res
    # the windows' working memory, freed but kept by the heaps of the threads that used it,
    # goes back to the system before the records and the report are made beside the take
    release_freed_memory()
    records = []
    for (step, cleaner, first_info), mask, info in zip(heads, masks, infos):
        skipped = {s for _, _, s in info}
        merged = merge_info([i for i, _, _ in info])
        merged["windows"] = len(info)
        skipped = skipped.pop() if len(skipped) == 1 else None
        kept = mask["distances"] is not None
        records.append(StepRecord(step, cleaner, sum(s for _, s, _ in info),
                                  mask["filled"], mask["flagged"],
                                  mask["distances"] if kept else np.zeros((0, J)),
                                  merged if skipped is None else first_info, skipped,
                                  mask["replaced"],
                                  moved_mean=None if kept else mask["moved"] / (T * J)))
    if plan.windows is not None:
        apart = sum(o == 0 for o in plan.overlaps[1:-1])    # the take's own cuts
        notes.append(f"cleaned in {len(cuts) - 1} windows of {plan.windows.frames} frames "
                     f"with {plan.windows.overlap} frames of overlap (memory_budget)"
                     + (f"; cut with no overlap where the take jumps as a whole ({apart} "
                        f"frame{'s' if apart > 1 else ''})" if apart else ""))
        held = [positions, confidence, channels, residual]
        if taken is None:
            held += [motion.positions, motion.confidence, motion.channels]
        heavy = over_budget(pipeline.memory_budget, sum(a.nbytes for a in held if a is not None),
                            input_on_disk=taken is not None)
        if heavy:
            notes.append(heavy)
    cleaned = motion.replace(positions=positions, confidence=confidence, channels=channels,
                             times=motion.times, notes=notes)
    cleaned.fill_errors = written_fill_errors(cleaned, records)   # in place: no copy of the take
    return cleaned, records, residual


_INPUT_ARRAYS = ("positions", "confidence", "channels")


def _input_to_disk(motion: Motion, folder: Path):
    """``(arrays, None)``: the motion's positions, confidence and channels, to be cleaned
    in place, with ``motion`` and its source (the values a writer compares with) now
    reading the values as read from disk (:class:`FramesOnDisk`); ``(None, note)``,
    nothing changed, when they cannot be written there (no room, no permission)."""
    arrays = [getattr(motion, name) for name in _INPUT_ARRAYS]
    try:
        kept = [None if a is None else FramesOnDisk(a, folder) for a in arrays]
    except OSError as exc:
        return None, (f"the input could not be kept on disk in {folder} while it was "
                      f"cleaned ({exc.strerror or exc}): it was held in memory beside the "
                      "output")
    source = motion.source
    out = []
    for name, array, disk in zip(_INPUT_ARRAYS, arrays, kept):
        if array is None:
            out.append(None)
            continue
        formats.replace_shared_values(source, array, disk)
        try:
            array.flags.writeable = True        # read-only as shared with the source
        except ValueError:                      # a view of memory it cannot write
            array = array.copy()
        setattr(motion, name, disk)
        out.append(array)
    return tuple(out), None


def _disk_folder(output: Path) -> Path:
    """Where a long take's input is kept while it is cleaned: the output's folder, or the
    nearest folder above it that exists (the output's is made when it is written)."""
    return next(f for f in Path(output).absolute().parents if f.is_dir())


def report_paths(output: Path, kinds) -> dict[str, Path]:
    """``take.c3d`` → ``take.c3d.report.json`` (``.md``, ``.html``): named after the whole
    output name, so that ``take.c3d`` and ``take.bvh`` in one folder do not share reports
    (named after the stem, one overwrote the others — which one depended on ``-j`` — and
    a failed file's cleanup removed the report of its namesake). A name too long for that
    (over 243 bytes) keeps the stem only, as the file system allows no more."""
    base = output.name
    if len(os.fsencode(f"{base}.report.html")) > NAME_MAX and output.suffix:
        base = output.name[: -len(output.suffix)]
    return {k: output.with_name(f"{base}.report.{k}") for k in kinds}


def output_files(output: Path) -> list[Path]:
    """The files a clean of ``output`` writes under its name: the motion and the reports
    of every kind (for removing stale ones). Not the ASF an AMC is written beside, which
    the subject's other AMCs there share (:func:`mocapfix.batch.plan.skeleton_written`)."""
    return [output, *report_paths(output, REPORT_KINDS).values()]


def remove_outputs(paths) -> None:
    """Remove the files at ``paths`` that exist. Never raises: it runs after a failure,
    whose error is the one to report, and must not stop the batch. A folder where an
    output would go is not an output (it is left), nor a device or a pipe (or a link to
    one) that refused the output; a file that cannot be removed stays."""
    for p in paths:
        p = Path(p)
        try:
            if stat.S_ISDIR(os.lstat(p).st_mode) or is_stream(p):
                continue
        except OSError:     # not there, or a name the file system refuses (over 255 bytes:
            continue        # Path.is_dir raised that, replacing the error and ending the batch)
        # not there: neither the file nor, when part of its folder path is a file, the folder
        with contextlib.suppress(OSError):
            p.unlink()


def clean_file(source: Path, output: Path, pipeline: Pipeline, reports=("json",),
               read_options: dict | None = None, skeleton_checked: bool = False,
               to: str | None = None) -> dict:
    """Read, clean, write (in format ``to``; None: the format read). Returns a JSON-able
    summary; raises MocapfixError on failure.

    ``skeleton_checked``: an AMC's ASF copy was checked with its batch's
    (:func:`mocapfix.batch.plan.skeleton_conflicts`), so its writer does not check it alone.
    Every report is rendered before anything is written, and a failure while writing
    removes the output and its reports, so a failed file leaves nothing behind (but the
    ASF an AMC is written beside, which the subject's other AMCs there share). Reports of kinds
    not asked for this time are removed beside the new output (no stale reports). An output
    or report path that is a device or a pipe, or a link to one, is a WriteError before
    anything is written (it would swallow the output)."""
    # cleaning never writes into the motion read: the source's values are its own arrays
    motion = formats.read(source, share_values=True, **(read_options or {}))
    # the reader's freed temporaries go back to the system before the take is cleaned
    release_freed_memory()
    if motion.n_frames == 0:
        raise UnreadableFileError(source, "holds no frames; nothing to clean")
    result = clean_motion(motion, pipeline, to, keep_input_on_disk=_disk_folder(output))
    report = build_report(result, pipeline.report)
    paths = report_paths(output, reports)
    writers = {"json": lambda: to_json(report), "md": lambda: to_markdown(report),
               "html": lambda: to_html(report, result, viewer=pipeline.report.get("viewer", True))}
    texts = {kind: writers[kind]() for kind in paths}
    for path in (output, *paths.values()):
        refuse_stream(path)
    written: list[Path] = []
    try:
        # in the format that was read, which the content decided, not the name: a BVH
        # saved as .c3d stays a BVH (the output mirrors the input's name)
        written = list(formats.write(result.cleaned, output, format=to or motion.format,
                                     **({"skeleton_checked": True} if skeleton_checked
                                        and motion.format == "asfamc" else {})))
        for kind, path in paths.items():
            atomic_write_text(path, texts[kind])
    except BaseException:
        # the motion and this call's reports; never the skeleton an AMC is written beside,
        # which the other AMCs of that subject in the folder use too
        remove_outputs([output, *paths.values()])
        raise
    remove_outputs(p for k, p in report_paths(output, REPORT_KINDS).items() if k not in paths)
    f = report["file"]
    return {
        "input": str(source), "output": str(output), "written": [str(p) for p in written],
        "reports": [str(p) for p in paths.values()], "status": f["status"],
        "frames": f["frames"], "joints": f["joints"], "missing_before": f["missing_before"],
        "missing_after": f["missing_after"], "samples_filled": f["samples_filled"],
        "samples_flagged": f["samples_flagged"], "seconds": round(result.seconds, 4),
        "reasons": sorted({r for j in report["joints"] for r in j["reasons"] if r.startswith(f["status"])})[:3]
        or f.get("reasons", []),
        "worst": [[j["name"], j["status"]] for j in ranked(report)[:3] if j["status"] != "OK"],
        **({"steps_not_run": f["steps_not_run"]} if f.get("steps_not_run") else {}),
        **({"format": to, "not_carried": result.not_carried}
           if to and to != motion.format else {}),
    }
