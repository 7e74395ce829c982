"""``kinect_skeleton``: clean depth-sensor skeletons (Kinect v1/v2/Azure, MSR, UTKinect)
using their tracking state and their bones.

Written for mocapfix (issue 12); each stage cites the method it uses:

1. **Limb confusion** (left/right legs exchanged for a few frames when the body turns).
   For the knee-ankle-foot chains of the two legs, per frame: ``keep`` = distance of each
   chain to a robust reference of its own side (running median over ±``swap_window``
   of the joints relative to the pelvis, so walking does not blur it) plus the deviation
   of the hip-knee bones from their median lengths; ``swap`` = the same with the chains
   exchanged. A frame is exchanged (positions and confidences of the whole chain) when
   ``keep − swap > swap_threshold`` and ``swap < keep / 2`` — the continuity and
   rigid-distance cues of the ``swaps`` cleaner, applied to whole limbs. Two passes.
2. **Tracking state → weights.** NotTracked (missing) = weight 0; Inferred (confidence
   < 0.75) = σ ``inferred_noise``; Tracked = σ_j(z) from the noise model below. With
   ``inferred_debias`` an Inferred run is taken as the joint plus a slowly changing
   offset: the offset is read at each end of the run as the jump of the data there
   (linear fits to ``debias_window`` samples on each side, evaluated at the run's end
   sample: :mod:`mocapfix.solvers.run_offsets`; an end without Tracked samples next to it
   falls back to the Inferred samples against the smooth of the Tracked samples alone),
   removed with linear interpolation in time in between, and the run then gets σ
   ``debiased_factor · inferred_noise``. (Measured on the ``kinect`` protocol, whose
   Inferred offsets glide linearly between two values, so the model fits that corruption
   well; the jump read from both sides replaced a read against the Tracked smooth, which
   at the edge of a gap is off by centimetres for a fast foot: 11 files x 2 seeds,
   inferred+occlusion 0.663 → 0.642 of the best baseline. On real files it moves
   Inferred joints more, e.g. 28 % of KinectReader_joints' samples by > 5 cm.)
3. **Noise model from the data.** A first smooth (step 4 with even weights) gives the
   residuals of tracked samples; per joint a scale ``s_j`` and, pooled over joints, a
   depth exponent ``p`` (least squares of log |residual| on log depth, clamped to
   [0, 2]): ``σ_j(z) = s_j (z / z̄)^p``. Depth is the camera z of the file when it is
   positive everywhere (Kinect camera space), else not used (p = 0).
   **Rigid pairs the skeleton does not list** (``rigid_pairs``). Joints two bones apart
   (siblings such as the two hips or the two shoulders, grandparent and grandchild such
   as elbow and hand) whose distance, averaged over 0.5 s, varies no more than
   ``rigid_pairs`` × what their noise scales explain (:func:`mocapfix.solvers.
   bone_projection.steady_pairs`; at least 90 frames with both tracked) are held at
   their median distance like bones: the raw samples are projected onto the bones and
   these pairs (position-based dynamics, each joint moving in proportion to its variance;
   a Tracked sample the first smooth puts beyond the outlier threshold stays out and as
   it was, so that a glitch does not drag its neighbours and step 5 still reports it)
   and the noise model is refitted on them; step 8 holds them too, before the bones.
   With 40 one-frame jumps of 15-40 cm on Tracked joints (6 files): 7.67 mm against 8.03
   without the pairs, 8.10 when the jumps took part in the projection.
   The bones alone let the two hips turn about the spine base; with the hip-hip distance
   the three joints are one rigid triangle and their jitter averages. Measured on the
   ``kinect`` protocol (11 files x 3 seeds): jitter 0.721 → 0.688 of the best baseline,
   inferred+occlusion 0.589 → 0.575, mixed 0.327 → 0.323 (the pairs found there:
   spine-shoulders, the two shoulders, the two hips, elbow-hand, hand-thumb); with 1.3
   or 2.0 in place of 1.5, jitter 0.698 or 0.704 (measured with a full GCV refit,
   which the refit with the first cut-offs matches within 0.003). On the shared real
   files the test takes one pair (LabanotationSuite Ges01: hand-thumb) and no other:
   their links vary far beyond their noise (a Kinect skeleton's bones do too), so the
   other files' output is unchanged. Judged against the file's own bones instead of its
   noise, the test took 9 or more pairs on real files, shoulder-wrist across a bending
   elbow among them, and moved MSR a06 twice as much.
4. **Smoothing set by the data.** Per joint a weighted Whittaker smoother on the true
   time axis (``Motion.times``: dropped frames are where they happened) with the
   strength chosen by GCV (:mod:`mocapfix.solvers.whittaker`), d = ``order``: the
   penalty on the d-th derivative leaves accelerations alone for d = 3.
5. **Outliers.** Samples whose residual exceeds ``max(outlier_k max(σ, σ_local),
   min_outlier)`` (σ_local: median residual over ±3 samples / 1.5382, Hampel's local
   scale, so a stretch the smooth cannot follow is not called an outlier) and that the
   joint's own path contradicts (:func:`mocapfix.solvers.glitches.contradicted_by_path`:
   a spike thrown out and back, not a fast turn the smooth cuts) get weight 0 and the
   joint is refitted (``passes`` rounds): tracked is trusted unless the geometry says
   otherwise. Their fitted value replaces them. A sample more than 100 m
   from its joint's median position (a corrupt field) is taken out before step 1, as if
   missing, and reported as an outlier.
6. **Untrusted samples from the parent** (``limb_frame``): missing and outlier samples
   become the parent's estimate plus the smooth of the joint's offset to it, parents
   first (an occluded hand follows the tracked elbow). That smooth penalises the
   ``fill_order``-th derivative: 1 (the offset interpolated linearly through the gap, a
   forearm's direction changing steadily) measured 0.587 of the best baseline on
   inferred+occlusion (11 files x 2 seeds) against 0.615 for 2 and 0.650 for 3. With
   ``validate_fills`` each untrusted run is that estimate and the joint's own smooth
   through the run averaged, weighted by their inverse squared errors on validation runs
   of the same length cut where the joint and its parent were tracked (up to two on each
   side of the run, both re-estimated on ±max(2n, 15) frames without them:
   :func:`validated_shares`, the validation idea of ``fill_ensemble``): the parent-based
   estimate is the better one on average (NotTracked samples 84 mm RMS against 110 for
   the own smooth, 11 files x 3 seeds) but not on every run (short runs, and runs whose
   parent is lost too: an acrobat's arm missing from the elbow down, CMU 90_31, 188 mm
   against 136 for the baseline's linear interpolation, now 97). ``kinect`` protocol, 11
   files x 3 seeds: inferred+occlusion 0.575 → 0.540 of the best baseline, worst file
   1.08 → 0.85; mixed 0.323 → 0.309; a fixed average (3/4 from the parent) measured 0.552
   / 0.321. Before
   that, optimal singular-value shrinkage across joints (``spatial_shrink``,
   :mod:`mocapfix.solvers.svshrink`) of the noise-whitened trajectories and one more
   smooth remove some jitter the joints share. That last smooth varies its strength
   along time (``local_steps``): each stretch of ±``local_half`` frames takes, among the
   cut-offs 0.5-2x the joint's GCV choice, the one of least Stein risk there
   (:func:`mocapfix.solvers.whittaker.local_sure_candidates`), so a fast swing is
   smoothed less than a still pose (jitter 8.27 → 8.05 mm, acceleration 0.84 → 0.87x
   the truth's, 11 files seed 0). The chosen strength's log is averaged over the same
   ±``local_half`` and the joint smoothed once with it varying along time
   (:func:`mocapfix.solvers.whittaker.smooth_varying`) instead of being pieced together
   from the candidate smooths sample by sample: jitter 0.688 → 0.683 of the best
   baseline (11 files x 3 seeds; per-joint smooths with the noise σ from the truth:
   9.58 → 9.41 mm).
7. **Fill.** Missing samples in interior gaps of at most ``max_gap`` take the smooth
   (a spline through the gap); gaps at the ends of at most ``max_gap`` are filled from
   the parent joint with the offset of the nearest observed frame (body model).
8. **Bones.** Target lengths = median over frames of each bone (and rigid pair) in the
   smoothed motion where both ends are tracked; positions projected toward them
   (:func:`mocapfix.solvers.bone_projection.project_lengths`), each joint moving in
   proportion to its variance (tracked σ_j(z)², inferred ``inferred_noise``², filled
   (2 ``inferred_noise``)²) with ``bone_stiffness``. Bones that are exactly constant in
   the input (MSR Action3D stores some) keep that length exactly: their child joints are
   put back at it, parents first.

The output keeps the file's rows and timestamps (the writers change only samples).

Not used, by measurement (``kinect`` jitter scenario, 11 files, seed 0; 0.719 of the best
baseline before the rigid pairs of step 3): motion priors trained on ../shared/training (a
Gaussian prior over 8-frame windows of the 25 joints, M-SSA bases, the partlet-kinect
dictionary) measured 0.92-1.48 alone and 0.694-0.706 blended 0.2 with this cleaner's
output; per-joint smoothing whose strength the truth picks every ±5 frames 0.751
(``benchmarks/studies/kinect_priors.py``). Smoothing cluster centroids (hand, foot, pelvis,
shoulders) and offsets to them separately, and shrinkage across joints in a body frame or
in 1-8 s windows, measured 8.45-8.65 mm against 8.46 (4 files, seed 0); the ICI rule
(Katkovnik 1999) in place of the local Stein risk 8.58-10.0. A Gaussian-mixture prior over
8-frame windows of each body part (EPLL-style; ``benchmarks/studies/kinect_gmm_prior.py``), trained on
the same corpus, 0.765 alone and 0.648 blended 0.3 with this cleaner's output (0.682), the
best trained prior measured; trained on the test motions' own truth, 0.626 / 0.592: not
shipped (a model of several MB and a blend weight for a 0.03 gain, short of 0.6)."""
from __future__ import annotations

