"""Spatio-temporal recovery of skeleton motion: low rank + sparse errors + wavelet
sparsity + bone-length isometry (Yang, Guo, Li, Wang, Lai & Wu 2019, "Spatio-temporal
reconstruction for 3D motion recovery", IEEE TIP).

The motion is the 3T × S matrix D (each block of three rows one frame, each column one
joint's trajectory) and is split as D = A + E, A the clean motion, by::

    min ||A||_* + λ||E||_1 + γ/2 E_iso(N) + μ||C||_1   s.t.  D = A + E,  N = A,  C = W A

(eq. 8): a nuclear-norm (low-rank) prior, sparse gross errors, the isometry energy of
eq. 5 (:mod:`mocapfix.solvers.isometry`) and an ℓ1 prior on the orthonormal Daubechies
wavelet coefficients of every trajectory (:mod:`mocapfix.solvers.wavelet_ops`), solved by
the ADM-ALM of Algorithm 1 with one Gauss–Newton step per iteration for N (eq. 20).
The defaults are the paper's (λ = 1/√T, γ = 100, μ = 0.01, ρ = 0.5, η = 1.3).

Beyond the paper: missing samples are unobserved entries (so the method also fills
gaps); the time axis is padded for the periodized wavelet; A⁰ = D; bones and lengths come
from the rig or a robust estimate (:func:`estimate_lengths`); the solver works in metres;
the Gauss–Newton step is bounded (:meth:`IsometrySystem.limit_step`) and a diverging
solve falls back to the convex model or the data (``info``: ``diverged``,
``diverged_at``, ``fallback``). Why, and the measurements against the paper's Table II:
docs/methods/lowrank_isometry.md.
"""
from __future__ import annotations


import numpy as np

from mocapfix.cleaners import register
from mocapfix.cleaners.base import Cleaner, Param
from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion
from mocapfix.solvers import wavelet_ops
from mocapfix.solvers.lowrank_isometry import Settings, estimate_lengths, recover


def rig_lengths(motion: Motion, bones: np.ndarray) -> np.ndarray:
    """Rest length (file units) of each bone that is a rig parent link whose child has no
    translation channel; NaN for the others (and all NaN without a rig)."""
    bones = np.asarray(bones, dtype=np.intp).reshape(-1, 2)
    out = np.full(len(bones), np.nan)
    rig = motion.rig
    if rig is None or getattr(rig, "names", None) != motion.names:
        return out
    parents = np.asarray(rig.parents)
    moving = (np.asarray(rig.trans_columns) >= 0).any(axis=1)
    offsets = np.linalg.norm(np.asarray(rig.offsets, dtype=np.float64), axis=1)
    for b, (i, j) in enumerate(bones):
        for a, c in ((i, j), (j, i)):
            if parents[c] == a and not moving[c]:
                out[b] = offsets[c]
    return out


