"""Cuts: frames where the whole take jumps at once, as one take ends and another begins.

A take joined from recordings (a loop made in an editor, takes concatenated for a
database, a tracker that lost the subject and found it again, a Kinect that switched to
another body) has frames where every point moves at once, far more than it ever moves
between two frames, and then goes on from there. No marker went wrong there and nothing
is missing between the frames; but the cleaners cannot tell: the outlier tests judge the
points wrong, the fillers bridge the two takes, the smoothers blend them. With CMU 85_02
(which the default leaves untouched) played as a 2 s loop the default judged the points
wrong at every loop point and wrote fills up to 133 mm from the data
(``benchmarks/degenerate_takes.py --cuts``).

So a take with cuts is cleaned as the takes between its cuts, each on its own, put back
together frame by frame (:mod:`mocapfix.pipeline.windows`: the cuts are pieces with no
overlap, and a gap that spans a cut is two gaps, one at the end of each take).

A point's jump at frame ``t`` is how far its step from ``t − 1`` to ``t`` is from the mean
of its steps before and after: ``e_t = |d_t − (d_{t−1} + d_{t+1}) / 2|`` with
``d_t = p_t − p_{t−1}`` (one step when the other is missing), a second difference that
fast smooth motion keeps small and a jump makes the size of the jump. Frame ``t`` is a cut
when, of the points with a jump there, at least :data:`SHARE` jump more than
:data:`RATIO` times their own usual jump (1.4826 × the median over the take, at least
:data:`FLOOR_M`) and more than :data:`MIN_JUMP_M`, at least three of them, and the
points with a jump there are at least half the take's. A jump also shows, half as large,
on the frames either side: of neighbouring candidate frames the one with the largest
median jump is the cut, when it is the only large one (the whole body one frame off and
back has two, 1.5 times its offset each) and the frames around are quiet. Cuts closer
than :data:`MIN_PART_S` to each other or to an end of the take are a burst of whole-body
errors (a tracker's glitch of a few frames), not a new take: they are left to the
cleaners. The points are the take's markers or joints (:func:`cut_points`): a C3D's model
outputs and unlabelled trajectories are not measured.
"""
from __future__ import annotations

import numpy as np

from mocapfix.core.motion import Motion
from mocapfix.pipeline.selection import not_cleaned
from mocapfix.solvers.nanstats import nanmedian_columns

#: frames measured at a time (the temporaries stay a few MB)
BLOCK = 4096
#: a point jumps when its second difference exceeds this many times its usual one
RATIO = 20.0
#: ... and this much (m)
MIN_JUMP_M = 0.05
#: the least a point's usual second difference is taken to be (m): a still point's is ~0
FLOOR_M = 0.0005
#: the share of the points with a jump at a frame that must jump for a cut
SHARE = 0.5
#: frames each side of a cut (beyond the one next to it) where few points may jump
QUIET = 4
#: the shortest take between two cuts (s)
MIN_PART_S = 0.5


def jumps(positions: np.ndarray, frames: slice | None = None,
          cols: np.ndarray | None = None) -> np.ndarray:
    """(T, J) float32 ``e_t`` of every point (see the module docstring), of ``frames``
    (all of them by default) and the points ``cols`` (indices; all by default); NaN where
    the point is missing at ``t − 1`` or ``t`` or has no step on either side, and at
    ``t = 0``."""
    T = positions.shape[0]
    J = positions.shape[1] if cols is None else len(cols)
    first, last, _ = (frames or slice(None)).indices(T)
    out = np.full((last - first, J), np.nan, np.float32)
    for a in range(max(first, 1), last, BLOCK):
        b = min(a + BLOCK, last)
        # steps[k]: the step into frame a − 1 + k (NaN where there is none), k = 0 .. b − a + 1
        lo, hi = max(a - 2, 0), min(b + 1, T)
        block = positions[lo:hi] if cols is None else positions[lo:hi, cols]
        d = np.diff(block, axis=0)                              # d[i]: into frame lo + 1 + i
        steps = np.full((b - a + 2, J, 3), np.nan)
        off = a - 2 - lo
        k0, k1 = max(0, -off), min(b - a + 2, len(d) - off)
        steps[k0:k1] = d[k0 + off:k1 + off]
        step, before, after = steps[1:-1], steps[:-2], steps[2:]
        mean = np.where(np.isnan(before), after,
                        np.where(np.isnan(after), before, (before + after) / 2))
        out[a - first:b - first] = np.linalg.norm(step - mean, axis=-1)
    return out


