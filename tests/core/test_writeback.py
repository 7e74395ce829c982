"""Rotation write-back (positions → channels) on synthetic rigs with known answers and
on the real BVH and ASF/AMC files."""
from __future__ import annotations

import numpy as np
import pytest

from mocapfix.core.kinematics import Rig, euler_to_matrix
from mocapfix.core.writeback import decompose, solve_channels
from conftest import shared, shared_files, need


def _branching_rig():
    names = ["root", "spine", "lsh", "rsh", "lhand", "rhand", "head"]
    parents = [-1, 0, 1, 1, 2, 3, 1]
    offsets = [[0, 0, 0], [0, 10, 0], [-5, 2, 0], [5, 2, 0], [-10, 0, 0], [10, 0, 0], [0, 5, 1]]
    return Rig(names, parents, offsets, ["ZXY", "YXZ", "ZYX", "XZY", "", "", ""],
               [[3, 4, 5], [6, 7, 8], [9, 10, 11], [12, 13, 14], [], [], []],
               [[0, 1, 2]] + [[-1, -1, -1]] * 6)


def test_unchanged_positions_give_bit_identical_channels():
    rig = _branching_rig()
    rng = np.random.default_rng(0)
    ch = rng.uniform(-80, 80, (300, 15))
    assert np.array_equal(solve_channels(rig, ch, rig.positions(ch)), ch)


def test_recovers_positions_of_a_different_pose_exactly():
    """Targets from other angles (same bone lengths) are reached to machine precision;
    a joint with one child keeps the input twist, so only reachable poses are used."""
    rig = _branching_rig()
    rng = np.random.default_rng(1)
    ch = rng.uniform(-80, 80, (300, 15))
    target_ch = ch + rng.normal(0, 8, ch.shape)
    target = rig.positions(target_ch)
    new = solve_channels(rig, ch, target)
    assert np.abs(rig.positions(new) - target).max() < 1e-9


def test_noisy_targets_are_approximated_and_root_translation_follows():
    rig = _branching_rig()
    rng = np.random.default_rng(2)
    ch = rng.uniform(-60, 60, (200, 15))
    clean = rig.positions(ch)
    noisy = clean + rng.normal(0, 0.2, clean.shape)
    new = solve_channels(rig, ch, noisy)
    fk = rig.positions(new)
    assert np.allclose(new[:, :3], noisy[:, 0], atol=1e-12)
    # root-to-leaf fitting of rigid bones aimed at absolute targets: the result stays at
    # the noise level of the targets and of the truth
    assert np.sqrt(np.mean((fk - noisy) ** 2)) < 0.25
    assert np.sqrt(np.mean((fk - clean) ** 2)) < 0.25
    np.testing.assert_allclose(np.linalg.norm(fk[:, 4] - fk[:, 2], axis=1), 10.0)


