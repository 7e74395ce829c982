"""Gap filling by averaging several fillers, after Tits, Laraba, Caulier, Tilmanne &
Dutoit (2018), "Robust and automatic motion-capture data recovery using soft skeleton
constraints and model averaging", PLoS ONE 13(7): e0199744 ("PMA").

Written from the paper's description (no code of its authors was used). Per gap of a
marker ``j`` (a run of missing frames ``s..e-1``, bounded by the observed frames ``s-1``
and ``e`` when they exist):

1. *Neighbours*: the markers observed on every frame of the gap and at its borders,
   ranked by how rigidly they move with ``j`` (the standard deviation of their distance
   to ``j`` over the frames where both are seen; :func:`distance_stats`).
2. *Fillers* (each returns ``j`` on the gap and at the border frames):

   - ``interp`` — local interpolation: ``j``'s coordinates in the rigid frame of its
     closest neighbours at the two borders, interpolated linearly across the gap;
   - ``poly`` — local polynomial regression (degree 2, ridge) of ``j`` on the neighbours'
     coordinates, both in the neighbours' rigid frame;
   - ``grnn`` — generalised regression neural network (Specht 1991; a Nadaraya–Watson
     kernel regression) of the same variables;
   - ``linear`` — global weighted linear regression (ridge) of ``j`` on every marker
     observed through the gap, in their common body frame, the columns weighted by
     ``exp(-d² / 2s²)`` of their mean distance ``d`` to ``j``;
   - ``pose`` (ours, not in the paper) — linear regression (ridge) of ``j`` on its 6 and
     on its 12 next most rigid neighbours, all in the rigid frame of its closest
     neighbours (those of ``interp``; the first count when there are several;
     :func:`pose_fills`);
   - any fills passed in by the caller (the cleaner passes ``fill_pca``: Gløersen &
     Federolf's weighted PCA).
3. *Borders*: every fill gets the linear ramp ``(1-f)(x(s-1) - F(s-1)) + f(x(e) - F(e))``
   so it meets the data at both ends of the gap (the one available offset, held, at an
   end gap).
4. *Averaging*: fill ``k`` gets the weight ``1 / mean z²``, ``z = (d - μ)/σ`` over the
   gap frames and the neighbours, with ``d`` the fill's distance to a neighbour and
   ``μ, σ`` the observed distribution of that distance (:func:`plausibility`).
5. *Soft constraint*: where the average lies outside ``μ ± c σ`` of its distance to one of
   its 1–3 most rigid neighbours, it is moved radially onto the interval's edge (corrections
   of the violated neighbours averaged, a few rounds; :func:`soft_distance_constraint`).

Kernels are vectorised over the frames of a gap; the loop is over gaps (over the fits
that serve them, in the calling thread: :func:`member_fills` says why), in two groups of
markers, the second in a forked child process where that can pay
(:func:`validated_member_fills`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mocapfix.solvers.nanstats import mean_of, median_of
from mocapfix.solvers.rigid import kabsch_to_shapes
from mocapfix.solvers.segments import steepest_step

#: the fillers computed here (the caller may add its own, e.g. weighted PCA)
LOCAL_FILLERS = ("interp", "poly", "grnn", "linear", "pose")
#: the fillers run once per neighbour count (the others once per gap)
PER_NEIGHBOUR_COUNT = ("interp", "poly", "grnn")
#: ``pose``: its members regress on the frame markers and this many more neighbours each
POSE_SIZES = (6, 12)


def distance_stats(pos: np.ndarray, observed: np.ndarray, min_frames: int = 3):
    """Mean and standard deviation (J, J) of every inter-marker distance over the frames
    where both markers are observed (NaN with fewer than ``min_frames`` such frames).
    One marker at a time, the distances to the markers after it over all frames (from
    contiguous (J, T) coordinate rows), their sums and squared sums: O(T J²) time, O(T J)
    memory."""
    T, J, _ = pos.shape
    ob = observed.astype(np.float64)
    n = ob.T @ ob                                           # frames where both are seen
    rows = [np.ascontiguousarray(np.where(observed, pos[..., k], 0.0).T) for k in range(3)]
    obT = np.ascontiguousarray(ob.T)
    mu, var = np.zeros((J, J)), np.zeros((J, J))
    for i in range(J - 1):
        d = np.zeros((J - i - 1, T))
        for r in rows:
            diff = r[i + 1:] - r[i]
            diff *= diff
            d += diff
        np.sqrt(d, out=d)
        d *= obT[i + 1:] * obT[i]                           # 0 where either is missing
        s = d.sum(axis=1)
        m = s / np.maximum(n[i, i + 1:], 1)
        v = ((d * d).sum(axis=1) - m * s) / np.maximum(n[i, i + 1:] - 1, 1)
        mu[i, i + 1:] = mu[i + 1:, i] = m
        var[i, i + 1:] = var[i + 1:, i] = np.maximum(v, 0.0)
    ok = n >= min_frames
    mu = np.where(ok, mu, np.nan)
    sd = np.where(ok, np.sqrt(var), np.nan)
    np.fill_diagonal(mu, np.where(np.diag(ok), 0.0, np.nan))
    np.fill_diagonal(sd, np.where(np.diag(ok), 0.0, np.nan))
    return mu, sd


def _frames(points: np.ndarray, ref: np.ndarray | None):
    """Rigid transform of each frame of ``points`` (n, K, 3) onto ``ref`` (K, 3); with
    fewer than 3 points a translation only. Returns ``(to_local, to_global)`` functions of
    (n, M, 3) arrays. A generator: it yields its Kabsch fit as ``(points, shape)`` and is
    sent ``(R, cs, ct)`` (:func:`_fit_together`)."""
    n, K, _ = points.shape
    centre = points.mean(axis=1)
    if K < 3:
        return (lambda x: x - centre[:, None]), (lambda x: x + centre[:, None])
    return _transforms(*(yield points, ref))


def _frames_two(first: np.ndarray, second: np.ndarray, ref: np.ndarray):
    """:func:`_frames` of two point sets (n1, K, 3) and (n2, K, 3), K ≥ 3, with one
    batched Kabsch fit (the same values as two calls); a generator as :func:`_frames`."""
    R, cs, ct = yield np.concatenate([first, second]), ref
    n1 = len(first)
    return (_transforms(R[:n1], cs[:n1], ct[:n1]), _transforms(R[n1:], cs[n1:], ct[n1:]))


def _transforms(R, cs, ct):
    """``(to_local, to_global)`` of per-frame rigid fits ``R (p − cs) + ct``."""
    def to_local(x):
        return (x - cs[:, None]) @ np.swapaxes(R, 1, 2) + ct[:, None]

    def to_global(x):
        return (x - ct[:, None]) @ R + cs[:, None]
    return to_local, to_global


def _block(a: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """``a[np.ix_(rows, cols)]`` by two ``take`` calls (~5x faster on (T, J, 3) arrays)."""
    return a.take(rows, axis=0).take(cols, axis=1)


def _reference(points: np.ndarray):
    """Mean shape of (n, K, 3) point sets, after one rigid alignment to the first frame's
    centred shape (enough for a consistent local frame); a generator as :func:`_frames`."""
    if len(points) > 100:                       # a mean shape needs no more frames
        points = points[np.linspace(0, len(points) - 1, 100).astype(int)]
    centred = points - points.mean(axis=1, keepdims=True)
    if points.shape[1] < 3:
        return centred.mean(axis=0)
    R, cs, ct = yield points, centred[0]
    return ((points - cs[:, None]) @ np.swapaxes(R, 1, 2) + ct[:, None]).mean(axis=0)


#: a reference shape another job of the same round is making (:func:`_cached_reference`)
_MAKING = object()


def _cached_reference(cache: dict | None, key, points: np.ndarray):
    """:func:`_reference` of ``points``, from ``cache[key]`` when there, stored there when
    not (``cache`` None: no cache); a generator as :func:`_frames`. A job that finds the
    key being made by an earlier job of its round waits a round for it (yields None), so
    that the first job to ask makes it, as when the jobs ran one after another."""
    if cache is None:
        return (yield from _reference(points))
    while cache.get(key) is _MAKING:
        yield None
    if key not in cache:
        cache[key] = _MAKING
        try:
            cache[key] = yield from _reference(points)
        finally:
            if cache.get(key) is _MAKING:       # abandoned: let no other job wait on it
                del cache[key]
    return cache[key]


#: points (frames × markers) the jobs of one :func:`_fit_together` call may hold at once:
#: a job holds its training frames' points while it waits for its fit (about 48 bytes a
#: point with their copy for the fit), so a long window's hundreds of gaps, or a capture
#: of hundreds of markers, are fitted a batch of jobs at a time (~10 MB; the 4,500-frame
#: case of benchmarks/clean_speed.py peaked 16 MB higher with all its jobs at once)
TOGETHER_POINTS = 200_000


def _batches(items, points):
    """``items`` in order, in lists whose ``points(item)`` sum to at most
    :data:`TOGETHER_POINTS` (an item larger than that alone)."""
    batch, held = [], 0
    for item in items:
        n = points(item)
        if batch and held + n > TOGETHER_POINTS:
            yield batch
            batch, held = [], 0
        batch.append(item)
        held += n
    if batch:
        yield batch


def _fit_together(jobs) -> list:
    """Run the generators ``jobs`` (:func:`window_fills`) side by side and return what
    each returns. Each round, every job is advanced to the next Kabsch fit it needs
    (``(points, shape)``, or None to wait a round) and the fits of all of them are made in
    one :func:`mocapfix.solvers.rigid.kabsch_to_shapes` call: a few hundred fits of a few
    dozen frames (a short take's gaps and their validation windows) cost about as much as
    one of the size of them all."""
    results = [None] * len(jobs)
    sent = [None] * len(jobs)
    active = list(range(len(jobs)))
    while active:
        asked = []
        for i in active:
            try:
                asked.append((i, jobs[i].send(sent[i])))
            except StopIteration as done:
                results[i] = done.value
        fits = iter(kabsch_to_shapes([fit for _, fit in asked if fit is not None]))
        for i, fit in asked:
            sent[i] = None if fit is None else next(fits)
        active = [i for i, _ in asked]
    return results


def _ridge(X: np.ndarray, Y: np.ndarray, lam: float = 1e-3):
    """Ridge regression with standardised features; returns a predictor
    (:func:`_nested_ridge` on all the columns)."""
    return lambda Xn: _nested_ridge(X, Y, Xn, [X.shape[1]], lam)[0]


#: training points (evenly spaced) whose 5th-nearest-neighbour distances set the GRNN
#: spread: 200 of 600 cost a third of the all-pairs distances (fill_ensemble 0.91 → 0.80 s
#: on the 4,500-frame case of benchmarks/clean_speed.py, one thread) and moved no gap RMSE
#: of benchmarks/versus_peers.py (9 captures, seeds 0–5, both gap ranges, pma and
#: default) by more than 0.1 %
SPREAD_POINTS = 200


def _grnn(X: np.ndarray, Y: np.ndarray, max_train: int = 800):
    """GRNN (Specht 1991) predictor: Gaussian-kernel weighted mean of the training targets;
    spread = the median distance of a training point to its 5th nearest neighbour (over
    :data:`SPREAD_POINTS` evenly spaced training points, their neighbours among all)."""
    if len(X) > max_train:
        pick = np.linspace(0, len(X) - 1, max_train).astype(int)
        X, Y = X[pick], Y[pick]
    mx, sx = X.mean(axis=0), X.std(axis=0)
    sx[sx < 1e-9] = 1.0
    Z = (X - mx) / sx
    sq = (Z ** 2).sum(axis=1)
    q = np.linspace(0, len(Z) - 1, min(len(Z), SPREAD_POINTS)).astype(int)
    D2 = np.maximum(sq[q, None] + sq[None, :] - 2 * Z[q] @ Z.T, 0.0)
    k = min(5, len(Z) - 1)
    spread2 = median_of(_kth_smallest(D2, k)) if k > 0 else 1.0
    spread2 = max(spread2, 1e-9)

    def predict(Xn):
        Zn = (Xn - mx) / sx
        # the same operations as max(|zn|² + |z|² − 2 zn·z, 0), exp(−½ (d² − min) / s²),
        # in place: a (gaps' frames × 800) array is made twice instead of seven times
        cross = Zn @ Z.T
        cross *= 2.0
        d2 = (Zn ** 2).sum(axis=1)[:, None] + sq[None, :]
        d2 -= cross
        np.maximum(d2, 0.0, out=d2)
        d2 -= d2.min(axis=1, keepdims=True)              # stable exponent
        d2 *= -0.5
        d2 /= spread2
        w = np.exp(d2, out=d2)
        return (w @ Y) / w.sum(axis=1, keepdims=True)
    return predict


def _kth_smallest(rows: np.ndarray, k: int) -> np.ndarray:
    """The ``k``-th smallest value (from 0) of each row of ``rows`` (n, m), as
    ``np.partition(rows, k, axis=1)[:, k]`` gives it: on arrays of 8,000 values or more
    by striking out the ``k`` smallest one at a time, for the GRNN's k = 5 over 600-point
    rows ~6x faster than the partition (0.15 against 0.91 ms for 200 rows; the two are
    even near 89 × 89, the partition faster below). May overwrite ``rows``."""
    if rows.size < 8000:
        return np.partition(rows, k, axis=1)[:, k]
    at = np.arange(len(rows))
    for _ in range(k):
        rows[at, rows.argmin(axis=1)] = np.inf
    return rows.min(axis=1)


def _poly(z: np.ndarray) -> np.ndarray:
    return np.concatenate([z, z ** 2], axis=1)


def window_fills(pos, observed, j, windows, neighbours, train, body, *,
                 fillers=LOCAL_FILLERS, weight_scale: float = 300.0, mu=None,
                 references: dict | None = None):
    """The local fillers' estimates of marker ``j`` on each window ``(s, e)``, on frames
    ``s-1 .. e`` (the gap plus the border frames that exist), from one fit of each filler
    on ``train``: the regressions are learnt once and predict every window (a real gap
    and the synthetic gaps that validate it). Returns one ``(frames, fills)`` per window,
    ``fills`` name → (len(frames), 3).

    ``neighbours``: indices of the rigid neighbours; ``body``: the markers of ``linear``
    and ``pose`` (most rigid first); both observed on every window's frames. ``train``:
    frames where ``j`` is observed. ``weight_scale`` in the data's units.
    ``references``: reference shapes of the rigid frames by ``(j, markers)``, used when
    present and added when not (so that the validation copies of a gap fit their frames
    onto the real gap's reference shape instead of computing it again).

    A generator: it yields each rigid (Kabsch) fit it needs as ``(points, shape)`` and is
    sent the fit, so that :func:`member_fills` makes the fits of all its jobs together
    (:func:`_fit_together`, which also runs one job alone); the windows' fills are its
    return value."""
    T = pos.shape[0]
    spans = [np.arange(max(s - 1, 0), min(e + 1, T)) for s, e in windows]
    frames = np.concatenate(spans)
    ends = np.cumsum([len(f) for f in spans]).tolist()
    # each window's rows of an array over ``frames`` (np.split's views, without its ~6 µs)
    pieces = list(zip([0, *ends[:-1]], ends))
    out = {}
    K = len(neighbours)
    if K and set(fillers) & {"interp", "poly", "grnn", "pose"}:
        tr_local = train[_block(observed, train, neighbours).all(axis=1)]
        nb = _block(pos, frames, neighbours)
        nb_train = _block(pos, tr_local, neighbours)
        # only a reference from the training frames is shared (the first call's for the
        # key: the refill rounds train on more frames and reuse it; it only fixes the
        # frame's orientation); one from this job's own frames stays this job's
        ref = yield from (_cached_reference(references, (j, tuple(neighbours.tolist())),
                                            nb_train) if len(tr_local) else _reference(nb))
        if K >= 3 and len(tr_local) >= max(10, 2 * K):
            (loc, glob), (tl, _) = yield from _frames_two(nb, nb_train, ref)
        else:
            (loc, glob), tl = (yield from _frames(nb, ref)), None
        if "interp" in fillers:
            lj = loc(np.nan_to_num(pos[frames, j])[:, None])[:, 0]
            ramps = []
            for (s, e), (lo, hi) in zip(windows, pieces):
                part = lj[lo:hi]
                n = len(part)
                have0, have1 = s > 0, e < T
                a = part[0] if have0 else part[-1]
                b = part[-1] if have1 else part[0]
                f = (np.arange(n) / max(n - 1, 1))[:, None]
                ramps.append((1 - f) * a + f * b)
            out["interp"] = glob(np.concatenate(ramps)[:, None])[:, 0]
        if len(tr_local) >= max(10, 2 * K):
            if tl is None:
                tl, _ = yield from _frames(nb_train, ref)
            Xt = tl(nb_train).reshape(len(tr_local), -1)
            Yt = tl(pos[tr_local, j][:, None])[:, 0]
            Xg = loc(nb).reshape(len(frames), -1)
            if "poly" in fillers and K >= 3:
                out["poly"] = glob(_ridge(_poly(Xt), Yt)(_poly(Xg))[:, None])[:, 0]
            if "grnn" in fillers and K >= 3:
                out["grnn"] = glob(_grnn(Xt, Yt)(Xg)[:, None])[:, 0]
            if "pose" in fillers and K >= 3:
                out.update(pose_fills(pos, observed, j, frames, body, K, tr_local, tl, loc,
                                      glob))
    if "linear" in fillers and len(body) >= 3:
        tr = train[_block(observed, train, body).all(axis=1)]
        if len(tr) >= max(10, len(body)):
            body_train, body_gap = _block(pos, tr, body), _block(pos, frames, body)
            ref = yield from _cached_reference(references, (j, tuple(body.tolist())), body_train)
            (tl, _), (loc, glob) = yield from _frames_two(body_train, body_gap, ref)
            d = mu[j, body] if mu is not None else np.zeros(len(body))
            w = np.repeat(np.exp(-0.5 * (np.nan_to_num(d, nan=1e9) / weight_scale) ** 2), 3)
            Xt = tl(body_train).reshape(len(tr), -1) * w
            Yt = tl(pos[tr, j][:, None])[:, 0]
            Xg = loc(body_gap).reshape(len(frames), -1) * w
            keep = w > 1e-6
            if keep.sum() >= 3:
                out["linear"] = glob(_ridge(Xt[:, keep], Yt)(Xg[:, keep])[:, None])[:, 0]
    return [(f, {k: v[lo:hi] for k, v in out.items()}) for f, (lo, hi) in zip(spans, pieces)]


def pose_fills(pos, observed, j, frames, cand, K, train, to_local_train, to_local, to_global,
               *, sizes=POSE_SIZES, lam: float = 1e-3):
    """The ``pose`` members: marker ``j`` in the rigid frame (Kabsch 1976) of its ``K``
    most rigid neighbours, predicted by a linear ridge regression on the coordinates, in
    that same frame, of its ``K + M`` most rigid neighbours (one member ``poseM`` per
    ``M`` in ``sizes``). The rigid frame removes the motion of the body part; the
    neighbours beyond it carry the pose of the adjacent parts (a joint's angle), on which
    the marker's place in that frame depends — what ``poly``/``grnn`` (whose inputs are
    only the frame markers, nearly constant in their own frame) and ``linear`` (one frame
    for the whole body) do not model.

    ``cand``: the neighbours observed on ``frames`` (the gap and its borders), most rigid
    first, the first ``K`` being the frame's; ``train``: frames where ``j`` and the frame
    markers are seen; ``to_local_train``, ``to_local``, ``to_global``: the frame's
    transforms on ``train`` and on ``frames`` (:func:`_frames_two`, shared with
    ``poly``/``grnn``). Returns name → (len(frames), 3), not yet ramped to the borders."""
    out = {}
    feats = cand[:K + max(sizes)]
    if len(feats) <= K:
        return out
    counts = {}                                 # member → neighbours used (the first M wins
    for M in sizes:                             # when there are fewer than M: same member)
        counts.setdefault(min(K + M, len(feats)), M)
    # frames where every neighbour is seen (usually nearly all): one standardised Gram
    # matrix serves every member (its leading block); too few: the smallest member alone,
    # on the frames where its own neighbours are seen
    rows = _block(observed, train, feats).all(axis=1)
    if rows.sum() < max(10, 2 * len(feats)):
        feats = cand[:min(counts)]
        rows = _block(observed, train, feats).all(axis=1)
        counts = {len(feats): counts[min(counts)]}
        if rows.sum() < max(10, 2 * len(feats)):
            return out
    Xt = to_local_train(_block(pos, train, feats))[rows].reshape(int(rows.sum()), -1)
    Yt = to_local_train(pos[train, j][:, None])[rows, 0]
    Xg = to_local(_block(pos, frames, feats)).reshape(len(frames), -1)
    for k, Y in zip(counts, _nested_ridge(Xt, Yt, Xg, [3 * k for k in counts], lam)):
        out[f"pose{counts[k]}"] = to_global(Y[:, None])[:, 0]
    return out


def _nested_ridge(X, Y, Xn, widths, lam: float = 1e-3):
    """:func:`_ridge` of ``Y`` on the first ``w`` columns of ``X`` for each ``w`` in
    ``widths``, predicted at ``Xn``: one standardisation and one Gram matrix, each fit
    solving its leading block (the same values as separate calls)."""
    mx, sx = X.mean(axis=0), X.std(axis=0)
    sx[sx < 1e-9] = 1.0
    my = Y.mean(axis=0)
    Z, Zn = (X - mx) / sx, (Xn - mx) / sx
    G, b = Z.T @ Z, Z.T @ (Y - my)
    out = []
    for w in widths:
        B = np.linalg.solve(G[:w, :w] + lam * len(Z) * np.eye(w), b[:w])
        out.append(Zn[:, :w] @ B + my)
    return out


def meet_borders(fill: np.ndarray, data: np.ndarray, has_start: bool, has_end: bool):
    """Add the linear ramp that makes ``fill`` (n, 3: border, gap, border rows as present)
    equal ``data`` at the border rows (Tits 2018: fills meet the gap's ends)."""
    n = len(fill)
    d0 = data[0] - fill[0] if has_start else None
    d1 = data[-1] - fill[-1] if has_end else None
    if d0 is None and d1 is None:
        return fill
    if d0 is None:
        d0 = d1
    if d1 is None:
        d1 = d0
    f = (np.arange(n) / max(n - 1, 1))[:, None]
    return fill + (1 - f) * d0 + f * d1


def plausibility(fill: np.ndarray, others: np.ndarray, mu: np.ndarray, sd: np.ndarray,
                 floor: float) -> float:
    """Mean squared z-score of the distances from ``fill`` (n, 3) to ``others`` (n, K, 3)
    against their observed mean ``mu`` (K,) and standard deviation ``sd`` (K,), the
    deviation floored at ``floor``. Lower is more plausible."""
    d = np.linalg.norm(others - fill[:, None], axis=2)
    z = (d - mu) / np.maximum(sd, floor)
    return float(np.mean(z ** 2))


def soft_distance_constraint(x: np.ndarray, others: np.ndarray, mu: np.ndarray, sd: np.ndarray,
                             width: float = 2.0, rounds: int = 5) -> np.ndarray:
    """Move each row of ``x`` (n, 3) radially onto ``mu ± width·sd`` of its distance to
    ``others`` (n, K, 3) where it lies outside (corrections averaged over the K
    neighbours, ``rounds`` times): Tits 2018's soft skeleton constraint."""
    x = x.copy()
    lo, hi = mu - width * sd, mu + width * sd
    for _ in range(rounds):
        v = x[:, None] - others
        d = np.linalg.norm(v, axis=2)
        target = np.clip(d, lo, hi)
        if np.allclose(target, d):
            break
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = np.where(d[..., None] > 0, v * ((target - d) / d)[..., None], 0.0)
        x += corr.mean(axis=1)
    return x


# -- the loop over gaps, shared by ``pma`` and ``fill_ensemble`` -----------------------------

def gap_list(observed: np.ndarray, max_gap: float | None = None, fill_ends: bool = True):
    """(marker, start, stop) of every gap to fill: runs of missing samples of markers seen
    at least once, at most ``max_gap`` frames, end gaps only with ``fill_ends``."""
    from mocapfix.core.gaps import runs

    T = observed.shape[0]
    j, s, n = runs(~observed)
    keep = n < T
    if max_gap is not None:
        keep &= n <= max_gap
    if not fill_ends:
        keep &= (s > 0) & (s + n < T)
    return list(zip(j[keep].tolist(), s[keep].tolist(), (s + n)[keep].tolist()))


def member_fills(pos, observed, gaps, external, *, local=LOCAL_FILLERS, neighbours=3,
                 weight_scale: float = 300.0, mu=None, sd=None, max_train: int = 600,
                 references: dict | None = None):
    """Every member's fill of every gap, ramped to meet the borders.

    ``external``: name → (T, J, 3) fills computed elsewhere (NaN where not filled);
    ``neighbours``: K, or several K (the local fillers then run once per K, named
    ``interp3``, ``interp5``, ...); ``max_train``: the regressions learn from at most this
    many frames where the marker is seen (evenly spaced); ``references``: the rigid
    frames' reference shapes to use and extend (:func:`window_fills`). Returns
    one entry per gap: ``(cand, fills)`` with ``cand`` the markers observed on the gap and
    its borders, most rigid first, and ``fills`` name → (gap length, 3).

    A member learns the same model for every gap of a marker with the same neighbours (the
    training frames are those where the marker is seen): it is fitted once per marker and
    neighbour set and predicts all those gaps (:func:`window_fills`); their rigid frames
    are fitted together (:func:`_fit_together`). The fits are
    independent but run one after another in the calling thread: each is ~100 array
    operations on a few hundred frames, between which it holds the GIL, so on two task
    threads (:func:`mocapfix.core.threads.parallel_map`) the threads mostly hand the
    GIL to each other — measured against them, paired runs on the 2-core machine: c3d.org
    s02 (89 frames, 279 fits) 1.4× faster, s20, s28 and s09 1.1–1.4×, the 4,500-frame case
    of ``benchmarks/clean_speed.py`` through the CLI 0.90× the wall time
    (benchmarks/RESULTS.md, "The fill ensemble's fits on one thread"). A process of its
    own runs them side by side: :func:`validated_member_fills` fits half the markers in a
    forked child."""
    if mu is None:
        mu, sd = distance_stats(pos, observed)
    T = pos.shape[0]
    sizes = (neighbours,) if np.isscalar(neighbours) else tuple(neighbours)
    cands = [candidates(observed, sd, j, s, e) for j, s, e in gaps]
    # one job per (marker, member set, neighbour count, markers used): the gaps it fills
    jobs: dict = {}
    for g, ((j, s, e), cand) in enumerate(zip(gaps, cands)):
        for n, K in enumerate(sizes):
            # the global regression and the pose members do not depend on K: one job
            # (for the first K); pose regresses on the next POSE_SIZES neighbours too
            members = tuple(f for f in local if f != "linear" and (n == 0 or f in PER_NEIGHBOUR_COUNT))
            if members:
                extra = tuple(cand[:K + max(POSE_SIZES)]) if "pose" in members else ()
                jobs.setdefault((j, members, K, tuple(cand[:K]), extra), []).append(g)
            if n == 0 and "linear" in local:
                jobs.setdefault((j, ("linear",), K, (), tuple(cand)), []).append(g)
    train = {j: _training_frames(observed[:, j], max_train) for j, *_ in jobs}

    def held_points(job):
        (j, _, _, markers, body), _ = job
        return len(train[j]) * max(len(markers), len(body))

    fills = [{} for _ in gaps]
    for batch in _batches(jobs.items(), held_points):
        fitted = _fit_together([
            window_fills(pos, observed, j, [gaps[g][1:] for g in group],
                         np.array(markers, dtype=np.intp), train[j],
                         np.array(body, dtype=np.intp), fillers=members, mu=mu,
                         weight_scale=weight_scale, references=references)
            for (j, members, K, markers, body), group in batch])
        for ((j, members, K, markers, body), group), parts in zip(batch, fitted):
            for g, (_, part) in zip(group, parts):
                fills[g].update({_member_name(f, K, sizes): v for f, v in part.items()})
    order = member_names(local, sizes)
    out = []
    for (j, s, e), cand, f in zip(gaps, cands, fills):
        frames = np.arange(max(s - 1, 0), min(e + 1, T))
        f = {name: f[name] for name in order if name in f}
        out.append((cand, _ramped(pos, observed, j, s, e, frames, f, external)))
    return out


def member_names(local, neighbours) -> list[str]:
    """The names of the members :func:`member_fills` computes from the local fillers
    ``local`` with ``neighbours`` (K or several K), in its order."""
    sizes = (neighbours,) if np.isscalar(neighbours) else tuple(neighbours)
    return [_member_name(f, K, sizes) for n, K in enumerate(sizes) for name in local
            if n == 0 or name in PER_NEIGHBOUR_COUNT
            for f in ([f"pose{M}" for M in POSE_SIZES] if name == "pose" else [name])]


def _member_name(filler: str, K: int, sizes: tuple) -> str:
    """A member's name: the fillers run once per neighbour count carry it when there are
    several counts (``interp3``, ``interp5``); ``linear`` and ``poseM`` run once."""
    return filler + (str(K) if len(sizes) > 1 and filler in PER_NEIGHBOUR_COUNT else "")


def validated_member_fills(pos, observed, gaps, copies, external, *, local=LOCAL_FILLERS,
                           neighbours=3, weight_scale: float = 300.0, mu=None, sd=None,
                           max_train: int = 600, copy_external=None,
                           references: dict | None = None, finish=None):
    """:func:`member_fills` of every gap with each member's mean squared error on the
    gap's validation windows. ``copies``: per copy, ``(cut, windows)`` with ``cut`` the
    observed mask with the copy's windows removed and ``windows`` a list of ``(gap index,
    u, v)``: synthetic gaps of the gap's length where its marker and borders were seen.
    Each copy is filled as a capture of its own (:func:`member_fills` on ``cut``: one fit
    per marker and neighbour set serves all its windows); ``copy_external(cut)`` gives the
    ``external`` members' fills of the copy (None: the external members are not
    validated). The copies fit their rigid frames onto the reference shapes of the real
    gaps' frames (the same marker and neighbours; a reference only fixes the frame's
    orientation; ``references``: those shapes by ``(marker, neighbours)``, used and
    extended; the refill rounds of :class:`mocapfix.cleaners.pma.PMA` pass the first
    pass's, made from other training frames). Returns one ``(cand, fills, errors,
    windows)`` per gap, ``errors`` name → mean squared error over the copies and
    ``windows`` one ``(copy, u, v, cand, fills, errors)`` per window of the gap: the
    members' fills of that window and their squared errors on it (so that a caller can
    measure its own combination of the members on the windows).

    The gaps are fitted in two groups of markers (:func:`marker_groups`), each group's
    fits together, the second group in a child process beside this one where that can
    pay (:func:`mocapfix.core.forked.both`; the same values either way): the fits hold
    the GIL, so threads could not run them side by side. A reference shape belongs to
    one marker's gaps, so each group makes the ones it uses as it would alone.

    ``finish(indices, rows)``: what a caller makes of a group's rows (one result per gap
    of ``indices``), run in the process that fitted the group, so that the child sends
    back that with the rows (which ``finish`` may trim of what it alone needed); the call
    then returns ``(rows, finished)``, ``finished`` one result per gap."""
    from mocapfix.core.forked import both

    references = {} if references is None else references
    if mu is None:
        mu, sd = distance_stats(pos, observed)
    settings = dict(local=local, neighbours=neighbours, weight_scale=weight_scale, mu=mu,
                    sd=sd, max_train=max_train, copy_external=copy_external)
    groups = marker_groups(gaps, copies) if not external else [list(range(len(gaps)))]

    def group(which, refs):
        place = {g: k for k, g in enumerate(which)}
        rows = _validated_member_fills(
            pos, observed, [gaps[g] for g in which],
            [(cut, [(place[g], u, v) for g, u, v in windows if g in place])
             for cut, windows in copies], external, references=refs, **settings)
        return rows, (finish(which, rows) if finish else None)

    if len(groups) < 2:
        rows, finished = group(list(range(len(gaps))), references)
        return (rows, finished) if finish else rows
    known = set(references)

    def aside():
        refs = dict(references)
        done = group(groups[1], refs)
        return done, {k: v for k, v in refs.items() if k not in known}

    tested = np.bincount([g for _, windows in copies for g, _, _ in windows],
                         minlength=len(gaps))
    work = [len(which) + int(tested[which].sum()) for which in groups]
    (second, made), first = both(aside, lambda: group(groups[0], references),
                                 fork=min(work) >= FORK_WORK)
    references.update(made)
    out, finished = [None] * len(gaps), [None] * len(gaps)
    for which, (rows, extra) in zip(groups, (first, second)):
        for k, g in enumerate(which):
            out[g] = rows[k]
            finished[g] = extra[k] if finish else None
    return (out, finished) if finish else out


#: the least work (gaps and validation windows) the smaller group of
#: :func:`validated_member_fills` must have for a child process to fit it: ~2 ms of
#: fits each on the 4,500-frame case of benchmarks/clean_speed.py, the fork ~3 ms
FORK_WORK = 8


def marker_groups(gaps, copies) -> list[list[int]]:
    """The gaps' indices in two groups of whole markers with about the same work (a
    marker's gaps and their validation windows, largest first into the lighter group),
    or one group when one marker has all the gaps. Depends on the gaps and windows
    only (not on the cores)."""
    load: dict = {}
    for j, _, _ in gaps:
        load[j] = load.get(j, 0) + 1
    for _, windows in copies:
        for g, _, _ in windows:
            load[gaps[g][0]] = load.get(gaps[g][0], 0) + 1
    if len(load) < 2:
        return [list(range(len(gaps)))]
    side, totals = {}, [0, 0]
    for j in sorted(load, key=lambda m: (-load[m], m)):
        k = int(totals[1] < totals[0])
        side[j] = k
        totals[k] += load[j]
    return [[g for g, (j, _, _) in enumerate(gaps) if side[j] == k] for k in (0, 1)]


def _validated_member_fills(pos, observed, gaps, copies, external, *, local, neighbours,
                            weight_scale, mu, sd, max_train, copy_external, references):
    """:func:`validated_member_fills` of one group of gaps (copies with no window of
    theirs are skipped)."""
    references = {} if references is None else references
    real = member_fills(pos, observed, gaps, external, local=local, neighbours=neighbours,
                        weight_scale=weight_scale, mu=mu, sd=sd, max_train=max_train,
                        references=references)
    errors = [{} for _ in gaps]
    windows_of = [[] for _ in gaps]
    for c, (cut, windows) in enumerate(copies):
        if not windows:
            continue
        synth = [(gaps[g][0], u, v) for g, u, v in windows]
        fills = member_fills(np.where(cut[..., None], pos, np.nan), cut, synth,
                             copy_external(cut) if copy_external else {}, local=local,
                             neighbours=neighbours, weight_scale=weight_scale, mu=mu, sd=sd,
                             max_train=max_train, references=references)
        for (g, u, v), (cand, f) in zip(windows, fills):
            j = gaps[g][0]
            mine = {name: mean_of(np.sum((value - pos[u:v, j]) ** 2, axis=1))
                    for name, value in f.items()}
            for name, value in mine.items():
                errors[g].setdefault(name, []).append(value)
            windows_of[g].append((c, u, v, cand, f, mine))
    return [(cand, f, {k: mean_of(v) for k, v in err.items()}, mine)
            for (cand, f), err, mine in zip(real, errors, windows_of)]


def candidates(observed, sd, j, s, e):
    """The markers observed on frames ``s-1 .. e`` (the gap ``s..e-1`` of ``j`` and its
    borders) with a known distance deviation to ``j``, most rigid first: the neighbours
    every local filler draws on (none: no local filler can fill the gap)."""
    T = observed.shape[0]
    seen = observed[max(s - 1, 0):min(e + 1, T)].all(axis=0)
    seen[j] = False
    cand = np.flatnonzero(seen & np.isfinite(sd[j]))
    return cand[np.argsort(sd[j, cand], kind="stable")]


def _training_frames(seen, max_train):
    """The frames where ``seen``, at most ``max_train`` of them evenly spaced (the
    regressions need no more: the cost stays O(gaps))."""
    train = np.flatnonzero(seen)
    if len(train) > max_train:
        train = train[np.linspace(0, len(train) - 1, max_train).astype(int)]
    return train


def _ramped(pos, observed, j, s, e, frames, fills, external):
    """The fills (and the ``external`` fills that cover the whole gap) on frames ``s..e-1``,
    each ramped to meet the observed borders (:func:`meet_borders`)."""
    T = pos.shape[0]
    fills = dict(fills)
    data = np.where(observed[frames, j][:, None], pos[frames, j], np.nan)
    gap_rows = (frames >= s) & (frames < e)
    for name, full in external.items():
        value = full[frames, j]
        if not np.isnan(value[gap_rows]).any():
            fills[name] = np.where(np.isnan(value), data, value)
    return {k: meet_borders(v, data, s > 0, e < T)[gap_rows] for k, v in fills.items()}


def hermite_short_gaps(pos: np.ndarray, observed: np.ndarray, gaps) -> list:
    """Fill (in place) the interior gaps ``(j, s, e)`` of ``pos`` (T, J, 3) by a cubic
    Hermite curve through the bounding samples, with one-sided difference slopes where the
    samples beyond are observed (the chord's slope otherwise). Meant for holes of a few
    frames (spike holes, dropouts), where it matches PCHIP without loading SciPy.
    Vectorised over all gaps at once (one row per filled sample). Returns the gaps it filled."""
    T = pos.shape[0]
    done = [(j, s, e) for j, s, e in gaps if s > 0 and e < T]
    if not done:
        return done
    g = np.array(done, dtype=np.intp).reshape(-1, 3)
    j, s, e = g[:, 0], g[:, 1], g[:, 2]
    n = e - s
    p0, p1 = pos[s - 1, j], pos[e, j]                                     # (G, 3)
    chord = (p1 - p0) / (n + 1)[:, None]
    has0 = (s >= 2) & observed[np.maximum(s - 2, 0), j]
    has1 = (e + 1 < T) & observed[np.minimum(e + 1, T - 1), j]
    m0 = np.where(has0[:, None], p0 - pos[np.maximum(s - 2, 0), j], chord)
    m1 = np.where(has1[:, None], pos[np.minimum(e + 1, T - 1), j] - p1, chord)
    gi = np.repeat(np.arange(len(g)), n)                                  # one row per sample
    k = np.arange(len(gi)) - np.repeat(np.cumsum(n) - n, n) + 1           # 1 .. n in each gap
    u = (k / (n + 1)[gi])[:, None]
    h00, h10 = 2 * u ** 3 - 3 * u ** 2 + 1, u ** 3 - 2 * u ** 2 + u
    h01, h11 = -2 * u ** 3 + 3 * u ** 2, u ** 3 - u ** 2
    L = (n + 1)[gi][:, None]
    pos[s[gi] + k - 1, j[gi]] = (h00 * p0[gi] + h10 * L * m0[gi] + h01 * p1[gi]
                                 + h11 * L * m1[gi])
    return done


# -- one gap's fill from its members' fills (the combination of fill_ensemble and pma) ----

@dataclass(frozen=True)
class Combination:
    """What combining one gap's member fills needs, shared by every gap of a capture:
    the distance statistics of the marker pairs (``mu``, ``sd``: :func:`distance_stats`),
    the smallest distance deviation in the plausibility weights (``floor``), the capture
    volume (``box``: the observed samples' box grown by 10 % a side), each marker's
    largest observed step (``top``: :func:`mocapfix.solvers.segments.largest_steps`), and
    the cleaner's settings: how members are weighted (``weights``: plausibility,
    validation or best), the soft constraint (``constraint_neighbours``, ``width``) and
    the jump screen (``max_step``)."""

    mu: np.ndarray
    sd: np.ndarray
    floor: float
    box: tuple
    top: np.ndarray
    weights: str = "plausibility"
    constraint_neighbours: int = 3
    width: float = 2.0
    max_step: float = 0.0


def combine(pos, gap, cand, fills, verr, ctx: Combination):
    """One gap's fill from its members' fills: their average weighted by validation
    error (or by plausibility where a member was not validated), pulled inside the
    distance intervals of the marker's most rigid neighbours; averaged again without
    the members that jump when that fill jumps (:func:`without_jumps`). Returns None
    when no member filled the gap, else ``(avg, spread, names, weights)`` with ``avg``
    None when the fill leaves the capture volume ``ctx.box``."""
    if not fills:
        return None
    result = weighted(pos, gap, cand, fills, verr, ctx)
    smooth = without_jumps(pos, gap, fills, result[0], ctx)
    if smooth is not None:
        result = weighted(pos, gap, cand, smooth, verr, ctx)
    avg = result[0]
    if ((avg < ctx.box[0]) | (avg > ctx.box[1])).any():
        return (None, *result[1:])
    return result


def _weighted_sum(w: np.ndarray, stack: np.ndarray) -> np.ndarray:
    """``np.tensordot(w, stack, axes=1)`` for weights ``w`` (M,) of a stack (M, ...): the
    one matrix product it makes, (1, M) by (M, the rest), without its ~12 µs of wrapping."""
    return np.dot(w.reshape(1, -1), stack.reshape(len(w), -1)).reshape(stack.shape[1:])


def weighted(pos, gap, cand, fills, verr, ctx: Combination):
    """:func:`combine`'s weighted average of ``fills`` and soft constraint →
    ``(avg, spread, names, weights)``."""
    j, s, e = gap
    frames = np.arange(s, e)
    names = list(fills)
    stack = np.stack([fills[k] for k in names])              # (M, n, 3)
    rig = cand[:5]
    if all(k in verr for k in names):
        w = validation_weights([verr[k] for k in names], ctx.weights)
    elif len(rig):
        others = pos[np.ix_(frames, rig)]
        score = np.array([plausibility(f, others, ctx.mu[j, rig], ctx.sd[j, rig], ctx.floor)
                          for f in stack])
        w = 1.0 / (score + 1e-3)
    else:
        w = np.ones(len(names))
    w /= w.sum()
    avg = _weighted_sum(w, stack)
    spread = np.sqrt(_weighted_sum(w, ((stack - avg) ** 2).sum(axis=2)))
    k = ctx.constraint_neighbours
    if k and len(cand):
        rig = cand[:k]
        avg = soft_distance_constraint(
            avg, pos[np.ix_(frames, rig)], ctx.mu[j, rig], np.maximum(ctx.sd[j, rig], ctx.floor),
            ctx.width)
    return avg, spread, names, w


def validation_weights(mse, how: str = "validation"):
    """Member weights from their validation errors: inverse squared error, or all on
    the best (``how == "best"``)."""
    mse = np.asarray(mse, dtype=float)
    return (mse == mse.min()).astype(float) if how == "best" \
        else 1.0 / (mse + 1e-12 + 1e-6 * mse.min())


def without_jumps(pos, gap, fills, fill, ctx: Combination):
    """When ``fill`` (a gap's average), joined to the data at the gap's borders, moves
    further from one frame to the next than ``ctx.max_step`` × the marker's largest
    observed step ``ctx.top[j]``: the members of ``fills`` that do not, if there are some
    and not all; else None (keep the average: ``max_step`` 0, a marker never seen
    twice in a row, a fill that does not jump, or no member that does better)."""
    j, s, e = gap
    limit = ctx.max_step * ctx.top[j]
    if limit <= 0:
        return None
    T = pos.shape[0]
    before = pos[s - 1, j] if s > 0 else None
    after = pos[e, j] if e < T else None
    if steepest_step(fill, before, after) <= limit:
        return None
    smooth = {k: f for k, f in fills.items() if steepest_step(f, before, after) <= limit}
    return smooth if 0 < len(smooth) < len(fills) else None


def average(pos, gap, fills, verr, ctx: Combination):
    """The validation-weighted average of a gap's validated member fills (all of them
    when none was validated), without the members that jump when it jumps
    (:func:`without_jumps`)."""
    avg = plain_average(fills, verr, ctx.weights)
    smooth = without_jumps(pos, gap, fills, avg, ctx)
    return avg if smooth is None else plain_average(smooth, verr, ctx.weights)


def plain_average(fills, verr, how: str = "validation"):
    """The average of ``fills`` weighted by their validation errors ``verr`` (equal
    weights when none was validated)."""
    names = [k for k in fills if k in verr] or list(fills)
    w = validation_weights([verr[k] for k in names], how) if names[0] in verr \
        else np.ones(len(names))
    return _weighted_sum(w / w.sum(), np.stack([fills[k] for k in names]))
