"""Trust-data detection and temporal-stable robust matrix completion (Feng et al. 2014,
"Exploiting temporal stability and low-rank structure for motion capture data refinement",
Information Sciences 277).

``trust`` (Algorithm 1): every channel is smoothed by robust penalised least squares
(eq. 11–12, Welsch weights, smoothing parameter by GCV, eq. 16–18;
:func:`mocapfix.solvers.dct.robust_smooth`) and a sample is untrusted when its 3-D
distance to the smooth exceeds ``θ`` (eq. 19) or the reader gave it a low confidence.
``θ`` is ``threshold`` robust standard deviations of the marker's residual, clipped to
[``min_threshold``, ``max_threshold``]. Gross errors (a corrupt field metres off) are
untrusted before the smoothing starts. Untrusted samples are made missing (default),
replaced by the smooth (eq. 20) or only reported.

``tsmc`` (Algorithm 2): with the channels as rows and scaled to cm, the model of eq. 8/21

    min ||Y||_* + α ||Ω∘E||_1 + β/2 ||M O||_F²   s.t.  Y + E = X,  Y = M,

solved by the inexact augmented Lagrange multiplier method (singular value thresholding
for Y with :func:`mocapfix.solvers.lowrank.svt`, masked soft-thresholding for E, the DCT
solve of :mod:`mocapfix.solvers.dct` for M). Ω is "observed and confident". With
``prior: pca`` (default) X is each marker's deviation from its PPCA prediction by the
other markers of the same frame; ``prior: none`` is the paper's model. Fills that leave
the capture volume or jump more than ``max_step`` × the marker's largest step are left
missing.

What we changed from the paper (the PCA prior, β = 3, gap bridging, padding, γ and tol,
the rejected fills) and the measurements behind each: docs/methods/tsmc.md.
"""
from __future__ import annotations


import numpy as np

from mocapfix.cleaners import register
from mocapfix.cleaners.base import NOT_ESTIMATED, REJECTED_FILLS, Cleaner, FillGate, Param
from mocapfix.core.motion import Motion
from mocapfix.solvers import dct, glitches, segments
from mocapfix.solvers import tsmc as tsmc_kernels
from mocapfix.solvers.lowrank import leave_block_out_residual, ppca_fit
from mocapfix.solvers.pca_gapfill import fill_gaps_pca
from mocapfix.solvers.rigid import body_frame, to_global, to_local
from mocapfix.solvers.segments import implausible_runs, linear_bridge

_CM = 100.0  # cm per metre


def _cm_per_unit(motion: Motion) -> float:
    return motion.metres_per_unit * _CM


def _confident(motion: Motion, min_confidence: float) -> np.ndarray:
    """(T, J) True where the reader's confidence is at least ``min_confidence``."""
    if motion.confidence is None:
        return np.ones(motion.positions.shape[:2], dtype=bool)
    return np.nan_to_num(motion.confidence, nan=0.0) >= min_confidence


def _pad_frames(cleaner: Cleaner, motion: Motion) -> int:
    T = motion.n_frames
    return int(min(round(cleaner.frames("pad", motion)), max(T - 1, 0)))


