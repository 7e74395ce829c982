"""`mocapfix view`: captures played in 3D in one self-contained HTML file.

:func:`to_html` turns one or more :class:`~mocapfix.core.motion.Motion` into a single page
that needs nothing but a browser (no network, no CDN; a Content-Security-Policy forbids any
request): markers as points, skeleton bones as lines, play/pause, scrub, speed, orbit and
zoom with the mouse, a ground grid and the joint's name on hover. Given a capture and its
cleaned output (:func:`before_after`), the two are overlaid: the input in grey, the output
in colour, samples the cleaner filled coloured by their estimated error (the ``MOCAPFIX``
group of a cleaned C3D, or ``Motion.fill_errors``) or as "filled" when no estimate is
known, samples it moved or deleted marked, and — in the clean report, which knows the
steps (:func:`embed`) — the samples each step judged wrong coloured by step. Kinect joints
that were inferred or of low confidence are rings. A take that travels is followed by the
camera. ``view.html#frame=N`` opens paused at frame N.

Size: positions are converted to metres and quantised to int16 per axis relative to each
layer's bounding box (a 5 m box gives 0.08 mm steps; -32768 = missing), base64-encoded
(8 bytes of text per sample). The "before" layer of an overlay is stored as its
differences from the "after" layer (int8 steps where a sample moved a little, the sample
itself where it was filled, deleted or moved far) when that is smaller. When the page would
exceed ``budget`` bytes (3 MB by default) every layer keeps every k-th frame, the smallest
k that fits; the page says so. Measured (``benchmarks/viewer_size.py``): a 4,500-frame ×
41-marker capture is 1.50 MB alone and 2.40 MB as a before/after overlay of a cleaned
corruption, both with every frame, interactive in 0.12 and 0.25 s in headless Chromium.
Embedded in a clean report the budget is 1.5 MB (the shared data's 53 reports: 17.6 MB
without the viewer, 30.4 MB with it).

Why hand-written: the page draws at most a few hundred points and lines per frame, which
Canvas 2D does in well under a millisecond; ``viewer.js`` (perspective projection, orbit
camera, grid, picking, marks) is 19 KB unminified, the page's HTML and CSS 2 KB. three.js
0.170.0's ``build/three.module.min.js`` alone is 691,648 bytes (measured from the npm
tarball), would be vendored with its licence and pinned, and would still need our own
controls, picking and colouring code: 35x the size, for features (meshes, lights, shaders)
that points and lines do not use.
"""
from __future__ import annotations

import base64
import html
import json
import math
import os
import re
import warnings
from importlib import resources
from pathlib import Path

import numpy as np

from mocapfix.core.motion import Motion, missing_samples

#: bytes a page may hold; the viewer embedded in a clean report holds half
DEFAULT_BUDGET = 3_000_000
EMBED_BUDGET = DEFAULT_BUDGET // 2
MISSING = -32768
_STEPS = 65534                          # int16 codes -32767..32767 for present samples


def _template(name: str) -> str:
    return resources.files("mocapfix.quality").joinpath(name).read_text(encoding="utf-8")


def _markers(motion: Motion) -> np.ndarray:
    """Indices of the points drawn: markers and joints, not a C3D's model outputs."""
    if motion.kinds is None:
        return np.arange(motion.n_joints)
    return np.array([j for j, k in enumerate(motion.kinds) if k == "marker"], dtype=np.intp)


def _bones(motion: Motion, keep: np.ndarray) -> list[list[int]]:
    if motion.skeleton is None:
        return []
    where = {int(j): n for n, j in enumerate(keep)}
    return [[where[a], where[b]] for a, b in motion.skeleton.bones if a in where and b in where]


def up_axis(metres: np.ndarray) -> int:
    """The vertical axis of a capture of people: per frame, the extent of the points along
    each axis; a body is taller than it is wide or deep, so the axis of the largest median
    extent is up (Y for BVH/AMC/Kinect, Z for most C3D); Z when nothing is seen."""
    if not metres.size:                     # no point or no frame: no extent to compare
        return 2
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)     # frames where nothing is seen
        extent = np.nanmax(metres, axis=1) - np.nanmin(metres, axis=1)      # (T, 3)
        med = np.nanmedian(extent, axis=0)
    if not np.isfinite(med).any():
        return 2
    return int(np.nanargmax(med))


