"""Forward kinematics for hierarchical formats (BVH, ASF/AMC), vectorised over frames.

Both formats are described by one :class:`Rig`. Per joint ``j`` with parent ``p``::

    F_j   = F_p · pre_j · M_j(θ_j)                    (world orientation of j's frame)
    pos_j = pos_p + F_k · (offset_j  or  t_j)          k = j if offset_in_own_frame else p

``M_j`` is the product of elementary rotations about the axes in ``rot_axes[j]``, in
matrix-product order: ``"ZXY"`` means ``Rz(θz) · Rx(θx) · Ry(θy)`` (column vectors),
i.e. intrinsic rotations in the listed order — the BVH convention. ASF lists its DOFs
and ``axis ... XYZ`` in extrinsic order, so its reader reverses them (``XYZ`` → ``"ZYX"``).

BVH: ``pre`` is the identity and a joint's offset lives in its parent's frame.
ASF (Acclaim): with ``C_j`` the bone's ``axis`` matrix and ``L_j = C_j M_j C_j⁻¹`` the
local rotation, the global bone rotation is ``G_j = G_p L_j``. Writing ``F_j = G_j C_j``
gives ``F_j = F_p · (C_p⁻¹ C_j) · M_j``, so ``pre_j = C_p⁻¹ C_j``; the bone end is
``pos_p + length · G_j · direction = pos_p + F_j · (length · C_j⁻¹ · direction)``, an
offset in the bone's own frame.

Translation channels (``trans_columns``, -1 where absent) either add to the rest offset
(``trans_adds_offset`` True, ASF root and BVH root by convention) or replace it.
The loop is over joints (tens); every operation inside is over all frames at once.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

_AXIS_INDEX = {"X": 0, "Y": 1, "Z": 2}


def axis_rotation(axis: str, angles: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) about one principal axis by ``angles`` (radians)."""
    angles = np.asarray(angles, dtype=np.float64)
    c, s = np.cos(angles), np.sin(angles)
    out = np.zeros(angles.shape + (3, 3))
    i = _AXIS_INDEX[axis.upper()]
    j, k = (i + 1) % 3, (i + 2) % 3
    out[..., i, i] = 1.0
    out[..., j, j] = c
    out[..., k, k] = c
    out[..., j, k] = -s
    out[..., k, j] = s
    return out


def euler_to_matrix(axes: str, angles: np.ndarray) -> np.ndarray:
    """Product ``R_axes[0](angles[...,0]) · R_axes[1](...) · ...`` (radians).

    ``angles`` has shape (..., len(axes)). Returns (..., 3, 3). Right-multiplying by an
    elementary rotation about axis i only mixes columns j and k, so each factor costs two
    column updates instead of a batched 3×3 product.
    """
    angles = np.asarray(angles, dtype=np.float64)
    out = np.zeros(angles.shape[:-1] + (3, 3))
    out[..., 0, 0] = out[..., 1, 1] = out[..., 2, 2] = 1.0
    for n, axis in enumerate(axes):
        i = _AXIS_INDEX[axis.upper()]
        j, k = (i + 1) % 3, (i + 2) % 3
        c, s = np.cos(angles[..., n])[..., None], np.sin(angles[..., n])[..., None]
        col_j, col_k = out[..., :, j].copy(), out[..., :, k]
        out[..., :, j] = col_j * c + col_k * s
        out[..., :, k] = col_k * c - col_j * s
    return out


def descendants(parents: np.ndarray) -> list[np.ndarray]:
    """Per joint of a hierarchy ordered parents first, the joints below it (sorted): those
    whose positions its rotation moves."""
    below: list[list[int]] = [[] for _ in parents]
    for j in range(len(parents) - 1, -1, -1):     # children before their parents
        p = parents[j]
        if p >= 0:
            below[p] += [j, *below[j]]
    return [np.array(sorted(b), dtype=np.intp) for b in below]


def moved_by_rotation(rig) -> list[np.ndarray]:
    """Per joint of ``rig``, the joints its rotation moves: those below it and, where its
    offset is in its own frame (an ASF bone, whose joint is the bone's end), itself."""
    below = descendants(rig.parents)
    own = np.asarray(rig.offset_in_own_frame, bool)
    return [np.union1d(below[j], [j]).astype(np.intp) if own[j] else below[j]
            for j in range(rig.n_joints)]


