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

Beyond the paper:

* **Missing samples** (C3D gaps, Kinect NotTracked, padding) are unobserved entries: no
  ℓ1 penalty on E there and no multiplier (E = D − A − Z1/ρ1 with Z1 = 0, so the data
  term does not act), which makes the method fill gaps as it denoises.
* **Pad and mask**: the orthonormal periodized wavelet needs T divisible by 2^L; the time
  axis is padded with unobserved frames — at least a filter length of them, so that the
  periodic wrap (last frame → first) falls where the solver is free to be smooth.
* **Start**: A⁰ = D (gaps bridged linearly) instead of the paper's A⁰ = 0; from zero, with
  the paper's penalty growth η = 1.3, the ALM stops about 1.4 m from the data on CMU 05_01.
* **Bones**: the skeleton's bones (ASF/AMC, BVH, Kinect topology), or a config list of
  marker-name pairs. Lengths: the rig's rest offsets when the motion has a rig and the
  bone is a rig link without translation channels; otherwise a robust estimate from the
  data (:func:`estimate_lengths`).
* **Units**: the solver works in metres whatever the file's unit, so λ, γ, μ keep the
  paper's meaning (they are scale dependent).
* **Bounded Gauss–Newton step**: no bone vector moves by more than its length plus its
  current extent in one N-step (:meth:`IsometrySystem.limit_step`). Under heavy noise a
  bone squeezed to a few centimetres linearises badly (the step along it is about
  l²/(2|d|)), joints were thrown metres away, and with γ = 1000, η = 1.1 the ALM then
  diverged (CMU 05_01, feng2015 snr5, seed 0: RMSE 3·10^11 cm; bounded: 60 cm from 75).
  On ordinary data it scales 0.3–4 % of the frame steps (short bones squeezed by noise
  or outliers) and the RMSE stays within 0.3 % on the other feng2015 and yang2019
  levels of 05_01.
* **Divergence guard**: an iterate that is not finite or reaches ten times farther than
  the data from its centre stops the solve; it is redone without the isometry term (the
  convex rest of the model), or, should that diverge too, the data is returned; ``info``
  says so (``diverged``, ``diverged_at``, ``fallback``).
* **Speed**: the N-step is T independent per-frame systems, solved exactly by block
  elimination along the skeleton tree for all frames at once (never the (3TS)² matrix);
  BLAS is held to one thread while the solver runs (when ``threadpoolctl`` is installed).

