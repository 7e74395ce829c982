"""Body parts from joint and marker names: the five partlets of Feng et al. 2015 (§III-B,
Fig. 4: torso with head, left arm, right arm, left leg, right leg, with the joints at the
seams shared), the torso joints that fix each pose's frame, and name aliases so that a model
trained on one skeleton convention applies to another.

Conventions understood: CMU ASF (``lhumerus``, ``rfemur`` …), the CMU BVH conversions
(``LeftKnee``, ``RightWrist`` …), Kinect v1 / v2 / Azure Kinect and MSR Action3D joint names
(``ElbowLeft``, ``HipCenter``, ``SHOULDER_LEFT`` …), Mixamo and most marker sets whose names
carry a side (``L``/``R`` prefix or ``Left``/``Right``) and a body word.
"""
from __future__ import annotations

import re

import numpy as np

PARTLETS = ("torso", "left_arm", "right_arm", "left_leg", "right_leg")

_ARM = ("clavicle", "collar", "shoulder", "humerus", "uparm", "upperarm", "elbow", "radius",
        "forearm", "lowerarm", "wrist", "hand", "finger", "thumb", "handtip", "index", "pinky",
        "palm", "arm", "sho", "elb", "wra", "wrb", "fin", "upa", "frm")
_LEG = ("hipjoint", "hip", "femur", "thigh", "upleg", "upperleg", "knee", "tibia", "shin",
        "lowerleg", "leg", "ankle", "foot", "toe", "heel", "thi", "kne", "tib", "ank", "hee",
        "asi", "psi")
_FRAME_EXCLUDE = ("head", "neck", "skull", "nose", "eye", "ear", "jaw")

# CMU BVH conversions (cgspeed): BVH joint → the ASF bone whose end it sits at (checked on
# the rest offsets of cmu_cgspeed_131_01.bvh against 05.asf, bone by bone).
_CMU_BVH_TO_ASF = {
    "hips": "root", "lefthip": "lhipjoint", "leftknee": "lfemur", "leftankle": "ltibia",
    "lefttoe": "lfoot", "lefttoe_end": "ltoes", "righthip": "rhipjoint", "rightknee": "rfemur",
    "rightankle": "rtibia", "righttoe": "rfoot", "righttoe_end": "rtoes",
    # the conversion has two spine bones for the ASF's three: Chest2, where the collars
    # hang, is the thorax; Chest lies between lowerback and upperback and maps to neither
    "chest2": "thorax", "neck": "lowerneck", "head": "upperneck",
    # joints at a zero offset from another one share its position (and its ASF bone)
    "lhipjoint": "root", "rhipjoint": "root", "lowerback": "root", "lowerneck": "thorax",
    "leftcollar": "thorax", "rightcollar": "thorax", "lthumb": "lwrist", "rthumb": "rwrist",
    "head_end": "head", "leftshoulder": "lclavicle", "leftelbow": "lhumerus",
    "leftwrist": "lradius", "lhand": "lwrist", "lfingers": "lhand", "lfingers_end": "lfingers",
    "lthumb_end": "lthumb", "rightshoulder": "rclavicle", "rightelbow": "rhumerus",
    "rightwrist": "rradius", "rhand": "rwrist", "rfingers": "rhand", "rfingers_end": "rfingers",
    "rthumb_end": "rthumb",
}
# Kinect v1 / MSR Action3D / Azure Kinect → Kinect v2 names.
_KINECT_TO_V2 = {
    "hipcenter": "SpineBase", "spine": "SpineMid", "shouldercenter": "SpineShoulder",
    "pelvis": "SpineBase", "spine_navel": "SpineMid", "spine_chest": "SpineShoulder",
    "neck": "Neck", "head": "Head", "shoulder_left": "ShoulderLeft", "elbow_left": "ElbowLeft",
    "wrist_left": "WristLeft", "hand_left": "HandLeft", "handtip_left": "HandTipLeft",
    "thumb_left": "ThumbLeft", "shoulder_right": "ShoulderRight", "elbow_right": "ElbowRight",
    "wrist_right": "WristRight", "hand_right": "HandRight", "handtip_right": "HandTipRight",
    "thumb_right": "ThumbRight", "hip_left": "HipLeft", "knee_left": "KneeLeft",
    "ankle_left": "AnkleLeft", "foot_left": "FootLeft", "hip_right": "HipRight",
    "knee_right": "KneeRight", "ankle_right": "AnkleRight", "foot_right": "FootRight",
}
#: Kinect v2 joints as averages of CMU ASF bone ends (for models trained on CMU data).
ASF_TO_KINECT_V2 = {
    "SpineBase": ("root",), "SpineMid": ("upperback",), "Neck": ("lowerneck",),
    "Head": ("upperneck", "head"), "SpineShoulder": ("thorax",),
    "ShoulderLeft": ("lclavicle",), "ElbowLeft": ("lhumerus",), "WristLeft": ("lradius",),
    "HandLeft": ("lhand",), "HandTipLeft": ("lfingers",), "ThumbLeft": ("lthumb",),
    "ShoulderRight": ("rclavicle",), "ElbowRight": ("rhumerus",), "WristRight": ("rradius",),
    "HandRight": ("rhand",), "HandTipRight": ("rfingers",), "ThumbRight": ("rthumb",),
    "HipLeft": ("lhipjoint",), "KneeLeft": ("lfemur",), "AnkleLeft": ("ltibia",),
    "FootLeft": ("lfoot",), "HipRight": ("rhipjoint",), "KneeRight": ("rfemur",),
    "AnkleRight": ("rtibia",), "FootRight": ("rfoot",),
}
KINECT_V2_NAMES = tuple(ASF_TO_KINECT_V2)