import numpy as np

from mocapfix.cleaners import register
from mocapfix.cleaners.base import REPLACED_FRAMES, Cleaner, Param
from mocapfix.core.errors import ConfigError
from mocapfix.core.kinect_joints import normalise_name
from mocapfix.core.motion import Motion
from mocapfix.solvers import run_offsets, svshrink, whittaker
from mocapfix.solvers.glitches import contradicted_by_path
from mocapfix.solvers.bone_projection import (median_lengths, project_lengths, steady_pairs,
                                               two_bone_pairs)
from mocapfix.solvers.localfit import moving_median
from mocapfix.solvers.rigid import norms
from mocapfix.solvers.segments import NO_CAPTURE_VOLUME_M, fillable, runs

_LEG = ("knee", "ankle", "foot")
_PELVIS = ("spinebase", "hipcenter", "pelvis")
#: cutoff frequencies (Hz) whose λ form the GCV grid
_CUTOFFS = np.geomspace(0.7, 12.0, 8)
#: GCV chooses the smoothing on at most this many frames (the middle of a long file)
_GCV_FRAMES = 3000
#: the rigid-pair test averages distances over this long (s) ...
_RIGID_WINDOW_S = 0.5
#: ... on at least this many frames where both joints are tracked (3 s at 30 fps)
_RIGID_MIN_FRAMES = 90


