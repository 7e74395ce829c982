"""Which markers a pipeline or one of its steps cleans: ``markers:`` and ``exclude:`` in a
config (exact names or shell-style glob patterns, ``*``, ``?``, ``[abc]``, matched
case-sensitively against the whole name, e.g. ``"Probe*"``, ``"*:C7"``), the points a
file says are not markers (``Motion.kinds``: C3D model outputs such as POINT:ANGLES),
which are never cleaned, and unlabelled trajectories (vendors' placeholder names, points
seen on a small share of the take: :mod:`mocapfix.pipeline.unlabelled`), which are not cleaned
unless the config says so.

Running a step on a selection hands the cleaner a Motion with only the selected columns
and writes its result back into the full motion; the rest is returned bit-identical. On a
BVH/AMC rig a joint's position hangs on its parents', so there the step runs on the whole
rig and the joints left out get their own channels back as they were
(:func:`keep_rig_joints`): their curves are untouched, and they move with their parents.
"""
from __future__ import annotations

from dataclasses import dataclass
from fnmatch import fnmatchcase

import numpy as np

from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion, Skeleton
from mocapfix.pipeline.unlabelled import Unlabelled, is_unlabelled

#: the unlabelled-trajectory policy of a caller that names none: not cleaned, not judged
DEFAULT_POLICY = Unlabelled()


@dataclass(frozen=True)
class Selection:
    """``markers`` (None = every marker) minus ``exclude``; patterns or names."""

    markers: tuple[str, ...] | None = None
    exclude: tuple[str, ...] = ()

    @classmethod
    def parse(cls, raw: dict, where: str) -> "Selection | None":
        """From a config mapping's ``markers``/``exclude`` keys (None when neither)."""
        if "markers" not in raw and "exclude" not in raw:
            return None
        out = {}
        for key in ("markers", "exclude"):
            value = raw.get(key)
            if value is None:
                continue
            if isinstance(value, str):
                value = [value]
            if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
                raise ConfigError(f"{where}: '{key}' must be a marker name, a glob pattern or a "
                                  f"list of them, got {value!r}")
            out[key] = tuple(value)
        return cls(out.get("markers"), out.get("exclude", ()))

    def mask(self, names: list[str]) -> np.ndarray:
        def hit(name, patterns):
            return any(fnmatchcase(name, p) for p in patterns)
        keep = np.array([self.markers is None or hit(n, self.markers) for n in names], bool)
        keep &= np.array([not hit(n, self.exclude) for n in names], bool)
        return keep

    def config(self) -> dict:
        out = {}
        if self.markers is not None:
            out["markers"] = list(self.markers)
        if self.exclude:
            out["exclude"] = list(self.exclude)
        return out


#: the reason :func:`not_cleaned` gives for a point a selection leaves out
EXCLUDED = "excluded by the config"
#: a step's ``info["skipped"]`` when its own ``markers:``/``exclude:`` select none of the
#: points the pipeline cleans in a file
NO_MARKER_SELECTED = "no marker selected"


def not_cleaned(motion: Motion, *selections: "Selection | None",
                unlabelled: Unlabelled = DEFAULT_POLICY) -> list[str | None]:
    """Per point, why the pipeline leaves it alone (None: it is cleaned): a model output
    the file lists (``"model output (force)"``), an unlabelled trajectory
    (``"unlabelled trajectory (Vicon *N name)"``, see :mod:`mocapfix.pipeline.unlabelled`; by the
    policy ``unlabelled``) or a point a given ``markers:``/``exclude:`` selection leaves
    out. The report grades only the points cleaned."""
    out: list[str | None] = [None] * motion.n_joints
    for sel in selections:
        if sel is not None:
            for j in np.flatnonzero(~sel.mask(motion.names)):
                out[j] = EXCLUDED
    markers = np.ones(motion.n_joints, bool)
    if motion.kinds is not None:
        markers = np.array([kind == "marker" for kind in motion.kinds], bool)
    for j, why in enumerate(unlabelled.reasons(motion, markers)):
        out[j] = why or out[j]
    if motion.kinds is not None:
        for j, kind in enumerate(motion.kinds):
            if kind != "marker":
                out[j] = f"model output ({kind})"
    return out


def moved_channels(before: Motion, after: Motion) -> bool:
    """Whether a step's output ``after`` on a rig is its channels' forward kinematics (a
    rotation step: it changed channels) rather than cleaned positions the channels do not
    follow yet (a position step)."""
    ch = before.channels if after.channels is None else after.channels
    target = after.positions
    return bool(((before.rig.positions(ch) == target) | np.isnan(target)).all())


