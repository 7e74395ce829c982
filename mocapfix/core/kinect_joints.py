"""Built-in Kinect joint sets and their bone topologies (parent of every joint).

Four sets, each a list of joint names in the order the source stores them and a
``{joint: parent}`` map (``None`` for the root):

* ``kinect_v1`` -- Kinect for Windows SDK 1.x ``NUI_SKELETON_POSITION_INDEX`` order
  (20 joints, HipCenter ... FootRight); UTKinect-Action3D stores this order.
* ``kinect_v2`` -- Kinect SDK 2.0 ``JointType`` order (25 joints, SpineBase ...
  ThumbRight); the LabanotationSuite CSV stores this order. Bones follow the SDK
  BodyBasics sample: HandTip hangs off Hand, Thumb off Wrist.
* ``azure_kinect`` -- Azure Kinect Body Tracking ``k4abt_joint_id_t`` order (32 joints,
  PELVIS ... EAR_RIGHT) with the parents of Microsoft's "Azure Kinect body tracking
  joints" table (clavicles hang off SPINE_CHEST, thumbs off the wrists, face points off
  HEAD).
* ``msr_action3d`` -- MSR Action3D skeleton files: the same 20 body points as Kinect v1
  but stored in another order. The order is not written in the data files; it is the
  one implied by the bone list of the dataset's own ``drawskt.m`` viewer
  (``J = [20 1 2 1 8 10 2 9 11 3 4 7 7 5 6 14 15 16 17; 3 3 3 8 10 12 9 11 13 4 7 5 6
  14 15 16 17 18 19]``), named with Kinect v1 names. Which side is "left" is assumed
  (it matches the Kinect convention on the shared files: the "left" chain lies at
  smaller camera x, as in the Kinect v1/v2 files), not documented by the dataset.

Names from users' headed CSVs are matched loosely (case, ``_``/space/``.``/``-``
ignored, ``Left``/``L``/``Right``/``R`` as prefix or suffix), see :func:`match_joint_set`.
"""
from __future__ import annotations

import re

import numpy as np

from mocapfix.core.motion import Skeleton

KINECT_V1 = [
    "HipCenter", "Spine", "ShoulderCenter", "Head",
    "ShoulderLeft", "ElbowLeft", "WristLeft", "HandLeft",
    "ShoulderRight", "ElbowRight", "WristRight", "HandRight",
    "HipLeft", "KneeLeft", "AnkleLeft", "FootLeft",
    "HipRight", "KneeRight", "AnkleRight", "FootRight",
]
KINECT_V1_PARENTS = {
    "HipCenter": None, "Spine": "HipCenter", "ShoulderCenter": "Spine", "Head": "ShoulderCenter",
    "ShoulderLeft": "ShoulderCenter", "ElbowLeft": "ShoulderLeft", "WristLeft": "ElbowLeft",
    "HandLeft": "WristLeft",
    "ShoulderRight": "ShoulderCenter", "ElbowRight": "ShoulderRight", "WristRight": "ElbowRight",
    "HandRight": "WristRight",
    "HipLeft": "HipCenter", "KneeLeft": "HipLeft", "AnkleLeft": "KneeLeft", "FootLeft": "AnkleLeft",
    "HipRight": "HipCenter", "KneeRight": "HipRight", "AnkleRight": "KneeRight",
    "FootRight": "AnkleRight",
}

