"""The ``harm`` bench protocol: what a method does to a take as it is.

Every other protocol injects damage and scores the repair, which rewards recall. This one
runs the method on the real file **exactly as read** (no corruption; BVH/AMC with their
rig and channels, C3D with their residuals, Kinect with its tracking states) through
:func:`mocapfix.cleaning.clean_motion` — what ``mocapfix clean`` writes, rotation write-back
included — and scores what it changed:

- ``rms_mm``, ``p999_mm``, ``max_mm``: displacement of every sample seen in the input and
  in the output (joint positions by forward kinematics for BVH/AMC), RMS, 99.9th
  percentile and largest; never the mean alone;
- ``moved5_pct``: share of those samples moved more than 5 mm; ``moved10``: how many moved
  more than 10 mm;
- ``flagged``: samples some step judged wrong (made missing or rebuilt in place);
- ``unsupported``: changes of more than 10 mm (*cases*, below) that the take itself does
  not contradict;
- ``jitter_ratio``: RMS acceleration of the output over that of the input (samples seen
  in both, on three consecutive frames);
- ``lost``: samples seen in the input and missing in the output;
- ``written``: samples missing in the input and present in the output, also by the length
  of their run (``written_0.1s`` … ``written_long``: runs up to 0.1, 0.5, 1.5 s and longer),
  and ``written_longest_s``.

**Cases.** Every sample moved more than 10 mm belongs to a case: a run of frames on which
a step judged points wrong (flagged or rebuilt them: a marker spike, a BVH joint's rotation
glitch — with the joints re-made with it —, a Kinect outlier), with every point they move
— for a rig, the joints below a re-made joint — or, for what no step judged wrong, a run
of one point's frames moved by smoothing. Each case carries the take's own evidence that the input was wrong there: the
summed squared second difference (acceleration) of the points it moves over the case's
frames and two frames on each side, in the input and in the output. A glitch throws the
points out and back — the output's path is much smoother (``accel_ratio`` ≤
:data:`SUPPORTED_RATIO`); a real fast movement (a kick's peak at 30 Hz) is a smooth path
that a wrong repair makes rougher. A case is also explained when its largest change is
within :data:`NOISE_SPAN` times the white noise measured on that point's path in the input
(``noise_mm``: smoothing a noisy capture moves samples by about its noise). On a skeleton
of points (Kinect: joints with bones, no rig) a case is also explained by its bones: a bone
with an end among the points it moves is off its median length there by more than
:data:`NOISE_SPAN` times the combined noise of its two ends (no sensor noise makes a
forearm 5 cm longer), the output brings that error at least halfway back, and the case
moves nothing further than the error plus that noise (``bone_error_in_mm`` →
``bone_error_out_mm``). A case none of these explains is *unsupported*. The Markdown lists every case; ``benchmarks/harm.py`` also
draws each one.
"""
from __future__ import annotations

import numpy as np

from mocapfix.core.gaps import runs
from mocapfix.core.kinematics import moved_by_rotation
from mocapfix.core.motion import Motion
from mocapfix.solvers import glitches
from mocapfix.solvers.noise import difference_noise

SETTINGS = ("as-read",)
#: displacements (mm) counted: ``moved5_pct`` and the cases (``moved10``)
MOVED_MM = (5.0, 10.0)
#: run lengths (s) that bucket the samples written that were missing
WRITTEN_BUCKETS_S = (0.1, 0.5, 1.5)
#: a case is supported when the output's acceleration around it is at most this share of
#: the input's (the glitch thrown out and back is gone), over the case and ``CONTEXT``
#: frames on each side: the cleaners' own evidence test
#: (:func:`mocapfix.solvers.glitches.limb_contradicts`)
SUPPORTED_RATIO = glitches.EVIDENCE_RATIO
CONTEXT = glitches.EVIDENCE_CONTEXT
#: ... or when it moves nothing by more than this many times the white noise measured on
#: the path of the point it moves most (per coordinate, :func:`mocapfix.solvers.noise.
#: difference_noise` at order 4): a change the take's own noise explains (3-D noise of σ
#: per coordinate exceeds 5σ once in about 10,000 samples)
NOISE_SPAN = 5.0

#: the protocol's metrics, for :data:`mocapfix.bench.METRICS`
METRICS = [("max_mm", "max mm", 1), ("p999_mm", "99.9th pct mm", 2), ("rms_mm", "RMS mm", 2),
           ("moved5_pct", "moved > 5 mm %", 2), ("moved10", "moved > 10 mm", 0),
           ("unsupported", "unsupported cases", 0), ("flagged", "flagged", 0),
           ("jitter_ratio", "jitter out/in", 3), ("lost", "lost", 0), ("written", "written", 0),
           ("written_long", f"written in runs > {WRITTEN_BUCKETS_S[-1]:g} s", 0),
           ("written_longest_s", "longest run written s", 2)]