def keep_rig_joints(before: Motion, after: Motion, excluded: np.ndarray,
                    channel_step: bool | None = None) -> Motion:
    """``after`` (a step's output on the whole rig of ``before``) with the rotation and
    translation channels of the joints ``excluded`` (J,) bool as ``before`` has them. A
    joint's position is its parents' business: an excluded joint keeps its own channels,
    not its place. A step that cleaned positions is written back into channels first
    (:func:`mocapfix.core.writeback.solve_channels`, as the pipeline's end does), so that the
    rotations of the other joints are the step's. The excluded joints and the joints below
    them take the positions of those channels; every other joint keeps the positions the
    step gave it. Samples the step flagged (made missing) stay missing on every joint,
    excluded ones included: they are the evidence of a glitch in a joint above (a wrist
    thrown off by its elbow's rotation), which the steps after it fill and the pipeline's
    end writes back (then puts the excluded joints' channels back). ``channel_step``:
    :func:`moved_channels` of the step, if already known."""
    from mocapfix.core.writeback import solve_channels

    rig = before.rig
    excluded = np.asarray(excluded, bool)
    ch = np.array(before.channels if after.channels is None else after.channels, dtype=np.float64)
    target = after.positions
    if not (moved_channels(before, after) if channel_step is None else channel_step):
        ch = solve_channels(rig, ch, target)
    ch = own_channels(rig, ch, before.channels, excluded)
    below = excluded.copy()
    for j, p in enumerate(rig.parents):           # parents come first
        below[j] |= p >= 0 and below[p]
    positions = target.copy()
    positions[:, below] = rig.positions(ch)[:, below]
    flagged = np.isnan(target).any(axis=-1) & ~np.isnan(before.positions).any(axis=-1)
    positions[flagged] = np.nan
    return after.replace(channels=ch, positions=positions)


def own_channels(rig, channels: np.ndarray, source: np.ndarray, excluded: np.ndarray) -> np.ndarray:
    """``channels`` with the rotation and translation columns of the joints ``excluded``
    (J,) bool taken from ``source``."""
    out = np.array(channels, dtype=np.float64)
    for j in np.flatnonzero(excluded):
        cols = [int(c) for c in rig.rot_columns[j]] + [int(c) for c in rig.trans_columns[j] if c >= 0]
        out[:, cols] = source[:, cols]
    return out


def take(motion: Motion, cols: np.ndarray) -> Motion:
    """The Motion of the points ``cols`` (J,) bool only (not for a BVH/AMC rig, whose
    positions are tied to every joint: :func:`keep_rig_joints`)."""
    if motion.rig is not None or motion.channels is not None:
        raise ConfigError(f"{motion.path or 'motion'}: a {motion.format} rig's joints cannot "
                          "be taken apart (its positions hang on every joint)")
    idx = np.flatnonzero(cols)
    skeleton = None
    if motion.skeleton is not None:
        new = -np.ones(motion.n_joints, dtype=np.intp)
        new[idx] = np.arange(len(idx))
        parents = [int(new[p]) if p >= 0 else -1 for p in motion.skeleton.parents[idx]]
        bones = [(int(new[a]), int(new[b])) for a, b in motion.skeleton.bones
                 if new[a] >= 0 and new[b] >= 0]
        skeleton = Skeleton(np.array(parents, dtype=np.intp), bones)
    return motion.replace(
        positions=motion.positions[:, idx].copy(), names=[motion.names[i] for i in idx],
        confidence=None if motion.confidence is None else motion.confidence[:, idx].copy(),
        kinds=None if motion.kinds is None else [motion.kinds[i] for i in idx],
        skeleton=skeleton)


def without_unlabelled(motion: Motion) -> tuple[Motion, list[str]]:
    """``motion`` without the trajectories the default policy finds unlabelled, and their
    names: the truth a benchmark measures methods against (no pipeline cleans them by
    default, so an error there would measure the policy, not a method). ``motion`` itself
    when it has none."""
    drop = np.array([is_unlabelled(w) for w in not_cleaned(motion)], bool)
    if not drop.any():
        return motion, []
    return take(motion, ~drop), [n for n, d in zip(motion.names, drop) if d]


def put(motion: Motion, cols: np.ndarray, part: Motion) -> Motion:
    """``motion`` with the points ``cols`` replaced by ``part`` (from :func:`take`)."""
    idx = np.flatnonzero(cols)
    positions = motion.positions.copy()
    positions[:, idx] = part.positions
    confidence = None if motion.confidence is None else motion.confidence.copy()
    if part.confidence is not None:
        if confidence is None:
            confidence = (~motion.missing).astype(np.float64)
        confidence[:, idx] = part.confidence
    return motion.replace(positions=positions, confidence=confidence,
                          notes=list(part.notes))