KINECT_V2 = [
    "SpineBase", "SpineMid", "Neck", "Head",
    "ShoulderLeft", "ElbowLeft", "WristLeft", "HandLeft",
    "ShoulderRight", "ElbowRight", "WristRight", "HandRight",
    "HipLeft", "KneeLeft", "AnkleLeft", "FootLeft",
    "HipRight", "KneeRight", "AnkleRight", "FootRight",
    "SpineShoulder", "HandTipLeft", "ThumbLeft", "HandTipRight", "ThumbRight",
]
KINECT_V2_PARENTS = {
    "SpineBase": None, "SpineMid": "SpineBase", "SpineShoulder": "SpineMid",
    "Neck": "SpineShoulder", "Head": "Neck",
    "ShoulderLeft": "SpineShoulder", "ElbowLeft": "ShoulderLeft", "WristLeft": "ElbowLeft",
    "HandLeft": "WristLeft", "HandTipLeft": "HandLeft", "ThumbLeft": "WristLeft",
    "ShoulderRight": "SpineShoulder", "ElbowRight": "ShoulderRight", "WristRight": "ElbowRight",
    "HandRight": "WristRight", "HandTipRight": "HandRight", "ThumbRight": "WristRight",
    "HipLeft": "SpineBase", "KneeLeft": "HipLeft", "AnkleLeft": "KneeLeft", "FootLeft": "AnkleLeft",
    "HipRight": "SpineBase", "KneeRight": "HipRight", "AnkleRight": "KneeRight",
    "FootRight": "AnkleRight",
}

AZURE_KINECT = [
    "PELVIS", "SPINE_NAVEL", "SPINE_CHEST", "NECK",
    "CLAVICLE_LEFT", "SHOULDER_LEFT", "ELBOW_LEFT", "WRIST_LEFT", "HAND_LEFT", "HANDTIP_LEFT",
    "THUMB_LEFT",
    "CLAVICLE_RIGHT", "SHOULDER_RIGHT", "ELBOW_RIGHT", "WRIST_RIGHT", "HAND_RIGHT",
    "HANDTIP_RIGHT", "THUMB_RIGHT",
    "HIP_LEFT", "KNEE_LEFT", "ANKLE_LEFT", "FOOT_LEFT",
    "HIP_RIGHT", "KNEE_RIGHT", "ANKLE_RIGHT", "FOOT_RIGHT",
    "HEAD", "NOSE", "EYE_LEFT", "EAR_LEFT", "EYE_RIGHT", "EAR_RIGHT",
]
AZURE_KINECT_PARENTS = {
    "PELVIS": None, "SPINE_NAVEL": "PELVIS", "SPINE_CHEST": "SPINE_NAVEL", "NECK": "SPINE_CHEST",
    "CLAVICLE_LEFT": "SPINE_CHEST", "SHOULDER_LEFT": "CLAVICLE_LEFT",
    "ELBOW_LEFT": "SHOULDER_LEFT", "WRIST_LEFT": "ELBOW_LEFT", "HAND_LEFT": "WRIST_LEFT",
    "HANDTIP_LEFT": "HAND_LEFT", "THUMB_LEFT": "WRIST_LEFT",
    "CLAVICLE_RIGHT": "SPINE_CHEST", "SHOULDER_RIGHT": "CLAVICLE_RIGHT",
    "ELBOW_RIGHT": "SHOULDER_RIGHT", "WRIST_RIGHT": "ELBOW_RIGHT", "HAND_RIGHT": "WRIST_RIGHT",
    "HANDTIP_RIGHT": "HAND_RIGHT", "THUMB_RIGHT": "WRIST_RIGHT",
    "HIP_LEFT": "PELVIS", "KNEE_LEFT": "HIP_LEFT", "ANKLE_LEFT": "KNEE_LEFT",
    "FOOT_LEFT": "ANKLE_LEFT",
    "HIP_RIGHT": "PELVIS", "KNEE_RIGHT": "HIP_RIGHT", "ANKLE_RIGHT": "KNEE_RIGHT",
    "FOOT_RIGHT": "ANKLE_RIGHT",
    "HEAD": "NECK", "NOSE": "HEAD", "EYE_LEFT": "HEAD", "EAR_LEFT": "HEAD",
    "EYE_RIGHT": "HEAD", "EAR_RIGHT": "HEAD",
}

