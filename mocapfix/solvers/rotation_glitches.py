"""Glitches in the rotation channels of a BVH/AMC rig, re-made only where the limb's
world-space path contradicts the input: the kernel of the ``rotation_outliers`` cleaner
(:mod:`mocapfix.cleaners.rotations`, whose docstring gives the method and the
measurements). Candidates come from :func:`mocapfix.solvers.glitches.glitches` on the
continuous rotation features (:mod:`mocapfix.solvers.rotchannels`); the evidence test is
:func:`mocapfix.solvers.glitches.limb_contradicts` on forward kinematics of the rig.
"""
from __future__ import annotations

import numpy as np

from mocapfix.core.gaps import runs
from mocapfix.core.kinematics import moved_by_rotation
from mocapfix.solvers import glitches, rotchannels, segments


def remake(rig, ch: np.ndarray, F: np.ndarray, *, width: int, k: float, floor: float,
           neutral: float, ratio: float):
    """The channels ``ch`` (T, C) of ``rig`` with the rotation glitches its limbs
    contradict re-made by PCHIP interpolation of the joint's features ``F``
    (:func:`rotchannels.to_features`) from the frames around; every other value is kept
    bit for bit. Returns (channels, (T, joints with rotations) mask of the joint-frames
    re-made, how many joint-frames the channel test suspected)."""
    spikes = glitches.glitches(F, width=width, k=k, floor=floor)
    layout = rotchannels.layout(rig)
    edges = np.cumsum([0] + [e["size"] for e in layout])
    joint_bad = np.stack([spikes[:, a:b].any(axis=1) for a, b in zip(edges[:-1], edges[1:])], axis=1)
    if not joint_bad.any():
        return ch, joint_bad, 0
    G = F.copy()
    for n, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        G[joint_bad[:, n], a:b] = np.nan
    G, _ = segments.interpolate_gaps(G, "pchip")
    G = np.where(np.isnan(G), F, G)           # spikes at the very ends: hold the input
    new = rotchannels.from_features(rig, G, ch)
    joints = [j for j, axes in enumerate(rig.rot_axes) if axes]
    candidates = int(joint_bad.sum())
    joint_bad = contradicted_by_limbs(rig, ch, new, joint_bad, joints, neutral, ratio)
    out = ch.copy()
    for n, j in enumerate(joints):
        rows = joint_bad[:, n]
        if rows.any():
            out[np.ix_(rows, rig.rot_columns[j])] = new[np.ix_(rows, rig.rot_columns[j])]
    return out, joint_bad, candidates


def contradicted_by_limbs(rig, ch: np.ndarray, new: np.ndarray, bad: np.ndarray, joints: list[int],
                           neutral: float, ratio: float) -> np.ndarray:
    """``bad`` (T, joints with rotations) without the runs the world-space motion of the
    limb does not contradict. A run of a joint's re-made channels is kept only when it
    moves the joints its rotation moves (:func:`mocapfix.core.kinematics.moved_by_rotation`)
    by more than ``neutral`` — with no lever there is nothing in the take to test the
    channels against (the 30 Hz Bandai toes, whose end sites sit on the joint, bend at
    every toe-off) — and makes their path smoother, by
    :func:`mocapfix.solvers.glitches.limb_contradicts`: a glitch in the channels throws
    the limb's end out and back, a real fast turn (a kick's knee at 30 Hz) moves it along
    a smooth path that re-making the joint alone would break. Runs whose frames (with the
    test's context) overlap and whose joints move some joint in common
    (:func:`mocapfix.solvers.glitches.overlapping_runs`) are judged one after the other,
    the most evident first, each against the take with the runs kept before it re-made:
    a glitch on a foot and its toe at once leaves the toe's path rough while only one is
    re-made, and a toe bent at a knee glitch gains no evidence from the knee's."""
    T = len(ch)
    moved = moved_by_rotation(rig)
    context = glitches.EVIDENCE_CONTEXT
    found = [(n, int(s), int(L)) for n in range(len(joints)) if len(moved[joints[n]])
             for _, s, L in zip(*runs(bad[:, n][:, None]))]

    def effect(run, state) -> float:
        """The share of its limb's squared acceleration a run's re-making leaves in
        ``state`` (inf without a lever)."""
        n, s, L = run
        j = joints[n]
        a, b = max(s - context, 0), min(s + L + context, T)
        trial = state[a:b].copy()
        trial[s - a:s - a + L, rig.rot_columns[j]] = new[s:s + L, rig.rot_columns[j]]
        before = rig.positions(state[a:b])[:, moved[j]]
        after = rig.positions(trial)[:, moved[j]]
        if np.nanmax(np.linalg.norm(after - before, axis=-1), initial=0.0) <= neutral:
            return np.inf
        return glitches.acceleration_share(before, after)

    keep = np.zeros_like(bad)
    for group in glitches.overlapping_runs(found, [set(moved[j].tolist()) for j in joints], context):
        state = ch
        while group:
            shares = [effect(run, state) for run in group]
            best = int(np.argmin(shares))
            if not shares[best] <= ratio:
                break
            n, s, L = group.pop(best)
            keep[s:s + L, n] = True
            cols = rig.rot_columns[joints[n]]
            state = state.copy()
            state[s:s + L, cols] = new[s:s + L, cols]
    return keep
