"""Rotation channels of a BVH or ASF/AMC rig as continuous signals, and back
(never filter raw, wrapped Euler angles: a wrap from 179° to −179° is a 358° jump to a
filter; Grassia 1998, "Practical parameterization of rotations using the exponential map").

*Features* are a (T, L) array in degree-like units, one block per joint with rotation
DOFs, in rig order:

- a joint with three rotation DOFs → its unit quaternion (intrinsic order of the file),
  signs made continuous in time (q and −q are the same rotation; a flip would be a jump)
  and the whole track oriented so that its mean w ≥ 0, scaled by 360/π: a small rotation
  by δ degrees moves the four components by at most δ, so thresholds in degrees apply;
- a joint with one or two DOFs → its angles in degrees, unwrapped in time.

:func:`from_features` turns features back into channel values, each angle shifted by
whole turns — and, for three-axis joints, as whichever of the two equivalent Euler
triplets is nearer — to the branch nearest a reference (the input channels), so a cleaned
file keeps its Euler branches. Translation channels are not features.
"""
from __future__ import annotations

import numpy as np

from mocapfix.core.kinematics import nearest_branch, nearest_euler

QUAT_SCALE = 360.0 / np.pi   # feature units per quaternion unit (≈ degrees for small angles)


def continuous_quaternions(q: np.ndarray) -> np.ndarray:
    """Flip signs of a (T, 4) quaternion track so consecutive observed samples have a
    non-negative dot product (the shortest path between equal rotations). NaN rows are
    skipped: the sample after a gap is compared with the last one before it."""
    q = np.array(q, dtype=np.float64)
    ok = np.flatnonzero(~np.isnan(q).any(axis=1))
    if len(ok) < 2:
        return q
    v = q[ok]
    dots = np.einsum("ti,ti->t", v[1:], v[:-1])
    flips = np.concatenate([[1.0], np.cumprod(np.where(dots < 0, -1.0, 1.0))])
    q[ok] = v * flips[:, None]
    return q


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (T, 4) quaternions, w first."""
    aw, ax, ay, az = a.T
    bw, bx, by, bz = b.T
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=1)


def euler_quaternions(axes: str, degrees: np.ndarray) -> np.ndarray:
    """(T, 4) unit quaternions (w first) of ``R_axes[0](a) · R_axes[1](b) · R_axes[2](c)``
    (intrinsic order, the rig's convention) for angles (T, 3) in degrees."""
    half = np.deg2rad(degrees) / 2.0
    out = None
    for n, axis in enumerate(axes.upper()):
        q = np.zeros((len(degrees), 4))
        q[:, 0] = np.cos(half[:, n])
        q[:, 1 + "XYZ".index(axis)] = np.sin(half[:, n])
        out = q if out is None else _qmul(out, q)
    return out


def layout(rig) -> list[dict]:
    """The feature layout of a rig: per joint with rotation DOFs its name, axes, kind
    ("quat" or "angle") and number of features. Models are matched on this."""
    out = []
    for j, axes in enumerate(rig.rot_axes):
        if not axes:
            continue
        kind = "quat" if len(axes) == 3 else "angle"
        out.append({"joint": rig.names[j], "axes": axes, "kind": kind,
                    "size": 4 if kind == "quat" else len(axes)})
    return out


def noise_shape(rig, F: np.ndarray) -> np.ndarray:
    """(T, L) standard deviation of each feature's noise per unit of rotation noise.

    Rotation noise of δ degrees about an axis (isotropic: jitter on every Euler channel)
    moves a unit quaternion q by ½ q ⊗ (0, ω) — in the tangent space, orthogonal to q —
    so in feature units (360/π per quaternion unit) component i has variance
    δ² (1 − q_i²): the w of a joint near its rest pose barely moves at all. Angle features
    (one- and two-DOF joints) carry the noise as it is (1). NaN rows give 1."""
    F = np.asarray(F, dtype=np.float64)
    out = np.ones_like(F)
    n = 0
    for e in layout(rig):
        if e["kind"] == "quat":
            q = F[:, n:n + 4]
            with np.errstate(invalid="ignore", divide="ignore"):
                q = q / np.linalg.norm(q, axis=1, keepdims=True)
            out[:, n:n + 4] = np.where(np.isnan(q), 1.0, np.sqrt(np.clip(1.0 - q ** 2, 1e-4, 1.0)))
        n += e["size"]
    return out


def _joint_rows(rig):
    return [j for j, axes in enumerate(rig.rot_axes) if axes]


def to_features(rig, channels: np.ndarray) -> np.ndarray:
    """(T, L) features of the rotation channels (see the module docstring)."""
    channels = np.asarray(channels, dtype=np.float64)
    T = channels.shape[0]
    blocks = []
    for j in _joint_rows(rig):
        axes, cols = rig.rot_axes[j], rig.rot_columns[j]
        ang = channels[:, cols]
        deg = ang if rig.degrees else np.rad2deg(ang)
        if len(axes) == 3:
            q = np.full((T, 4), np.nan)
            ok = ~np.isnan(deg).any(axis=1)
            if ok.any():
                q[ok] = euler_quaternions(axes, deg[ok])
            q = continuous_quaternions(q)
            if np.nanmean(q[:, 0]) < 0:
                q = -q
            blocks.append(q * QUAT_SCALE)
        else:
            out = deg.copy()
            for c in range(out.shape[1]):
                ok = ~np.isnan(out[:, c])
                out[ok, c] = np.unwrap(out[ok, c], period=360.0)
            blocks.append(out)
    return np.concatenate(blocks, axis=1) if blocks else np.zeros((T, 0))


def from_features(rig, F: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Channels with the rotation channels of ``reference`` (T, C) replaced by those of the
    features F; angles on the branch nearest the reference. Translation channels are
    copied from the reference."""
    F = np.asarray(F, dtype=np.float64)
    out = np.array(reference, dtype=np.float64)
    n = 0
    for j in _joint_rows(rig):
        axes, cols = rig.rot_axes[j], rig.rot_columns[j]
        if len(axes) == 3:
            q = F[:, n:n + 4] / QUAT_SCALE
            n += 4
            norm = np.linalg.norm(q, axis=1, keepdims=True)
            ok = (norm[:, 0] > 1e-9) & np.isfinite(norm[:, 0])
            deg = np.full((len(F), 3), np.nan)
            if ok.any():
                qn = q[ok] / norm[ok]
                from scipy.spatial.transform import Rotation  # imported here: not loaded unless needed
                deg[ok] = Rotation.from_quat(qn[:, [1, 2, 3, 0]]).as_euler(axes.upper(), degrees=True)
        else:
            deg = F[:, n:n + len(axes)]
            n += len(axes)
        ang = deg if rig.degrees else np.deg2rad(deg)
        ref = out[:, cols]
        near = nearest_euler if len(axes) == 3 else nearest_branch
        new = near(ang, np.where(np.isnan(ref), ang, ref), rig.degrees)
        out[:, cols] = np.where(np.isnan(new), ref, new)
    return out