The defaults are the paper's (λ = 1/√T, γ = 100, μ = 0.01, ρ = 0.5, η = 1.3, 2-level
Daubechies, ℓ1 on every wavelet coefficient). Measured on the nine shared CMU trials with
the ``yang2019`` protocol (lengths estimated from the corrupted data), they stay above
the paper's Table II (AJE 0.0057 / 0.0095 / 0.0150 / 0.0216 / 0.104 m at 5 / 10 / 15 / 20 /
80 %, paper 0.004 / 0.006 / 0.007 / 0.010 / 0.067). A slower penalty growth and a wavelet
penalty on the detail bands only (``eta: 1.1, mu: 0.03, approx_penalty: false``) give
0.0024 / 0.0030 / 0.0039 / 0.0051 / 0.070, and adding ``keep_inliers: 50 mm`` 0.0006 /
0.0010 / 0.0016 / 0.0024 / 0.067, at about twice the iterations. On short Kinect clips
γ = 100 is too weak to steady bone lengths (the variation grows on three of the four MSR
Action3D clips); ``gamma: 1000`` with the settings above lowers it on all twelve files.
"""
from __future__ import annotations

import math

import numpy as np

from mocapfix.cleaners import register
from mocapfix.cleaners.base import Cleaner, Param
from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion
from mocapfix.solvers import wavelet_ops
from mocapfix.solvers.isometry import IsometrySystem, energy
from mocapfix.solvers.lowrank import blas_single_thread, shrink, svt
from mocapfix.solvers.segments import linear_bridge


# --------------------------------------------------------------------------------------
# bone lengths
# --------------------------------------------------------------------------------------
def window_mode(values: np.ndarray, half_width: float) -> float:
    """The densest value of ``values`` at resolution ``half_width``: the sample with the
    most samples within ± half_width (a box-kernel density mode, Parzen 1962), refined as
    the median of those neighbours. Survives a majority of scattered outliers as long as
    they are sparser around the true value than the inliers."""
    v = np.sort(np.asarray(values, dtype=np.float64))
    counts = np.searchsorted(v, v + half_width, "right") - np.searchsorted(v, v - half_width, "left")
    best = np.flatnonzero(counts == counts.max())
    centre = v[best[len(best) // 2]]
    near = v[np.abs(v - centre) <= half_width]
    return float(np.median(near))


def estimate_lengths(X: np.ndarray, bones: np.ndarray, trusted: np.ndarray,
                     half_width: float) -> np.ndarray:
    """Robust constant length of each bone from the frames where both ends are trusted.

    The length of a bone is the :func:`window_mode` of its per-frame lengths: gross errors
    at either end spread the length distribution widely (and shift its bulk upwards)
    while the true length stays a sharp peak, so the mode survives a majority of
    corrupted frames where the median (over frames where both ends are trusted) is pulled away by 10–20 cm. NaN for a bone never observed.

    Parameters
    ----------
    X : (T, S, 3) positions (NaN = missing).
    bones : (B, 2) joint indices.
    trusted : (T, S) samples that may be used.
    half_width : resolution of the mode, in the unit of X.

    Returns
    -------
    (B,) lengths.
    """
    bones = np.asarray(bones, dtype=np.intp).reshape(-1, 2)
    out = np.full(len(bones), np.nan)
    d = np.linalg.norm(X[:, bones[:, 0]] - X[:, bones[:, 1]], axis=-1)     # (T, B)
    ok = trusted[:, bones[:, 0]] & trusted[:, bones[:, 1]] & np.isfinite(d)
    for b in range(len(bones)):
        if ok[:, b].any():
            out[b] = window_mode(d[ok[:, b], b], half_width)
    return out


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
# Algorithm 1
# --------------------------------------------------------------------------------------
def recover(X: np.ndarray, bones: np.ndarray, lengths: np.ndarray, lam: float | None = None,
            gamma: float = 100.0, mu: float = 0.01, rho: float = 0.5, eta: float = 1.3,
            wavelet: str = "db10", level: int = 2, max_iter: int = 100, tol: float = 1e-4,
            init: str = "data", approx_penalty: bool = True,
            margin: int | None = None) -> tuple[np.ndarray, np.ndarray, dict]:
    """ADM-ALM of Yang et al. 2019 (Algorithm 1) on positions ``X`` (T, S, 3), NaN missing.

    Parameters
    ----------
    X : (T, S, 3) positions in metres (the paper's λ, γ, μ are for metres).
    bones, lengths : (B, 2) joint pairs and (B,) target lengths (metres); B may be 0.
    lam : weight of ||E||_1; None → 1/√T (the paper's choice).
    gamma, mu : weights of the isometry energy and of ||W A||_1.
    rho, eta : initial penalty ρ1 = ρ2 = ρ3 and its growth factor per iteration.
    wavelet, level : orthogonal wavelet and number of levels of W.
    max_iter, tol : stop when the relative primal residual
        max(||D − A − E||, ||N − A||, ||C − W A||) / ||D|| (over observed entries) < tol.
    init : "data" (A⁰ = D with gaps bridged linearly) or "zero" (the paper's A⁰ = 0,
        which with the paper's fast penalty growth stops far from the data: ~1.4 m AJE on
        CMU 05_01, so "data" is the default).
    margin : unobserved frames added at the end (then up to a multiple of 2^L) for the
        periodic wrap of the wavelet; None: the filter length. 0: only the 2^L padding.
    approx_penalty : ℓ1 on every wavelet coefficient (the paper) or only on the detail
        coefficients (False: the coarse trajectory, the approximation band, is free; the
        ℓ1 on it otherwise pulls positions towards the origin).

    Returns
    -------
    A : (T, S, 3) recovered positions (every sample, gaps filled).
    E : (T, S, 3) sparse error on the observed samples (NaN where unobserved).
    info : iterations, final residual, isometry energy before/after (on N⁰ and A),
        ``steps_limited`` (frame steps of N scaled down by
        :meth:`~mocapfix.solvers.isometry.IsometrySystem.limit_step`) and, when the
        iteration diverged (see :func:`_diverged`), ``diverged: True``, ``diverged_at``
        (iteration) and ``fallback``: the solve is stopped and redone without the
        isometry term (γ = 0, the convex rest of the model); should that diverge too, A
        is the data with gaps bridged linearly.
    """
    args = (lam, mu, rho, eta, wavelet, level, max_iter, tol, init, approx_penalty, margin)
    with blas_single_thread():
        A, E, info = _recover(X, bones, lengths, gamma, *args)
        if "diverged_at" not in info:
            return A, E, info
        failed = {"diverged": True, "diverged_at": info["diverged_at"]}
        use_iso = len(bones) > 0 and gamma > 0
        if use_iso:
            A, E, info = _recover(X, bones, lengths, 0.0, *args)
            if "diverged_at" not in info:
                info.update(failed, fallback="isometry dropped (gamma 0): low rank + sparse "
                                             "+ wavelet only")
                _report_isometry(info, X, A, bones, lengths)
                return A, E, info
        A = linear_bridge(X)
        E = np.where(np.isfinite(X).all(axis=2)[..., None], 0.0, np.nan)
        info = dict(failed, fallback="data returned (gaps bridged linearly)", iterations=0,
                    residual=float("nan"), steps_limited=0,
                    **{"lambda": 1.0 / math.sqrt(len(X)) if lam is None else float(lam)})
        if use_iso:
            _report_isometry(info, X, A, bones, lengths)
        return A, E, info


#: the ALM is stopped as divergent when an iterate of A reaches farther from the centre
#: of the observed data than this many times the data's own reach (at least 1 m): a
#: recovery, gap filling included, stays inside the capture volume, while a divergent
#: ALM grows geometrically (CMU 05_01, feng2015 snr5 seed 0, kinect settings, without
#: the step bound: coordinates of 35 m after 3 iterations, 4·10^5 m after 50, 4·10^11 m
#: after 100, from data within 4 m)
DIVERGENCE_REACH = 10.0


def _diverged(A: np.ndarray, centre: np.ndarray, limit: float) -> bool:
    """True when the iterate ``A`` (S, 3, Tp) is not finite or leaves the ball of radius
    ``limit`` about ``centre`` (1, 3, 1)."""
    if not np.isfinite(A).all():
        return True
    off = A - centre
    return float(np.einsum("sxt,sxt->st", off, off).max()) > limit * limit


def _report_isometry(info: dict, X, A, bones, lengths) -> None:
    """Isometry energy of the input (gaps bridged) and of the result ``A`` (T, S, 3)."""
    info["iso_energy_before"] = energy(linear_bridge(X).transpose(1, 2, 0),
                                       bones, lengths)
    info["iso_energy_after"] = energy(A.transpose(1, 2, 0), bones, lengths)


def _recover(X, bones, lengths, gamma, lam, mu, rho, eta, wavelet, level, max_iter, tol, init,
             approx_penalty, margin):
    X = np.asarray(X, dtype=np.float64)
    T, S, _ = X.shape
    lam = 1.0 / math.sqrt(T) if lam is None else float(lam)
    if margin is None:
        margin = wavelet_ops.check_wavelet(wavelet).dec_len
    Xp, _ = wavelet_ops.pad_time(X, level, margin=margin)                     # (Tp, S, 3)
    Tp = Xp.shape[0]
    # Layout (S, 3, Tp), time last: the wavelet runs along contiguous rows, the isometry
    # solver works on length-Tp vectors, and (S, 3Tp) is the transpose of the paper's
    # 3T × S matrix up to a row permutation, which leaves singular values and SVT as
    # they are.
    obs = np.isfinite(Xp).all(axis=2).T[:, None, :]                          # (S, 1, Tp)
    D = np.ascontiguousarray(linear_bridge(Xp).transpose(1, 2, 0))
    scale = float(np.linalg.norm(D * obs)) or 1.0
    centre, limit = _divergence_ball(D, obs)

    def W(M):
        return wavelet_ops.forward(M.reshape(3 * S, Tp), wavelet, level, axis=1).reshape(S, 3, Tp)

    def Wt(M):
        return wavelet_ops.inverse(M.reshape(3 * S, Tp), wavelet, level, axis=1).reshape(S, 3, Tp)

    n_approx = Tp >> level
    use_iso = len(bones) > 0 and gamma > 0
    system = IsometrySystem(bones, S) if use_iso else None
    lengths = np.asarray(lengths, dtype=np.float64)

    A = D.copy() if init == "data" else np.zeros_like(D)
    N = D.copy()
    Z1 = np.zeros_like(D)
    Z2 = np.zeros_like(D)
    Z3 = np.zeros_like(D)
    r1 = r2 = r3 = float(rho)
    rho_max = 1e8 * float(rho)
    WA = W(A)
    iso_before = energy(N, bones, lengths) if use_iso else 0.0
    it, res, limited, diverged_at = 0, float("inf"), 0, None
    for it in range(1, max_iter + 1):
        # line 4–5: Gauss–Newton step for N (per-frame systems, batched)
        if use_iso:
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                delta = system.step(N, A, Z2, lengths, gamma, r2)
            # a frame whose Gauss–Newton system degenerated (overflow under extreme
            # noise) is not moved by this step rather than poisoned with inf/NaN
            delta[~np.isfinite(delta)] = 0.0
            # no bone moved past every point of its length constraint (Gauss–Newton on a
            # bone squeezed far below its length overshoots by metres; see limit_step)
            delta, n_limited = system.limit_step(N, delta, lengths)
            limited += n_limited
            N += delta
        else:
            N = A - Z2 / r2
        # line 6: wavelet coefficients
        V = WA - Z3 * (1.0 / r3)
        C = shrink(V, mu / r3)
        if not approx_penalty:
            C[..., :n_approx] = V[..., :n_approx]
        # line 7: sparse errors; on unobserved entries no penalty and no multiplier
        # (Z1 = 0 there), so E = D − A and H1 = A: the data term does not act
        G = D - A
        G -= Z1 * (1.0 / r1)
        E = np.where(obs, shrink(G, lam / r1), G)
        # lines 8–11: A = SVT of (ρ1 H1 + ρ2 H2 + ρ3 H3) / Σρ with
        # H1 = D − E − Z1/ρ1 = G + A − E, ρ2 H2 = ρ2 N + Z2, ρ3 H3 = Wᵀ(ρ3 C + Z3)
        C3 = C * r3
        C3 += Z3
        M = G - E
        M += A
        M *= r1
        M += Wt(C3)
        M += Z2
        M += r2 * N
        rs = r1 + r2 + r3
        M *= 1.0 / rs
        # the tall (3Tp × S) view: LAPACK's thin SVD is about twice as fast that way round
        A = np.ascontiguousarray(svt(M.reshape(S, 3 * Tp).T, 1.0 / rs).T).reshape(S, 3, Tp)
        if _diverged(A, centre, limit):
            diverged_at = it
            break
        WA = W(A)
        # lines 12–17: multipliers and penalties
        R1 = (E - D + A) * obs
        R2 = N - A
        R3 = C - WA
        Z1 += r1 * R1
        Z2 += r2 * R2
        Z3 += r3 * R3
        # penalties grow geometrically (Algorithm 1) but are capped, as in inexact-ALM
        # practice (Lin, Chen & Ma 2010): past ~1e8·ρ0 the 3×3 Gauss–Newton systems
        # overflow (ρ³ terms) while nothing is gained in accuracy
        r1, r2, r3 = (min(eta * r, rho_max) for r in (r1, r2, r3))
        res = max(np.linalg.norm(R1), np.linalg.norm(R2), np.linalg.norm(R3)) / scale
        if res < tol:
            break
    info = {"iterations": it, "residual": res, "lambda": lam, "steps_limited": limited}
    if diverged_at is not None:
        info["diverged_at"] = diverged_at
        return None, None, info
    A_out = A[..., :T].transpose(2, 0, 1).copy()
    E_out = E[..., :T].transpose(2, 0, 1).copy()
    E_out[~np.isfinite(X).all(axis=2)] = np.nan
    if use_iso:
        info["iso_energy_before"] = iso_before
        info["iso_energy_after"] = energy(A, bones, lengths)
    return A_out, E_out, info


def _divergence_ball(D: np.ndarray, obs: np.ndarray) -> tuple[np.ndarray, float]:
    """Centre (1, 3, 1) of the observed samples of ``D`` (S, 3, Tp) and the radius
    beyond which an iterate counts as divergent (:data:`DIVERGENCE_REACH`)."""
    weight = np.broadcast_to(obs, D.shape)
    if not weight.any():
        return np.zeros((1, 3, 1)), DIVERGENCE_REACH
    centre = (D * weight).sum(axis=(0, 2), keepdims=True) / weight[:, :1].sum()
    off = (D - centre) * obs
    reach = math.sqrt(float(np.einsum("sxt,sxt->st", off, off).max()))
    return centre, DIVERGENCE_REACH * max(reach, 1.0)


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
            X, index[bones] if len(bones) else bones, lengths, lam=self["lam"],
            gamma=self["gamma"], mu=self["mu"], rho=self["rho"], eta=self["eta"],
            wavelet=self["wavelet"], level=self["level"], approx_penalty=self["approx_penalty"],
            max_iter=self["iterations"],
            tol=self["tolerance"])
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