def _side_pairs(names: list[str], parts) -> list[tuple[int, int]]:
    """(left, right) joint indices of the named parts present on both sides."""
    key = {normalise_name(n): i for i, n in enumerate(names)}
    out = []
    for part in parts:
        a, b = key.get(part + "left"), key.get(part + "right")
        if a is not None and b is not None:
            out.append((a, b))
    return out


def _pelvis(names):
    key = {normalise_name(n): i for i, n in enumerate(names)}
    return next((key[p] for p in _PELVIS if p in key), None)


def leg_swap_frames(P: np.ndarray, names: list[str], threshold: float) -> np.ndarray:
    """Frames (T,) where the leg chains are exchanged (module docstring, stage 1): the
    labelling (kept / exchanged per frame) of least cost by Viterbi (two states)."""
    T = P.shape[0]
    pairs = _side_pairs(names, _LEG)
    root = _pelvis(names)
    if not pairs or root is None or T < 3:
        return np.zeros(T, bool)
    L = [a for a, _ in pairs]
    R = [b for _, b in pairs]
    rel = P - P[:, root:root + 1]
    Y = (rel[:, L], rel[:, R])                           # the data labelled as stored
    # path length of the relabelled chains between frames t-1 and t: [prev, cur]
    step = np.zeros((T, 2, 2))
    for ps in range(2):
        for cs in range(2):
            a_prev, b_prev = (Y[0], Y[1]) if ps == 0 else (Y[1], Y[0])
            a_cur, b_cur = (Y[0], Y[1]) if cs == 0 else (Y[1], Y[0])
            d = norms(a_cur[1:] - a_prev[:-1]) + norms(b_cur[1:] - b_prev[:-1])
            step[1:, ps, cs] = np.nansum(d, axis=1)
    # two-state Viterbi; plain floats: a numpy call per frame costs more than the sums
    s00, s01, s10, s11 = (step[:, 0, 0].tolist(), step[:, 0, 1].tolist(),
                          step[:, 1, 0].tolist(), step[:, 1, 1].tolist())
    u1 = float(threshold)
    c0, c1 = 0.0, u1
    back0 = bytearray(T)
    back1 = bytearray(T)
    for t in range(1, T):
        a, b = c0 + s00[t], c1 + s10[t]                  # into state 0 from 0 / from 1
        if b < a:
            back0[t], n0 = 1, b
        else:
            n0 = a
        a, b = c0 + s01[t], c1 + s11[t]                  # into state 1
        if b < a:
            back1[t], n1 = 1, b + u1
        else:
            n1 = a + u1
        c0, c1 = n0, n1
    state = np.zeros(T, dtype=np.int8)
    cur = 0 if c0 <= c1 else 1
    state[-1] = cur
    for t in range(T - 1, 0, -1):
        cur = back1[t] if cur else back0[t]
        state[t - 1] = cur
    return state == 1


def _fill_ends_from_parent(Z, missing, parents, order, max_gap_frames):
    """Fill leading/trailing gaps (≤ max_gap_frames) with the parent + nearest offset."""
    T = Z.shape[0]
    filled = np.zeros(missing.shape, bool)
    for j in order:
        p = parents[j]
        if p < 0:
            continue
        obs = np.flatnonzero(~np.isnan(Z[:, j]).any(axis=1))
        if not len(obs):
            continue
        for lo, hi, edge in ((0, obs[0], obs[0]), (obs[-1] + 1, T, obs[-1])):
            n = hi - lo
            if n <= 0 or n > max_gap_frames:
                continue
            offset = Z[edge, j] - Z[edge, p]
            span = Z[lo:hi, p] + offset
            ok = ~np.isnan(span).any(axis=1)
            Z[lo:hi][ok, j] = span[ok]
            filled[lo:hi, j] |= ok
    return filled


def _topological(parents):
    order, seen = [], set()

    def visit(j):
        if j in seen:
            return
        if parents[j] >= 0:
            visit(int(parents[j]))
        seen.add(j)
        order.append(j)

    for j in range(len(parents)):
        visit(j)
    return order


#: the share of the parent-based estimate where no validation run is found: the best
#: fixed share on the ``kinect`` protocol (0.5-1 tried; 11 files x 3 seeds)
_PARENT_SHARE = 0.75
#: validation runs cut on each side of an untrusted run
_VALIDATION_RUNS = 2


def validation_starts(ok: np.ndarray, length: int) -> np.ndarray:
    """Every start ``u`` of a run ``u .. u+length-1`` on which ``ok`` (T,) holds, and on
    one sample either side of it."""
    T, n = len(ok), length
    okc = np.concatenate([[0], np.cumsum(ok, dtype=np.int64)])
    u = np.arange(1, max(T - n, 1))
    return u[okc[u + n + 1] - okc[u - 1] == n + 2]


def nearest_starts(starts: np.ndarray, start: int, length: int, per_side: int) -> list[int]:
    """Of ``starts`` (:func:`validation_starts`, ascending), up to ``per_side`` on each
    side of the run ``start .. start+length-1``, nearest first, overlapping neither it nor
    each other."""
    n, out = length, []
    limit = start - n - 1                                    # the latest start before it
    for _ in range(per_side):
        k = int(np.searchsorted(starts, limit, side="right")) - 1
        if k < 0:
            break
        out.append(int(starts[k]))
        limit = out[-1] - n
    limit = start + n + 1                                    # the earliest start after it
    for _ in range(per_side):
        k = int(np.searchsorted(starts, limit, side="left"))
        if k >= len(starts):
            break
        out.append(int(starts[k]))
        limit = out[-1] + n
    return out


