"""The stages of the depth-sensor skeleton cleaner, as kernels on arrays (positions in
metres, (T, J, 3), NaN = missing), run in order by :mod:`mocapfix.cleaners.depth_skeleton`;
the method, with the measurements behind each choice: docs/methods/kinect_skeleton.md.

1. :func:`repair_leg_swaps` (:func:`leg_swap_frames`: two-state Viterbi on the leg chains'
   path lengths);
2. tracking state as weights, Inferred runs debiased (:func:`debias_inferred`);
3. the noise model from the data (:func:`noise_model`) and the rigid pairs the skeleton
   does not list (:func:`hold_rigid_pairs`);
4. per-joint Whittaker smoothing with GCV strength on the true time axis
   (:meth:`Smoothing.fit`; Eilers 2003, Garcia 2010);
5. outliers the path contradicts (:func:`reject_outliers`);
6. shrinkage across joints (:func:`shrink_across_joints`; Gavish & Donoho 2017) and
   untrusted samples from the parent (:func:`estimate_from_parents`);
7. fills (:func:`fill_gaps`);
8. bone lengths (:func:`hold_bone_lengths`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocapfix.core.kinect_joints import normalise_name
from mocapfix.solvers import run_offsets, svshrink, whittaker
from mocapfix.solvers.bone_projection import (median_lengths, project_lengths, steady_pairs,
                                               two_bone_pairs)
from mocapfix.solvers.glitches import contradicted_by_path
from mocapfix.solvers.localfit import moving_median
from mocapfix.solvers.rigid import norms
from mocapfix.solvers.segments import NO_CAPTURE_VOLUME_M, fillable, runs

_LEG = ("knee", "ankle", "foot")
_PELVIS = ("spinebase", "hipcenter", "pelvis")
#: cutoff frequencies (Hz) whose λ form the GCV grid
CUTOFFS = np.geomspace(0.7, 12.0, 8)
#: GCV chooses the smoothing on at most this many frames (the middle of a long file)
GCV_FRAMES = 3000
#: the rigid-pair test averages distances over this long (s) ...
RIGID_WINDOW_S = 0.5
#: ... on at least this many frames where both joints are tracked (3 s at 30 fps)
RIGID_MIN_FRAMES = 90


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


def fill_ends_from_parent(Z, missing, parents, order, max_gap_frames):
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


def topological(parents):
    """Joint indices, every parent before its children."""
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


# -- the stages of kinect_skeleton (mocapfix.cleaners.depth_skeleton, stages 1-8) -----------

def time_axis(times, fps: float, T: int) -> np.ndarray:
    """The sample times the smoother works on: the file's stamps, or ``arange(T) / fps``
    without; backward stamps fall back to indices, repeated ones are spread a quarter frame
    apart."""
    t = np.asarray(times, dtype=np.float64) if times is not None else np.arange(T) / fps
    dt = np.diff(t)
    if np.any(dt < 0):
        t = np.arange(T) / fps
    elif np.any(dt == 0):
        step = 0.25 / fps
        t = t + step * np.cumsum(np.r_[0.0, dt == 0])
    return t


def gross_errors(P: np.ndarray) -> np.ndarray:
    """(T, J) samples farther than :data:`NO_CAPTURE_VOLUME_M` from their joint's median
    position (P in metres): a corrupt field, taken out before anything looks at the
    samples — left in, one 1e9 m value steered the first GCV smooth and moved its whole
    joint by 0.3 m (1e10 m: 2.4 m), a -1e20 m depth turned the depth model off for the
    whole file and the leg-swap test saw swaps that were not there."""
    J = P.shape[1]
    seen = ~np.isnan(P).any(axis=2)
    centre = np.zeros((J, 3))
    centre[seen.any(axis=0)] = np.nanmedian(P[:, seen.any(axis=0)], axis=0)
    with np.errstate(invalid="ignore", over="ignore"):
        return seen & ~(norms(P - centre) <= NO_CAPTURE_VOLUME_M)


def repair_leg_swaps(P: np.ndarray, conf: np.ndarray, names: list[str], threshold: float):
    """Stage 1: the frames where the leg chains are exchanged (:func:`leg_swap_frames`)
    exchanged back, positions and confidences; returns (P, conf, swapped frames (T,))."""
    swapped = np.zeros(P.shape[0], bool)
    if threshold > 0:
        swapped = leg_swap_frames(P, names, threshold)
        for a, b in _side_pairs(names, _LEG):
            P[np.ix_(swapped, [a, b])] = P[np.ix_(swapped, [b, a])]
            conf[np.ix_(swapped, [a, b])] = conf[np.ix_(swapped, [b, a])]
    return P, conf, swapped


@dataclass(frozen=True)
class Smoothing:
    """What every smooth of the stages shares: the time axis ``t`` (median step ``h``),
    the penalised derivative ``order``, a fixed cut-off (None: GCV per joint), the spread
    of strengths the final smooth chooses among (None: one), the half-width of its local
    risk, and the caches of the banded penalties (filled as the stages ask)."""

    t: np.ndarray
    order: int
    fixed: float | None
    spread: np.ndarray | None
    local_half: int
    cache: dict = field(default_factory=dict, compare=False)

    @property
    def h(self) -> float:
        return float(np.median(np.diff(self.t)))

    def bands(self, win: slice, order: int):
        key = (win.start, win.stop, order)
        if key not in self.cache:
            self.cache[key] = whittaker.penalty_bands(self.t[win], order)
        return self.cache[key]

    def coefficients(self, order: int):
        key = ("coefficients", order)
        if key not in self.cache:
            self.cache[key] = whittaker.difference_coefficients(self.t, order)
        return self.cache[key]

    def fit(self, data: np.ndarray, weights: np.ndarray, cut=None, prev=None, joints=None,
            local: bool = False, fit_order: int | None = None):
        """Stage 4: per joint a weighted Whittaker smooth of ``data`` (T, J, 3), its
        strength by GCV on the middle :data:`GCV_FRAMES` frames (``cut``: reuse these
        cut-offs, one solve per joint; ``local``: the strength varying along time by the
        local Stein risk, stage 6); only ``joints`` are refitted, the others are taken
        from ``prev``. Returns (Z, cut-offs (J,) in Hz)."""
        T, J, _ = data.shape
        t, h = self.t, self.h
        order = self.order if fit_order is None else fit_order
        bands = self.bands(slice(0, T), order)
        Z = np.full_like(data, np.nan) if prev is None else prev.copy()
        new_cut = np.full(J, np.nan) if cut is None else cut.copy()
        for j in (range(J) if joints is None else joints):
            w = weights[:, j]
            if (w > 0).sum() <= order + 1:
                Z[:, j] = np.nan
                continue
            y = np.where(w[:, None] > 0, data[:, j], 0.0)
            wbar = float(w[w > 0].mean())
            if self.fixed is not None or (cut is not None and np.isfinite(cut[j])):
                c = self.fixed if self.fixed is not None else cut[j]
                if local and self.spread is not None:
                    Z[:, j] = self._local(y, w, c, wbar, order, bands)
                else:
                    lam = float(whittaker.lambda_for_cutoff(c, wbar, h, order))
                    Z[:, j] = whittaker.smooth(y, w, t, lam, order=order, bands=bands)
                new_cut[j] = c
                continue
            # GCV on the middle GCV_FRAMES frames of a long file, then one solve
            win = slice(max(0, (T - GCV_FRAMES) // 2), max(0, (T - GCV_FRAMES) // 2)
                        + min(T, GCV_FRAMES))
            ww = w[win]
            if (ww > 0).sum() <= order + 1:
                win, ww = slice(0, T), w
            wb = float(ww[ww > 0].mean())
            grid = whittaker.lambda_for_cutoff(CUTOFFS, wb, h, order)[::-1]
            zs, lam, _ = whittaker.smooth_gcv(y[win], ww, t[win], grid, order=order,
                                              bands=self.bands(win, order), refine=True)
            # the cut-off of the chosen λ (inverse of lambda_for_cutoff)
            c = (wb / (h * lam)) ** (1.0 / (2 * order)) / (2.0 * np.pi)
            new_cut[j] = c
            if local and self.spread is not None:
                Z[:, j] = self._local(y, w, c, wbar, order, bands)
            elif win == slice(0, T):
                Z[:, j] = zs
            else:
                lam = float(whittaker.lambda_for_cutoff(c, wbar, h, order))
                Z[:, j] = whittaker.smooth(y, w, t, lam, order=order, bands=bands)
        return Z, new_cut

    def _local(self, y, w, c, wbar, order, bands):
        """The final smooth's strength varying along time (stage 6)."""
        lams = whittaker.lambda_for_cutoff(c * self.spread, wbar, self.h, order)
        return whittaker.smooth_local_sure(
            y, w, self.t, lams, order=order, bands=bands, half=self.local_half,
            coefficients=self.coefficients(order))[0]