@register
class Trust(Cleaner):
    """Trust-data detection (Feng 2014, Algorithm 1): robust GCV smoothing per channel,
    samples far from the smooth (or with low reader confidence) are untrusted and made
    missing (``untrusted: flag``), replaced by the smooth (``replace``, eq. 20) or only
    counted (``keep``). See the module docstring. A sample far from the smooth stays
    trusted unless its marker's own path contradicts it
    (:func:`mocapfix.solvers.glitches.contradicted_by_path`: a spike thrown out and back,
    not a fast turn the smooth cuts); the count of those is ``kept_by_path``."""

    name = "trust"
    single_thread_blas = True
    summary = "flag untrusted samples (robust GCV smoothing residual, Feng 2014 Alg. 1)"
    flags_samples = True
    params = (
        Param("threshold", "float", 5.0, "θ in robust standard deviations of the marker's "
              "residual to the robust smooth", low=1.0, high=100.0),
        Param("min_threshold", "length", "10 mm", "smallest θ (floor for clean markers)",
              unit="mm", low=0.0, low_open=True),
        Param("max_threshold", "length", "60 mm", "largest θ (the paper's fixed 6 cm)",
              unit="mm", low=0.0, low_open=True),
        Param("welsch", "length", None, "Welsch scale p of the robust weights (paper: 5 cm; "
              "default: θ of the marker)", unit="mm", low=0.0, low_open=True, nullable=True),
        Param("iterations", "int", 6, "robust re-weighting steps per stage", low=1, high=100),
        Param("min_confidence", "float", 0.5, "samples with reader confidence below this "
              "are untrusted", low=0.0, high=1.0),
        Param("untrusted", "choice", "flag", "what to do with untrusted samples",
              choices=("flag", "replace", "keep")),
        Param("pad", "time", "0.5 s", "end padding before the DCT smoothing", unit="s",
              low=0.0),
    )

    def _validate(self):
        from mocapfix.core.errors import ConfigError
        if self["min_threshold"].si > self["max_threshold"].si:
            raise ConfigError(f"{self.step}: min_threshold must not exceed max_threshold")

    def _apply(self, motion: Motion):
        pos = motion.positions
        T, J, _ = pos.shape
        observed = ~motion.missing
        info = {"untrusted": 0, "untrusted_per_joint": {}}
        if T < 3 or not observed.any():
            return motion.copy(), info
        confident = _confident(motion, self["min_confidence"])
        weights = np.where(confident & observed, 1.0 if motion.confidence is None else
                           np.clip(np.nan_to_num(motion.confidence), 0.0, 1.0), 0.0)
        # gross errors are untrusted from the start: one sample 1 km off (1e6 mm) steered
        # the first robust smooth and all 810 samples of its marker on CMU 85_02 came out
        # untrusted (deleted, then refilled from the other markers; 100 m: 731 of 810)
        gross = tsmc_kernels.gross_errors(motion.positions, motion.fps, motion.metres_per_unit)
        weights[gross] = 0.0
        welsch = None if self["welsch"] is None else self.length("welsch", motion)
        trusted, smooth, theta, mu = tsmc_kernels.trust_mask(
            pos, weights, self["threshold"], self.length("min_threshold", motion),
            self.length("max_threshold", motion), self["iterations"], _pad_frames(self, motion),
            welsch)
        # far from the robust smooth is a suspicion; the marker's own path must contradict
        # it (a spike thrown out and back, not a fast turn the smooth cuts)
        far = observed & (weights > 0) & ~trusted
        kept = far & ~glitches.contradicted_by_path(pos, far)
        untrusted = observed & ~trusted & ~kept
        out = pos.copy()
        if self["untrusted"] == "flag":
            out[untrusted] = np.nan
        elif self["untrusted"] == "replace":
            out[untrusted] = smooth[untrusted]
        per = untrusted.sum(axis=0)
        mm = motion.metres_per_unit * 1e3
        info = {
            "untrusted": int(per.sum()),
            "untrusted_low_confidence": int((observed & ~confident).sum()),
            "untrusted_gross": int(gross.sum()),
            "kept_by_path": int(kept.sum()),
            "untrusted_per_joint": {motion.names[j]: int(per[j]) for j in np.flatnonzero(per)},
            "threshold_mm": {"median": round(float(np.median(theta)) * mm, 3),
                             "max": round(float(np.max(theta)) * mm, 3)},
            "mu_median": float(np.median(mu)),
        }
        return motion.replace(positions=out), info