def validated_shares(rows, ok, t, y, w, cut, order, off, parent, wrel, cut_off, off_order):
    """Per sample (T,), the share of the parent-based estimate (parent + smoothed offset)
    in each run of ``rows`` against the joint's own smooth: ``e_own / (e_parent +
    e_own)``, the squared errors of the two on validation runs of the same length where
    ``ok`` (:func:`validation_starts`, :func:`nearest_starts`), each re-estimated without
    the run on its stretch of ±max(2n, 15) samples by the Whittaker smoother
    (:mod:`mocapfix.solvers.whittaker`) at the joint's cut-off ``cut`` (``order``) and
    the offset's ``cut_off`` (``off_order``), and compared with the samples there;
    :data:`_PARENT_SHARE` where no such run exists. All stretches of the joint are
    smoothed in one banded solve (:func:`mocapfix.solvers.whittaker.stretch_bands`).
    Inverse-error weights are the validation weights of
    :class:`mocapfix.cleaners.pma.FillEnsemble` (after Tits et al. 2018)."""
    T = len(rows)
    share = np.full(T, _PARENT_SHARE)
    if not (np.isfinite(cut) and np.isfinite(cut_off)) or T < 2:
        return share
    _, starts, lengths = runs(rows[:, None])
    by_length: dict[int, np.ndarray] = {}
    cuts = []                                   # (run, validation start, length)
    for r, (s, n) in enumerate(zip(starts.tolist(), lengths.tolist())):
        if n not in by_length:
            by_length[n] = validation_starts(ok, n)
        cuts += [(r, u, n) for u in nearest_starts(by_length[n], s, n, _VALIDATION_RUNS)]
    if not cuts:
        return share
    run_of, u, n = (np.array(c, dtype=np.intp) for c in zip(*cuts))
    margin = np.maximum(2 * n, 15)
    lo, hi = np.maximum(u - margin, 0), np.minimum(u + n + margin, T)
    bands_y, index = whittaker.stretch_bands(t, lo, hi, order)
    bands_o = whittaker.stretch_bands(t, lo, hi, off_order)[0]
    # the rows of each validation run (cut out: weight 0) among the stacked stretches
    first = np.cumsum(hi - lo) - (hi - lo)
    held = np.repeat(first + u - lo, n) + np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    wy, wo = w[index], wrel[index]
    wy[held] = 0.0
    wo[held] = 0.0
    h = float(np.median(np.diff(t)))
    lam = float(whittaker.lambda_for_cutoff(cut, float(w[w > 0].mean()), h, order))
    lam_off = float(whittaker.lambda_for_cutoff(cut_off, float(wrel[wrel > 0].mean()), h,
                                                off_order))
    own = whittaker.smooth(np.where(wy[:, None] > 0, y[index], 0.0), wy, t[index], lam,
                           order=order, bands=bands_y)[held]
    rel = whittaker.smooth(np.where(wo[:, None] > 0, off[index], 0.0), wo, t[index], lam_off,
                           order=off_order, bands=bands_o)[held]
    truth = y[index[held]]
    which = np.repeat(run_of, n)
    e_own = np.bincount(which, np.sum((own - truth) ** 2, axis=1), minlength=len(starts))
    e_parent = np.bincount(which, np.sum((parent[index[held]] + rel - truth) ** 2, axis=1),
                           minlength=len(starts))
    total = e_own + e_parent
    value = np.where(total > 0, e_own / np.where(total > 0, total, 1.0), _PARENT_SHARE)
    share[rows] = np.repeat(value, lengths)
    return share