@dataclass(frozen=True)
class Noise:
    """Stage 3's noise model: the first smooth's cut-offs, the noise scale per joint
    (m), the depth exponent, σ per sample (T, J) and the first smooth's residuals."""

    cut: np.ndarray
    scale: np.ndarray
    depth_exponent: float
    sigma: np.ndarray
    residuals: np.ndarray


#: the noise σ (m) of the even weights of the first smooth
FIRST_SIGMA = 0.01


def noise_model(smooth: Smoothing, P: np.ndarray, w0: np.ndarray, tracked: np.ndarray,
                depth: np.ndarray, use_depth: bool, zref: float, cut=None) -> Noise:
    """Stage 3: a first smooth with even weights ``w0``; from its residuals on the tracked
    samples the noise scale per joint (the 3-D residual norm of N(0, s² I) has median
    1.5382 s) and, pooled over joints, the depth exponent (least squares of
    log |residual| on log depth, clamped to [0, 2])."""
    J = P.shape[1]
    Z, cut0 = smooth.fit(P, w0, cut=cut)
    res = norms(P - Z)
    p_exp = 0.0
    scale = np.full(J, FIRST_SIGMA)
    ok = tracked & np.isfinite(res) & (res > 0)
    for j in range(J):
        if ok[:, j].sum() > 10:
            scale[j] = max(np.median(res[ok[:, j], j]) / 1.5382, 1e-4)
    if use_depth and ok.sum() > 50:
        zlog = np.log(depth[ok] / zref)
        rlog = np.log(res[ok] / scale[np.nonzero(ok)[1]])
        if np.var(zlog) > 1e-4:
            p_exp = float(np.clip(np.cov(zlog, rlog)[0, 1] / np.var(zlog), 0.0, 2.0))
    with np.errstate(invalid="ignore"):
        rel = (np.nan_to_num(depth, nan=zref) / zref) ** p_exp if use_depth else 1.0
    return Noise(cut0, scale, p_exp, scale[None, :] * rel, res)


