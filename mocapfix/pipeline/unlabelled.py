"""Unlabelled trajectories: points of an optical capture that are not markers of the marker
set, which the pipeline passes through instead of rebuilding.

An optical system reconstructs every reflection it sees. The trajectories its labelling
assigns to the marker set take the set's names; the others, when the export keeps them,
take a placeholder name and come and go as the tracker picks them up (a stray reflection,
a marker seen for a few frames). Filled like markers they became invented paths over the
whole take: a Vicon trial's five ``*N`` trajectories, each seen on one frame, were filled
over its 2.85 s (confidence 0.00), written with residual 0 so that every other tool reads
them as measured, and failed the file's grading although its 61 named markers were
complete. They are also no donors: a filler rebuilding a named marker from them rebuilds
it from noise.

Recognised (:meth:`Unlabelled.reasons`):

- **by name** (:data:`NAME_CONVENTIONS`, whole label, a subject prefix ``Subject:`` allowed):

  - Vicon ``*N`` (``*3``, ``Matt:*12``): Vicon names the trajectories its labelling left
    unlabelled ``*`` and a number. The HDM05 C3D files carry three (``*0``, ``*1``,
    ``*2`` in ``c3d/hdm05_HDM_mm_01-02_03_120.c3d`` of the shared data: exact copies of
    LFHD, CLAV and LFWT), which a public HDM05 loading script removes
    (``removeMarkers012``: "Remove markers *0, *1, *2 from the C3D struct");
    haripen/rmC3DPoints removes "all labels (with their data) labeled with prefix *" from
    C3D files with ezc3d for the same reason.
  - Qualisys QTM ``Unidentified N``: QTM's trajectory windows label what AIM did not
    identify "always Unidentified and Discarded followed by a sequential number"
    (docs.qualisys.com, QTM manual, *Data in Trajectory info windows*); its C3D export
    keeps them unless "exclude unidentified trajectories" is ticked (the export steps in
    Aza-Spearal/Automatic_3D-Trajectory_labeling, Builder/README.md). Discarded
    trajectories are not exported and are not matched.
  - OptiTrack Motive ``Unlabeled N``: Motive lists the markers no asset labelled as
    unlabeled (docs.optitrack.com, *Labels pane*) and gives each an id: public readers of
    Motive exports find them as ``Unlabeled:10081`` (take files), ``Unlabeled:140``
    (CSV columns, read by ``name.startswith('Unlabeled')``); Motive assigns a new id
    each time a stray marker reappears (ha5dzs/optitrack-motive-file-converter issue 4:
    "1000+ reported markers from a 6-marker set-up"). ``Unlabeled 1001``,
    ``Unlabeled:1001``, ``Unlabeled_1001`` and ``Unlabeled1001`` are matched (the
    separator differs between Motive's exports), as is the British ``Unlabelled``.

  The words are matched in any case; the number is required (a marker named
  ``Unlabeled`` alone is left to the seen-share rule).

- **by how little it is seen**: a point seen on at least one frame but on fewer than
  ``min_seen`` (default :data:`MIN_SEEN`, 10 %) of the frames of the take (the frames
  from the first to the last on which a marker is seen, as the report counts them).
  Rebuilt from so little, a trajectory is more model than measurement (the report's
  ``uncertain`` figure of such a fill is above 90 %). A point never seen is not caught: it
  is a marker of the set with no data at all (a marker that fell off, a probe point of
  another trial), which the ``never_seen`` rule of ``check`` and the clean report's
  grading are there to report.

  Measured on the 25 C3D files of the shared data (take frames, markers only): the rule
  catches one marker, ``Sternum`` of ``c3d/ktk_racing_full.c3d`` (seen on 21 of 700
  frames, 3.0 %). The next-least-seen markers that are seen at all are far above the
  threshold: ``LR_FME`` (17.8 %) and ``LR_FM5`` (17.9 %) of
  ``c3d/numediart_03_rolling.c3d``, then 34-46 % (numediart, ``c3d/ezc3d_BTS.c3d``'s
  ``r heel``, ``c3d/c3dorg_s28_dynamic.C3D``'s pelvis markers, ktk racing's ``NAR``).
  By name, only HDM05's ``*0``, ``*1``, ``*2`` match (each seen on every frame).

Only for trajectory data: a motion whose points are the joints of a skeleton (a BVH/AMC
rig, a Kinect body: ``Motion.rig`` or ``Motion.skeleton`` set) has no unlabelled
trajectories. Its tracker or solver reports every joint of its model by name, and a
joint missing most of the take is still a joint of the body, rebuilt from its bones. The
decision is made here, on the Motion, not in a reader, so any reader of marker data
(C3D now, TRC or vendor CSV later) gets it.

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