def _plain(name: str) -> str:
    """Lower case, without a subject or rig prefix (``Matt:C7``, ``mixamorig:Hips``) and
    without the ``_End`` suffixes of BVH end sites."""
    n = name.rsplit(":", 1)[-1].strip().lower()
    while n.endswith("_end"):
        n = n[:-4]
    return n


def canonical_names(names: list[str]) -> list[str]:
    """The names a model file uses for ``names``. The convention is told from the whole
    list: CMU BVH conversions (they have ``Chest2`` and ``LeftHip``) become their ASF bones,
    Kinect v1/Azure/MSR skeletons (``HipCenter``, ``SPINE_NAVAL``, ``ElbowLeft`` …) their
    Kinect v2 names; anything else is kept. All lower case."""
    plain = [n.rsplit(":", 1)[-1].strip().lower() for n in names]
    present = set(plain)
    if {"chest2", "lefthip"} <= present:
        table = _CMU_BVH_TO_ASF
    elif present & {"hipcenter", "spinebase", "pelvis", "spine_navel", "elbowleft", "elbow_left"}:
        table = {k: v.lower() for k, v in _KINECT_TO_V2.items()}
    else:
        table = {}
    return [table.get(n, n) for n in plain]


def side(name: str) -> str | None:
    n = _plain(name)
    if "left" in n or n.endswith(("_l", ".l")) or n.startswith(("l_", "l.")):
        return "left"
    if "right" in n or n.endswith(("_r", ".r")) or n.startswith(("r_", "r.")):
        return "right"
    word = n[1:]
    if n[:1] in "lr" and any(word.startswith(w) for w in _ARM + _LEG):
        return "left" if n[0] == "l" else "right"
    return None


def limb(name: str) -> str | None:
    n = re.sub(r"(left|right)", "", _plain(name))
    n = n[1:] if side(name) and n[:1] in "lr" and not n.startswith(("leg",)) else n
    if any(w in n for w in ("hipjoint", "femur", "thigh", "upleg", "knee", "tibia", "shin",
                            "ankle", "foot", "toe", "heel")):
        return "leg"
    if any(w in n for w in ("clavicle", "collar", "shoulder", "humerus", "elbow", "radius",
                            "forearm", "wrist", "hand", "finger", "thumb", "arm")):
        return "arm"
    if "hip" in n or "leg" in n:
        return "leg"
    return None


def partlets(names: list[str], parents=None, mean_positions=None) -> dict[str, list[int]]:
    """Joint indices of the five partlets, seams included: each limb also holds the torso
    joint it hangs from (its topmost joint's parent, or the nearest torso joint on average).
    Raises ValueError when the names show no left/right arms and legs."""
    groups: dict[str, list[int]] = {p: [] for p in PARTLETS}
    for j, name in enumerate(names):
        s, l = side(name), limb(name)
        if s and l:
            groups[f"{s}_{l}"].append(j)
        else:
            groups["torso"].append(j)
    empty = [p for p in PARTLETS if not groups[p]]
    if empty:
        raise ValueError(f"no joints recognised for {', '.join(empty)}")
    torso = groups["torso"]
    for p in PARTLETS[1:]:
        members = set(groups[p])
        seam = None
        if parents is not None:
            tops = [j for j in groups[p] if parents[j] not in members]
            above = [int(parents[j]) for j in tops if parents[j] >= 0 and parents[j] in torso]
            seam = above[0] if above else None
        if seam is None and mean_positions is not None:
            first = groups[p][0]
            d = np.linalg.norm(mean_positions[torso] - mean_positions[first], axis=1)
            seam = torso[int(np.nanargmin(d))] if np.isfinite(d).any() else None
        if seam is not None:
            groups[p] = [seam] + groups[p]
    return groups


def frame_joints(names: list[str], groups: dict[str, list[int]]) -> list[int]:
    """Joints that fix a pose's frame (Feng 2015 §III-B-1 uses root, both femurs and the
    upper neck): the torso partlet without head and neck joints, plus the top joint of
    each leg (the hips)."""
    torso = [j for j in groups["torso"] if not any(w in _plain(names[j]) for w in _FRAME_EXCLUDE)]
    hips = []
    for p in ("left_leg", "right_leg"):
        own = [j for j in groups[p] if j not in groups["torso"]]
        if own:
            hips.append(own[0])
    return sorted(set(torso + hips))
