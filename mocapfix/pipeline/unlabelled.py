"""Unlabelled trajectories: points of an optical capture that are not markers of the marker
set, which the pipeline passes through instead of rebuilding.

An optical system reconstructs every reflection it sees. The trajectories its labelling
assigns to the marker set take the set's names; the others, when the export keeps them,
take a placeholder name and come and go as the tracker picks them up. Filled like markers
they became invented paths over the whole take, written as if measured; and they are no
donors: a filler rebuilding a named marker from them rebuilds it from noise.

Recognised (:meth:`Unlabelled.reasons`):

- **by name** (:data:`NAME_CONVENTIONS`, whole label, a subject prefix ``Subject:``
  allowed, the words in any case, the number required): Vicon ``*N`` (``*3``,
  ``Matt:*12``), Qualisys QTM ``Unidentified N``, OptiTrack Motive ``Unlabeled N``
  (``Unlabeled 1001``, ``Unlabeled:1001``, ``Unlabeled_1001``, ``Unlabeled1001``, and the
  British ``Unlabelled``);
- **by how little it is seen**: a point seen on at least one frame but on fewer than
  ``min_seen`` (default :data:`MIN_SEEN`, 10 %) of the frames of the take (the frames
  from the first to the last on which a marker is seen, as the report counts them). A
  point never seen is not caught: the ``never_seen`` rule of ``check`` and the clean
  report's grading report it.

The vendors' documentation for each naming convention, and what the rules catch on the
shared data: docs/configs.md, "Unlabelled trajectories are not markers".

Only for trajectory data: a motion whose points are the joints of a skeleton (a BVH/AMC
rig, a Kinect body: ``Motion.rig`` or ``Motion.skeleton`` set) has no unlabelled
trajectories. The decision is made here, on the Motion, not in a reader, so any reader
of marker data gets it.

Policy (:class:`Unlabelled`): by default such trajectories are not cleaned (not filled,
smoothed or flagged), are no donors for the fillers (the cleaners never see them, see
:mod:`mocapfix.pipeline.selection`), are written back as read and are neither graded by the clean
report nor judged by ``check``; the report and ``info`` list them with the reason. A
config's ``unlabelled: {clean: true}`` cleans them as markers again (a rules file's
``unlabelled: {judge: true}`` judges them); ``min_seen`` sets the seen-share threshold
(0 turns that rule off).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from mocapfix.core.errors import ConfigError
from mocapfix.core.gaps import take_frames

#: the words every reason starts with (:func:`is_unlabelled`)
UNLABELLED = "unlabelled trajectory"

#: default seen-share threshold: a point seen on fewer than this share of the take's frames
MIN_SEEN = 0.10

#: the vendors' names of unlabelled trajectories: (system and convention, pattern of the
#: label without its subject prefix)
NAME_CONVENTIONS = (
    ("Vicon *N name", re.compile(r"\*\d+")),
    ("QTM Unidentified N name", re.compile(r"unidentified[ _:]?\d+", re.IGNORECASE)),
    ("Motive Unlabeled N name", re.compile(r"unlabell?ed[ _:]?\d+", re.IGNORECASE)),
)


def name_convention(name: str) -> str | None:
    """The convention (e.g. "Vicon *N name") whose unlabelled-trajectory name ``name`` is,
    with or without a subject prefix (``Matt:*3``); None for any other name."""
    bare = name.strip()
    candidates = [bare] + ([bare.split(":", 1)[1]] if ":" in bare else [])
    for convention, pattern in NAME_CONVENTIONS:
        if any(pattern.fullmatch(c) for c in candidates):
            return convention
    return None


def is_unlabelled(why: str | None) -> bool:
    """Whether a reason :func:`mocapfix.pipeline.selection.not_cleaned` gives is this module's."""
    return bool(why) and why.startswith(UNLABELLED)


def holds_trajectories(motion) -> bool:
    """Whether ``motion``'s points are trajectories (marker data) rather than the joints of
    a skeleton (BVH/AMC rig, Kinect body), which are never unlabelled."""
    return motion.rig is None and motion.channels is None and motion.skeleton is None