@pytest.mark.parametrize("axes", ["X", "Y", "Z", "ZX", "XY", "YZ", "ZXY"])
def test_decompose_restricted_axes(axes):
    rng = np.random.default_rng(3)
    ang = rng.uniform(-1.2, 1.2, (100, len(axes)))
    np.testing.assert_allclose(decompose(axes, euler_to_matrix(axes, ang)), ang, atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("path", shared_files("bvh", "*.bvh"))
def test_real_bvh_perturbed_positions_write_back(path):
    from mocapfix.formats import read

    motion = read(need(path))
    T = min(motion.n_frames, 300)
    ch = motion.channels[:T]
    assert np.array_equal(solve_channels(motion.rig, ch, motion.positions[:T]), ch)
    rng = np.random.default_rng(4)
    rot = [c for cols in motion.rig.rot_columns for c in cols]
    other = ch.copy()
    other[:, rot] += rng.normal(0, 3, (T, len(rot)))
    target = motion.rig.positions(other)
    new = solve_channels(motion.rig, ch, target)
    size = np.ptp(motion.positions[0], axis=0).max()
    err = np.linalg.norm(motion.rig.positions(new) - target, axis=-1)
    # the perturbed pose has the same bones, so it is reachable: the twist of a joint with
    # one child is invisible in positions but also does not move them. Measured on the 7
    # shared files: median 9e-18–4e-17, max 2e-16–2e-15 of the skeleton size.
    assert err.max() < 1e-9 * size


@pytest.mark.slow
def test_real_amc_perturbed_positions_write_back():
    from mocapfix.formats import read

    motion = read(shared("asfamc/05_01.amc"))
    ch = motion.channels[:200]
    assert np.array_equal(solve_channels(motion.rig, ch, motion.positions[:200]), ch)
    rng = np.random.default_rng(5)
    target = motion.positions[:200] + rng.normal(0, 0.02, (200, motion.n_joints, 3))  # ~1 mm
    new = solve_channels(motion.rig, ch, target)
    res = np.linalg.norm(motion.rig.positions(new) - target, axis=-1)
    # noise of 0.035 units per sample; joints with one or two DOFs (tibia, radius, toes)
    # cannot follow it, so the fit stays a little above (measured 0.041)
    assert np.sqrt(np.mean(res ** 2)) < 0.05


@pytest.mark.slow
@pytest.mark.parametrize("name", ["05_10.amc", "60_10.amc", "61_10.amc"])
def test_other_euler_solution_kept_when_nothing_changes(name, tmp_path):
    """CMU 05_10 (rfemur), 60_10 and 61_10 (root) store some frames on the second
    Tait–Bryan solution (middle angle beyond ±90°). A re-decomposition returns the first
    one; write-back and the rotation features must keep the file's triplet, so a clean
    that changes nothing leaves the channels as read (it used to rewrite them by 180°)."""
    from click.testing import CliRunner

    from mocapfix.cli import main
    from mocapfix.formats import read
    from mocapfix.solvers import rotchannels

    src = shared(f"asfamc/{name}")
    motion = read(src, fps=120.0)
    ch = motion.channels
    # positions moved by 1e-6 units (a micron-scale change): channels follow by as little
    nudged = solve_channels(motion.rig, ch, motion.positions + 1e-6)
    assert np.abs(nudged - ch).max() < 1e-3
    back = rotchannels.from_features(motion.rig, rotchannels.to_features(motion.rig, ch), ch)
    assert np.abs(back - ch).max() < 1e-9
    config = tmp_path / "nothing.yaml"
    config.write_text("version: 1\npipeline:\n  - cleaner: fill\n    method: pchip\n")
    res = CliRunner().invoke(main, ["clean", str(src), "-o", str(tmp_path / "out"), "-c", str(config),
                                    "--fps", "120", "--report", "none"])
    assert res.exit_code == 0, res.output
    written = read(next((tmp_path / "out").rglob(name)), fps=120.0).channels
    # AMC text keeps 6 decimals
    assert np.abs(written - ch).max() < 1e-5


@pytest.mark.parametrize("axes", ["ZXY", "XYZ", "ZYX"])
def test_nearest_euler_picks_the_equivalent_triplet_of_the_reference(axes):
    from mocapfix.core.kinematics import matrix_to_euler, nearest_euler

    rng = np.random.default_rng(7)
    ref = rng.uniform(-170, 170, (200, 3))
    ref[:100, 1] = rng.uniform(95, 175, 100) * rng.choice([-1, 1], 100)   # second solution
    principal = np.rad2deg(matrix_to_euler(axes, euler_to_matrix(axes, np.deg2rad(ref))))
    assert (np.abs(principal[:100] - ref[:100]).max(axis=1) > 1).all()
    np.testing.assert_allclose(nearest_euler(principal, ref), ref, atol=1e-9)
    np.testing.assert_allclose(np.deg2rad(nearest_euler(principal, ref)),
                               nearest_euler(np.deg2rad(principal), np.deg2rad(ref), degrees=False), atol=1e-12)


@pytest.mark.slow
def test_write_back_keeps_the_channels_of_rotation_cleaners_and_solves_moved_positions(monkeypatch):
    """The rotation cleaners return channels and their forward kinematics: nothing is
    left to solve, the channels are written as the cleaner made them (residual 0). A step
    that moves positions still gets its channels solved."""
    from mocapfix import formats
    from mocapfix.core import writeback
    from mocapfix.cleaning import clean_motion
    from mocapfix.config import loads_config

    m = formats.read(shared("bvh/cmu_cgspeed_131_01.bvh"))
    calls = []
    real = writeback.solve_channels
    monkeypatch.setattr(writeback, "solve_channels", lambda *a, **k: calls.append(1) or real(*a, **k))
    rot = loads_config("pipeline:\n  - cleaner: rotation_denoise\n")
    result = clean_motion(m, rot)
    alone, _ = rot.steps[0].cleaner.apply(m)
    assert calls == []
    np.testing.assert_array_equal(result.cleaned.channels, alone.channels)
    assert np.nanmax(result.writeback_residual) == 0.0
    moved = loads_config("pipeline:\n  - cleaner: gaussian\n    sigma: 0.02 s\n")
    result = clean_motion(m, moved)
    assert calls == [1]
    assert not np.array_equal(result.cleaned.channels, m.channels)
    assert np.nanmax(result.writeback_residual) < 1.0        # cm: the smoothed pose is reached