MSR_ACTION3D = [
    "ShoulderLeft", "ShoulderRight", "ShoulderCenter", "Spine", "HipLeft", "HipRight",
    "HipCenter", "ElbowLeft", "ElbowRight", "WristLeft", "WristRight", "HandLeft", "HandRight",
    "KneeLeft", "KneeRight", "AnkleLeft", "AnkleRight", "FootLeft", "FootRight", "Head",
]

JOINT_SETS: dict[str, tuple[list[str], dict[str, str | None]]] = {
    "kinect_v2": (KINECT_V2, KINECT_V2_PARENTS),
    "kinect_v1": (KINECT_V1, KINECT_V1_PARENTS),
    "azure_kinect": (AZURE_KINECT, AZURE_KINECT_PARENTS),
    "msr_action3d": (MSR_ACTION3D, KINECT_V1_PARENTS),
}

#: spellings seen in the wild for the same joint (after normalisation)
_EXTRA_ALIASES = {"spinenaval": "spinenavel"}


def normalise_name(name: str) -> str:
    """Lower case, separators removed: ``"SPINE_BASE"``, ``"Spine Base"`` -> ``"spinebase"``."""
    key = re.sub(r"[\s_.\-:]+", "", name.strip().lower())
    return _EXTRA_ALIASES.get(key, key)


def _variants(name: str) -> set[str]:
    """Normalised spellings of a built-in joint name (``ShoulderLeft``, ``LShoulder``...)."""
    key = normalise_name(name)
    out = {key}
    for side, short in (("left", "l"), ("right", "r")):
        if key.endswith(side) and len(key) > len(side):
            body = key[: -len(side)]
            out |= {body + short, side + body, short + body}
    return out


def _lookup(set_names: list[str]) -> dict[str, str]:
    table = {}
    for name in set_names:
        for variant in _variants(name):
            table.setdefault(variant, name)
    return table


_LOOKUPS = {key: _lookup(names) for key, (names, _) in JOINT_SETS.items()}


def skeleton_for(set_name: str) -> Skeleton:
    """The Skeleton of a built-in set in its own storage order."""
    names, parents = JOINT_SETS[set_name]
    return Skeleton.from_names(names, parents)


def match_joint_set(names: list[str]) -> tuple[str, Skeleton] | None:
    """The built-in set that holds every one of ``names`` (loosely spelled), and the
    skeleton over those names in their given order.

    A joint whose built-in parent is absent hangs off its nearest present ancestor, so a
    file with a subset of a set still gets a connected topology. Returns None when no set
    holds all names (or when names repeat). Ties go to the set with fewer unused joints,
    then to the order of ``JOINT_SETS``.
    """
    if not names or len({normalise_name(n) for n in names}) != len(names):
        return None
    best = None
    for set_name, (set_names, parent_map) in JOINT_SETS.items():
        if set_name == "msr_action3d":
            continue  # same names as kinect_v1: match by name gives the same topology
        table = _LOOKUPS[set_name]
        canonical = [table.get(normalise_name(n)) for n in names]
        if any(c is None for c in canonical) or len(set(canonical)) != len(canonical):
            continue
        unused = len(set_names) - len(names)
        if best is None or unused < best[0]:
            best = (unused, set_name, canonical, parent_map)
    if best is None:
        return None
    _, set_name, canonical, parent_map = best
    return set_name, Skeleton(_parents_over_subset(canonical, parent_map))


def _parents_over_subset(canonical: list[str], parent_map: dict[str, str | None]) -> np.ndarray:
    index = {name: i for i, name in enumerate(canonical)}
    parents = np.full(len(canonical), -1, dtype=np.intp)
    for i, name in enumerate(canonical):
        ancestor = parent_map.get(name)
        for _ in range(len(parent_map)):  # bounded walk up the tree
            if ancestor is None or ancestor in index:
                break
            ancestor = parent_map.get(ancestor)
        parents[i] = index[ancestor] if ancestor in index else -1
    return parents
