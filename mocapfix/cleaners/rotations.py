"""Channel-space smoothing of the rotations a BVH or AMC file stores.

Position-space cleaners work on forward-kinematics joint positions and are written back
as rotations (:mod:`mocapfix.writeback`). This cleaner instead low-passes the channels
themselves, in a continuous representation (ALGORITHMS.md, "Rotations"): each joint with
three rotation DOFs is turned into unit quaternions (scipy ``Rotation``, intrinsic order
of the file), signs are made continuous (q and −q are the same rotation; a flip would be
a jump for the filter), the four components are filtered, renormalised and turned back
into the joint's Euler angles, each shifted by multiples of 360° to the branch nearest
the input — so no Euler wrap (±180°) and no quaternion sign flip is ever filtered across.
Joints with one or two DOFs are unwrapped and filtered as angles; translation channels
are filtered as they are. The filters are the shared NaN-safe kernels of
:mod:`mocapfix.solvers.segments`.

Marker data (no rotation channels) passes through unchanged. When an earlier step of the
pipeline changed the positions, they are first written back into the channels, so the
two kinds of cleaning compose.
"""
from __future__ import annotations

import numpy as np
from scipy import signal
from scipy.spatial.transform import Rotation

from mocapfix.cleaners import register
from mocapfix.cleaners.base import Cleaner, Param
from mocapfix.errors import ConfigError
from mocapfix.kinematics import nearest_branch
from mocapfix.motion import Motion
from mocapfix.solvers import segments
from mocapfix.writeback import solve_channels


def continuous_quaternions(q: np.ndarray) -> np.ndarray:
    """Flip signs of a (T, 4) quaternion track so consecutive samples have a positive dot
    product (the shortest path between equal rotations)."""
    dots = np.einsum("ti,ti->t", q[1:], q[:-1])
    flips = np.concatenate([[1.0], np.cumprod(np.where(dots < 0, -1.0, 1.0))])
    return q * flips[:, None]


@register
class RotationSmooth(Cleaner):
    """Low-pass the rotation (and translation) channels of BVH/AMC motions."""

    name = "rotation_smooth"
    summary = "smooth BVH/AMC rotation channels as continuous quaternions"
    params = (
        Param("method", "choice", "butterworth", choices=("butterworth", "gaussian")),
        Param("cutoff", "frequency", "6 Hz", "Butterworth cut-off", unit="Hz", low=0.0, low_open=True),
        Param("order", "int", 2, "Butterworth order (doubled by the zero-phase pass)", low=1, high=10),
        Param("sigma", "time", "2 frames", "Gaussian sigma", unit="s", low=0.0),
        Param("translations", "bool", True, "also smooth translation channels"),
    )

    def _filter(self, x: np.ndarray, motion: Motion) -> np.ndarray:
        if self["method"] == "gaussian":
            return segments.gaussian(x, self.frames("sigma", motion))
        cutoff = self.hertz("cutoff")
        if not cutoff < motion.fps / 2.0:
            raise ConfigError(f"{self.step}: cutoff {cutoff:g} Hz must be below the Nyquist "
                              f"frequency {motion.fps / 2.0:g} Hz of this motion")
        sos = signal.butter(self["order"], cutoff, fs=motion.fps, output="sos")
        pad = max(segments.default_padlen(sos), int(np.ceil(motion.fps / cutoff)))
        return segments.filtfilt(x, sos, padlen=pad)

    def _apply(self, motion: Motion):
        rig = motion.rig
        if rig is None or motion.channels is None or motion.n_frames < 3:
            return motion.copy(), {"skipped": "no rotation channels"}
        ch = motion.channels.copy()
        if not np.allclose(rig.positions(ch), motion.positions, rtol=0, atol=1e-9, equal_nan=False):
            # an earlier step cleaned positions: take them into the channels first
            ch = solve_channels(rig, ch, motion.positions)
        full = [j for j in range(rig.n_joints) if len(rig.rot_axes[j]) == 3]
        partial = [c for j in range(rig.n_joints) if 0 < len(rig.rot_axes[j]) < 3
                   for c in rig.rot_columns[j]]
        unit = 360.0 if rig.degrees else 2 * np.pi
        if full:
            quats = []
            for j in full:
                rot = Rotation.from_euler(rig.rot_axes[j].upper(), ch[:, rig.rot_columns[j]],
                                          degrees=rig.degrees)
                quats.append(continuous_quaternions(rot.as_quat()))
            smooth = self._filter(np.concatenate(quats, axis=1), motion)
            for n, j in enumerate(full):
                q = smooth[:, 4 * n:4 * n + 4]
                q = q / np.linalg.norm(q, axis=1, keepdims=True)
                cols = rig.rot_columns[j]
                ang = Rotation.from_quat(q).as_euler(rig.rot_axes[j].upper(), degrees=rig.degrees)
                ch[:, cols] = nearest_branch(ang, ch[:, cols], rig.degrees)
        if partial:
            unwrapped = np.unwrap(ch[:, partial], period=unit, axis=0)
            smooth = self._filter(unwrapped, motion)
            ch[:, partial] = nearest_branch(smooth, ch[:, partial], rig.degrees)
        trans = rig.trans_columns[rig.trans_columns >= 0]
        if self["translations"] and trans.size:
            ch[:, trans] = self._filter(ch[:, trans], motion)
        positions = rig.positions(ch)
        return motion.replace(channels=ch, positions=positions), {
            "joints_as_quaternions": len(full), "angle_channels": len(partial),
            "translation_channels": int(trans.size) if self["translations"] else 0}