def nearest_branch(angles: np.ndarray, reference: np.ndarray, degrees: bool = True) -> np.ndarray:
    """Shift each angle by whole turns to lie nearest ``reference`` (same shape), so that a
    re-decomposed rotation keeps the file's Euler branch and never jumps by 360°."""
    turn = 360.0 if degrees else 2.0 * np.pi
    return angles - turn * np.round((angles - reference) / turn)


def nearest_euler(angles: np.ndarray, reference: np.ndarray, degrees: bool = True) -> np.ndarray:
    """Three Tait–Bryan angles (..., 3) written as the equivalent triplet nearest
    ``reference``: of the two solutions of one rotation, (a, b, c) and
    (a + 180°, 180° − b, c + 180°), each shifted by whole turns (:func:`nearest_branch`),
    the one with the smaller summed distance to the reference. A decomposition returns
    the middle angle in [−90°, 90°]; a file whose channels sit on the other solution (CMU
    05_10 ``rfemur``, 60_10 ``root``) thus keeps its values when the rotation is unchanged.
    Where the reference is NaN the principal solution is kept."""
    half = 180.0 if degrees else np.pi
    angles = np.asarray(angles, dtype=np.float64)
    reference = np.asarray(reference, dtype=np.float64)
    ref = np.where(np.isnan(reference), angles, reference)
    first = nearest_branch(angles, ref, degrees)
    alt = angles + np.array([half, 0.0, half])
    alt[..., 1] = half - angles[..., 1]
    second = nearest_branch(alt, ref, degrees)
    use = np.abs(second - ref).sum(axis=-1) < np.abs(first - ref).sum(axis=-1)
    return np.where(use[..., None], second, first)


def matrix_to_euler(axes: str, matrices: np.ndarray) -> np.ndarray:
    """Inverse of :func:`euler_to_matrix` for three distinct axes (Tait–Bryan).

    Returns angles (..., 3) in radians with the middle angle in [-π/2, π/2].
    """
    if len(axes) != 3 or len(set(axes.upper())) != 3:
        raise ValueError(f"matrix_to_euler needs three distinct axes, got {axes!r}")
    i, j, k = (_AXIS_INDEX[a] for a in axes.upper())
    # parity of the permutation (i, j, k): +1 for cyclic XYZ/YZX/ZXY
    sign = 1.0 if (j - i) % 3 == 1 else -1.0
    R = np.asarray(matrices, dtype=np.float64)
    # For R = Ri(a) Rj(b) Rk(c):  R[i,k] = sign*sin(b)
    sb = np.clip(sign * R[..., i, k], -1.0, 1.0)
    b = np.arcsin(sb)
    a = np.arctan2(-sign * R[..., j, k], R[..., k, k])
    c = np.arctan2(-sign * R[..., i, j], R[..., i, i])
    # gimbal lock: cos(b) ~ 0 → put all of the residual rotation into a
    lock = np.abs(sb) > 1.0 - 1e-12
    if np.any(lock):
        c = np.where(lock, 0.0, c)
        a_lock = np.arctan2(sign * R[..., k, j], R[..., j, j])
        a = np.where(lock, a_lock, a)
    return np.stack([a, b, c], axis=-1)


