#!/usr/bin/env python3
"""Generate ``sample_data/``: a small procedural walker in all four formats, with the
defects mocapfix cleans — marker gaps, jitter and spikes in the C3D, shaky and partly
untracked joints in the Kinect CSV, noisy rotation channels in the BVH and AMC.

The files are written as text (BVH, ASF/AMC, Kinect CSV) and through py-c3d (C3D) by this
script itself — not by mocapfix's writers — so they are an independent check on the
readers. Deterministic (seeded): ``python scripts/make_sample_data.py`` reproduces them.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from mocapfix.core.kinematics import Rig

OUT = Path(__file__).resolve().parents[1] / "sample_data"
RNG_SEED = 20261122

# name, parent, offset (cm, Y up, Z forward)
JOINTS = [
    ("Hips", None, (0, 95, 0)),
    ("Spine", "Hips", (0, 10, 0)),
    ("Chest", "Spine", (0, 20, 0)),
    ("Neck", "Chest", (0, 20, 0)),
    ("Head", "Neck", (0, 10, 2)),
    ("HeadTop", "Head", (0, 16, 0)),
    ("LeftShoulder", "Chest", (17, 16, 0)),
    ("LeftElbow", "LeftShoulder", (0, -28, 0)),
    ("LeftWrist", "LeftElbow", (0, -25, 2)),
    ("LeftHandEnd", "LeftWrist", (0, -8, 0)),
    ("RightShoulder", "Chest", (-17, 16, 0)),
    ("RightElbow", "RightShoulder", (0, -28, 0)),
    ("RightWrist", "RightElbow", (0, -25, 2)),
    ("RightHandEnd", "RightWrist", (0, -8, 0)),
    ("LeftHip", "Hips", (9, -5, 0)),
    ("LeftKnee", "LeftHip", (0, -42, 0)),
    ("LeftAnkle", "LeftKnee", (0, -42, -1)),
    ("LeftToe", "LeftAnkle", (0, -7, 13)),
    ("LeftToeEnd", "LeftToe", (0, 0, 5)),
    ("RightHip", "Hips", (-9, -5, 0)),
    ("RightKnee", "RightHip", (0, -42, 0)),
    ("RightAnkle", "RightKnee", (0, -42, -1)),
    ("RightToe", "RightAnkle", (0, -7, 13)),
    ("RightToeEnd", "RightToe", (0, 0, 5)),
]
NAMES = [j[0] for j in JOINTS]
PARENT = {n: p for n, p, _ in JOINTS}
ENDS = {"HeadTop", "LeftHandEnd", "RightHandEnd", "LeftToeEnd", "RightToeEnd"}
ROTATING = [n for n in NAMES if n not in ENDS]


def walk_angles(t: np.ndarray) -> dict[str, np.ndarray]:
    """Joint angles (degrees, Z X Y per joint) of a procedural walk at times ``t`` (s)."""
    w = 2 * np.pi / 1.1                     # one gait cycle in 1.1 s
    z = np.zeros_like(t)
    a = {n: np.stack([z, z, z], axis=1) for n in ROTATING}

    def zxy(zr, xr, yr):
        return np.stack([zr, xr, yr], axis=1)

    for side, phase in (("Left", 0.0), ("Right", np.pi)):
        s = w * t + phase
        a[f"{side}Hip"] = zxy(3 * np.sin(s), -25 * np.sin(s), z)
        a[f"{side}Knee"] = zxy(z, 32 + 30 * np.sin(s - 1.2), z)
        a[f"{side}Ankle"] = zxy(z, -8 * np.sin(s - 0.6), z)
        a[f"{side}Shoulder"] = zxy((8 if side == "Left" else -8) + 0 * t, 20 * np.sin(s + np.pi), z)
        a[f"{side}Elbow"] = zxy(z, -(18 + 10 * np.sin(s + np.pi)), z)
    a["Hips"] = zxy(2 * np.sin(w * t), z, 5 * np.sin(w * t))
    a["Spine"] = zxy(-1.5 * np.sin(w * t), 3 + 0 * t, -4 * np.sin(w * t))
    a["Head"] = zxy(z, -3 * np.sin(2 * w * t), 2 * np.sin(w * t))
    return a


def build_rig() -> Rig:
    index = {n: i for i, n in enumerate(NAMES)}
    rot_axes, rot_cols, trans = [], [], []
    col = 3
    for n in NAMES:
        if n in ENDS:
            rot_axes.append(""), rot_cols.append([])
        else:
            rot_axes.append("ZXY"), rot_cols.append([col, col + 1, col + 2])
            col += 3
        trans.append([0, 1, 2] if n == "Hips" else [-1, -1, -1])
    return Rig(NAMES, [index[PARENT[n]] if PARENT[n] else -1 for n in NAMES],
               np.array([j[2] for j in JOINTS], float), rot_axes, rot_cols, trans)


def channels_at(t: np.ndarray) -> np.ndarray:
    ang = walk_angles(t)
    w = 2 * np.pi / 1.1
    root = np.stack([1.5 * np.sin(w * t), 2.0 * np.cos(2 * w * t), 120.0 * t], axis=1)  # 1.2 m/s
    return np.concatenate([root] + [ang[n] for n in ROTATING], axis=1)


def fmt(x: float) -> str:
    return f"{x:.4f}".rstrip("0").rstrip(".") if abs(x) > 5e-5 else "0"


# -- BVH ------------------------------------------------------------------------------

def write_bvh(path: Path, rng) -> None:
    fps, T = 60, 300
    t = np.arange(T) / fps
    ch = channels_at(t)
    ch[:, 3:] += rng.normal(0, 0.4, ch[:, 3:].shape)          # sensor jitter on rotations
    spikes = rng.choice(T, 3, replace=False)
    ch[spikes, 3 + 3 * ROTATING.index("LeftElbow") + 1] += 35.0  # three glitched frames
    lines = ["HIERARCHY"]

    def emit(name, depth):
        pad = "\t" * depth
        off = " ".join(f"{v:.2f}" for v in dict((n, o) for n, _, o in JOINTS)[name])
        kids = [n for n, p, _ in JOINTS if p == name]
        if name in ENDS:
            lines.extend([f"{pad}End Site", f"{pad}{{", f"{pad}\tOFFSET {off}", f"{pad}}}"])
            return
        head = "ROOT" if PARENT[name] is None else "JOINT"
        lines.extend([f"{pad}{head} {name}", f"{pad}{{", f"{pad}\tOFFSET {off}"])
        chans = ("CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
                 if head == "ROOT" else "CHANNELS 3 Zrotation Xrotation Yrotation")
        lines.append(f"{pad}\t{chans}")
        for k in kids:
            emit(k, depth + 1)
        lines.append(f"{pad}}}")

    emit("Hips", 0)
    lines += ["MOTION", f"Frames: {T}", f"Frame Time: {1 / fps:.6f}"]
    lines += [" ".join(fmt(v) for v in row) for row in ch]
    path.write_text("\n".join(lines) + "\n")


# -- ASF/AMC --------------------------------------------------------------------------

ASF_BONES = [  # bone name, parent bone, BVH joint whose offset it spans (child end)
    ("lowerback", "root", "Spine"), ("upperback", "lowerback", "Chest"),
    ("neck", "upperback", "Neck"), ("head", "neck", "Head"), ("headtop", "head", "HeadTop"),
    ("lclavicle", "upperback", "LeftShoulder"), ("lhumerus", "lclavicle", "LeftElbow"),
    ("lradius", "lhumerus", "LeftWrist"), ("lhand", "lradius", "LeftHandEnd"),
    ("rclavicle", "upperback", "RightShoulder"), ("rhumerus", "rclavicle", "RightElbow"),
    ("rradius", "rhumerus", "RightWrist"), ("rhand", "rradius", "RightHandEnd"),
    ("lhipjoint", "root", "LeftHip"), ("lfemur", "lhipjoint", "LeftKnee"),
    ("ltibia", "lfemur", "LeftAnkle"), ("lfoot", "ltibia", "LeftToe"), ("ltoes", "lfoot", "LeftToeEnd"),
    ("rhipjoint", "root", "RightHip"), ("rfemur", "rhipjoint", "RightKnee"),
    ("rtibia", "rfemur", "RightAnkle"), ("rfoot", "rtibia", "RightToe"), ("rtoes", "rfoot", "RightToeEnd"),
]
# which BVH joint's rotation drives each ASF bone (the joint at the bone's start)
ASF_DRIVER = {b: PARENT[j] for b, _, j in ASF_BONES}
ASF_NO_DOF = {"lhipjoint", "rhipjoint", "headtop", "lhand", "rhand", "ltoes", "rtoes", "lclavicle", "rclavicle"}
ASF_UNIT_CM = 2.54 / 0.45


def write_asf_amc(asf_path: Path, amc_path: Path, rng) -> None:
    offsets = {n: np.array(o, float) for n, _, o in JOINTS}
    lines = ["# procedural walker generated by mocapfix scripts/make_sample_data.py",
             ":version 1.10", ":name walker", ":units", "  mass 1.0", "  length 0.45", "  angle deg",
             ":documentation", "   Synthetic sample for the mocapfix README.",
             ":root", "   order TX TY TZ RX RY RZ", "   axis XYZ", "   position 0 0 0",
             "   orientation 0 0 0", ":bonedata"]
    for n, (bone, _, joint) in enumerate(ASF_BONES, start=1):
        off = offsets[joint]
        length = np.linalg.norm(off)
        d = off / length
        lines += ["  begin", f"     id {n}", f"     name {bone}",
                  f"     direction {d[0]:.6f} {d[1]:.6f} {d[2]:.6f}",
                  f"     length {length / ASF_UNIT_CM:.6f}", "     axis 0 0 0  XYZ"]
        if bone not in ASF_NO_DOF:
            lines += ["    dof rx ry rz", "    limits (-160.0 160.0)", "           (-70.0 70.0)",
                      "           (-60.0 60.0)"]
        lines.append("  end")
    lines.append(":hierarchy")
    lines.append("  begin")
    parents = {}
    for bone, parent, _ in ASF_BONES:
        parents.setdefault(parent, []).append(bone)
    for parent, kids in parents.items():
        lines.append(f"    {parent} {' '.join(kids)}")
    lines += ["  end", ""]
    asf_path.write_text("\r\n".join(lines))

    fps, T = 120, 240
    t = np.arange(T) / fps
    ang = walk_angles(t)
    ch = channels_at(t)
    out = ["#!OML:ASF walker.asf", ":FULLY-SPECIFIED", ":DEGREES"]
    for f in range(T):
        out.append(str(f + 1))
        # BVH root sits at the pelvis offset; the ASF root position is 0, so add it
        tx, ty, tz = (ch[f, :3] + offsets["Hips"]) / ASF_UNIT_CM
        rz, rx, ry = ang["Hips"][f]
        out.append(f"root {fmt(tx)} {fmt(ty)} {fmt(tz)} {fmt(rx)} {fmt(ry)} {fmt(rz)}")
        for bone, _, _ in ASF_BONES:
            if bone in ASF_NO_DOF:
                continue
            zr, xr, yr = ang[ASF_DRIVER[bone]][f] + rng.normal(0, 0.3, 3)
            out.append(f"{bone} {fmt(xr)} {fmt(yr)} {fmt(zr)}")
    amc_path.write_text("\r\n".join(out) + "\r\n")


# -- C3D ------------------------------------------------------------------------------

def write_c3d(path: Path, rng) -> list[str]:
    import c3d

    fps, T = 120, 600
    rig = build_rig()
    pos, frames = rig.forward(channels_at(np.arange(T) / fps))
    keep = [n for n in NAMES if n not in ("Spine", "Neck", "LeftToe", "RightToe")]
    markers = [pos[:, NAMES.index(n)] for n in keep]
    labels = [n.upper() for n in keep]
    # lateral markers: rigidly attached to thigh, shank and upper arm frames
    for name, joint, off in (("LTHI", "LeftHip", (6, -20, 0)), ("RTHI", "RightHip", (-6, -20, 0)),
                             ("LTIB", "LeftKnee", (5, -20, 2)), ("RTIB", "RightKnee", (-5, -20, 2)),
                             ("LUPA", "LeftShoulder", (5, -14, 0)), ("RUPA", "RightShoulder", (-5, -14, 0))):
        j = NAMES.index(joint)
        markers.append(pos[:, j] + np.einsum("tab,b->ta", frames[:, j], np.array(off, float)))
        labels.append(name)
    xyz = np.stack(markers, axis=1) * 10.0                      # cm → mm
    xyz = np.stack([xyz[..., 0], -xyz[..., 2], xyz[..., 1]], axis=-1)  # lab frame: Z up
    xyz += rng.normal(0, 0.6, xyz.shape)                        # camera noise
    M = xyz.shape[1]
    residual = np.full((T, M), 0.8)
    # occlusions: a hand marker behind the body, a knee marker, a short dropout
    for label, start, length in (("LEFTWRIST", 200, 60), ("LTIB", 380, 35),
                                 ("RIGHTHANDEND", 90, 8), ("HEADTOP", 450, 20)):
        residual[start:start + length, labels.index(label)] = -1.0
    for _ in range(6):                                           # single-frame spikes
        f, m = rng.integers(10, T - 10), rng.integers(M)
        xyz[f, m] += rng.normal(0, 1, 3) / np.sqrt(3) * 45.0
    writer = c3d.Writer(point_rate=float(fps), point_units="mm  ")
    writer.set_point_labels(labels)
    for f in range(T):
        pts = np.zeros((M, 5), np.float32)
        pts[:, :3] = np.where(residual[f, :, None] < 0, 0.0, xyz[f])
        pts[:, 3] = residual[f]
        pts[:, 4] = np.where(residual[f] < 0, 0, 0b0000111)
        writer.add_frames([(pts, np.zeros((0, 0), np.float32))])
    with open(path, "wb") as fh:
        writer.write(fh)
    return labels


# -- Kinect v2 CSV --------------------------------------------------------------------

KINECT_V2_FROM = [  # Kinect v2 joint order → generator joint (Kinect's left is the subject's left)
    "Hips", "Spine", "Neck", "Head", "LeftShoulder", "LeftElbow", "LeftWrist", "LeftHandEnd",
    "RightShoulder", "RightElbow", "RightWrist", "RightHandEnd", "LeftHip", "LeftKnee",
    "LeftAnkle", "LeftToe", "RightHip", "RightKnee", "RightAnkle", "RightToe", "Chest",
    "LeftHandEnd", "LeftWrist", "RightHandEnd", "RightWrist",   # tips/thumbs: placed below
]


def write_kinect(path: Path, rng) -> None:
    fps, T = 30, 150
    t = np.arange(T) / fps
    ch = channels_at(t)
    ch[:, 2] = 0.0                                              # walking on a treadmill
    ch[:, 3:6] += np.array([0.0, 0.0, 180.0])                   # facing the camera
    pos = build_rig().positions(ch) / 100.0                     # metres
    xyz = np.stack([pos[:, NAMES.index(n)] for n in KINECT_V2_FROM], axis=1)
    # hand tips beyond the hands, thumbs beside them (the walker has no fingers)
    for hand, wrist, tip, thumb, side in ((7, 6, 21, 22, 1.0), (11, 10, 23, 24, -1.0)):
        along = xyz[:, hand] - xyz[:, wrist]
        xyz[:, tip] = xyz[:, hand] + 0.8 * along
        xyz[:, thumb] = xyz[:, wrist] + 0.5 * along + np.array([0.03 * side, 0.0, 0.02])
    xyz = xyz + np.array([0.05, -0.95, 2.6])
    xyz += rng.normal(0, 0.006, xyz.shape)                      # depth-sensor jitter
    state = np.full((T, 25), 2)
    state[60:72, [7, 21, 22]] = 1                               # left hand inferred (occluded)
    state[95:101, 15] = 0                                        # left foot lost for 6 frames
    xyz[95:101, 15] = 0.0
    ticks = 89810293609 + np.round(np.arange(T) * 1e7 / fps).astype(np.int64)
    ticks = np.delete(ticks, 40)                                 # one dropped frame
    rows = []
    for f, tick in enumerate(ticks):
        cells = [str(int(tick))]
        for j in range(25):
            cells += [f"{v:.6g}" for v in xyz[f, j]] + [str(state[f, j])]
        rows.append(",".join(cells) + ",")
    path.write_text("\n".join(rows) + "\n")


def main() -> None:
    OUT.mkdir(exist_ok=True)
    rng = np.random.default_rng(RNG_SEED)
    write_bvh(OUT / "walk.bvh", rng)
    write_asf_amc(OUT / "walker.asf", OUT / "walker_01.amc", rng)
    write_c3d(OUT / "walk_markers.c3d", rng)
    write_kinect(OUT / "walk_kinect_v2.csv", rng)
    for p in sorted(OUT.iterdir()):
        print(f"{p.relative_to(OUT.parent)}  {p.stat().st_size} bytes")


if __name__ == "__main__":
    main()