def cut_points(motion: Motion) -> np.ndarray | None:
    """The points a cut is looked for on: the markers or joints, not the model outputs a
    file lists nor unlabelled trajectories (by the default policy,
    :mod:`mocapfix.pipeline.unlabelled`: a raw export's hundreds of fragments are not the
    take's points, and measuring them cost most of a clean); indices, None for all. The
    same for ``clean`` and ``check``/``info`` whatever their configs say."""
    keep = np.array([why is None for why in not_cleaned(motion)], bool)
    return None if keep.all() else np.flatnonzero(keep)


def take_cuts(motion: Motion, points: np.ndarray | None = None) -> np.ndarray:
    """The frames where ``motion`` jumps as a whole (the first frame of the take after each
    cut), sorted; empty when there are none (see the module docstring), measured on the
    ``points`` (indices, all by default; :func:`cut_points`). The take is measured
    :data:`BLOCK` frames at a time, twice but for the first block (a point's usual jump is
    the median of its medians over the blocks: its median when the take is one block), so
    the memory does not grow with the take."""
    T = motion.n_frames
    if T < 4 or (motion.n_joints if points is None else len(points)) < 3:
        return np.zeros(0, np.intp)               # a cut needs three points that jump
    P, unit = motion.positions, motion.metres_per_unit
    blocks = [slice(a, min(a + BLOCK, T)) for a in range(0, T, BLOCK)]
    first = jumps(P, blocks[0], points)            # a take of one block: measured once
    medians = np.array([nanmedian_columns(first if k == 0 else jumps(P, b, points))
                        for k, b in enumerate(blocks)])
    usual = 1.4826 * nanmedian_columns(medians)
    n_points = int(np.isfinite(medians).any(axis=0).sum())
    usual = np.maximum(np.nan_to_num(usual, nan=np.inf), FLOOR_M / unit)
    share, size = np.zeros(T), np.zeros(T)
    frames = []
    for k, b in enumerate(blocks):
        e = first if k == 0 else jumps(P, b, points)
        with np.errstate(invalid="ignore"):
            big = (e > RATIO * usual) & (e > MIN_JUMP_M / unit)
        n_has, n_big = (~np.isnan(e)).sum(axis=1), big.sum(axis=1)
        share[b] = n_big / np.maximum(n_has, 1)
        hit = np.flatnonzero((n_big >= np.maximum(SHARE * n_has, 3))
                             & (n_has >= max(n_points / 2, 3)))
        size[b.start + hit] = np.median(np.where(big[hit], e[hit], 0.0), axis=1)
        frames.append(b.start + hit)
    frames = np.concatenate(frames)
    cuts = []
    # neighbouring candidates (the half-size jumps either side of a cut): the largest, when
    # the frames around them are quiet (a burst of whole-body errors is no cut)
    for run in np.split(frames, np.flatnonzero(np.diff(frames) > 2) + 1):
        if not len(run):
            continue
        t = int(run[np.argmax(size[run])])
        around = np.r_[max(t - QUIET, 0):max(t - 1, 0), min(t + 2, T):min(t + QUIET + 1, T)]
        one_peak = (size[run] >= 0.75 * size[t]).sum() == 1    # a spike has two
        if run[-1] - run[0] <= 2 and one_peak and not (share[around] >= SHARE / 2).any():
            cuts.append(t)
    return _isolated(np.array(cuts, np.intp), T, max(round(MIN_PART_S * motion.fps), 2))


def _isolated(cuts: np.ndarray, T: int, shortest: int) -> np.ndarray:
    """The cuts at least ``shortest`` frames from every other cut and from both ends."""
    parts = np.diff(np.concatenate([[0], cuts, [T]]))
    return cuts[(parts[:-1] >= shortest) & (parts[1:] >= shortest)]


def note(frames: np.ndarray) -> str:
    """The report's note on a take cleaned as the takes between its cuts at ``frames``."""
    shown = ", ".join(str(int(f)) for f in frames[:10]) + (", ..." if len(frames) > 10 else "")
    return (f"the take jumps as a whole at {len(frames)} frame{'s' if len(frames) > 1 else ''} "
            f"({shown}): every point moves at once far more than it does between any other "
            "two frames (takes joined, or a tracker that lost the subject); the "
            f"{len(frames) + 1} takes between were cleaned each on its own")


def cut_frames(motion: Motion, held) -> list[int]:
    """The take's frames where it jumps as a whole, found on its distinct frames as
    ``clean`` finds them: ``held`` is the take's
    :meth:`HeldFrames.find <mocapfix.pipeline.held.HeldFrames.find>` (None: no held frames)."""
    at = take_cuts(motion if held is None else held.take(motion), cut_points(motion))
    return (at if held is None else held.kept[at]).tolist()