@dataclass(frozen=True)
class Unlabelled:
    """What to do with unlabelled trajectories. ``clean`` (a config's ``clean``, a rules
    file's ``judge``): treat them as markers; ``min_seen``: the seen-share threshold
    (fraction of the take's frames, 0 turns the rule off)."""

    clean: bool = False
    min_seen: float = MIN_SEEN

    def reasons(self, motion, markers: np.ndarray) -> list[str | None]:
        """Per point, why it is an unlabelled trajectory (None: it is not, or this policy
        cleans them). ``markers`` (J,) bool: the points that are markers at all (not
        model outputs); the take and the seen shares are counted over them."""
        out: list[str | None] = [None] * motion.n_joints
        if self.clean or not holds_trajectories(motion) or not np.any(markers):
            return out
        for j in np.flatnonzero(markers):
            convention = name_convention(motion.names[j])
            if convention:
                out[j] = f"{UNLABELLED} ({convention})"
        missing = motion.missing
        span = take_frames(missing, markers)
        frames = span.stop - span.start
        seen = (~missing[span]).sum(axis=0)
        rare = markers & (seen > 0) & (seen < self.min_seen * frames)
        for j in np.flatnonzero(rare):
            if out[j] is None:
                out[j] = (f"{UNLABELLED} (seen on {seen[j]} of {frames} frames of the take, "
                          f"{100 * seen[j] / frames:.1f} % < {100 * self.min_seen:g} %)")
        return out

    @classmethod
    def parse(cls, raw, source: str, verb: str = "clean") -> "Unlabelled":
        """From a config's (``verb`` "clean") or a rules file's (``verb`` "judge")
        ``unlabelled:`` mapping; None or absent keys take the defaults. Errors name the
        file, the line and the key."""
        if raw is None:
            return cls()
        if not isinstance(raw, dict):
            raise ConfigError(f"{source}{_line(raw)}: 'unlabelled' must be a mapping "
                              f"({{{verb}: true|false, min_seen: 10 %}}), got {raw!r}")
        unknown = sorted((str(k) for k in raw if not str(k).startswith("__")
                          and k not in (verb, "min_seen")))
        if unknown:
            raise ConfigError(f"{source}: unlabelled{_line(raw, unknown[0])}: unknown key(s) "
                              f"{', '.join(map(repr, unknown))} (known: {verb}, min_seen)")
        clean = raw.get(verb, False)
        if not isinstance(clean, bool):
            raise ConfigError(f"{source}: unlabelled{_line(raw, verb)}: '{verb}' must be true "
                              f"or false, got {clean!r}")
        where = f"{source}: unlabelled{_line(raw, 'min_seen')}: min_seen"
        return cls(clean, _share(raw.get("min_seen", MIN_SEEN), where))

    def config(self, verb: str = "clean") -> dict:
        """The mapping :meth:`parse` reads back."""
        return {verb: self.clean, "min_seen": f"{100 * self.min_seen:g} %"}


def _line(raw, key=None) -> str:
    """`` (line N)`` of ``key`` in a mapping loaded with line marks (of the mapping
    without a key), or nothing."""
    if not isinstance(raw, dict):
        return ""
    line = (raw.get("__keylines__") or {}).get(key) if key is not None else None
    line = line or raw.get("__line__")
    return f" (line {line})" if line else ""


_PERCENT = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*%\s*$")


def _share(value, where: str) -> float:
    """A share of frames: a number in [0, 1) or a percentage text ("10 %")."""
    number = None
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        number = float(value)
    elif isinstance(value, str) and _PERCENT.match(value):
        number = float(_PERCENT.match(value).group(1)) / 100.0
    if number is None or not math.isfinite(number) or not 0.0 <= number < 1.0:
        raise ConfigError(f"{where} must be a share of the take's frames in [0, 1) or a "
                          f"percentage below 100 % (e.g. '10 %'; 0 turns the rule off), "
                          f"got {value!r}")
    return number
