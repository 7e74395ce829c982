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

Kernels are vectorised over the frames of a gap; the loop is over gaps.
"""
from __future__ import annotations

import numpy as np

from mocapfix.solvers.rigid import kabsch_to_shape

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


def _translation(points: np.ndarray):
    """``(to_local, to_global)`` of the translation that centres each frame of ``points``
    (n, K, 3): the local frame of fewer than 3 markers."""
    centre = points.mean(axis=1)
    return (lambda x: x - centre[:, None]), (lambda x: x + centre[:, None])


class LocalFrames:
    """Per-frame rigid fits (Kabsch 1976) of a marker's neighbour sets onto their mean
    shape, each frame fitted once and kept: :func:`validated_member_fills` fills the real
    gaps and then its validation copies, whose training frames are a subset of the real
    ones (:func:`member_fills`' ``train``), so most of a copy's fits are already known.
    Keyed by (marker, neighbour set); the mean shape (:func:`_reference`) is taken from the
    first request's reference frames (the real capture's training frames)."""

    def __init__(self):
        self._store: dict = {}

    def get(self, key, pos: np.ndarray, markers: np.ndarray, frame_sets, ref_frames):
        """``(to_local, to_global)`` on each array of ``frame_sets`` of the rigid frame of
        ``markers`` (≥ 3, observed on those frames), with the reference shape of
        ``ref_frames`` on first use; the frames not yet known are fitted in one batch."""
        entry = self._store.get(key)
        if entry is None:
            ref = _reference(_block(pos, ref_frames, markers))
            # slot of each frame's fit in R/cs (-1: not fitted yet)
            entry = self._store[key] = {"ref": ref, "slot": np.full(pos.shape[0], -1, np.intp),
                                        "R": np.empty((0, 3, 3)), "cs": np.empty((0, 3))}
        slot = entry["slot"]
        every = np.concatenate(frame_sets)
        new = every[slot[every] < 0]
        if len(new):
            new = np.unique(new)
            R, cs, _ = kabsch_to_shape(_block(pos, new, markers), entry["ref"])
            slot[new] = len(entry["R"]) + np.arange(len(new))
            entry["R"] = np.concatenate([entry["R"], R])
            entry["cs"] = np.concatenate([entry["cs"], cs])
        centre = entry["ref"].mean(axis=0)
        out = []
        for frames in frame_sets:
            at = slot[frames]
            out.append(_transforms(entry["R"][at], entry["cs"][at],
                                   np.broadcast_to(centre, (len(frames), 3))))
        return out


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


def _reference(points: np.ndarray) -> np.ndarray:
    """Mean shape of (n, K, 3) point sets, after one rigid alignment to the first frame's
    centred shape (enough for a consistent local frame)."""
    if len(points) > 100:                       # a mean shape needs no more frames
        points = points[np.linspace(0, len(points) - 1, 100).astype(int)]
    centred = points - points.mean(axis=1, keepdims=True)
    if points.shape[1] < 3:
        return centred.mean(axis=0)
    ref = centred[0]
    R, cs, ct = kabsch_to_shape(points, ref)
    return ((points - cs[:, None]) @ np.swapaxes(R, 1, 2) + ct[:, None]).mean(axis=0)


class Ridge:
    """Ridge regression of ``Y`` on standardised features (penalty λ·n), predicting from
    the first ``w`` columns for each requested width (nested models from one Gram
    matrix), and refitted on other training rows when asked (``drop`` some of its rows,
    add ``extra`` ones): their sums are subtracted or added and the model re-centred on
    the rows it then has (the standardisation stays). A validation copy's training frames
    are mostly the real capture's, so its model is the real one with a few rows changed
    (:func:`_reuse`)."""

    def __init__(self, X: np.ndarray, Y: np.ndarray, lam: float = 1e-3):
        self.mx, self.sx = X.mean(axis=0), X.std(axis=0)
        self.sx[self.sx < 1e-9] = 1.0
        self.Z, self.Y, self.lam = (X - self.mx) / self.sx, Y, lam
        self.sums = (len(X), self.Z.sum(axis=0), self.Z.T @ self.Z, Y.sum(axis=0),
                     self.Z.T @ Y)

    def predict(self, Xn: np.ndarray, widths=None, drop=None, extra=None) -> list:
        n, s1, s2, sy, szy = self.sums
        if drop is not None and drop.any():
            Zd, Yd = self.Z[drop], self.Y[drop]
            n, s1, s2 = n - len(Zd), s1 - Zd.sum(axis=0), s2 - Zd.T @ Zd
            sy, szy = sy - Yd.sum(axis=0), szy - Zd.T @ Yd
        if extra is not None:
            Za, Ya = (extra[0] - self.mx) / self.sx, extra[1]
            n, s1, s2 = n + len(Za), s1 + Za.sum(axis=0), s2 + Za.T @ Za
            sy, szy = sy + Ya.sum(axis=0), szy + Za.T @ Ya
        zbar, ybar = s1 / n, sy / n
        G = s2 - n * np.outer(zbar, zbar)
        b = szy - n * np.outer(zbar, ybar)
        Zn = (Xn - self.mx) / self.sx - zbar
        out = []
        for w in widths or [len(zbar)]:
            B = np.linalg.solve(G[:w, :w] + self.lam * n * np.eye(w), b[:w])
            out.append(Zn[:, :w] @ B + ybar)
        return out


class GRNN:
    """GRNN (Specht 1991): Gaussian-kernel weighted mean of the training targets; spread =
    the median distance of a training point to its 5th nearest neighbour. At prediction
    ``drop`` leaves training rows out and ``extra`` adds others (spread and
    standardisation kept)."""

    def __init__(self, X: np.ndarray, Y: np.ndarray, max_train: int = 800):
        self.rows = np.arange(len(X))
        if len(X) > max_train:
            self.rows = np.linspace(0, len(X) - 1, max_train).astype(int)
            X, Y = X[self.rows], Y[self.rows]
        self.mx, self.sx = X.mean(axis=0), X.std(axis=0)
        self.sx[self.sx < 1e-9] = 1.0
        self.Z, self.Y = (X - self.mx) / self.sx, Y
        self.sq = (self.Z ** 2).sum(axis=1)
        D2 = np.maximum(self.sq[:, None] + self.sq[None, :] - 2 * self.Z @ self.Z.T, 0.0)
        k = min(5, len(self.Z) - 1)
        spread2 = float(np.median(np.partition(D2, k, axis=1)[:, k])) if k > 0 else 1.0
        self.spread2 = max(spread2, 1e-9)

    def predict(self, Xn: np.ndarray, drop=None, extra=None) -> np.ndarray:
        Z, sq, Y = self.Z, self.sq, self.Y
        if drop is not None and drop.any():
            keep = ~drop[self.rows]
            Z, sq, Y = Z[keep], sq[keep], Y[keep]
        if extra is not None:
            Za = (extra[0] - self.mx) / self.sx
            Z, sq, Y = (np.concatenate([Z, Za]), np.concatenate([sq, (Za ** 2).sum(axis=1)]),
                        np.concatenate([Y, extra[1]]))
        Zn = (Xn - self.mx) / self.sx
        d2 = np.maximum((Zn ** 2).sum(axis=1)[:, None] + sq[None, :] - 2 * Zn @ Z.T, 0.0)
        d2 -= d2.min(axis=1, keepdims=True)              # stable exponent
        w = np.exp(-0.5 * d2 / self.spread2)
        return (w @ Y) / w.sum(axis=1, keepdims=True)


def _reuse(fits: dict, key, frames: np.ndarray, rows, make):
    """``(model, drop, extra)``: the model stored under ``key`` when ``frames`` (sorted,
    unique) share all but a quarter of its training frames, with ``drop`` marking its
    training rows not in ``frames`` and ``extra`` the training rows ``rows(added)`` of the
    frames it lacks (None when none); else ``make(*rows(frames))``, stored for the next
    caller, with ``drop`` and ``extra`` None."""
    if key in fits:
        model, fitted_on = fits[key]
        size = max(int(fitted_on.max(initial=-1)), int(frames.max(initial=-1))) + 1
        wanted, had = np.zeros(size, bool), np.zeros(size, bool)
        wanted[frames], had[fitted_on] = True, True
        added = frames[~had[frames]]
        if len(added) <= len(frames) // 4:
            return model, ~wanted[fitted_on], (rows(added) if len(added) else None)
    model = make(*rows(frames))
    fits[key] = (model, frames)
    return model, None, None


def _poly(z: np.ndarray) -> np.ndarray:
    return np.concatenate([z, z ** 2], axis=1)


def _poly_rows(X: np.ndarray, Y: np.ndarray):
    return _poly(X), Y


def window_fills(pos, observed, j, windows, neighbours, train, body, *,
                 fillers=LOCAL_FILLERS, weight_scale: float = 300.0, mu=None, frames_of=None,
                 fits=None):
    """The local fillers' estimates of marker ``j`` on each window ``(s, e)``, on frames
    ``s-1 .. e`` (the gap plus the border frames that exist), from one fit of each filler
    on ``train``: the regressions are learnt once and predict every window (a real gap
    and the synthetic gaps that validate it). Returns one ``(frames, fills)`` per window,
    ``fills`` name → (len(frames), 3).

    ``neighbours``: indices of the rigid neighbours; ``body``: the markers of ``linear``
    and ``pose`` (most rigid first); both observed on every window's frames. ``train``:
    frames where ``j`` is observed. ``weight_scale`` in the data's units. ``frames_of``
    (:class:`LocalFrames`) and ``fits`` (model key → (model, training frames)) carry the
    rigid fits and the models from one call to the next: a model fitted on a superset of
    this call's training frames is reused less the frames not in this call's
    (:func:`_reuse`)."""
    T = pos.shape[0]
    spans = [np.arange(max(s - 1, 0), min(e + 1, T)) for s, e in windows]
    frames = np.concatenate(spans)
    cuts = np.cumsum([len(f) for f in spans])[:-1]
    out = {}
    K = len(neighbours)
    frames_of = LocalFrames() if frames_of is None else frames_of
    fits = {} if fits is None else fits
    if K and set(fillers) & {"interp", "poly", "grnn", "pose"}:
        tr_local = train[_block(observed, train, neighbours).all(axis=1)]
        key = (j, tuple(neighbours.tolist()))
        if K >= 3:
            (loc, glob), _ = frames_of.get(key, pos, neighbours, (frames, tr_local),
                                           tr_local if len(tr_local) else frames)
        else:
            loc, glob = _translation(_block(pos, frames, neighbours))

        def local_on(fr):
            """The local frame's transform on frames ``fr`` (K ≥ 3)."""
            return frames_of.get(key, pos, neighbours, (fr,), tr_local)[0][0]

        if "interp" in fillers:
            lj = loc(np.nan_to_num(pos[frames, j])[:, None])[:, 0]
            ramps = []
            for (s, e), part in zip(windows, np.split(lj, cuts)):
                n = len(part)
                have0, have1 = s > 0, e < T
                a = part[0] if have0 else part[-1]
                b = part[-1] if have1 else part[0]
                f = (np.arange(n) / max(n - 1, 1))[:, None]
                ramps.append((1 - f) * a + f * b)
            out["interp"] = glob(np.concatenate(ramps)[:, None])[:, 0]
        if len(tr_local) >= max(10, 2 * K) and K >= 3:
            Xg = loc(_block(pos, frames, neighbours)).reshape(len(frames), -1)
            memo = {}

            def rows(fr):
                """Training rows (neighbours, marker) in the local frame on frames ``fr``."""
                if fr.tobytes() not in memo:
                    tl = local_on(fr)
                    memo[fr.tobytes()] = (tl(_block(pos, fr, neighbours)).reshape(len(fr), -1),
                                          tl(pos[fr, j][:, None])[:, 0])
                return memo[fr.tobytes()]

            if "poly" in fillers:
                model, drop, extra = _reuse(fits, key + ("poly",), tr_local,
                                            lambda fr: _poly_rows(*rows(fr)), Ridge)
                out["poly"] = glob(model.predict(_poly(Xg), drop=drop, extra=extra)[0][:, None])[:, 0]
            if "grnn" in fillers:
                model, drop, extra = _reuse(fits, key + ("grnn",), tr_local, rows, GRNN)
                out["grnn"] = glob(model.predict(Xg, drop=drop, extra=extra)[:, None])[:, 0]
            if "pose" in fillers:
                out.update(pose_fills(pos, observed, j, frames, body, K, tr_local, local_on, loc,
                                      glob, fits=fits, key=key))
    if "linear" in fillers and len(body) >= 3:
        tr = train[_block(observed, train, body).all(axis=1)]
        d = mu[j, body] if mu is not None else np.zeros(len(body))
        w = np.repeat(np.exp(-0.5 * (np.nan_to_num(d, nan=1e9) / weight_scale) ** 2), 3)
        keep = w > 1e-6
        if len(tr) >= max(10, len(body)) and keep.sum() >= 3:
            key = (j, tuple(body.tolist()))
            (loc, glob), _ = frames_of.get(key, pos, body, (frames, tr), tr)

            def body_rows(fr):
                tl = frames_of.get(key, pos, body, (fr,), tr)[0][0]
                X = tl(_block(pos, fr, body)).reshape(len(fr), -1) * w
                return X[:, keep], tl(pos[fr, j][:, None])[:, 0]

            model, drop, extra = _reuse(fits, key + ("linear",), tr, body_rows, Ridge)
            Xg = loc(_block(pos, frames, body)).reshape(len(frames), -1) * w
            out["linear"] = glob(model.predict(Xg[:, keep], drop=drop, extra=extra)[0][:, None])[:, 0]
    parts = {k: np.split(v, cuts) for k, v in out.items()}
    return [(f, {k: v[i] for k, v in parts.items()}) for i, f in enumerate(spans)]


