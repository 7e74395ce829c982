"""Cleaning a long take in overlapping windows, so that the cleaners' working memory is
set by a budget and not by the length of the take.

A take longer than its window is cut at nominal frames ``c_k = k · frames``; window ``k``
is cleaned on frames ``[c_k − overlap, c_{k+1} + overlap)`` and gives the output of the
frames between its two cuts. The cut is made per point, at the frame nearest to ``c_k``
within ``overlap / 2`` where the point is seen on both sides (:func:`point_cuts`), so a gap
shorter than that lies whole in one window, with at least ``overlap / 2`` frames of its
own take around it; only a gap spanning the whole search range is cut (each window fills
its side, as it would a gap at the end of a take). Smoothers and outlier tests then see
``overlap`` frames past every frame they give, which their supports (a fraction of a
second) never reach; methods that estimate something from the whole take (a subspace, a
noise level, the fill-error calibration) estimate it per window, and that difference is
measured, not assumed away (``benchmarks/long_takes.py`` compares windowed and whole-take
outputs).

A take with cuts (:mod:`mocapfix.pipeline.cuts`: frames where it jumps as a whole, as one
take ends and another begins) is cut there with no overlap, each of its takes cleaned on
its own (and in windows, when longer than one): :func:`pieces`.

What the steps record is put together frame by frame as the output is (the per-sample
masks of :class:`~mocapfix.pipeline.steps.StepRecord`); their ``info`` is merged
(:func:`merge_info`): frame-numbered entries keep the window that gave the frame, counts
are added (overlaps counted in each window that saw them: ``windows`` says how many ran).

The window comes from the config's ``memory_budget`` (:func:`window_for`).
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from mocapfix.cleaners.base import FILL_ERRORS, REJECTED_FILLS, REPLACED_FRAMES, shift_frames
from mocapfix.core.errors import ConfigError

#: the default memory budget of one clean
DEFAULT_MEMORY_BUDGET = "1 GB"
#: the cleaners' working memory per sample of a window, default pipeline (bytes; the peak
#: of a whole 5,000-frame clean over its samples, ``benchmarks/long_takes.py``: 300–600)
WORKING_BYTES_PER_SAMPLE = 800
#: what the whole take costs per sample besides (bytes), in deciding whether a take is
#: cleaned whole: the input and output positions, confidences and the steps' per-sample
#: records (an upper bound: the arrays themselves are 64 bytes a sample for a C3D, 96 for
#: a CMU BVH with its channels and write-back residual, with the input held; 32 and 52 with
#: it kept on disk as ``clean`` keeps it; the report's note counts them: :func:`over_budget`)
TAKE_BYTES_PER_SAMPLE = 150
#: context each side of a window (s), and the shortest window a budget may ask for (s)
OVERLAP_S = 6.0
MIN_WINDOW_S = 30.0

_BYTES = {"b": 1, "kb": 1e3, "mb": 1e6, "gb": 1e9, "kib": 1024, "mib": 1024 ** 2,
          "gib": 1024 ** 3}


def parse_memory_budget(value, where: str) -> int | None:
    """``memory_budget``: bytes as ``"1 GB"``, ``"512 MiB"``, a bare number of bytes, or
    None (no windowing: a take is cleaned whole whatever its length)."""
    if value is None:
        return None
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        number = float(value)
    else:
        m = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]+)?)\s*([KMG]i?B|B)\s*", str(value), re.IGNORECASE)
        if m is None:
            raise ConfigError(f"{where} = {value!r}: expected a size such as '1 GB' or "
                              "'512 MiB' (B, KB, MB, GB, KiB, MiB, GiB), or null")
        number = float(m.group(1)) * _BYTES[m.group(2).lower()]
    if not (64e6 <= number <= 2 ** 50):
        raise ConfigError(f"{where} = {value!r} is out of range (allowed: 64 MB to 1 PiB, or "
                          "null to clean every take whole)")
    return int(number)


@dataclass(frozen=True)
class Windows:
    """Windows of ``frames`` frames each, with ``overlap`` frames of context each side."""

    frames: int
    overlap: int

    def __post_init__(self):
        if self.frames < 1 or self.overlap < 2:
            raise ValueError(f"windows of {self.frames} frames with {self.overlap} of overlap")

    def cuts(self, T: int) -> list[int]:
        """The nominal cuts ``0 = c_0 < ... < c_n = T``; a last window shorter than the
        overlap joins the one before."""
        cuts = list(range(0, T, self.frames)) + [T]
        if len(cuts) > 2 and cuts[-1] - cuts[-2] < self.overlap:
            del cuts[-2]
        return cuts


def window_for(budget: int | None, n_frames: int, n_joints: int, fps: float) -> Windows | None:
    """The windows a take of ``n_frames × n_joints`` is cleaned in under ``budget`` bytes
    (None: it fits whole): half the budget for the cleaners' working memory of one window
    (with its overlap), at least :data:`MIN_WINDOW_S`; the other half for what the whole
    take costs (the budget cannot bound that: :func:`over_budget` says when it is more).
    The windows do not depend on the take's length, so time grows linearly with it."""
    if budget is None or n_frames * n_joints == 0:
        return None
    if n_frames * n_joints * (WORKING_BYTES_PER_SAMPLE + TAKE_BYTES_PER_SAMPLE) <= budget:
        return None
    overlap = max(round(OVERLAP_S * fps), 16)
    frames = int(budget / 2 // (n_joints * WORKING_BYTES_PER_SAMPLE)) - 2 * overlap
    frames = max(frames, round(MIN_WINDOW_S * fps), 2 * overlap)
    return None if frames >= n_frames else Windows(frames, overlap)


def over_budget(budget: int | None, held: int, input_on_disk: bool = False) -> str | None:
    """A note when the whole take's arrays held beside the windows (``held`` bytes: the
    output's, and the input's unless it was kept on disk) are more than half of
    ``budget``: windows bound the cleaners, not those."""
    if budget is None or held <= budget / 2:
        return None
    whose = "the cleaned take's arrays (its input kept on disk)" if input_on_disk \
        else "the take's own arrays (input and output)"
    return (f"{whose} need about {held / 1e9:.2g} GB, more than half the memory_budget "
            f"({budget / 1e9:g} GB): the windows bound the cleaners' memory, not the take's")


@dataclass(frozen=True)
class Pieces:
    """The pieces a take is cleaned in: piece ``k`` gives the frames between ``cuts[k]``
    and ``cuts[k + 1]`` (per point: :func:`point_cuts`) and is cleaned on those and
    ``overlaps`` frames each side (``overlaps[k]`` at cut ``k``: 0 at the take's ends and
    at the cuts of :mod:`mocapfix.pipeline.cuts`, where the take is two takes).
    ``windows``: the memory budget's windows the pieces were cut in (None: none)."""

    cuts: tuple
    overlaps: tuple
    windows: Windows | None = None

    def bounds(self, k: int) -> tuple[int, int]:
        """The frames piece ``k`` is cleaned on."""
        return self.cuts[k] - self.overlaps[k], self.cuts[k + 1] + self.overlaps[k + 1]


def pieces(n_frames: int, windows: Windows | None, take_cuts=()) -> Pieces | None:
    """The pieces of a take of ``n_frames``: the takes between ``take_cuts`` (no overlap),
    each cut in ``windows`` when longer than one (None: the take is one piece)."""
    edges = [0, *(int(c) for c in take_cuts), n_frames]
    cuts, overlaps = [0], [0]
    for a, b in zip(edges[:-1], edges[1:]):
        inner = windows.cuts(b - a)[1:-1] if windows is not None else []
        cuts += [a + c for c in inner] + [b]
        overlaps += [windows.overlap if inner else 0] * len(inner) + [0]
    if len(cuts) <= 2:
        return None
    return Pieces(tuple(cuts), tuple(overlaps),
                  windows if any(overlaps) else None)


def point_cuts(missing: np.ndarray, cuts: list[int], overlap) -> np.ndarray:
    """(len(cuts), J) the frame each point's output switches window at: for each inner
    nominal cut, the frame ``f`` nearest to it within ``overlap // 2`` with the point seen
    on frames ``f − 1`` and ``f`` (no gap spans the switch); the nominal cut where there is
    none. The first row is 0 and the last ``T``. ``overlap``: one for every cut, or one
    per cut (0: the cut itself)."""
    T, J = missing.shape
    out = np.empty((len(cuts), J), np.intp)
    out[0], out[-1] = 0, T
    overlaps = [overlap] * len(cuts) if np.isscalar(overlap) else list(overlap)
    for k, c in enumerate(cuts[1:-1], start=1):
        half = overlaps[k] // 2
        lo, hi = max(c - half, 1), min(c + half, T - 1)
        frames = np.arange(lo, hi + 1)
        ok = ~missing[lo - 1:hi] & ~missing[lo:hi + 1]               # (len(frames), J)
        distance = np.where(ok, np.abs(frames - c)[:, None], T + 1)
        best = distance.argmin(axis=0)
        out[k] = np.where(distance[best, np.arange(J)] <= T, frames[best], c)
    return out


def paste(whole: np.ndarray, piece: np.ndarray, lo: int, start: np.ndarray, stop: np.ndarray) -> None:
    """``whole[start[j]:stop[j], j] = piece[start[j] − lo:stop[j] − lo, j]`` for each point
    ``j`` (in place; ``piece`` holds frames ``lo:`` of ``whole``)."""
    for j, (a, b) in enumerate(zip(start.tolist(), stop.tolist())):
        if b > a:
            whole[a:b, j] = piece[a - lo:b - lo, j]


def _owned(frame: int, j: int | None, start: np.ndarray, stop: np.ndarray) -> bool:
    if j is None:
        return bool(start.min() <= frame < stop.max())
    return bool(start[j] <= frame < stop[j])


def _keep_frames(info: dict, lo: int, start: np.ndarray, stop: np.ndarray, index: dict) -> dict:
    """A window's frame-numbered ``info`` entries made whole-take frames
    (:func:`~mocapfix.cleaners.base.shift_frames`), keeping those that
    start in the frames the window gives (per point)."""
    shifted = shift_frames(info, lo)
    out = {}
    if shifted.get(REPLACED_FRAMES):
        out[REPLACED_FRAMES] = {name: [f for f in frames
                                       if _owned(f, index.get(name), start, stop)]
                                for name, frames in shifted[REPLACED_FRAMES].items()}
    for key in (REJECTED_FILLS, FILL_ERRORS):
        if shifted.get(key):
            out[key] = {name: [e for e in entries if _owned(e[0], index.get(name), start, stop)]
                        for name, entries in shifted[key].items()}
    if isinstance(shifted.get("swaps"), list):
        out["swaps"] = [s for s in shifted["swaps"]
                        if isinstance(s, dict) and "start" in s and "end" in s
                        and _owned(s["start"], None, start, stop)]
    return out


def merge_info(parts: list[dict]) -> dict:
    """The ``info`` of one step over the windows, from each window's (its frame-numbered
    entries already kept and shifted by :func:`_keep_frames`): lists and per-point lists
    joined, counts (ints) and per-point counts added, anything else kept when every
    window gave the same and listed per window (``{"per_window": [...]}``) when not."""
    out: dict = {}
    keys = list(dict.fromkeys(k for p in parts for k in p))
    for key in keys:
        values = [p[key] for p in parts if key in p]
        first = values[0]
        if all(isinstance(v, list) for v in values):
            out[key] = [x for v in values for x in v]
        elif all(isinstance(v, dict) for v in values):
            names = list(dict.fromkeys(n for v in values for n in v))
            out[key] = merge_info([{n: v[n] for n in names if n in v} for v in values])
        elif all(isinstance(v, int) and not isinstance(v, bool) for v in values) \
                and key not in _NOT_COUNTS:
            out[key] = sum(values)
        elif all(v == first for v in values):
            out[key] = first
        else:
            out[key] = {"per_window": values}
    return out


#: ints in the steps' ``info`` that are not counts of what a step did (not added)
_NOT_COUNTS = {"rank", "iterations", "points_not_cleaned", "constant_bones"}


def shifted_info(info: dict, lo: int, start: np.ndarray, stop: np.ndarray, names) -> dict:
    """One window's step ``info`` ready for :func:`merge_info`."""
    index: dict = {}
    for j, name in enumerate(names):
        index[name] = j if name not in index else None
    info = dict(info or {})
    info.update(_keep_frames(info, lo, start, stop, index))
    return info