def hold_rigid_pairs(P: np.ndarray, bones: np.ndarray, tracked: np.ndarray,
                     inferred: np.ndarray, noise: Noise, sig_inf: float, floor: float,
                     outlier_k: float, ratio: float, stiffness: float, h: float):
    """Stage 3b: joints two bones apart whose distance the data shows rigid
    (:func:`mocapfix.solvers.bone_projection.steady_pairs`) held at their median distance
    with the bones; a Tracked sample the first smooth calls an outlier stays out of the
    projection and as it was (it would drag its neighbours along, and stage 5 is where
    outliers are judged). Returns (P, the pairs (K, 2))."""
    J = P.shape[1]
    window = max(3, int(round(RIGID_WINDOW_S / max(h, 1e-9))))
    rigid = steady_pairs(P, tracked, two_bone_pairs(bones, J), noise.scale, window=window,
                         ratio=ratio, min_frames=RIGID_MIN_FRAMES)
    if len(rigid):
        links = np.vstack([rigid, bones])
        var = np.where(inferred, np.maximum(noise.sigma, sig_inf) ** 2, noise.sigma ** 2)
        with np.errstate(invalid="ignore"):
            far = tracked & (noise.residuals > np.maximum(outlier_k * noise.sigma, floor))
        held = project_lengths(np.where(far[..., None], np.nan, P), links,
                               median_lengths(P, tracked & ~far, links), var, sweeps=4,
                               stiffness=stiffness)
        P = np.where(far[..., None], P, held)
    return P, rigid


def debias_inferred(smooth: Smoothing, P: np.ndarray, inferred: np.ndarray,
                    tracked: np.ndarray, sigma: np.ndarray, cut: np.ndarray, window: int,
                    degree: int):
    """Stage 2's debiasing: an Inferred run is the joint plus a slowly changing offset,
    read at the run's ends as the jump of the data there
    (:func:`mocapfix.solvers.run_offsets.run_end_offsets`; an end without enough Tracked
    samples next to it: against the smooth of the Tracked samples alone) and removed,
    linearly in time in between. Returns (P, samples debiased)."""
    t = smooth.t
    T = len(t)
    debiased = 0
    col, start, length = runs(inferred)
    first, last, ok0, ok1 = run_offsets.run_end_offsets(
        t, P, inferred, tracked, col, start, length, k=window, degree=degree)
    Zt = None
    if not (ok0.all() and ok1.all()):
        need = np.unique(col[~(ok0 & ok1)])
        Zt, _ = smooth.fit(P, np.where(tracked, 1.0 / sigma ** 2, 0.0), cut=cut, joints=need)
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
    return P, debiased