def clean(method, motion: Motion):
    """The :class:`~mocapfix.quality.measure.CleanResult` of ``method`` (a
    :class:`mocapfix.bench.Method`) on ``motion`` as ``mocapfix clean`` makes it, whole (the
    per-sample displacements each step made are kept only then)."""
    from mocapfix.cleaning import clean_motion
    from mocapfix.pipeline.steps import Pipeline

    return clean_motion(motion, method.pipeline if method.pipeline is not None else Pipeline([]),
                        windows=None)


def _moved_by(motion: Motion) -> list[np.ndarray]:
    """Per point, the points a change judged at it moves: a marker itself, a rig joint what
    its rotation moves (:func:`mocapfix.core.kinematics.moved_by_rotation`)."""
    if motion.rig is None:
        return [np.array([j]) for j in range(motion.n_joints)]
    return moved_by_rotation(motion.rig)


def _acceleration(positions: np.ndarray) -> float:
    """Summed squared second difference of (W, K, 3) positions (NaN left out)."""
    return float(np.nansum(np.diff(positions, n=2, axis=0) ** 2)) if len(positions) >= 3 else 0.0


def point_noise(positions: np.ndarray) -> np.ndarray:
    """(J,) white noise per coordinate of each point's path (the median over its three
    coordinates of :func:`~mocapfix.solvers.noise.difference_noise` at order 4)."""
    T, J, _ = positions.shape
    return np.median(difference_noise(positions.reshape(T, 3 * J), 4).reshape(J, 3), axis=1)


def bone_errors(positions: np.ndarray, bones: np.ndarray) -> np.ndarray:
    """(T, B) how far each bone's length is from its median over the take (the
    positions' unit; NaN where an end is missing)."""
    if not len(bones):
        return np.zeros((len(positions), 0))
    L = np.linalg.norm(positions[:, bones[:, 0]] - positions[:, bones[:, 1]], axis=-1)
    with np.errstate(all="ignore"):
        return np.abs(L - np.nanmedian(L, axis=0))


def _bone_evidence(bones: np.ndarray, errors: tuple, noise: np.ndarray, points: np.ndarray,
                   a: int, b: int) -> tuple[float, float, float]:
    """Of the bones with an end among ``points``, over frames ``a:b``: the largest error
    of a bone's length in the input and in the output, and what the noise of its two ends
    explains of it (:data:`NOISE_SPAN` × their combined σ); zeros without bones."""
    touch = np.flatnonzero(np.isin(bones, points).any(axis=1)) if len(bones) else np.zeros(0, int)
    if not len(touch):
        return 0.0, 0.0, 0.0
    e_in, e_out = (np.nan_to_num(e[a:b, touch]).max(axis=0) for e in errors)
    worst = int(np.argmax(e_in))
    span = NOISE_SPAN * float(np.hypot(*noise[bones[touch[worst]]]))
    return float(e_in[worst]), float(e_out[worst]), span


def _case(before: np.ndarray, after: np.ndarray, moved: np.ndarray, noise: np.ndarray, names,
          start: int, length: int, points: np.ndarray, fps: float, mm: float, steps: list[str],
          judged: str | None, bones: np.ndarray, errors: tuple) -> dict:
    T = len(before)
    a, b = max(start - CONTEXT, 0), min(start + length + CONTEXT, T)
    acc_in = _acceleration(before[a:b, points])
    acc_out = _acceleration(after[a:b, points])
    ratio = acc_out / acc_in if acc_in > 0 else (0.0 if acc_out == 0 else float("inf"))
    inside = moved[start:start + length][:, points]
    worst = np.unravel_index(np.nanargmax(inside), inside.shape)
    big = inside > MOVED_MM[1]
    to_ms2 = fps * fps * mm / 1000.0
    most = points[worst[1]]
    sigma = float(noise[most]) * mm
    bone_in, bone_out, bone_span = _bone_evidence(bones, errors, noise, points, a, b)
    # the input's skeleton contradicts it there: a bone off its length by more than its
    # ends' noise explains, brought at least halfway back, by a move no larger than the error
    by_bones = (bone_in > bone_span and bone_out <= 0.5 * bone_in
                and inside[worst] <= (bone_in + bone_span) * mm)
    return {"point": judged, "frame": int(start), "frames": int(length),
            "seconds": round(length / fps, 4) if fps else None, "steps": steps,
            "moved_max_mm": round(float(inside[worst]), 2),
            "moved_most": names[most], "moved_most_frame": int(start + worst[0]),
            "samples_moved_10mm": int(big.sum()),
            "accel_in_ms2": round(np.sqrt(acc_in) * to_ms2, 3),
            "accel_out_ms2": round(np.sqrt(acc_out) * to_ms2, 3),
            "accel_ratio": round(ratio, 4) if np.isfinite(ratio) else None,
            "noise_mm": round(sigma, 3),
            "bone_error_in_mm": round(bone_in * mm, 2), "bone_error_out_mm": round(bone_out * mm, 2),
            "supported": bool(ratio <= SUPPORTED_RATIO or inside[worst] <= NOISE_SPAN * sigma
                              or by_bones)}


