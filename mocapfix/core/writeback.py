"""Rotation write-back: turn cleaned joint positions of a BVH or ASF/AMC motion back into
the channel values its file stores.

Bone offsets stay fixed. Walking the hierarchy from the root, each joint's frame is
rotated by the smallest world rotation that maps the bone vectors it carries onto the
cleaned ones: one bone → the minimal swing (the twist about the bone is the input's);
several bones → orthogonal Procrustes (Kabsch, weighted by bone length). The joint's
local rotation then follows from its parent's new frame, and is decomposed into the
joint's own Euler axes (restricted to its degrees of freedom where it has fewer than
three). The root translation comes from the cleaned root position. Forward kinematics of
the new channels gives the written positions; their distance to the cleaned positions is
the write-back residual. Channel values that move by less than ``keep_tol`` are kept
bit-identical, so untouched frames write back unchanged.

Everything is vectorised over frames; the loop is over joints.
"""
from __future__ import annotations

import numpy as np

from mocapfix.core.kinematics import Rig, euler_to_matrix, matrix_to_euler, nearest_branch, nearest_euler

_AXES = "XYZ"


def _minimal_rotation(u: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Smallest rotation taking direction u to direction w, (T, 3, 3) (Rodrigues)."""
    u = u / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-300)
    w = w / np.maximum(np.linalg.norm(w, axis=-1, keepdims=True), 1e-300)
    v = np.cross(u, w)
    c = np.einsum("ti,ti->t", u, w)
    K = np.zeros(u.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    # R = I + K + K²/(1+c); opposite vectors (c ≈ -1) are rotated by π about any normal
    denom = np.where(c > -1 + 1e-12, 1.0 + c, np.inf)
    R = np.eye(3) + K + (K @ K) / denom[..., None, None]
    flip = c <= -1 + 1e-12
    if flip.any():
        axis = np.cross(u[flip], np.eye(3)[np.argmin(np.abs(u[flip]), axis=-1)])
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        R[flip] = 2 * axis[:, :, None] * axis[:, None, :] - np.eye(3)
    return R


def _fit_rotation(u: np.ndarray, w: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """World rotation taking the bones ``u`` (T, K, 3) onto ``w``: Kabsch when the bones
    span a plane, else the minimal swing of the longest bone (collinear or single bones
    leave the twist undetermined, so the input's is kept)."""
    longest = int(np.argmax(weights))
    swing = _minimal_rotation(u[:, longest], w[:, longest])
    if np.count_nonzero(weights > 0) < 2:
        return swing
    R = _kabsch(u, w, weights)
    # planar test on the rest bones: the second singular value of the weighted bone set
    sv = np.linalg.svd(u * weights[None, :, None], compute_uv=False)
    degenerate = sv[:, 1] < 1e-6 * np.maximum(sv[:, 0], 1e-300)
    R[degenerate] = swing[degenerate]
    return R


def _kabsch(u: np.ndarray, w: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Rotation R minimising Σ_k weight_k ||R u_k − w_k||² for stacks (T, K, 3)."""
    H = np.einsum("k,tki,tkj->tij", weights, w, u)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.ones(U.shape[:-1])
    D[..., -1] = d
    return (U * D[..., None, :]) @ Vt


def decompose(axes: str, M: np.ndarray) -> np.ndarray:
    """Angles (radians) for the joint's axes (matrix-product order) best representing M.

    Three distinct axes: exact Tait–Bryan decomposition. Two: the missing axis is placed
    in the middle of a three-axis decomposition and dropped (exact whenever M is
    representable). One: the least-squares angle about that axis.
    """
    if len(axes) == 3:
        return matrix_to_euler(axes, M)
    if len(axes) == 2:
        missing = next(a for a in _AXES if a not in axes)
        full = matrix_to_euler(axes[0] + missing + axes[1], M)
        return full[..., [0, 2]]
    i = _AXES.index(axes)
    j, k = (i + 1) % 3, (i + 2) % 3
    return np.arctan2(M[..., k, j] - M[..., j, k], M[..., j, j] + M[..., k, k])[..., None]


def _refine_restricted(axes, ang, base, rest, w, weights, iterations: int = 8):
    """Gauss–Newton on the joint's own angles (fewer than three DOFs) so that its bones
    point as close as possible to the cleaned directions — a swing outside the joint's
    DOFs cannot be dropped afterwards without losing accuracy. Finite-difference
    Jacobian; all frames at once."""
    wts = np.sqrt(weights / max(weights.sum(), 1e-300))[None, :, None]
    w_unit = w / np.maximum(np.linalg.norm(w, axis=-1, keepdims=True), 1e-300)
    rest_unit = rest / np.maximum(np.linalg.norm(rest, axis=-1, keepdims=True), 1e-300)
    ok = np.isfinite(w_unit).all(axis=(1, 2))

    def residual(a):
        u = np.einsum("tab,tkb->tka", base @ euler_to_matrix(axes, a), rest_unit)
        return ((u - w_unit) * wts).reshape(len(a), -1)

    a = np.where(ok[:, None], ang, 0.0)
    w_unit = np.where(ok[:, None, None], w_unit, 0.0)
    h = 1e-6
    for _ in range(iterations):
        r = residual(a)
        Jac = np.stack([(residual(a + h * np.eye(len(axes))[n]) - r) / h
                        for n in range(len(axes))], axis=-1)
        JtJ = np.swapaxes(Jac, 1, 2) @ Jac + 1e-9 * np.eye(len(axes))
        step = np.linalg.solve(JtJ, np.einsum("tri,tr->ti", Jac, r)[..., None])[..., 0]
        a = a - step
    return np.where(ok[:, None], a, ang)


def _carried_bones(rig: Rig):
    """For each joint with rotation DOFs, the bones whose direction its rotation sets, as
    (bone joint k, P) with P the constant rotation taking k's local vector into the
    carrying joint's frame. A bone carried by a joint without DOFs (ASF hip joints, BVH
    ``CHANNELS 0``, End Sites' parents' children) is rigidly attached to the nearest
    ancestor that has them."""
    carriers = [[] for _ in range(rig.n_joints)]
    for k in range(rig.n_joints):
        if rig.parents[k] < 0:
            continue
        c = k if rig.offset_in_own_frame[k] else rig.parents[k]
        P = np.eye(3)
        while not rig.rot_axes[c] and rig.parents[c] >= 0:
            P = rig.pre_rotation[c] @ P
            c = rig.parents[c]
        if rig.rot_axes[c]:
            carriers[c].append((k, P))
    return carriers


def solve_channels(rig: Rig, channels: np.ndarray, target: np.ndarray,
                   keep_tol: float = 1e-6) -> np.ndarray:
    """New channel values whose FK best matches ``target`` positions (T, J, 3).

    ``channels`` are the original values (twist and untouched DOFs come from them).
    Frames/joints whose target is NaN keep their original rotation.
    """
    channels = np.asarray(channels, dtype=np.float64)
    out = channels.copy()
    T, J = channels.shape[0], rig.n_joints
    target = np.asarray(target, dtype=np.float64)
    frames: list[np.ndarray | None] = [None] * J
    placed = np.zeros((T, J, 3))             # positions of the new solution, joint by joint
    is_placed = np.zeros(J, dtype=bool)
    carriers = _carried_bones(rig)
    identity = np.broadcast_to(np.eye(3), (T, 3, 3))

    def place(k):
        if rig.parents[k] < 0:
            placed[:, k] = rig.local_offsets(out)[:, k]
        else:
            carrier = frames[k] if rig.offset_in_own_frame[k] else frames[rig.parents[k]]
            placed[:, k] = placed[:, rig.parents[k]] + (carrier @ local_vectors[:, k, :, None])[..., 0]
        is_placed[k] = True

    local_vectors = rig.local_offsets(channels)                    # (T, J, 3)
    for j in range(J):
        p = rig.parents[j]
        tcols = rig.trans_columns[j]
        if p < 0 and (tcols >= 0).any():       # root translation from the cleaned root position
            ok = np.isfinite(target[:, j]).all(axis=1)
            base = rig.offsets[j] if rig.trans_adds_offset[j] else np.zeros(3)
            for axis in np.flatnonzero(tcols >= 0):
                out[ok, tcols[axis]] = target[ok, j, axis] - base[axis]
        parent_frame = frames[p] if p >= 0 else identity
        if p >= 0 and not rig.offset_in_own_frame[j]:
            place(j)
        axes, cols = rig.rot_axes[j], rig.rot_columns[j]
        ang_old = channels[:, cols]
        to_rad = np.deg2rad if rig.degrees else np.asarray
        base = parent_frame @ rig.pre_rotation[j]
        current = base @ euler_to_matrix(axes, to_rad(ang_old)) if axes else base
        carried = carriers[j]
        if axes and carried:
            kids = [k for k, _ in carried]
            rest = np.stack([local_vectors[:, k] @ P.T for k, P in carried], axis=1)   # (T, K, 3)
            # aim each bone from where the new solution put its start (so errors do not add
            # up along the chain), or from the cleaned start when that is not placed yet
            origins = np.stack([placed[:, rig.parents[k]] if is_placed[rig.parents[k]]
                                else target[:, rig.parents[k]] for k in kids], axis=1)
            w = target[:, kids] - origins
            u = np.einsum("tab,tkb->tka", current, rest)
            lengths = np.linalg.norm(rest, axis=-1).mean(axis=0)
            valid = np.isfinite(w).all(axis=(1, 2)) & (lengths.max() > 0)
            if valid.any():
                R = _fit_rotation(u[valid], w[valid], lengths)
                M_new = np.swapaxes(base[valid] if base.ndim == 3 else base, -1, -2) @ (R @ current[valid])
                ang = decompose(axes, M_new)
                if len(axes) < 3:
                    ang = _refine_restricted(axes, ang, base[valid], rest[valid], w[valid], lengths)
                old = ang_old[valid]
                ang = np.rad2deg(ang) if rig.degrees else ang
                # of the equivalent Euler triplets, the one nearest the input values
                ang = (nearest_euler if len(axes) == 3 else nearest_branch)(ang, old, rig.degrees)
                ang = np.where(np.abs(ang - old) < keep_tol, old, ang)
                out[np.flatnonzero(valid)[:, None], cols] = ang
            current = base @ euler_to_matrix(axes, to_rad(out[:, cols]))
        frames[j] = np.ascontiguousarray(np.broadcast_to(current, (T, 3, 3)))
        if p < 0 or rig.offset_in_own_frame[j]:
            place(j)
    return out


def write_back(motion, keep_tol: float = 1e-6):
    """Channels, FK positions and per-joint residual (T, J) for a motion whose positions
    were cleaned while ``motion.channels`` still hold the values read from the file.
    When the positions already are the channels' forward kinematics, bit for bit (the
    rotation cleaners return both; nothing else moved a sample), the channels are kept as
    they are: solving would only re-derive them, to ``keep_tol`` at best."""
    rig = motion.rig
    fk = rig.positions(motion.channels)
    target = motion.positions
    if ((fk == target) | np.isnan(target)).all():
        channels, positions = np.array(motion.channels, dtype=np.float64), fk
    else:
        channels = solve_channels(rig, motion.channels, target, keep_tol)
        positions = rig.positions(channels)
    residual = np.linalg.norm(positions - target, axis=-1)
    return channels, positions, residual
