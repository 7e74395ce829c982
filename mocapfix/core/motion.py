"""The one in-memory type every reader produces, every cleaner transforms and every
writer consumes.

``Motion.positions`` is always present: (T, J, 3) float64 in the file's length unit,
NaN where a sample is missing. Hierarchical formats (BVH, ASF/AMC) also carry the
channel values they store (``channels``) and the rig that maps channels to positions
(``rig``, see :mod:`mocapfix.core.kinematics`); their positions are the rig's forward
kinematics. ``source`` is whatever the writer needs to reproduce the file and is never
touched by cleaners.

``fill_errors`` (optional) holds the estimated error and calibrated bound of each run of
samples a pipeline filled (:mod:`mocapfix.solvers.fill_error`).

``kinds`` (optional, one entry per joint) says what each point is when a file stores more
than markers: "marker", or e.g. "angle", "force", "moment", "power", "scalar" for the model
outputs a C3D keeps as points (POINT:ANGLES, ...). The pipeline cleans only markers and
passes the others through unchanged. None means every point is a marker or joint.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np


def missing_samples(positions: np.ndarray) -> np.ndarray:
    """(T, J) True where any coordinate of a (T, J, 3) sample is NaN: the three coordinate
    planes or-ed (``np.isnan(positions).any(axis=2)``, which reduces over an axis of 3, is
    6x slower)."""
    nan = np.isnan(positions)
    return nan[..., 0] | nan[..., 1] | nan[..., 2]


@dataclass
class Skeleton:
    """Topology of joints or markers: a parent per joint (-1 for roots).

    ``bones`` are the (parent, child) pairs whose length should stay constant; by default
    every parent link, but marker sets may list their own rigid pairs.
    """

    parents: np.ndarray
    bones: list[tuple[int, int]] | None = None

    def __post_init__(self):
        self.parents = np.asarray(self.parents, dtype=np.intp)
        if self.bones is None:
            self.bones = [(int(p), j) for j, p in enumerate(self.parents) if p >= 0]
        else:
            self.bones = [(int(a), int(b)) for a, b in self.bones]

    @property
    def bone_array(self) -> np.ndarray:
        """Bones as an (B, 2) integer array."""
        return np.asarray(self.bones, dtype=np.intp).reshape(-1, 2)

    @classmethod
    def from_names(cls, names: list[str], parent_names: dict[str, str | None]) -> "Skeleton":
        index = {n: i for i, n in enumerate(names)}
        parents = [index.get(parent_names.get(n) or "", -1) for n in names]
        return cls(np.array(parents))


@dataclass
class Motion:
    """A captured sequence. See the module docstring for the contract."""

    positions: np.ndarray
    names: list[str]
    fps: float
    units: str = "mm"
    metres_per_unit: float = 0.001
    format: str = "unknown"
    confidence: np.ndarray | None = None
    skeleton: Skeleton | None = None
    times: np.ndarray | None = None
    rig: Any = None
    channels: np.ndarray | None = None
    source: Any = None
    path: str | None = None
    notes: list[str] = field(default_factory=list)
    kinds: list[str] | None = None
    #: the error estimates of the fills a pipeline wrote, and of the gaps it left as too
    #: uncertain to fill, ``{name: [[start, length, error_mm, bound_mm, step, written,
    #: extrapolated], ...]}`` (set by :meth:`mocapfix.pipeline.steps.Pipeline.run`; error
    #: and bound None where a left gap had no estimate; ``extrapolated``: the estimate came
    #: from windows shorter than the gap; the report and the C3D writer list them)
    fill_errors: dict | None = None

    def __post_init__(self):
        self.positions = np.asarray(self.positions, dtype=np.float64)
        if self.positions.ndim != 3 or self.positions.shape[2] != 3:
            raise ValueError(f"positions must be (T, J, 3), got {self.positions.shape}")
        if len(self.names) != self.positions.shape[1]:
            raise ValueError(
                f"{len(self.names)} names for {self.positions.shape[1]} joints")
        if self.confidence is not None:
            self.confidence = np.asarray(self.confidence, dtype=np.float64)
            if self.confidence.shape != self.positions.shape[:2]:
                raise ValueError("confidence must be (T, J)")
        if self.channels is not None:
            self.channels = np.asarray(self.channels, dtype=np.float64)
        if self.kinds is not None and len(self.kinds) != len(self.names):
            raise ValueError(f"{len(self.kinds)} kinds for {len(self.names)} joints")

    # -- shape ---------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]

    @property
    def n_joints(self) -> int:
        return self.positions.shape[1]

    @property
    def duration(self) -> float:
        if self.times is not None and len(self.times) > 1:
            return float(self.times[-1] - self.times[0])
        return max(self.n_frames - 1, 0) / self.fps if self.fps > 0 else float("nan")

    @property
    def missing(self) -> np.ndarray:
        """(T, J) boolean: True where a sample is missing (any coordinate NaN)."""
        return missing_samples(self.positions)

    # -- copies ---------------------------------------------------------------
    def replace(self, **changes) -> "Motion":
        """A new Motion with some fields replaced; arrays not replaced are copied, so the
        result never aliases the original's mutable arrays."""
        out = dataclasses.replace(self, **changes)
        for name in ("positions", "confidence", "channels", "times"):
            if name not in changes and getattr(out, name) is not None:
                setattr(out, name, getattr(self, name).copy())
        if "notes" not in changes:
            out.notes = list(self.notes)
        return out

    def slice_frames(self, start: int | None = None, stop: int | None = None) -> "Motion":
        """Frames ``start:stop`` as a new Motion (for tests and benchmarks). The writer's
        ``source`` describes the whole file, so the slice has none."""
        span = slice(start, stop)
        pick = (lambda a: None if a is None else a[span].copy())
        return self.replace(positions=self.positions[span].copy(), confidence=pick(self.confidence),
                            channels=pick(self.channels), times=pick(self.times), source=None)

    def with_frames(self, start: int, part: "Motion") -> "Motion":
        """This Motion with frames ``start:start + part.n_frames`` taken from ``part`` (a
        :meth:`slice_frames` of it, cleaned): positions, confidence, channels and notes. A
        confidence the part gained (a filler's, for its fills) is kept, the frames around
        it taking 1 where a sample is seen and 0 where not (as
        :func:`mocapfix.pipeline.selection.put` does for points)."""
        span = slice(start, start + part.n_frames)

        def paste(whole, piece):
            if whole is None or piece is None:
                return None if whole is None else whole.copy()
            out = whole.copy()
            out[span] = piece
            return out
        confidence = self.confidence
        if confidence is None and part.confidence is not None:
            confidence = (~self.missing).astype(np.float64)
        return self.replace(positions=paste(self.positions, part.positions),
                            confidence=paste(confidence, part.confidence),
                            channels=paste(self.channels, part.channels),
                            notes=list(part.notes))

    def copy(self) -> "Motion":
        return self.replace()

    def index(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no joint or marker named {name!r}") from None