def cases(result) -> list[dict]:
    """The cases of a clean (see the module docstring): every sample moved more than 10 mm
    belongs to one, largest first. Runs judged wrong whose frames overlap and which move
    some point in common are one case (a foot and its toe re-made together), as the
    cleaners judge them (:func:`mocapfix.solvers.glitches.overlapping_runs`)."""
    before, after = result.original, result.cleaned
    T, J = before.positions.shape[:2]
    mm = before.metres_per_unit * 1000.0
    moved = np.linalg.norm(after.positions - before.positions, axis=-1) * mm
    moved[before.missing | after.missing] = np.nan
    big = np.nan_to_num(moved) > MOVED_MM[1]
    if not big.any():
        return []
    moves = _moved_by(before)
    noise = point_noise(before.positions)
    # a rig's bones are constant by construction: only a skeleton of points is evidence
    bones = (before.skeleton.bone_array if before.skeleton is not None and before.rig is None
             else np.zeros((0, 2), np.intp))
    errors = (bone_errors(before.positions, bones), bone_errors(after.positions, bones))
    judged = np.zeros((T, J), bool)
    for rec in result.records:
        judged |= rec.outliers
    covered = np.zeros((T, J), bool)
    out = []
    found = [(int(k), int(s), int(n)) for k, s, n in zip(*runs(judged)) if len(moves[k])]
    for group in glitches.overlapping_runs(found, [set(m.tolist()) for m in moves], CONTEXT):
        start = min(s for _, s, _ in group)
        stop = max(s + n for _, s, n in group)
        points = np.unique(np.concatenate([moves[k] for k, _, _ in group]))
        covered[start:stop][:, points] = True
        if not big[start:stop, points].any():
            continue
        steps = [r.step for r in result.records
                 if any(r.outliers[s:s + n, k].any() for k, s, n in group)]
        judged_names = ", ".join(dict.fromkeys(before.names[k] for k, _, _ in group))
        out.append(_case(before.positions, after.positions, moved, noise, before.names, start,
                         stop - start, points, before.fps, mm, steps, judged_names, bones, errors))
    for k, s, n in zip(*runs(big & ~covered)):
        steps = [r.step for r in result.records if (r.moved[s:s + n, k] > 0).any()]
        out.append(_case(before.positions, after.positions, moved, noise, before.names, int(s),
                         int(n), np.array([k]), before.fps, mm, steps, None, bones, errors))
    return sorted(out, key=lambda c: -c["moved_max_mm"])


def _written_runs(before: Motion, after: Motion) -> tuple[np.ndarray, np.ndarray]:
    """(lengths, counts) of the runs of samples missing in ``before`` and present in
    ``after``."""
    written = before.missing & ~after.missing
    _, _, length = runs(written)
    return length, written


def evaluate(result) -> tuple[dict, list[dict]]:
    """The protocol's metrics and cases of one clean (module docstring)."""
    before, after = result.original, result.cleaned
    mm = before.metres_per_unit * 1000.0
    seen = ~before.missing & ~after.missing
    d = (np.linalg.norm(after.positions - before.positions, axis=-1) * mm)[seen]
    d = d if d.size else np.zeros(1)
    flagged = np.zeros(before.missing.shape, bool)
    for rec in result.records:
        flagged |= rec.outliers
    length, written = _written_runs(before, after)
    fps = before.fps or 1.0
    seconds = length / fps
    edges = (0.0, *WRITTEN_BUCKETS_S)
    found = cases(result)
    out = {"rms_mm": float(np.sqrt(np.mean(d ** 2))), "p999_mm": float(np.percentile(d, 99.9)),
           "max_mm": float(d.max()), "moved5_pct": float(100.0 * np.mean(d > MOVED_MM[0])),
           "moved10": float(np.sum(d > MOVED_MM[1])),
           "unsupported": float(sum(not c["supported"] for c in found)),
           "flagged": float(flagged.sum()), "jitter_ratio": _jitter_ratio(before, after),
           "lost": float((~before.missing & after.missing).sum()), "written": float(written.sum())}
    for lo, hi in zip(edges[:-1], edges[1:]):
        out[f"written_{hi:g}s"] = float(length[(seconds > lo) & (seconds <= hi)].sum())
    out["written_long"] = float(length[seconds > edges[-1]].sum())
    out["written_longest_s"] = float(seconds.max()) if len(seconds) else 0.0
    return out, found