def reject_outliers(smooth: Smoothing, P: np.ndarray, weights: np.ndarray, observed: np.ndarray,
                    tracked: np.ndarray, sigma: np.ndarray, sigma_inf: np.ndarray, cut: np.ndarray,
                    outlier_k: float, floor: float, passes: int):
    """Stage 5: samples farther from the smooth than ``max(outlier_k max(σ, σ_local),
    floor)`` (σ_local: Hampel's local scale, the median residual over ±3 samples / 1.5382,
    so a stretch the smooth cannot follow is not an outlier) and that the joint's own path
    contradicts (:func:`mocapfix.solvers.glitches.contradicted_by_path`) get weight 0 and
    their joint is refitted, ``passes`` rounds. Returns (Z, cut-offs, flagged (T, J))."""
    flagged = np.zeros(observed.shape, bool)
    Z, cut = smooth.fit(P, weights, cut=cut)
    for _ in range(passes + 1):
        res = norms(P - Z)
        local = np.nan_to_num(moving_median(np.where(observed, res, np.nan), 3)) / 1.5382
        base = np.maximum(np.where(tracked, sigma, sigma_inf), local)
        limit = np.maximum(outlier_k * base, floor)
        new = observed & (res > limit) & ~flagged
        # off the smooth is a suspicion; the joint's own path must contradict it
        new &= contradicted_by_path(P, new | flagged)
        if not new.any():
            break
        flagged |= new
        Z, cut = smooth.fit(P, np.where(flagged, 0.0, weights), cut=cut, prev=Z,
                            joints=np.flatnonzero(new.any(axis=0)))
    return Z, cut, flagged


def shrink_across_joints(smooth: Smoothing, P: np.ndarray, Z: np.ndarray, trusted: np.ndarray,
                         weights: np.ndarray, sigma: np.ndarray, cut: np.ndarray):
    """Stage 6's shrinkage: the joints move together — optimal singular-value shrinkage
    (Gavish & Donoho 2017, :mod:`mocapfix.solvers.svshrink`) of the noise-whitened
    (T, 3J) trajectories, then the final smooth, its strength varying along time. Returns
    (Z, the rank kept; None when too few complete frames)."""
    T, J, _ = P.shape
    Y = np.where(trusted[..., None], P, Z)
    okrow = ~np.isnan(Y).any(axis=(1, 2))
    if okrow.sum() <= 3 * J:
        return Z, None
    sd = np.repeat(sigma.mean(axis=0), 3)
    X = Y[okrow].reshape(-1, 3 * J) / sd
    mean = X.mean(axis=0)
    # (embedding 3-10 lagged frames per row measured 8.8 mm against 8.95 on the jitter
    # scenario, at 6-10x the cost: not worth it)
    Xs, rank = svshrink.shrink_frobenius(X - mean, 1.0)
    Y2 = np.full_like(Y, np.nan)
    Y2[okrow] = ((Xs + mean) * sd).reshape(-1, J, 3)
    w2 = np.where(trusted & okrow[:, None], weights, 0.0)
    Z2, _ = smooth.fit(np.where(np.isnan(Y2), 0.0, Y2), w2, cut=cut, local=True)
    return np.where(trusted[..., None] & okrow[:, None, None], Z2, Z), rank


