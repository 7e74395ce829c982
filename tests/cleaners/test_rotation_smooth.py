"""Channel-space rotation smoothing: continuity of the representation and accuracy on
real BVH and AMC files with noisy rotation channels."""
from __future__ import annotations

import numpy as np
import pytest

from mocapfix.cleaners import build
from mocapfix.cleaners.rotations import continuous_quaternions
from mocapfix.core.kinematics import Rig
from mocapfix.core.motion import Motion
from conftest import shared


def test_quaternion_signs_made_continuous():
    q = np.tile([0.0, 0.0, 0.0, 1.0], (6, 1))
    q[2:4] *= -1
    out = continuous_quaternions(q)
    assert (out[:, 3] > 0).all()


def test_spinning_joint_crosses_the_euler_wrap_without_artefacts():
    """A root yawing steadily through ±180°: its channel jumps from 179° to -179°, yet the
    smoothed positions must follow the true circle (a filter on raw Euler values would swing
    through 0° at every wrap)."""
    T, fps = 400, 100.0
    yaw = np.linspace(0, 720, T)                             # two full turns
    wrapped = (yaw + 180) % 360 - 180
    ch = np.zeros((T, 6))
    ch[:, 3] = wrapped                                        # Y rotation of the root
    rig = Rig(["root", "arm"], [-1, 0], [[0, 0, 0], [100, 0, 0]], ["YXZ", ""],
              [[3, 4, 5], []], [[0, 1, 2], [-1, -1, -1]])
    motion = Motion(rig.positions(ch), ["root", "arm"], fps, rig=rig, channels=ch, format="bvh")
    out, info = build("rotation_smooth", cutoff="6 Hz").apply(motion)
    assert info["joints_as_quaternions"] == 1
    err = np.linalg.norm(out.positions - motion.positions, axis=-1)
    assert err.max() < 0.5          # a smooth 2-turn spin passes a 6 Hz filter nearly intact


def _noisy_copy(motion, deg, seed):
    rng = np.random.default_rng(seed)
    rig = motion.rig
    rot = [c for cols in rig.rot_columns for c in cols]
    ch = motion.channels.copy()
    ch[:, rot] += rng.normal(0, deg, (ch.shape[0], len(rot)))
    return motion.replace(channels=ch, positions=rig.positions(ch))


@pytest.mark.slow
@pytest.mark.parametrize("rel", ["bvh/cmu_cgspeed_131_03.bvh", "asfamc/05_01.amc"])
def test_noisy_rotation_channels_are_denoised(rel):
    clean = __import__("mocapfix").read(shared(rel))
    noisy = _noisy_copy(clean, 2.0, 1)
    out, _ = build("rotation_smooth", cutoff="6 Hz").apply(noisy)
    before = np.sqrt(np.mean(np.sum((noisy.positions - clean.positions) ** 2, -1)))
    after = np.sqrt(np.mean(np.sum((out.positions - clean.positions) ** 2, -1)))
    # 2° of white noise at 120 Hz is mostly above 6 Hz: the error must drop several-fold
    assert after < 0.4 * before, (before, after)
    assert np.array_equal(noisy.channels, _noisy_copy(clean, 2.0, 1).channels)  # input untouched


def test_follows_position_cleaning_of_an_earlier_step():
    """A position fix made before rotation_smooth must survive it (the channels are
    updated from the positions first)."""
    motion = __import__("mocapfix").read(shared("bvh/cmu_cgspeed_131_03.bvh"))
    target = motion.positions.copy()
    target[:, 0] += np.array([5.0, 0.0, 0.0])           # an earlier step moved the root
    moved = motion.replace(positions=target)
    out, _ = build("rotation_smooth", cutoff="20 Hz").apply(moved)
    shift = out.positions[:, 0] - motion.positions[:, 0]
    np.testing.assert_allclose(np.median(shift, axis=0), [5.0, 0.0, 0.0], atol=0.05)