@register
class KinectSkeleton(Cleaner):
    """Depth-sensor skeleton cleaning with tracking state, limb-swap repair, data-driven
    smoothing and bone lengths (see the module docstring)."""

    name = "kinect_skeleton"
    single_thread_blas = True
    summary = ("depth-sensor skeletons: leg-swap repair, tracking state as weights, GCV "
               "smoothing per joint and depth on the true time axis, outliers, lost samples "
               "from the parent joint and the joint's own smooth weighted by validation, bone "
               "lengths and the joint pairs the data shows rigid")
    params = (
        Param("order", "int", 3, "derivative penalised by the smoother (2: acceleration, "
              "3: jerk)", low=1, high=4),
        Param("cutoff", "frequency", None, "fixed smoothing cut-off instead of the GCV "
              "choice per joint (null: GCV)", unit="Hz", low=0.0, low_open=True, nullable=True),
        Param("inferred_noise", "length", "60 mm", "error assumed for Inferred joints",
              unit="mm", low=1e-4, high=2.0),
        Param("inferred_debias", "bool", True, "remove the offset of Inferred runs measured "
              "at their ends against the Tracked samples"),
        Param("debias_window", "int", 3, "samples on each side of an Inferred run's end "
              "that measure its offset (the jump there)", low=1, high=30),
        Param("debias_degree", "int", 1, "degree of the polynomial fitted on each side of "
              "the jump (1: unbiased for constant velocity)", low=0, high=3),
        Param("debiased_factor", "float", 0.3, "error of a debiased Inferred sample, as a "
              "share of inferred_noise", low=0.01, high=1.0),
        Param("swap_threshold", "length", "30 mm", "evidence (shorter leg paths and hip-knee "
              "bones closer to their lengths) a frame needs to be called leg-swapped; 0 "
              "disables", unit="mm", low=0.0),
        Param("outlier_k", "float", 4.5, "outlier threshold in noise σ (3-D)", low=1.0,
              high=100.0),
        Param("min_outlier", "length", "60 mm", "smallest residual ever called an outlier",
              unit="mm", low=0.0, low_open=True),
        Param("passes", "int", 2, "outlier rejection rounds", low=0, high=5),
        Param("max_gap", "time", "1.0 s", "longest gap filled (interior by the smooth, at "
              "the ends from the parent joint)", unit="s", low=0.0, nullable=True),
        Param("bone_stiffness", "float", 1.0, "share of each bone-length correction applied "
              "per sweep (0: no bone step)", low=0.0, high=1.0),
        Param("rigid_pairs", "float", 1.5, "joints two bones apart (the two hips, elbow and "
              "hand) are held at a constant distance like a bone when that distance varies "
              "no more than this many times what their noise explains (0: only the bones)",
              low=0.0, high=10.0),
        Param("depth_model", "bool", True, "let the jitter grow with camera depth"),
        Param("spatial_shrink", "bool", True, "denoise across joints by optimal singular-"
              "value shrinkage before the final smooth"),
        Param("local_steps", "int", 5, "strengths (cut-offs 0.5-2x the file's GCV choice) "
              "among which each stretch of the final smooth picks by its local Stein risk "
              "(1: one strength per joint)", low=1, high=15),
        Param("local_half", "int", 15, "half-width in frames of the window of the local risk",
              low=2, high=300),
        Param("fill_order", "int", 1, "derivative penalised when the offsets to the parent "
              "are smoothed through untrusted stretches", low=1, high=4),
        Param("validate_fills", "bool", True, "average each untrusted run's parent-based "
              "estimate with the joint's own smooth, weighted by their errors on runs of the "
              "same length cut where both joints were tracked (false: the parent-based "
              "estimate alone)"),
        Param("limb_frame", "bool", True, "estimate untrusted samples (inferred, missing, "
              "outliers) from the parent joint and the smoothed offset to it"),
    )

    def _apply(self, motion: Motion):
        try:
            return self._clean(motion)
        except np.linalg.LinAlgError:
            # the order-d penalty grows as 1 / step^(2d): at kilohertz rates, or with two
            # stamps a tick apart, the banded Cholesky of the smoother fails (it was an
            # "internal error LinAlgError: … not positive definite")
            t = (np.asarray(motion.times, dtype=np.float64) if motion.times is not None
                 else np.arange(len(motion.positions)) / motion.fps)
            steps = np.diff(t)
            shortest = float(steps[steps > 0].min()) if (steps > 0).any() else 1.0 / motion.fps
            raise ConfigError(
                f"{self.step}: its smoother's equations cannot be solved on this time axis "
                f"(shortest time step {shortest:.3g} s, {motion.fps:g} fps; order {self['order']}): "
                "it is made for depth-sensor rates (15-60 fps); check the frame rate (--fps) "
                "and the file's time stamps, or give a lower order") from None

    def _clean(self, motion: Motion):
        T, J, _ = motion.positions.shape
        info: dict = {}
        if T < 5 or J == 0:
            return motion.copy(), info
        mpu = motion.metres_per_unit
        P = motion.positions * mpu
        conf = (np.ones((T, J)) if motion.confidence is None
                else np.where(motion.missing, 0.0, motion.confidence))
        t = (np.asarray(motion.times, dtype=np.float64) if motion.times is not None
             else np.arange(T) / motion.fps)
        dt = np.diff(t)
        if np.any(dt < 0):                        # backward stamps: use indices
            t = np.arange(T) / motion.fps
        elif np.any(dt == 0):                     # repeated stamps: a quarter frame apart
            step = 0.25 / motion.fps
            t = t + step * np.cumsum(np.r_[0.0, dt == 0])
        parents = motion.skeleton.parents if motion.skeleton is not None else None
        names = list(motion.names)

        # gross errors are outliers from the start, taken out before anything looks at the
        # samples: left in, one 1e9 m value steered the first GCV smooth and moved its
        # whole joint by 0.3 m (1e10 m: 2.4 m), a -1e20 m depth turned the depth model off
        # for the whole file and the leg-swap test saw swaps that were not there
        seen = ~np.isnan(P).any(axis=2)
        centre = np.zeros((J, 3))
        centre[seen.any(axis=0)] = np.nanmedian(P[:, seen.any(axis=0)], axis=0)
        with np.errstate(invalid="ignore", over="ignore"):
            gross = seen & ~(norms(P - centre) <= NO_CAPTURE_VOLUME_M)
        P[gross] = np.nan

        # 1. leg confusion
        swapped = np.zeros(T, bool)
        thr = self.length("swap_threshold", motion) * mpu
        if thr > 0:
            swapped = leg_swap_frames(P, names, thr)
            for a, b in _side_pairs(names, _LEG):
                P[np.ix_(swapped, [a, b])] = P[np.ix_(swapped, [b, a])]
                conf[np.ix_(swapped, [a, b])] = conf[np.ix_(swapped, [b, a])]
        info["leg_swap_frames"] = int(swapped.sum())

        # 2-5. weights, noise model, GCV smoothing, outliers
        observed = ~np.isnan(P).any(axis=2)
        inferred = observed & (conf < 0.75)
        tracked = observed & ~inferred
        sig_inf = self.length("inferred_noise", motion) * mpu
        h = float(np.median(np.diff(t)))
        depth = P[..., 2]
        use_depth = self["depth_model"] and np.nanmin(depth) > 0.2 if observed.any() else False

        fixed = None if self["cutoff"] is None else self.hertz("cutoff")

        sub_cache = {}

        def bands_for(win, order):
            key = (win.start, win.stop, order)
            if key not in sub_cache:
                sub_cache[key] = whittaker.penalty_bands(t[win], order)
            return sub_cache[key]

        def coefficients_for(order):
            key = ("coefficients", order)
            if key not in sub_cache:
                sub_cache[key] = whittaker.difference_coefficients(t, order)
            return sub_cache[key]

        local_steps = self["local_steps"]
        spread = np.geomspace(0.5, 2.0, local_steps) if local_steps > 1 else None

        def fit(weights, data=None, cut=None, prev=None, joints=None, local=False,
                fit_order=None):
            """Per joint GCV smooth (``cut``: reuse these cut-offs, one solve per joint);
            only ``joints`` are refitted, the others are taken from ``prev``."""
            data = P if data is None else data
            order = self["order"] if fit_order is None else fit_order
            bands = bands_for(slice(0, T), order)
            Z = np.full_like(P, np.nan) if prev is None else prev.copy()
            new_cut = np.full(J, np.nan) if cut is None else cut.copy()

            def local_smooth(y, w, c, wbar):
                """The final smooth's strength varying along time (module docstring, 6)."""
                lams = whittaker.lambda_for_cutoff(c * spread, wbar, h, order)
                return whittaker.smooth_local_sure(
                    y, w, t, lams, order=order, bands=bands, half=self["local_half"],
                    coefficients=coefficients_for(order))[0]

            for j in (range(J) if joints is None else joints):
                w = weights[:, j]
                if (w > 0).sum() <= order + 1:
                    Z[:, j] = np.nan
                    continue
                y = np.where(w[:, None] > 0, data[:, j], 0.0)
                wbar = float(w[w > 0].mean())
                if fixed is not None or (cut is not None and np.isfinite(cut[j])):
                    c = fixed if fixed is not None else cut[j]
                    if local and spread is not None:
                        Z[:, j] = local_smooth(y, w, c, wbar)
                    else:
                        lam = float(whittaker.lambda_for_cutoff(c, wbar, h, order))
                        Z[:, j] = whittaker.smooth(y, w, t, lam, order=order, bands=bands)
                    new_cut[j] = c
                    continue
                # GCV on the middle _GCV_FRAMES frames of a long file, then one solve
                win = slice(max(0, (T - _GCV_FRAMES) // 2), max(0, (T - _GCV_FRAMES) // 2)
                            + min(T, _GCV_FRAMES))
                ww = w[win]
                if (ww > 0).sum() <= order + 1:
                    win, ww = slice(0, T), w
                wb = float(ww[ww > 0].mean())
                grid = whittaker.lambda_for_cutoff(_CUTOFFS, wb, h, order)[::-1]
                sub_bands = bands_for(win, order)
                zs, lam, _ = whittaker.smooth_gcv(y[win], ww, t[win], grid, order=order,
                                                  bands=sub_bands, refine=True)
                # the cut-off of the chosen λ (inverse of lambda_for_cutoff)
                c = (wb / (h * lam)) ** (1.0 / (2 * order)) / (2.0 * np.pi)
                new_cut[j] = c
                if local and spread is not None:
                    Z[:, j] = local_smooth(y, w, c, wbar)
                elif win == slice(0, T):
                    Z[:, j] = zs
                else:
                    lam = float(whittaker.lambda_for_cutoff(c, wbar, h, order))
                    Z[:, j] = whittaker.smooth(y, w, t, lam, order=order, bands=bands)
            cut = new_cut
            return Z, cut

        sig0 = 0.01
        w0 = np.where(tracked, 1.0 / sig0 ** 2, np.where(inferred, 1.0 / sig_inf ** 2, 0.0))
        zref = np.nanmedian(depth[observed]) if use_depth else 1.0

        def noise_model(cut=None):
            """First smooth with even weights; from its residuals the noise scale per
            joint, the depth exponent and σ (T, J) (step 3)."""
            Z, cut0 = fit(w0, cut=cut)
            res = norms(P - Z)
            p_exp = 0.0
            scale = np.full(J, sig0)
            ok = tracked & np.isfinite(res) & (res > 0)
            for j in range(J):
                if ok[:, j].sum() > 10:
                    # the 3-D residual norm of N(0, s² I) has median 1.5382 s
                    scale[j] = max(np.median(res[ok[:, j], j]) / 1.5382, 1e-4)
            if use_depth and ok.sum() > 50:
                zlog = np.log(depth[ok] / zref)
                rlog = np.log(res[ok] / scale[np.nonzero(ok)[1]])
                if np.var(zlog) > 1e-4:
                    p_exp = float(np.clip(np.cov(zlog, rlog)[0, 1] / np.var(zlog), 0.0, 2.0))
            with np.errstate(invalid="ignore"):
                rel = (np.nan_to_num(depth, nan=zref) / zref) ** p_exp if use_depth else 1.0
            return cut0, scale, p_exp, scale[None, :] * rel, res

        cut0, scale, p_exp, sigma, res0 = noise_model()
        P_read = P.copy()                        # after the swap repair, before debiasing

        # 3b. rigid pairs the skeleton does not list: held like bones from here on
        rigid = np.zeros((0, 2), dtype=np.intp)
        has_bones = motion.skeleton is not None and len(motion.skeleton.bones) > 0
        floor = self.length("min_outlier", motion) * mpu      # the smallest outlier (step 5)
        if self["rigid_pairs"] > 0 and self["bone_stiffness"] > 0 and has_bones:
            bones = motion.skeleton.bone_array
            window = max(3, int(round(_RIGID_WINDOW_S / max(h, 1e-9))))
            rigid = steady_pairs(P, tracked, two_bone_pairs(bones, J), scale, window=window,
                                 ratio=self["rigid_pairs"], min_frames=_RIGID_MIN_FRAMES)
            if len(rigid):
                links = np.vstack([rigid, bones])
                var = np.where(inferred, np.maximum(sigma, sig_inf) ** 2, sigma ** 2)
                # a Tracked sample the first smooth calls an outlier stays out of the
                # projection (as if missing) and as it was: it would drag its neighbours
                # along, and step 5 is where outliers are judged and reported (an Inferred
                # sample's large variance already makes it take the corrections)
                with np.errstate(invalid="ignore"):
                    far = tracked & (res0 > np.maximum(self["outlier_k"] * sigma, floor))
                held = project_lengths(np.where(far[..., None], np.nan, P), links,
                                       median_lengths(P, tracked & ~far, links), var, sweeps=4,
                                       stiffness=self["bone_stiffness"])
                P = np.where(far[..., None], P, held)
                cut0, scale, p_exp, sigma, _ = noise_model(cut=cut0)
        info["rigid_pairs"] = [f"{names[a]}-{names[b]}" for a, b in rigid]
        debiased = 0
        if self["inferred_debias"] and inferred.any() and tracked.any():
            # an Inferred run is the joint plus a slowly changing offset: the offset is
            # read at the run's ends against the smooth of the Tracked samples alone
            # and removed, linearly in between; what is left is trusted more
            col, start, length = runs(inferred)
            kk, deg = self["debias_window"], self["debias_degree"]
            first, last, ok0, ok1 = run_offsets.run_end_offsets(
                t, P, inferred, tracked, col, start, length, k=kk, degree=deg)
            Zt = None
            if not (ok0.all() and ok1.all()):
                # an end without enough Tracked samples next to it: its offset against the
                # smooth of the Tracked samples alone (two frames)
                need = np.unique(col[~(ok0 & ok1)])
                Zt, _ = fit(np.where(tracked, 1.0 / sigma ** 2, 0.0), cut=cut0, joints=need)
            for r, (j, s0, n) in enumerate(zip(col, start, length)):
                e = s0 + n
                ends = []
                if ok0[r]:
                    ends.append((0.0, first[r]))
                elif s0 > 0 and tracked[s0 - 1, j]:
                    ends.append((0.0, np.mean(P[s0:min(e, s0 + 2), j] - Zt[s0:min(e, s0 + 2), j], axis=0)))
                if ok1[r]:
                    ends.append((1.0, last[r]))
                elif e < T and tracked[e, j]:
                    ends.append((1.0, np.mean(P[max(s0, e - 2):e, j] - Zt[max(s0, e - 2):e, j], axis=0)))
                ends = [(u, b) for u, b in ends if np.isfinite(b).all()]
                if not ends:
                    continue
                if len(ends) == 1:
                    offset = np.broadcast_to(ends[0][1], (n, 3))
                else:
                    u = ((t[s0:e] - t[s0]) / max(t[e - 1] - t[s0], 1e-9))[:, None]
                    offset = ends[0][1] * (1.0 - u) + ends[1][1] * u
                P[s0:e, j] = P[s0:e, j] - offset
                debiased += n
            sig_inf = sig_inf * self["debiased_factor"]
        info["inferred_debiased"] = int(debiased)
        sigma_inf = np.maximum(sigma, sig_inf)
        weights = np.where(tracked, 1.0 / sigma ** 2, np.where(inferred, 1.0 / sigma_inf ** 2, 0.0))
        flagged = np.zeros((T, J), bool)
        Z, cut = fit(weights, cut=cut0)
        for _ in range(self["passes"] + 1):
            res = norms(P - Z)
            # a stretch the smooth cannot follow (fast motion, sparse rows) has large
            # residuals all along and is not an outlier: Hampel's local scale
            local = np.nan_to_num(moving_median(np.where(observed, res, np.nan), 3)) / 1.5382
            base = np.maximum(np.where(tracked, sigma, sigma_inf), local)
            limit = np.maximum(self["outlier_k"] * base, floor)
            new = observed & (res > limit) & ~flagged
            # off the smooth is a suspicion; the joint's own path must contradict it
            new &= contradicted_by_path(P, new | flagged)
            if not new.any():
                break
            flagged |= new
            Z, cut = fit(np.where(flagged, 0.0, weights), cut=cut, prev=Z,
                         joints=np.flatnonzero(new.any(axis=0)))
        if self["spatial_shrink"] and T > 3 * J:
            # the joints move together: optimal singular-value shrinkage (Gavish & Donoho
            # 2017) of the noise-whitened (T, 3J) trajectories, then the smoother again
            trusted = tracked & ~flagged
            Y = np.where(trusted[..., None], P, Z)
            okrow = ~np.isnan(Y).any(axis=(1, 2))
            if okrow.sum() > 3 * J:
                sd = np.repeat(sigma.mean(axis=0), 3)
                X = Y[okrow].reshape(-1, 3 * J) / sd
                mean = X.mean(axis=0)
                # (embedding 3-10 lagged frames per row measured 8.8 mm against 8.95 on
                # the jitter scenario, at 6-10x the cost: not worth it)
                Xs, rank = svshrink.shrink_frobenius(X - mean, 1.0)
                Y2 = np.full_like(Y, np.nan)
                Y2[okrow] = ((Xs + mean) * sd).reshape(-1, J, 3)
                w2 = np.where(trusted & okrow[:, None], weights, 0.0)
                Z2, _ = fit(w2, np.where(np.isnan(Y2), 0.0, Y2), cut=cut, local=True)
                Z = np.where(trusted[..., None] & okrow[:, None, None], Z2, Z)
                info["spatial_rank"] = rank
        # a joint seen on too few samples to smooth (order + 1 or fewer) keeps them as read
        unsmoothed = np.isnan(Z).any(axis=2) & observed & ~flagged
        Z[unsmoothed] = P[unsmoothed]
        if self["limb_frame"] and parents is not None:
            # untrusted samples (inferred, missing, outliers) from the parent: the smooth of
            # the joint's offset to its parent, added to the parent's estimate, parents
            # first -- an occluded hand follows the tracked elbow
            trusted = tracked & ~flagged
            with np.errstate(divide="ignore"):
                var = np.where(flagged, np.inf, 1.0 / weights)
            has_parent = parents >= 0
            pidx = np.where(has_parent, parents, 0)
            wrel = np.where(has_parent[None, :], 1.0 / (var + var[:, pidx]), 0.0)
            need = np.flatnonzero((~trusted).any(axis=0) & has_parent)
            Zr, cut_r = fit(wrel, P - P[:, pidx], joints=need, fit_order=self["fill_order"])
            wtrust = np.where(flagged, 0.0, weights)
            for j in _topological(parents):
                pj = parents[j]
                if pj < 0:
                    continue
                rows = ~(tracked | inferred)[:, j] | flagged[:, j]
                rows &= ~np.isnan(Zr[:, j]).any(axis=1)
                if not rows.any():
                    continue
                share = 1.0
                if self["validate_fills"]:
                    both = trusted[:, j] & trusted[:, pj]
                    share = validated_shares(
                        rows, both, t, P[:, j], wtrust[:, j], cut[j], self["order"],
                        P[:, j] - P[:, pj], Z[:, pj], wrel[:, j], cut_r[j],
                        self["fill_order"])[rows, None]
                from_parent, own = Z[rows, pj] + Zr[rows, j], Z[rows, j]
                # one estimate missing (a joint too rarely seen for its own smooth): the other
                Z[rows, j] = np.where(np.isnan(own), from_parent, np.where(
                    np.isnan(from_parent), own, share * from_parent + (1.0 - share) * own))
        replaced = flagged & observed | gross
        info[REPLACED_FRAMES] = {names[j]: np.flatnonzero(replaced[:, j]).tolist()
                                 for j in np.flatnonzero(replaced.any(axis=0))}
        info.update(outliers=int((flagged | gross).sum()), depth_exponent=round(p_exp, 3),
                    noise_mm={names[j]: round(float(scale[j]) * 1e3, 2) for j in range(J)},
                    cutoff_hz={names[j]: round(float(c), 2) for j, c in enumerate(cut)
                               if np.isfinite(c)})

        # 6. fill: interior gaps by the smooth, ends from the parent
        missing = ~observed
        max_gap = self["max_gap"]
        gap_frames = None if max_gap is None else self.frames("max_gap", motion)
        interior = fillable(missing, gap_frames)
        out = np.where((observed | interior)[..., None], Z, np.nan)
        if parents is not None:
            end_limit = T if gap_frames is None else gap_frames
            _fill_ends_from_parent(out, missing, parents, _topological(parents), end_limit)

        # 7. bones
        k = self["bone_stiffness"]
        if k > 0 and has_bones:
            bones = motion.skeleton.bone_array
            good = tracked & ~flagged
            lengths = np.full((T, len(bones)), np.nan)
            constant = np.zeros(len(bones), bool)
            for i, (a, b) in enumerate(bones):
                seen = observed[:, a] & observed[:, b]
                raw = norms(P_read[seen, a] - P_read[seen, b])
                if len(raw) >= 3 and np.ptp(raw) <= max(2e-5 * np.max(raw), 1e-5):
                    # stored constant to the file's 6 decimals
                    constant[i], lengths[:, i] = True, float(np.median(raw))
                    continue
                both = good[:, a] & good[:, b]
                if both.sum() < 3:                # never both tracked: every frame seen
                    both = seen & ~flagged[:, a] & ~flagged[:, b]
                if both.sum() < 3:
                    continue
                # one length per bone (letting it drift below 0.3-1 Hz kept UTKinect's
                # bone variation at 0.11-0.13 of 0.14: its bones change slowly with pose)
                lengths[:, i] = np.median(norms(out[both, a] - out[both, b]))
            var = np.where(tracked & ~flagged, sigma ** 2,
                           np.where(inferred & ~flagged, sig_inf ** 2, (2 * sig_inf) ** 2))
            # the rigid pairs (if any) first: the bones, last, end nearest their lengths
            pair_len = np.broadcast_to(median_lengths(out, good, rigid, min_frames=3),
                                       (T, len(rigid)))
            out = project_lengths(out, np.vstack([rigid, bones]), np.hstack([pair_len, lengths]),
                                  var, sweeps=8, stiffness=k)
            # bones the file stores at an exactly constant length (MSR Action3D) end
            # exactly at it: the child is put back on the sphere, parents first
            rank = {j: r for r, j in enumerate(_topological(motion.skeleton.parents))}
            for i in sorted(np.flatnonzero(constant), key=lambda i: rank[int(bones[i][1])]):
                a, b = bones[i]
                d = out[:, b] - out[:, a]
                n = norms(d)[:, None]
                with np.errstate(invalid="ignore", divide="ignore"):
                    out[:, b] = np.where(n > 0, out[:, a] + d * (lengths[:, i, None] / n), out[:, b])
            info["constant_bones"] = int(constant.sum())
        return motion.replace(positions=out / mpu), info
