"""``kinect_skeleton``: clean depth-sensor skeletons (Kinect v1/v2/Azure, MSR, UTKinect)
using their tracking state and their bones.

Written for mocapfix (issue 12); each stage cites the method it uses. The stages are
kernels in :mod:`mocapfix.solvers.depth_skeleton`; this module holds the parameters and
runs them in order:

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
   :func:`mocapfix.solvers.depth_skeleton.validated_shares`, the validation idea of ``fill_ensemble``): the parent-based
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
(``benchmarks/kinect_priors.py``). Smoothing cluster centroids (hand, foot, pelvis,
shoulders) and offsets to them separately, and shrinkage across joints in a body frame or
in 1-8 s windows, measured 8.45-8.65 mm against 8.46 (4 files, seed 0); the ICI rule
(Katkovnik 1999) in place of the local Stein risk 8.58-10.0. A Gaussian-mixture prior over
8-frame windows of each body part (EPLL-style; ``benchmarks/kinect_gmm_prior.py``), trained on
the same corpus, 0.765 alone and 0.648 blended 0.3 with this cleaner's output (0.682), the
best trained prior measured; trained on the test motions' own truth, 0.626 / 0.592: not
shipped (a model of several MB and a blend weight for a 0.03 gain, short of 0.6)."""
from __future__ import annotations

import numpy as np

from mocapfix.cleaners import register
from mocapfix.cleaners.base import REPLACED_FRAMES, Cleaner, Param
from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion
from mocapfix.solvers import depth_skeleton as ds


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
        t = ds.time_axis(motion.times, motion.fps, T)
        parents = motion.skeleton.parents if motion.skeleton is not None else None
        has_bones = motion.skeleton is not None and len(motion.skeleton.bones) > 0
        names = list(motion.names)
        gross = ds.gross_errors(P)
        P[gross] = np.nan
        P, conf, swapped = ds.repair_leg_swaps(P, conf, names,
                                               self.length("swap_threshold", motion) * mpu)
        info["leg_swap_frames"] = int(swapped.sum())

        # 2-3. tracking state, the noise model, the rigid pairs
        observed = ~np.isnan(P).any(axis=2)
        inferred = observed & (conf < 0.75)
        tracked = observed & ~inferred
        sig_inf = self.length("inferred_noise", motion) * mpu
        depth = P[..., 2]
        use_depth = self["depth_model"] and np.nanmin(depth) > 0.2 if observed.any() else False
        zref = np.nanmedian(depth[observed]) if use_depth else 1.0
        smooth = ds.Smoothing(t, self["order"], None if self["cutoff"] is None else self.hertz("cutoff"),
                              np.geomspace(0.5, 2.0, self["local_steps"]) if self["local_steps"] > 1 else None,
                              self["local_half"])
        w0 = np.where(tracked, 1.0 / ds.FIRST_SIGMA ** 2, np.where(inferred, 1.0 / sig_inf ** 2, 0.0))
        noise = ds.noise_model(smooth, P, w0, tracked, depth, use_depth, zref)
        P_read = P.copy()                        # after the swap repair, before debiasing
        rigid = np.zeros((0, 2), dtype=np.intp)
        floor = self.length("min_outlier", motion) * mpu      # the smallest outlier (stage 5)
        if self["rigid_pairs"] > 0 and self["bone_stiffness"] > 0 and has_bones:
            P, rigid = ds.hold_rigid_pairs(P, motion.skeleton.bone_array, tracked, inferred, noise,
                                           sig_inf, floor, self["outlier_k"], self["rigid_pairs"],
                                           self["bone_stiffness"], smooth.h)
            if len(rigid):
                noise = ds.noise_model(smooth, P, w0, tracked, depth, use_depth, zref, cut=noise.cut)
        info["rigid_pairs"] = [f"{names[a]}-{names[b]}" for a, b in rigid]
        sigma = noise.sigma
        debiased = 0
        if self["inferred_debias"] and inferred.any() and tracked.any():
            P, debiased = ds.debias_inferred(smooth, P, inferred, tracked, sigma, noise.cut,
                                             self["debias_window"], self["debias_degree"])
            sig_inf = sig_inf * self["debiased_factor"]
        info["inferred_debiased"] = int(debiased)

        # 4-6. smooth, outliers, shrinkage across joints, untrusted samples from the parent
        sigma_inf = np.maximum(sigma, sig_inf)
        weights = np.where(tracked, 1.0 / sigma ** 2, np.where(inferred, 1.0 / sigma_inf ** 2, 0.0))
        Z, cut, flagged = ds.reject_outliers(smooth, P, weights, observed, tracked, sigma, sigma_inf,
                                             noise.cut, self["outlier_k"], floor, self["passes"])
        if self["spatial_shrink"] and T > 3 * J:
            Z, rank = ds.shrink_across_joints(smooth, P, Z, tracked & ~flagged, weights, sigma, cut)
            if rank is not None:
                info["spatial_rank"] = rank
        # a joint seen on too few samples to smooth (order + 1 or fewer) keeps them as read
        unsmoothed = np.isnan(Z).any(axis=2) & observed & ~flagged
        Z[unsmoothed] = P[unsmoothed]
        if self["limb_frame"] and parents is not None:
            Z = ds.estimate_from_parents(smooth, P, Z, parents, tracked, inferred, flagged, weights,
                                         cut, self["fill_order"], self["validate_fills"])
        replaced = flagged & observed | gross
        info[REPLACED_FRAMES] = {names[j]: np.flatnonzero(replaced[:, j]).tolist()
                                 for j in np.flatnonzero(replaced.any(axis=0))}
        info.update(outliers=int((flagged | gross).sum()), depth_exponent=round(noise.depth_exponent, 3),
                    noise_mm={names[j]: round(float(noise.scale[j]) * 1e3, 2) for j in range(J)},
                    cutoff_hz={names[j]: round(float(c), 2) for j, c in enumerate(cut)
                               if np.isfinite(c)})

        # 7-8. fill, bones
        gap_frames = None if self["max_gap"] is None else self.frames("max_gap", motion)
        out = ds.fill_gaps(Z, observed, parents, gap_frames)
        if self["bone_stiffness"] > 0 and has_bones:
            out, info["constant_bones"] = ds.hold_bone_lengths(
                out, P_read, motion.skeleton.bone_array, motion.skeleton.parents, rigid, observed,
                tracked, inferred, flagged, sigma, sig_inf, self["bone_stiffness"])
        return motion.replace(positions=out / mpu), info