def _box(*arrays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for a in arrays:
        flat = a.reshape(-1, 3)
        ok = ~missing_samples(flat[None])[0]
        if ok.any():
            lo = np.minimum(lo, flat[ok].min(axis=0))
            hi = np.maximum(hi, flat[ok].max(axis=0))
    if not np.isfinite(lo).all():
        return np.zeros(3), np.full(3, 1e-6)
    return lo, np.maximum((hi - lo) / _STEPS, 1e-9)


def quantise(metres: np.ndarray, origin: np.ndarray, step: np.ndarray) -> np.ndarray:
    """(T, J, 3) int16 codes; a sample with any NaN coordinate is MISSING on all three."""
    codes = np.rint((metres - origin) / step) - 32767
    gone = missing_samples(metres)
    codes[gone] = 0
    out = np.clip(codes, -32767, 32767).astype("<i2")
    out[gone] = MISSING
    return out


def _b64(array: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(array).tobytes()).decode("ascii")


def _b64_len(n_bytes: int) -> int:
    return 4 * math.ceil(n_bytes / 3)


def _finite(x) -> float | None:
    return float(x) if x is not None and math.isfinite(x) else None


def _fill_runs(motion: Motion, keep: np.ndarray) -> list[list]:
    """``[joint, start, length, error_mm, bound_mm]`` of every run the cleaner filled, from
    ``Motion.fill_errors`` or, for a C3D read back from disk, its ``MOCAPFIX`` group
    (error/bound None when not estimated)."""
    where = {motion.names[int(j)]: n for n, j in enumerate(keep)}
    out = []
    if motion.fill_errors:
        for name, entries in motion.fill_errors.items():
            for e in entries:
                if name in where and (len(e) < 6 or e[5]):
                    out.append([where[name], int(e[0]), int(e[1]), _finite(e[2]), _finite(e[3])])
        return out
    if motion.format == "c3d" and motion.source is not None:
        from mocapfix.formats.c3d import listed_fills
        for name, start, length, error, bound in listed_fills(motion):
            if name in where:
                out.append([where[name], start, length, error, bound])
    return out


class Layer:
    """One capture as drawn: its markers in metres, names, bones and fills."""

    def __init__(self, motion: Motion, label: str, role: str = "motion"):
        self.keep = _markers(motion)
        # a long take is drawn every k-th frame: its points are taken and scaled to metres
        # then (:meth:`metres_at`), not copied whole first (a 500,000-frame take: 0.8 GB)
        self._positions = motion.positions
        self._to_metres = float(motion.metres_per_unit or 1.0)
        self.frames = motion.positions.shape[0]
        self.names = [str(motion.names[j]) for j in self.keep]
        self.bones = _bones(motion, self.keep)
        self.fps = float(motion.fps) if motion.fps and motion.fps > 0 else 30.0
        self.label = label
        self.role = role
        self.fills = _fill_runs(motion, self.keep) if role == "after" else []
        self.flags: list[list[int]] = []       # [joint, start, length, kind]
        self.flag_kinds: list[str] = []
        #: Kinect tracking state / confidence (Inferred = 0.5): drawn as rings below 1
        conf = motion.confidence
        self._confidence = (None if motion.format != "kinect" or conf is None
                            or not (conf[:, self.keep] < 1).any() else conf)

    def metres_at(self, stride: int) -> np.ndarray:
        """(frames, markers, 3) positions in metres of every ``stride``-th frame."""
        return self._positions[::stride][:, self.keep] * self._to_metres

    def confidence_at(self, stride: int) -> np.ndarray | None:
        """The drawn points' confidence on every ``stride``-th frame (None: not drawn)."""
        return None if self._confidence is None else self._confidence[::stride][:, self.keep]


def _as_differences(codes: np.ndarray, base: np.ndarray) -> tuple[dict, int] | None:
    """A layer's codes as differences from ``base`` (its "after"), when that is smaller
    than the codes: ``delta`` (int8 per axis, where both are present and every axis moved
    by at most 127 steps; absent when no sample moved) plus ``diffIndex``/``diffValues``,
    the samples a delta cannot hold (flat index, codes). None when storing whole is
    smaller."""
    both = (codes[..., 0] != MISSING) & (base[..., 0] != MISSING)
    step = codes.astype(np.int32) - base
    small = both & (np.abs(step) <= 127).all(axis=2)
    moved = small & (step != 0).any(axis=2)
    other = np.flatnonzero(((codes != base).any(axis=2) & ~small).ravel()).astype("<u4")
    out = {"diffIndex": _b64(other), "diffValues": _b64(codes.reshape(-1, 3)[other])}
    size = _b64_len(other.size * 4) + _b64_len(other.size * 6)
    if moved.any():
        delta = np.where(small[..., None], step, 0).astype("i1")
        out["delta"] = _b64(delta)
        size += _b64_len(delta.nbytes)
    return (out, size) if size < _b64_len(codes.nbytes) else None


def _encode(layers: list[Layer], stride: int) -> tuple[list[dict], int]:
    """The layers' JSON at one frame stride, and the bytes of positions text it holds. A
    "before" layer followed by its "after" shares its quantisation grid and is stored as
    its differences from it when that is smaller."""
    out, size = [], 0
    for n, layer in enumerate(layers):
        pos = layer.metres_at(stride)
        entry = {"label": layer.label, "role": layer.role, "names": layer.names,
                 "bones": layer.bones, "fps": layer.fps / stride, "frames": int(pos.shape[0]),
                 "stride": stride, "fills": layer.fills, "flags": layer.flags,
                 "flagKinds": layer.flag_kinds}
        partner = None
        if layer.role == "before" and n + 1 < len(layers) and layers[n + 1].role == "after":
            partner = layers[n + 1]
        elif layer.role == "after" and n > 0 and layers[n - 1].role == "before":
            partner = layers[n - 1]
        other = None if partner is None else partner.metres_at(stride)
        origin, step = _box(pos, *([] if other is None else [other]))
        codes = quantise(pos, origin, step)
        entry.update(origin=origin.tolist(), step=step.tolist())
        confidence = layer.confidence_at(stride)
        if confidence is not None:
            level = np.rint(np.clip(np.nan_to_num(confidence), 0, 1) * 255)
            entry["confidence"] = _b64(level.astype("u1"))
            size += _b64_len(level.size)
        stored = None
        if partner is not None and layer.role == "before":
            stored = _as_differences(codes, quantise(other, origin, step))
        if stored is not None:
            entry.update(base=n + 1, **stored[0])
            size += stored[1]
        else:
            entry["positions"] = _b64(codes)
            size += _b64_len(codes.nbytes)
        out.append(entry)
    return out, size


def payload(layers: list[Layer], budget: int = DEFAULT_BUDGET) -> dict:
    """What the page reads: the layers at the smallest frame stride whose positions fit
    in ``budget`` bytes of text, the up axis and the budget."""
    # a lower bound: the layers stored whole (a "before" may shrink to its differences)
    whole = sum(_b64_len(l.frames * len(l.keep) * 6) for l in layers if l.role != "before")
    stride = max(1, math.ceil(whole / budget))
    while True:
        encoded, size = _encode(layers, stride)
        if size <= budget or all(l.frames <= stride for l in layers):
            break
        stride += 1
    main = layers[-1]
    return {"layers": encoded, "up": up_axis(main.metres_at(max(1, main.frames // 500))),
            "stride": stride, "budget": budget, "bytes": size}


def _json_for_script(data) -> str:
    """JSON safe inside a <script> element: no '<', '>' or '&' (so no '</script>' or
    '<!--' in a name can end it) and no raw line separators."""
    text = json.dumps(data, ensure_ascii=True, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def to_html(layers: list[Layer], title: str, budget: int = DEFAULT_BUDGET) -> str:
    """The page: template + script + data, all inline, in at most ``budget`` bytes when
    the names alone leave room for one frame."""
    page, script = _template("viewer.html"), _template("viewer.js")
    # what does not shrink with the frame stride: the names, bones, fills and the runs
    # judged wrong (a long take's report can list megabytes of them)
    text = _json_for_script([[l.names, l.bones, l.fills, l.flags, l.flag_kinds, l.label]
                             for l in layers])
    fixed = len(page) + len(script) + len(text) + 6 * len(title) + 2048
    data = payload(layers, max(budget - fixed, 1))
    data["budget"] = budget
    values = {"TITLE": html.escape(title), "SCRIPT": script, "DATA": _json_for_script(data)}
    # one pass, so a title holding "{{DATA}}" is not filled in
    return re.sub(r"\{\{(TITLE|SCRIPT|DATA)\}\}", lambda m: values[m.group(1)], page)


def _label(path) -> str:
    """The file's name; bytes that are not UTF-8 (held as surrogates) as U+FFFD."""
    return os.fsencode(Path(path).name).decode("utf-8", "replace") if path else "motion"


def single(motions: list[Motion], budget: int = DEFAULT_BUDGET) -> str:
    """A page playing each motion (several are overlaid, each its own colour)."""
    layers = [Layer(m, _label(m.path)) for m in motions]
    return to_html(layers, " + ".join(l.label for l in layers), budget)


def _add_flags(layer: Layer, step: str, cleaner: str, col, start, length) -> None:
    """One step's runs of samples judged wrong (``col`` indexing ``layer.keep``) as
    ``[joint, start, length, kind]``, kind indexing ``layer.flag_kinds`` (the steps)."""
    col = np.asarray(col, dtype=np.intp)
    if col.size:
        kind = len(layer.flag_kinds)
        layer.flag_kinds.append(step if cleaner in step else f"{step} ({cleaner})")
        layer.flags += np.column_stack([col, start, length, np.full(col.size, kind)]).tolist()


def _flag_runs(layer: Layer, records) -> None:
    """The samples each step judged wrong (flagged or replaced: ``StepRecord.outliers``)."""
    from mocapfix.core.gaps import runs

    for record in records:
        _add_flags(layer, record.step, record.cleaner, *runs(record.outliers[:, layer.keep]))


def _report_flags(layer: Layer, steps: list[dict]) -> None:
    """The same from a JSON report's steps (their ``judged_wrong`` runs, by point name);
    points the layer does not draw are passed over."""
    where = {name: n for n, name in enumerate(layer.names)}
    for step in steps:
        rows = [r for r in step.get("judged_wrong") or () if r[0] in where]
        if rows:
            _add_flags(layer, step["step"], step["cleaner"], [where[r[0]] for r in rows],
                       [r[1] for r in rows], [r[2] for r in rows])


REPORT_SUFFIX = ".report.json"


def report_files(path) -> tuple[Path, Path, dict]:
    """The input and output a clean report (``<output name>.report.json``) describes, and
    the report: the input is its ``file.path``, the output the file beside the report.
    A :class:`~mocapfix.core.errors.MocapfixError` naming what is gone when either is."""
    from mocapfix.core.errors import MocapfixError

    path = Path(path)
    try:
        report = json.loads(path.read_text(encoding="utf-8"))
        source = report["file"]["path"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise MocapfixError(f"{path}: not a readable mocapfix clean report ({exc})") from exc
    if not source:
        raise MocapfixError(f"{path}: the report names no input file (cleaned from memory)")
    before, after = Path(source), path.with_name(path.name[:-len(REPORT_SUFFIX)])
    gone = [f"{what} {p}" for what, p in (("input", before), ("output", after)) if not p.is_file()]
    if gone:
        raise MocapfixError(f"{path}: the files this report describes are gone (moved or "
                            f"deleted?): {', '.join(gone)}; view them by name instead")
    return before, after, report


def from_report(path, budget: int = DEFAULT_BUDGET, **read_options) -> str:
    """A page overlaying the input and output of a clean report, the samples each step
    judged wrong coloured by step as in the report's own viewer (:func:`embed`)."""
    from mocapfix.formats import read

    before_path, after_path, report = report_files(path)
    layers = _overlay(read(before_path, **read_options), read(after_path, **read_options))
    _report_flags(layers[1], report.get("steps") or [])
    return _overlay_page(layers, budget)


def before_after(before: Motion, after: Motion, budget: int = DEFAULT_BUDGET,
                 records=()) -> str:
    """A page overlaying a capture and its cleaned output. They must hold the same points
    and frames (a cleaned file does); otherwise use :func:`single`. ``records``: the
    pipeline's :class:`~mocapfix.pipeline.steps.StepRecord` list, when known (the clean
    report), colours the samples each step judged wrong by step."""
    layers = _overlay(before, after)
    _flag_runs(layers[1], records)
    return _overlay_page(layers, budget)


def _overlay(before: Motion, after: Motion) -> list[Layer]:
    if not comparable(before, after):
        raise ValueError("before and after differ in frames or point names: not a capture "
                         "and its cleaned output")
    return [Layer(before, "before: " + _label(before.path), "before"),
            Layer(after, "after: " + _label(after.path), "after")]


def _overlay_page(layers: list[Layer], budget: int) -> str:
    return to_html(layers, f"{layers[0].label[8:]} → {layers[1].label[7:]}", budget)


def comparable(a: Motion, b: Motion) -> bool:
    """True when ``b`` can be the cleaned output of ``a`` (same frames and point names)."""
    return a.n_frames == b.n_frames and list(a.names) == list(b.names)


def embed(before: Motion, after: Motion, records=(), budget: int = EMBED_BUDGET) -> str:
    """The viewer of a cleaned motion as an ``<iframe>`` for another page (the HTML report
    of ``clean``): its document inline in ``srcdoc``, sandboxed to scripts only, so it can
    neither reach the page around it nor the network."""
    page = (before_after(before, after, budget, records) if comparable(before, after)
            else single([after], budget))
    return ('<iframe class="mocapfix-view" title="3D view" sandbox="allow-scripts" '
            'style="width:100%;height:560px;border:1px solid #ccc" srcdoc="'
            + html.escape(page, quote=True) + '"></iframe>')
