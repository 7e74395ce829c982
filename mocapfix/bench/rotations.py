"""The ``rotations`` bench protocol: corrupt the rotation channels of a BVH or ASF/AMC
motion the way solved animation data goes wrong, and judge a cleaning by what
``mocapfix clean`` would write.

Settings (seeded: ``numpy.random.default_rng(seed)``; angles in degrees whatever the
file's unit):

- ``clean`` — nothing: a cleaner must leave good data (almost) alone;
- ``jitter`` — N(0, 0.7°) added to every rotation channel of every frame;
- ``spikes`` — on 2 % of the frames a spike starts: one axis (channel) of a random joint
  with rotation DOFs is offset by ±U(10°, 40°) for 1–3 frames;
- ``mixed`` — jitter, then spikes.

Translation channels are never corrupted. The methods see the corrupted motion with its
rig and channels (positions = forward kinematics of the corrupted channels). Their output
goes through the rotation write-back of ``mocapfix clean``
(:func:`mocapfix.core.writeback.write_back`) and is scored by:

- ``pos_err_pct``: mean Euclidean joint position error of the written motion against the
  truth, in % of the skeleton height (the median over frames of the largest extent of
  the true joint positions' bounding box — the body's length in any pose);
- ``pos_err_mm``: the same in mm;
- ``deg_err``: mean |error| per rotation channel per frame, degrees (wrapped to ±180°;
  the thesis' "degrees per joint angle per frame");
- ``writeback_mm``: largest write-back residual (distance between the method's positions
  and the forward kinematics of the written channels), mm.
"""
from __future__ import annotations

import numpy as np

from mocapfix.core.motion import Motion

SETTINGS = ("clean", "jitter", "spikes", "mixed")
JITTER_DEG = 0.7
SPIKE_FRAMES = 0.02
SPIKE_DEG = (10.0, 40.0)
SPIKE_LENGTH = (1, 3)

def rotation_columns(rig) -> list[int]:
    return [c for cols in rig.rot_columns for c in cols]


def refusal(motion: Motion) -> str | None:
    """Why the protocol cannot corrupt ``motion`` (None: it can)."""
    if motion.rig is None or motion.channels is None:
        return "the rotations protocol needs rotation channels (BVH or ASF/AMC)"
    return None


def corrupt(motion: Motion, setting: str, seed: int = 0):
    """(corrupted motion with channels and positions, (T, J) mask of joints whose channels
    were changed)."""
    why = refusal(motion)
    if why:
        raise ValueError(why)
    if setting not in SETTINGS:
        raise ValueError(f"unknown rotations setting {setting!r} (known: {', '.join(SETTINGS)})")
    rng = np.random.default_rng(seed)
    rig = motion.rig
    ch = motion.channels.copy()
    T = len(ch)
    unit = 1.0 if rig.degrees else np.pi / 180.0
    joint_of = {c: j for j, cols in enumerate(rig.rot_columns) for c in cols}
    cols = rotation_columns(rig)
    mask = np.zeros((T, rig.n_joints), dtype=bool)
    if setting in ("jitter", "mixed"):
        ch[:, cols] += rng.normal(0.0, JITTER_DEG, (T, len(cols))) * unit
        mask[:, sorted({joint_of[c] for c in cols})] = True
    if setting in ("spikes", "mixed"):
        n = max(1, int(round(SPIKE_FRAMES * T)))
        starts = rng.choice(T, size=n, replace=False)
        for s in starts:
            c = cols[rng.integers(len(cols))]
            length = int(rng.integers(SPIKE_LENGTH[0], SPIKE_LENGTH[1] + 1))
            size = rng.uniform(*SPIKE_DEG) * rng.choice([-1.0, 1.0]) * unit
            ch[s:s + length, c] += size
            mask[s:s + length, joint_of[c]] = True
    mask &= ~np.isnan(motion.positions).any(axis=2)       # samples missing already stay so
    return motion.replace(channels=ch, positions=rig.positions(ch)), mask


def _wrapped(d: np.ndarray) -> np.ndarray:
    return np.abs((d + 180.0) % 360.0 - 180.0)


def channel_errors(rig, channels: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(T, rotation channels) |error| in degrees, wrapped to ±180°. A three-axis joint's
    angles (a, b, c) and (a + 180°, 180° − b, c + 180°) are the same rotation (the two
    Tait–Bryan solutions): the output's triplet is compared in whichever form is nearer
    the truth, so an equivalent rewrite is not counted as an error."""
    scale = 1.0 if rig.degrees else 180.0 / np.pi
    out = []
    for axes, cols in zip(rig.rot_axes, rig.rot_columns):
        if not axes:
            continue
        est, ref = channels[:, cols] * scale, truth[:, cols] * scale
        err = _wrapped(est - ref)
        if len(axes) == 3:
            alt = est + np.array([180.0, 0.0, 180.0])
            alt[:, 1] = 180.0 - est[:, 1]
            err_alt = _wrapped(alt - ref)
            use = err_alt.sum(axis=1) < err.sum(axis=1)
            err[use] = err_alt[use]
        out.append(err)
    return np.concatenate(out, axis=1) if out else np.zeros((len(channels), 0))


def skeleton_height(positions: np.ndarray) -> float:
    """Median over frames of the largest bounding-box extent of the joints."""
    with np.errstate(all="ignore"):
        ext = np.nanmax(positions, axis=1) - np.nanmin(positions, axis=1)
    return float(np.nanmedian(np.nanmax(ext, axis=1)))


def evaluate(truth: Motion, output: Motion) -> dict:
    """The protocol's metrics of a method's output motion (see the module docstring)."""
    from mocapfix.core.writeback import write_back

    rig = truth.rig
    mm = 1000.0 * truth.metres_per_unit
    if output.rig is not None and output.channels is not None:
        channels, positions, residual = write_back(output)
        wb = float(np.nanmax(residual)) * mm if residual.size else 0.0
    else:   # the method dropped the channels: nothing a BVH/AMC writer could write
        return {"pos_err_pct": float("nan"), "pos_err_mm": float("nan"), "deg_err": float("nan"),
                "writeback_mm": float("nan"), "unfilled_pct": 100.0}
    err = np.linalg.norm(positions - truth.positions, axis=-1)
    deg = channel_errors(rig, channels, truth.channels)
    return {"pos_err_pct": float(100.0 * np.nanmean(err) / skeleton_height(truth.positions)),
            "pos_err_mm": float(np.nanmean(err) * mm),
            "deg_err": float(np.nanmean(deg)),
            "writeback_mm": wb,
            "unfilled_pct": float(100.0 * np.isnan(positions).any(axis=2).mean())}