# --------------------------------------------------------------------------------------
# the cleaner
# --------------------------------------------------------------------------------------
@register
class LowRankIsometry(Cleaner):
    """Yang et al. 2019 spatio-temporal recovery: denoises every sample and fills gaps.

    Bones come from the motion's skeleton, or from ``bones`` (marker-name pairs on one
    rigid segment); without either the isometry term is dropped (low rank + wavelet
    sparsity only) and ``info`` says so. λ, γ, μ are the paper's, for data in metres (the
    solver converts). Gaps longer than ``max_gap`` are solved but left missing in the
    output. With ``keep_inliers``, observed samples whose sparse error is below that
    length keep their measured values (only outliers and gaps are replaced) — for
    accurate data with sparse gross errors, not for data noisy everywhere (Kinect).
    A divergent solve is stopped and replaced (see :func:`recover`); ``info`` then has
    ``diverged``, ``diverged_at`` and ``fallback``.
    """

    name = "lowrank_isometry"
    summary = "low-rank + sparse + wavelet + bone-length isometry recovery (Yang et al. 2019)"
    params = (
        Param("lam", "float", None, "weight of the sparse error ||E||_1 (default 1/sqrt(T))",
              low=0.0, low_open=True, nullable=True),
        Param("gamma", "float", 100.0, "weight of the bone-length isometry energy (metres)", low=0.0),
        Param("mu", "float", 0.01, "weight of the wavelet sparsity ||W A||_1 (metres)", low=0.0),
        Param("rho", "float", 0.5, "initial ALM penalty rho1 = rho2 = rho3", low=0.0, low_open=True),
        Param("eta", "float", 1.3, "growth of the penalties per iteration", low=1.0, low_open=True,
              high=10.0),
        Param("wavelet", "str", "db10", "orthogonal wavelet of W (Daubechies in the paper)"),
        Param("level", "int", 2, "wavelet levels", low=1, high=8),
        Param("approx_penalty", "bool", True, "l1 on the approximation coefficients too (the "
              "paper); false penalises only the detail bands"),
        Param("iterations", "int", 100, "maximum ALM iterations", low=1, high=10000),
        Param("tolerance", "float", 1e-4, "stop when the relative constraint residual is below",
              low=0.0, low_open=True, high=1.0),
        Param("bones", "list", None, "marker-name pairs [[A, B], ...] replacing the skeleton's bones",
              nullable=True),
        Param("lengths", "choice", "auto", "bone lengths: rig rest offsets when there is a rig "
              "(auto), or always estimated from the data", choices=("auto", "estimate")),
        Param("length_window", "length", "2.5 mm", "half-width of the density mode that "
              "estimates a bone length from the data", unit="mm", low=0.0, low_open=True),
        Param("min_confidence", "float", 0.9, "samples below this confidence are not used to "
              "estimate bone lengths", low=0.0, high=1.0),
        Param("max_gap", "time", None, "longest gap left filled in the output (default: all)",
              unit="s", low=0.0, nullable=True),
        Param("keep_inliers", "length", None, "observed samples whose sparse error |E| is below "
              "this keep their measured value (default: every sample is replaced by A, as in "
              "the paper)", unit="mm", low=0.0, nullable=True),
    )

    def _validate(self):
        try:
            wavelet_ops.check_wavelet(self["wavelet"])
        except ValueError as exc:
            raise ConfigError(f"{self.step}: parameter 'wavelet': {exc}") from None
        if self["bones"] is not None:
            for pair in self["bones"]:
                if not (isinstance(pair, (list, tuple)) and len(pair) == 2
                        and all(isinstance(n, str) for n in pair)):
                    raise ConfigError(f"{self.step}: parameter 'bones' must be a list of "
                                      f"[name, name] pairs, got {pair!r}")

    def _bones(self, motion: Motion) -> np.ndarray:
        if self["bones"] is not None:
            try:
                pairs = [(motion.index(a), motion.index(b)) for a, b in self["bones"]]
            except KeyError as exc:
                raise ConfigError(f"{self.step}: parameter 'bones': {exc.args[0]}") from None
            return np.asarray(pairs, dtype=np.intp).reshape(-1, 2)
        if motion.skeleton is not None and motion.skeleton.bones:
            return motion.skeleton.bone_array
        return np.zeros((0, 2), dtype=np.intp)

    def _apply(self, motion: Motion):
        pos = motion.positions
        T, J, _ = pos.shape
        observed = ~np.isnan(pos).any(axis=2)
        live = observed.any(axis=0)                   # joints never observed stay missing
        if T < 4 or live.sum() < 2:
            return motion.copy(), {"skipped": "too few frames or joints"}
        m = motion.metres_per_unit
        X = np.where(observed[..., None], pos, np.nan)[:, live] * m
        index = np.full(J, -1)
        index[live] = np.arange(live.sum())
        bones = self._bones(motion)
        bones = bones[live[bones].all(axis=1)] if len(bones) else bones
        info: dict = {}
        lengths = np.zeros(0)
        if len(bones):
            lengths = rig_lengths(motion, bones) * m if self["lengths"] == "auto" else \
                np.full(len(bones), np.nan)
            from_rig = np.isfinite(lengths)
            todo = ~from_rig
            if todo.any():
                trusted = observed
                if motion.confidence is not None:
                    trusted = observed & (motion.confidence >= self["min_confidence"])
                width = self.length("length_window", motion) * m
                est = estimate_lengths(pos * m, bones[todo], trusted, width)
                if motion.confidence is not None and np.isnan(est).any():
                    # bones never seen with both ends trusted: use every observed frame
                    est = np.where(np.isnan(est),
                                   estimate_lengths(pos * m, bones[todo], observed, width), est)
                lengths[todo] = est
            keep = np.isfinite(lengths) & (lengths > 0)
            bones, lengths = bones[keep], lengths[keep]
            info["bones"] = int(len(bones))
            info["lengths_from_rig"] = int(from_rig[keep].sum())
        if not len(bones):
            info["bones"] = 0
            info["note"] = "no bones: isometry term skipped (low rank + wavelet sparsity only)"
        A, E, sol = recover(
            X, index[bones] if len(bones) else bones, lengths, Settings(
                lam=self["lam"], gamma=self["gamma"], mu=self["mu"], rho=self["rho"],
                eta=self["eta"], wavelet=self["wavelet"], level=self["level"],
                approx_penalty=self["approx_penalty"], max_iter=self["iterations"],
                tol=self["tolerance"]))
        info.update(sol)
        out = np.full_like(pos, np.nan)
        out[:, live] = A / m
        if self["keep_inliers"] is not None:
            # a sample the model explains up to a small sparse error is an inlier: keep
            # the measurement and replace only the outliers (and fill the gaps)
            small = np.linalg.norm(E, axis=2) < self.length("keep_inliers", motion) * m
            inlier = np.zeros_like(observed)
            inlier[:, live] = small
            out[inlier] = pos[inlier]
            info["inliers_kept"] = int(inlier.sum())
        if self["max_gap"] is not None:
            from mocapfix.core.gaps import runs
            from mocapfix.solvers.segments import run_rows

            limit = self.frames("max_gap", motion)
            col, start, length = runs(~observed)
            long_ = length > limit
            if long_.any():
                rows = run_rows(start[long_], length[long_])
                out[rows, np.repeat(col[long_], length[long_])] = np.nan
        return motion.replace(positions=out), info
