"""The spatio-temporal recovery of Yang, Wang, Li & Xu 2019 ("Spatio-temporal reconstruction
for 3D motion recovery", IEEE TIP; Algorithm 1), on arrays: low rank + sparse errors +
wavelet sparsity + bone isometry by ADM-ALM (:func:`recover`), and the robust bone
lengths its isometry term needs (:func:`estimate_lengths`). The ``lowrank_isometry``
cleaner (:mod:`mocapfix.cleaners.lowrank_isometry`, whose docstring gives the model and the
measurements) runs it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

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


# --------------------------------------------------------------------------------------
# Algorithm 1
# --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Settings:
    """The weights and stopping rule of :func:`recover` (the paper's λ, γ, μ are for
    positions in metres).

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
    """

    lam: float | None = None
    gamma: float = 100.0
    mu: float = 0.01
    rho: float = 0.5
    eta: float = 1.3
    wavelet: str = "db10"
    level: int = 2
    max_iter: int = 100
    tol: float = 1e-4
    init: str = "data"
    approx_penalty: bool = True
    margin: int | None = None


def recover(X: np.ndarray, bones: np.ndarray, lengths: np.ndarray,
            settings: Settings = Settings()) -> tuple[np.ndarray, np.ndarray, dict]:
    """ADM-ALM of Yang et al. 2019 (Algorithm 1) on positions ``X`` (T, S, 3), NaN missing.

    Parameters
    ----------
    X : (T, S, 3) positions in metres (the paper's λ, γ, μ are for metres).
    bones, lengths : (B, 2) joint pairs and (B,) target lengths (metres); B may be 0.
    settings : the model's weights, the penalty schedule and the stopping rule
        (:class:`Settings`).

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
    with blas_single_thread():
        A, E, info = _recover(X, bones, lengths, settings)
        if "diverged_at" not in info:
            return A, E, info
        failed = {"diverged": True, "diverged_at": info["diverged_at"]}
        use_iso = len(bones) > 0 and settings.gamma > 0
        if use_iso:
            A, E, info = _recover(X, bones, lengths, replace(settings, gamma=0.0))
            if "diverged_at" not in info:
                info.update(failed, fallback="isometry dropped (gamma 0): low rank + sparse "
                                             "+ wavelet only")
                _report_isometry(info, X, A, bones, lengths)
                return A, E, info
        A = linear_bridge(X)
        E = np.where(np.isfinite(X).all(axis=2)[..., None], 0.0, np.nan)
        info = dict(failed, fallback="data returned (gaps bridged linearly)", iterations=0,
                    residual=float("nan"), steps_limited=0,
                    **{"lambda": 1.0 / math.sqrt(len(X)) if settings.lam is None
                       else float(settings.lam)})
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


def _recover(X, bones, lengths, settings: Settings):
    """One run of Algorithm 1 (:func:`recover`); (None, None, info) when it diverged."""
    gamma, mu, rho, eta = settings.gamma, settings.mu, settings.rho, settings.eta
    wavelet, level, margin = settings.wavelet, settings.level, settings.margin
    X = np.asarray(X, dtype=np.float64)
    T, S, _ = X.shape
    lam = 1.0 / math.sqrt(T) if settings.lam is None else float(settings.lam)
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

    A = D.copy() if settings.init == "data" else np.zeros_like(D)
    N = D.copy()
    Z1 = np.zeros_like(D)
    Z2 = np.zeros_like(D)
    Z3 = np.zeros_like(D)
    r1 = r2 = r3 = float(rho)
    rho_max = 1e8 * float(rho)
    WA = W(A)
    iso_before = energy(N, bones, lengths) if use_iso else 0.0
    it, res, limited, diverged_at = 0, float("inf"), 0, None
    for it in range(1, settings.max_iter + 1):
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
        if not settings.approx_penalty:
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
        if res < settings.tol:
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