@register
class TSMC(Cleaner):
    """Temporal-stable robust matrix completion (Feng 2014, Algorithm 2): fills missing and
    untrusted samples from a low-rank, temporally smooth model of all channels at once —
    by default of each marker's deviation from its PCA prediction by the other markers
    (``prior: pca``). Run ``trust`` before it to turn outliers into missing samples. See
    the module docstring."""

    name = "tsmc"
    single_thread_blas = True
    #: under the pipeline's ``max_fill_error`` it fills nothing (no estimate of its fills'
    #: error): the completion is not run, and ``observed: auto``/``smooth`` smooth the
    #: measured samples of channels bridged linearly across their gaps
    gated = True
    summary = ("fill gaps and untrusted samples: PCA prediction from the other markers + "
               "low-rank, smooth completion of the rest (Feng 2014 TSMC)")
    params = (
        Param("alpha", "float", 1.0, "weight of the sparse-error term (per cm)", low=0.0,
              low_open=True),
        Param("beta", "float", 3.0, "weight of the smoothness term (cm scale; paper: 100)",
              low=0.0),
        Param("gamma", "float", 1.5, "growth of the ALM penalties per iteration", low=1.0,
              low_open=True, high=10.0),
        Param("tol", "float", 1e-2, "stop when the relative constraint residual is below",
              low=0.0, low_open=True, high=1.0),
        Param("max_iter", "int", 300, "iteration cap", low=1, high=100000),
        Param("penalty0", "float", 1.25, "initial ALM penalties λ1 = λ2, times 1/||X||_2 "
              "(Lin, Chen & Ma 2010 use 1.25)", low=1e-9, high=1e9),
        Param("observed", "choice", "auto", "observed samples: keep them, replace by the "
              "model (paper), smooth every channel by GCV, or smooth only noisy channels",
              choices=("keep", "model", "smooth", "auto")),
        Param("noise_floor", "length", "0.1 mm", "observed: auto smooths channels whose "
              "GCV noise estimate exceeds this", unit="mm", low=0.0),
        Param("min_confidence", "float", 0.5, "samples with reader confidence below this "
              "are re-estimated", low=0.0, high=1.0),
        Param("min_observed", "float", 0.2, "frames with fewer than this fraction of the "
              "markers trusted are not filled (fill_pca: 0.5; the temporal model bridges "
              "sparser frames)", low=0.0, high=1.0),
        Param("bridge", "time", "0.2 s", "the model's offset from the samples at a gap's "
              "edges is carried into the gap, fading with this time constant (null: no "
              "fading)", unit="s", low=0.0, low_open=True, nullable=True),
        Param("prior", "choice", "pca", "what the low-rank + smooth model completes: 'pca' "
              "— each marker's deviation from its prediction by the other markers of the "
              "frame (PPCA of the fill_pca-prefilled body-frame data); 'none' — the centred "
              "channels themselves (the paper)", choices=("pca", "none")),
        Param("prior_variance", "float", 0.95, "prior: pca — fraction of the pose variance "
              "the prior's components keep", low=0.5, high=1.0),
        Param("frame", "choice", "body", "prior: none — coordinates of the completion: "
              "'body' (each frame rigidly aligned to the mean marker shape, as fill_pca "
              "does) or 'global'", choices=("body", "global")),
        Param("pad", "time", "0.5 s", "missing frames added at each end before solving",
              unit="s", low=0.0),
        Param("max_step", "float", 3.0, "a filled run that (joined to the samples around it) "
              "moves further from one frame to the next than this many times the marker's "
              "largest trusted step is left missing (0: no such check)", low=0.0, high=1e6),
    )

    def _apply(self, motion: Motion, gate: FillGate | None = None):
        pos = motion.positions
        T, J, _ = pos.shape
        observed = ~motion.missing
        info = {"iterations": 0, "residual": 0.0, "converged": True}
        rows = observed.any(axis=0)                  # markers with at least one sample
        if T < 2 or not rows.any():
            return motion.copy(), info
        trusted = observed & _confident(motion, self["min_confidence"])
        mode = self["observed"]
        if gate is not None:
            # no estimate of the completion's error: under the gate it fills nothing, and
            # the samples it would re-estimate (low reader confidence) stay as measured
            if mode in ("keep", "model"):
                return motion.copy(), {**info, "skipped_fills": NOT_ESTIMATED}
            trusted = observed
        cols = np.repeat(rows, 3)
        omega = np.repeat(trusted, 3, axis=1)[:, cols]
        x = pos.reshape(T, 3 * J)[:, cols]
        p = dct.fast_pad(T, _pad_frames(self, motion))
        if gate is not None and not omega.all():
            # the channels bridged across their gaps, only for the smoothing of the
            # measured samples: the completion is not run
            est = linear_bridge(np.where(omega, x, np.nan))
            sinfo = {"iterations": 0, "residual": 0.0, "converged": True, "rank": None,
                     "skipped_fills": NOT_ESTIMATED}
        elif mode == "model" or not omega.all():
            fill, sinfo = self._complete(motion, trusted, rows, p)
            est = fill if mode == "model" else np.where(omega, x, fill)
        else:   # every sample trusted: the completion would return the data unchanged
            est = x
            sinfo = {"iterations": 0, "residual": 0.0, "converged": True, "rank": None}
        smoothed_channels = 0
        if mode in ("smooth", "auto"):
            # the noise is judged on the trusted samples with linear bridges, not on the
            # model's fills (a poor fill distorts the smooth around it); the two smooths
            # are independent: on the task's threads. Under the gate the channels are
            # those bridges already: one smooth gives both
            from mocapfix.core.threads import parallel_map

            if gate is not None:
                smoothed, noise = tsmc_kernels.gcv_denoise(est, p, omega)
            else:
                bridged = linear_bridge(np.where(omega, x, np.nan))
                (smoothed, _), (_, noise) = parallel_map(
                    lambda args: tsmc_kernels.gcv_denoise(*args), [(est, p), (bridged, p, omega)])
            noisy = noise > self.length("noise_floor", motion) if mode == "auto" \
                else np.ones(noise.shape, bool)
            est = np.where(noisy[None, :], smoothed, est)
            smoothed_channels = int(noisy.sum())
        out = pos.copy().reshape(T, 3 * J)
        out[:, cols] = est
        out = out.reshape(T, J, 3)
        seen = rows.sum()
        frame_ok = trusted[:, rows].sum(axis=1) >= max(3, self["min_observed"] * seen)
        written = ~trusted & rows[None, :] & frame_ok[:, None]
        if gate is not None:
            out[~observed] = np.nan                 # the bridges are not fills
            written[:] = False
        out[~trusted & rows[None, :] & ~frame_ok[:, None]] = np.nan   # too few markers seen
        outside = jumped = np.zeros(written.shape, bool)
        if written.any():
            outside = implausible_runs(out, written, pos[trusted])
            jumped = segments.discontinuous_runs(out, written & ~outside,
                                                 segments.largest_steps(pos, trusted),
                                                 self["max_step"])
        rejected = outside | jumped
        out[rejected] = np.nan
        untrusted = observed & ~trusted
        per = untrusted.sum(axis=0)
        info = dict(sinfo)
        info["residual"] = float(sinfo["residual"])
        info.update({
            "untrusted": int(per.sum()),
            "untrusted_per_joint": {motion.names[j]: int(per[j]) for j in np.flatnonzero(per)},
            "filled": int((written & ~rejected).sum()),
            "rejected_samples": int(rejected.sum()),
            REJECTED_FILLS: segments.rejected_fills(motion.names, {
                "its fill left the capture volume": outside,
                f"its fill jumped more than {self['max_step']:g}x the marker's largest measured "
                "step in one frame": jumped}),
            "smoothed_channels": smoothed_channels,
            "correction_mm_max": round(float(np.nanmax(np.abs(
                np.where(np.repeat(trusted, 3, axis=1)[:, cols], est - x, 0.0)), initial=0.0))
                * motion.metres_per_unit * 1e3, 3),
        })
        return motion.replace(positions=out), info

    def _complete(self, motion: Motion, trusted: np.ndarray, rows: np.ndarray, p: int):
        """The completed channels (T, 3 × markers with samples): prior + the TSMC model of
        the trusted samples' deviation from it, plus the bridged residual of the samples
        at each gap's edges unless ``observed: model``."""
        pos = motion.positions
        T, J, _ = pos.shape
        cols = np.repeat(rows, 3)
        omega = np.repeat(trusted, 3, axis=1)[:, cols]
        back = None
        if self["prior"] == "pca":
            x, back = self._pca_frame(motion, trusted, rows)
            mean, W, sigma2, _ = ppca_fit(x, self["prior_variance"])
            centre = x - leave_block_out_residual(x, mean, W, sigma2)
        else:
            x = pos.reshape(T, 3 * J)[:, cols]
            if self["frame"] == "body":
                hold = 0.05 * motion.fps   # end gaps this short keep their marker in the fit
                work, back = tsmc_kernels.moving_reference(np.where(trusted[..., None], pos, np.nan),
                                              trusted, hold)
                x = work.reshape(T, 3 * J)[:, cols]
            centre = linear_bridge(np.where(omega, x, np.nan)).mean(axis=0)
        s = _cm_per_unit(motion)
        xc = np.where(omega, (x - centre) * s, 0.0)
        xp, p = dct.pad_missing(xc, p)
        op = np.pad(omega, ((p, p), (0, 0)))
        Y, _, sinfo = tsmc_kernels.tsmc_solve(np.nan_to_num(xp), op, self["alpha"], self["beta"],
                                 self["gamma"], self["tol"], self["max_iter"],
                                 penalty0=self["penalty0"])
        fill = dct.unpad(Y, p) / s + centre
        if self["observed"] != "model":
            tau = self.frames("bridge", motion) if self["bridge"] is not None else np.inf
            fill = fill + tsmc_kernels.bridge_residual(np.where(omega, x - fill, np.nan), tau)
        if back is not None:
            full = np.zeros((T, 3 * J))
            full[:, cols] = fill
            fill = back(full.reshape(T, J, 3)).reshape(T, 3 * J)[:, cols]
        return fill, sinfo

    def _pca_frame(self, motion: Motion, trusted: np.ndarray, rows: np.ndarray):
        """Channels of the markers in ``rows`` in the body frame, complete: untrusted and
        missing samples pre-filled by ``fill_pca`` (ends too; what it leaves, by linear
        interpolation / holding), the rigid body frame fitted on all of them.
        Returns ``(x (T, 3 × rows), back)``."""
        pos = np.where(trusted[..., None], motion.positions, np.nan)
        filled, _ = fill_gaps_pca(pos, metres_per_unit=motion.metres_per_unit, fill_ends=True)
        T, J, _ = pos.shape
        flat = filled[:, rows].reshape(T, -1)
        complete = linear_bridge(flat).reshape(T, -1, 3)
        if complete.shape[1] < 3:                       # no rigid fit: global frame
            return complete.reshape(T, -1), None
        # fitted on every marker, fills included: a fit on each frame's own trusted subset
        # tilts the frame wherever a group of markers drops out (up to 10° on CMU 85_02,
        # spike-hole RMSE 13.6 instead of 3.1 mm)
        everyone = np.ones(complete.shape[:2], bool)
        # three Procrustes rounds: the occlusion results are the same to 3 decimals as
        # with 50 (the PCA does not see the reference's last sub-mm drift)
        _, transform = body_frame(complete, everyone, rounds=3)
        local = to_local(complete, transform)

        def back(loc):
            out = loc.copy()
            out[:, rows] = to_global(loc[:, rows], transform)
            return out
        return local.reshape(T, -1), back