def estimate_from_parents(smooth: Smoothing, P: np.ndarray, Z: np.ndarray, parents: np.ndarray,
                          tracked: np.ndarray, inferred: np.ndarray, flagged: np.ndarray,
                          weights: np.ndarray, cut: np.ndarray, fill_order: int,
                          validate: bool) -> np.ndarray:
    """Stage 6: untrusted samples (inferred, missing, outliers) from the parent: the
    smooth of the joint's offset to its parent (penalising the ``fill_order``-th
    derivative) added to the parent's estimate, parents first — an occluded hand follows
    the tracked elbow; with ``validate`` averaged with the joint's own smooth by their
    errors on validation runs (:func:`validated_shares`)."""
    trusted = tracked & ~flagged
    with np.errstate(divide="ignore"):
        var = np.where(flagged, np.inf, 1.0 / weights)
    has_parent = parents >= 0
    pidx = np.where(has_parent, parents, 0)
    wrel = np.where(has_parent[None, :], 1.0 / (var + var[:, pidx]), 0.0)
    need = np.flatnonzero((~trusted).any(axis=0) & has_parent)
    Zr, cut_r = smooth.fit(P - P[:, pidx], wrel, joints=need, fit_order=fill_order)
    wtrust = np.where(flagged, 0.0, weights)
    for j in topological(parents):
        pj = parents[j]
        if pj < 0:
            continue
        rows = ~(tracked | inferred)[:, j] | flagged[:, j]
        rows &= ~np.isnan(Zr[:, j]).any(axis=1)
        if not rows.any():
            continue
        share = 1.0
        if validate:
            both = trusted[:, j] & trusted[:, pj]
            share = validated_shares(
                rows, both, smooth.t, P[:, j], wtrust[:, j], cut[j], smooth.order,
                P[:, j] - P[:, pj], Z[:, pj], wrel[:, j], cut_r[j], fill_order)[rows, None]
        from_parent, own = Z[rows, pj] + Zr[rows, j], Z[rows, j]
        # one estimate missing (a joint too rarely seen for its own smooth): the other
        Z[rows, j] = np.where(np.isnan(own), from_parent, np.where(
            np.isnan(from_parent), own, share * from_parent + (1.0 - share) * own))
    return Z


def fill_gaps(Z: np.ndarray, observed: np.ndarray, parents, gap_frames) -> np.ndarray:
    """Stage 7: missing samples in interior gaps of at most ``gap_frames`` (None: any)
    take the smooth; gaps at the ends of at most that are filled from the parent joint
    with the offset of the nearest observed frame."""
    missing = ~observed
    out = np.where((observed | fillable(missing, gap_frames))[..., None], Z, np.nan)
    if parents is not None:
        end_limit = len(Z) if gap_frames is None else gap_frames
        fill_ends_from_parent(out, missing, parents, topological(parents), end_limit)
    return out


def hold_bone_lengths(out: np.ndarray, P_read: np.ndarray, bones: np.ndarray, parents: np.ndarray,
                      rigid: np.ndarray, observed: np.ndarray, tracked: np.ndarray,
                      inferred: np.ndarray, flagged: np.ndarray, sigma: np.ndarray,
                      sig_inf: float, stiffness: float):
    """Stage 8: target lengths = median over frames of each bone (and rigid pair) in the
    smoothed motion where both ends are tracked; positions projected toward them
    (:func:`mocapfix.solvers.bone_projection.project_lengths`), each joint moving in
    proportion to its variance (tracked σ², inferred ``sig_inf``², filled (2 sig_inf)²).
    Bones exactly constant in the input ``P_read`` (MSR Action3D stores some) keep that
    length exactly: their child joints are put back at it, parents first. Returns (out,
    how many bones were constant)."""
    T = len(out)
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
        # one length per bone (letting it drift below 0.3-1 Hz kept UTKinect's bone
        # variation at 0.11-0.13 of 0.14: its bones change slowly with pose)
        lengths[:, i] = np.median(norms(out[both, a] - out[both, b]))
    var = np.where(tracked & ~flagged, sigma ** 2,
                   np.where(inferred & ~flagged, sig_inf ** 2, (2 * sig_inf) ** 2))
    # the rigid pairs (if any) first: the bones, last, end nearest their lengths
    pair_len = np.broadcast_to(median_lengths(out, good, rigid, min_frames=3), (T, len(rigid)))
    out = project_lengths(out, np.vstack([rigid, bones]), np.hstack([pair_len, lengths]),
                          var, sweeps=8, stiffness=stiffness)
    rank = {j: r for r, j in enumerate(topological(parents))}
    for i in sorted(np.flatnonzero(constant), key=lambda i: rank[int(bones[i][1])]):
        a, b = bones[i]
        d = out[:, b] - out[:, a]
        n = norms(d)[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            out[:, b] = np.where(n > 0, out[:, a] + d * (lengths[:, i, None] / n), out[:, b])
    return out, int(constant.sum())