@dataclass
class Rig:
    """The kinematic model of a BVH or ASF/AMC file; see the module docstring."""

    names: list[str]
    parents: np.ndarray
    offsets: np.ndarray
    rot_axes: list[str]
    rot_columns: list[list[int]]
    trans_columns: np.ndarray
    offset_in_own_frame: np.ndarray | None = None
    pre_rotation: np.ndarray | None = None
    trans_adds_offset: np.ndarray | None = None
    degrees: bool = True
    n_channels: int = field(default=0)

    def __post_init__(self):
        J = len(self.names)
        self.parents = np.asarray(self.parents, dtype=np.intp)
        self.offsets = np.asarray(self.offsets, dtype=np.float64).reshape(J, 3)
        self.trans_columns = np.asarray(self.trans_columns, dtype=np.intp).reshape(J, 3)
        if self.offset_in_own_frame is None:
            self.offset_in_own_frame = np.zeros(J, dtype=bool)
        if self.pre_rotation is None:
            self.pre_rotation = np.broadcast_to(np.eye(3), (J, 3, 3)).copy()
        if self.trans_adds_offset is None:
            self.trans_adds_offset = self.parents < 0
        for j, p in enumerate(self.parents):
            if p >= j:
                raise ValueError("rig joints must be ordered parents first")
        used = [c for cols in self.rot_columns for c in cols]
        used += [int(c) for c in self.trans_columns.ravel() if c >= 0]
        self.n_channels = max(self.n_channels, (max(used) + 1) if used else 0)

    @property
    def n_joints(self) -> int:
        return len(self.names)

    def local_rotations(self, channels: np.ndarray) -> np.ndarray:
        """``pre_j · M_j(θ_j)`` for every frame and joint: (T, J, 3, 3)."""
        channels = np.asarray(channels, dtype=np.float64)
        T = channels.shape[0]
        out = np.empty((T, self.n_joints, 3, 3))
        for j in range(self.n_joints):
            axes, cols = self.rot_axes[j], self.rot_columns[j]
            if axes:
                ang = channels[:, cols]
                if self.degrees:
                    ang = np.deg2rad(ang)
                out[:, j] = self.pre_rotation[j] @ euler_to_matrix(axes, ang)
            else:
                out[:, j] = self.pre_rotation[j]
        return out

    def local_offsets(self, channels: np.ndarray) -> np.ndarray:
        """The vector from each joint's parent to the joint in its carrier frame, per
        frame: the rest offset with translation channels added or substituted. (T, J, 3)."""
        channels = np.asarray(channels, dtype=np.float64)
        vec = np.broadcast_to(self.offsets, (channels.shape[0],) + self.offsets.shape).copy()
        for j in np.flatnonzero((self.trans_columns >= 0).any(axis=1)):
            tcols = self.trans_columns[j]
            has = tcols >= 0
            if self.trans_adds_offset[j]:
                vec[:, j, has] += channels[:, tcols[has]]
            else:
                vec[:, j, has] = channels[:, tcols[has]]
        return vec

    def forward(self, channels: np.ndarray, with_frames: bool = True):
        """World positions (T, J, 3) and frame orientations F (T, J, 3, 3) (None when
        ``with_frames`` is False)."""
        channels = np.asarray(channels, dtype=np.float64)
        if channels.ndim != 2 or channels.shape[1] < self.n_channels:
            raise ValueError(
                f"channels must be (T, >= {self.n_channels}), got {channels.shape}")
        vec = self.local_offsets(channels)
        # per-joint contiguous arrays: batched products on strided slices are several times slower
        frames: list[np.ndarray] = []
        pos: list[np.ndarray] = []
        for j in range(self.n_joints):
            p = self.parents[j]
            axes = self.rot_axes[j]
            if axes:
                ang = channels[:, self.rot_columns[j]]
                local = self.pre_rotation[j] @ euler_to_matrix(axes, np.deg2rad(ang) if self.degrees else ang)
            else:
                local = self.pre_rotation[j]
            if p < 0:
                frames.append(np.broadcast_to(local, (channels.shape[0], 3, 3)).copy())
                pos.append(np.ascontiguousarray(vec[:, j]))
                continue
            # joints without DOFs and an identity pre-rotation (End Sites) share the parent frame
            frames.append(frames[p] if (not axes and self._identity_pre[j]) else frames[p] @ local)
            carrier = frames[j] if self.offset_in_own_frame[j] else frames[p]
            pos.append(pos[p] + (carrier @ vec[:, j, :, None])[..., 0])
        return np.stack(pos, axis=1), (np.stack(frames, axis=1) if with_frames else None)

    @property
    def _identity_pre(self) -> np.ndarray:
        cached = getattr(self, "_identity_pre_cache", None)
        if cached is None or len(cached) != self.n_joints:
            cached = np.all(np.abs(self.pre_rotation - np.eye(3)) < 1e-15, axis=(1, 2))
            self._identity_pre_cache = cached
        return cached

    def positions(self, channels: np.ndarray) -> np.ndarray:
        return self.forward(channels, with_frames=False)[0]


def positions_in_chunks(rig: Rig, channels: np.ndarray, chunk: int = 4096) -> np.ndarray:
    """``rig.positions(channels)`` computed ``chunk`` frames at a time into one array:
    the same values (every frame's product is computed alone), without the orientation
    of every joint in every frame held at once (72 bytes a joint-frame)."""
    channels = np.asarray(channels, dtype=np.float64)
    if channels.ndim != 2 or len(channels) <= chunk:
        return rig.positions(channels)
    first = rig.positions(channels[:chunk])
    out = np.empty((len(channels), *first.shape[1:]))
    out[:chunk] = first
    for a in range(chunk, len(channels), chunk):
        out[a:a + chunk] = rig.positions(channels[a:a + chunk])
    return out