def pose_fills(pos, observed, j, frames, cand, K, train, local_on, to_local, to_global,
               *, sizes=POSE_SIZES, lam: float = 1e-3, fits=None, key=()):
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
    markers are seen; ``local_on(frames)`` gives the frame's transform on any of them,
    ``to_local``, ``to_global`` those on ``frames`` (:class:`LocalFrames`, shared with
    ``poly``/``grnn``); ``fits``/``key``: as :func:`window_fills`' (the model's key is
    ``key`` and its markers). Returns name → (len(frames), 3), not yet ramped to the
    borders."""
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

    def feature_rows(fr):
        tl = local_on(fr)
        return (tl(_block(pos, fr, feats)).reshape(len(fr), -1), tl(pos[fr, j][:, None])[:, 0])

    model, drop, extra = _reuse({} if fits is None else fits,
                                key + ("pose", tuple(feats.tolist())), train[rows], feature_rows,
                                lambda X, Y: Ridge(X, Y, lam))
    Xg = to_local(_block(pos, frames, feats)).reshape(len(frames), -1)
    for k, Y in zip(counts, model.predict(Xg, [3 * k for k in counts], drop, extra)):
        out[f"pose{counts[k]}"] = to_global(Y[:, None])[:, 0]
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
    from mocapfix.gaps import runs

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
                 train=None, frames_of=None, fits=None):
    """Every member's fill of every gap, ramped to meet the borders.

    ``external``: name → (T, J, 3) fills computed elsewhere (NaN where not filled);
    ``neighbours``: K, or several K (the local fillers then run once per K, named
    ``interp3``, ``interp5``, ...); ``max_train``: the regressions learn from at most this
    many frames where the marker is seen (evenly spaced); ``train``: marker → its training
    frames, filled in for the markers it lacks (a validation copy passes the real
    capture's, less the frames it cut); ``frames_of``, ``fits``: the rigid fits and models
    kept across copies (:func:`window_fills`). Returns
    one entry per gap: ``(cand, fills)`` with ``cand`` the markers observed on the gap and
    its borders, most rigid first, and ``fills`` name → (gap length, 3).

    A member learns the same model for every gap of a marker with the same neighbours (the
    training frames are those where the marker is seen): it is fitted once per marker and
    neighbour set and predicts all those gaps (:func:`window_fills`)."""
    if mu is None:
        mu, sd = distance_stats(pos, observed)
    T = pos.shape[0]
    sizes = (neighbours,) if np.isscalar(neighbours) else tuple(neighbours)
    cands = [_candidates(observed, sd, j, s, e) for j, s, e in gaps]
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
    fills = [{} for _ in gaps]
    train = {} if train is None else train
    frames_of = LocalFrames() if frames_of is None else frames_of
    fits = {} if fits is None else fits
    for (j, members, K, markers, body), group in jobs.items():
        if j not in train:
            train[j] = _training_frames(observed[:, j], max_train)
        parts = window_fills(pos, observed, j, [gaps[g][1:] for g in group],
                             np.array(markers, dtype=np.intp), train[j],
                             np.array(body, dtype=np.intp), fillers=members,
                             mu=mu, weight_scale=weight_scale, frames_of=frames_of,
                             fits=fits)
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
                           max_train: int = 600, copy_external=None):
    """:func:`member_fills` of every gap with each member's mean squared error on the
    gap's validation windows. ``copies``: per copy, ``(cut, windows)`` with ``cut`` the
    observed mask with the copy's windows removed and ``windows`` a list of ``(gap index,
    u, v)``: synthetic gaps of the gap's length where its marker and borders were seen.
    Each copy is filled as a capture of its own (:func:`member_fills` on ``cut``: one fit
    per marker and neighbour set serves all its windows), its models learning from the
    real capture's training frames it still sees, topped up to as many
    (:func:`_copy_training`): the real capture's models with those rows changed
    (:class:`Ridge`, :class:`GRNN`, :func:`_reuse`) and its rigid fits
    (:class:`LocalFrames`) serve the copies;
    ``copy_external(cut)`` gives the
    ``external`` members' fills of the copy (None: the external members are not
    validated). Returns one ``(cand, fills, errors)`` per gap, ``errors`` name → mean
    squared error over the copies."""
    train, frames_of, fits = {}, LocalFrames(), {}
    real = member_fills(pos, observed, gaps, external, local=local, neighbours=neighbours,
                        weight_scale=weight_scale, mu=mu, sd=sd, max_train=max_train,
                        train=train, frames_of=frames_of, fits=fits)
    errors = [{} for _ in gaps]
    for cut, windows in copies:
        synth = [(gaps[g][0], u, v) for g, u, v in windows]
        fills = member_fills(np.where(cut[..., None], pos, np.nan), cut, synth,
                             copy_external(cut) if copy_external else {}, local=local,
                             neighbours=neighbours, weight_scale=weight_scale, mu=mu, sd=sd,
                             max_train=max_train, frames_of=frames_of, fits=fits,
                             train={j: _copy_training(t, cut[:, j]) for j, t in train.items()})
        for (g, u, v), (_, f) in zip(windows, fills):
            j = gaps[g][0]
            for name, value in f.items():
                errors[g].setdefault(name, []).append(
                    float(np.mean(np.sum((value - pos[u:v, j]) ** 2, axis=1))))
    return [(cand, f, {k: float(np.mean(v)) for k, v in err.items()})
            for (cand, f), err in zip(real, errors)]


def _copy_training(real: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """A validation copy's training frames of a marker: the real capture's (``real``) it
    still sees, topped up to as many with other frames it sees (evenly spaced), so that a
    member is validated with as much data as it fills the real gap with (with fewer, the
    choice of members was worse: HDM05, 6 seeds, gap RMSE 3.51 against 3.30 mm)."""
    kept = real[seen[real]]
    short = len(real) - len(kept)
    others = np.flatnonzero(seen)
    others = others[~np.isin(others, real)]
    if short <= 0 or not len(others):
        return kept
    if len(others) > short:
        others = others[np.linspace(0, len(others) - 1, short).astype(int)]
    return np.union1d(kept, others)


def _candidates(observed, sd, j, s, e):
    """The markers observed on frames ``s-1 .. e`` (the gap ``s..e-1`` of ``j`` and its
    borders) with a known distance deviation to ``j``, most rigid first."""
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
