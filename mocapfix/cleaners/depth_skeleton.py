"""``kinect_skeleton``: clean depth-sensor skeletons (Kinect v1/v2/Azure, MSR, UTKinect)
using their tracking state and their bones.

Written for mocapfix (issue 12); each stage cites the method it uses. The stages are
kernels in :mod:`mocapfix.solvers.depth_skeleton`; this module holds the parameters and
runs them in order:

1. **Limb confusion**: left/right leg chains exchanged back on the frames a two-state
   Viterbi path on their frame-to-frame travel labels exchanged (``swap_threshold`` per
   exchanged frame; :func:`mocapfix.solvers.depth_skeleton.leg_swap_frames`).
2. **Tracking state → weights**: NotTracked 0, Inferred σ ``inferred_noise`` (with
   ``inferred_debias`` an Inferred run's offset, read at both ends of the run by
   :mod:`mocapfix.solvers.run_offsets`, is removed first), Tracked σ_j(z).
3. **Noise model from the data**: ``σ_j(z) = s_j (z / z̄)^p`` from the residuals of a
   first smooth; joint pairs two bones apart that the data shows rigid
   (``rigid_pairs``, :func:`mocapfix.solvers.bone_projection.steady_pairs`) are held
   like bones.
4. **Smoothing set by the data**: per joint a weighted Whittaker smoother on the true
   time axis, strength by GCV (:mod:`mocapfix.solvers.whittaker`), penalty order
   ``order``.
5. **Outliers**: residuals above ``max(outlier_k max(σ, σ_local), min_outlier)`` that the
   joint's own path contradicts (:func:`mocapfix.solvers.glitches.contradicted_by_path`)
   get weight 0 and the joint is refitted (``passes``).
6. **Untrusted samples from the parent** (``limb_frame``): the parent's estimate plus the
   smoothed offset to it, averaged with the joint's own smooth by validation
   (``validate_fills``, :func:`mocapfix.solvers.depth_skeleton.validated_shares`); before
   that, singular-value shrinkage across joints (``spatial_shrink``,
   :mod:`mocapfix.solvers.svshrink`) and a smooth whose strength varies along time by
   Stein's risk (``local_steps``, :func:`mocapfix.solvers.whittaker.smooth_varying`).
7. **Fill**: gaps of at most ``max_gap`` from the smooth, or from the parent at the ends.
8. **Bones**: positions projected toward the median bone (and rigid pair) lengths
   (:func:`mocapfix.solvers.bone_projection.project_lengths`, ``bone_stiffness``); bones
   constant in the input keep their length exactly.

The output keeps the file's rows and timestamps (the writers change only samples).
Why each stage is as it is, what was measured and what was tried and not used:
docs/methods/kinect_skeleton.md."""
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