def _jitter_ratio(before: Motion, after: Motion) -> float:
    """RMS second difference of ``after`` over that of ``before``, on the samples seen in
    both on three consecutive frames (1 for an unchanged take)."""
    a = np.diff(before.positions, n=2, axis=0)
    b = np.diff(after.positions, n=2, axis=0)
    ok = np.isfinite(a).all(axis=-1) & np.isfinite(b).all(axis=-1)
    den = float(np.sum(a[ok] ** 2))
    return float(np.sqrt(np.sum(b[ok] ** 2) / den)) if den > 0 else 1.0


# -- tables ---------------------------------------------------------------------------------

#: cases listed per file and method in the Markdown (largest first; the JSON has all)
LISTED = 20


def _bone_cell(case: dict) -> str:
    if not case["bone_error_in_mm"] and not case["bone_error_out_mm"]:
        return "–"
    return f"{case['bone_error_in_mm']:.1f} → {case['bone_error_out_mm']:.1f}"


def to_markdown(result, listed: int = LISTED) -> str:
    """Per method, one row per file, a worst-over-files row, and the ``listed`` largest
    cases of each file (with a count of the rest)."""
    from pathlib import Path

    parts = ["## `harm`", "", "Each method on the files exactly as read; what `mocapfix clean` "
             "would write, compared with the input (see `mocapfix/bench/harm.py`). Displacement "
             "of the samples seen in both, mm; `moved > 10 mm` counts samples (joint-frames); "
             "a case is a run judged wrong (or smoothed) that moved something more than 10 mm, "
             f"*supported* when the output's acceleration around it is ≤ {SUPPORTED_RATIO:g}× "
             f"the input's, when its largest move is within {NOISE_SPAN:g}× the point's noise, "
             "or (skeletons of points: Kinect) when a bone of the points it moves is off its "
             f"length by more than {NOISE_SPAN:g}× its ends' noise there and the output brings "
             "it at least halfway back, by a move no larger than that error.", ""]
    if result.notes:
        parts += [f"- note: {n}" for n in result.notes] + [""]
    heads = [h for _, h, _ in METRICS]
    for method in [m["name"] for m in result.methods]:
        rows = [r for r in result.runs if r["method"] == method]
        parts += [f"### {method}", "", "| file | " + " | ".join(heads) + " |",
                  "|---" * (len(heads) + 1) + "|"]
        for r in rows:
            name = Path(r["file"]).name
            if "error" in r:
                parts.append(f"| {name} | ERR: {r['error']} |")
                continue
            vals = [_fmt(r["metrics"].get(k), dec) for k, _, dec in METRICS]
            parts.append(f"| {name} | " + " | ".join(vals) + " |")
        ok = [r for r in rows if "error" not in r]
        if ok:
            worst = []
            for k, _, dec in METRICS:
                vals = [r["metrics"].get(k) for r in ok if r["metrics"].get(k) is not None]
                total = k in ("moved10", "unsupported", "flagged", "lost", "written", "written_long")
                worst.append(_fmt((sum(vals) if total else max(vals)) if vals else None, dec))
            parts.append("| **worst file (counts: sum)** | " + " | ".join(worst) + " |")
        parts.append("")
        shown = [(Path(r["file"]).name, c) for r in ok for c in r.get("cases", [])[:listed]]
        more = [(Path(r["file"]).name, r["cases"][listed:]) for r in ok
                if len(r.get("cases", [])) > listed]
        if shown:
            parts += [f"Cases of {method} (every sample moved > 10 mm is in one; at most "
                      f"{listed} per file here):", "",
                      "| file | judged wrong | frames | steps | moved max mm (point, frame) | "
                      "> 10 mm | accel in → out m/s² | noise mm | bone error in → out mm | "
                      "supported |", "|---" * 10 + "|"]
            for name, c in shown:
                where = c["point"] or "(smoothing)"
                parts.append(
                    f"| {name} | {where} | {c['frame']}+{c['frames']} | {', '.join(c['steps'])} | "
                    f"{c['moved_max_mm']:.1f} ({c['moved_most']}, {c['moved_most_frame']}) | "
                    f"{c['samples_moved_10mm']} | {c['accel_in_ms2']:.1f} → {c['accel_out_ms2']:.1f} | "
                    f"{c['noise_mm']:.2f} | {_bone_cell(c)} | {'yes' if c['supported'] else '**no**'} |")
            parts.append("")
            parts += [f"- {name}: {len(rest)} more cases, {sum(not c['supported'] for c in rest)} "
                      "of them unsupported" for name, rest in more]
            parts.append("")
    return "\n".join(parts)


def _fmt(v, dec) -> str:
    return "–" if v is None else f"{v:.{dec}f}"
