"""Trained motion priors against ``kinect_skeleton`` on the ``kinect`` protocol's jitter
scenario (issue 12: the 0.6x target there is not met; does a motion model trained on the
CMU corpus help?).

Methods, each on the same corrupted files as ``mocapfix bench --protocol kinect``:

- ``kinect_skeleton``: the cleaner of configs/kinect.yaml, as shipped;
- ``window-wiener``: a Gaussian prior over windows of ``--window`` frames of the 25 Kinect
  v2 joints (pelvis-centred, turned so the hip line lies along x), its covariance
  estimated on ``../shared/training/cmu-asfamc`` mapped to Kinect joints as the protocol
  maps its truth (:data:`mocapfix.bench.kinect.AMC_TO_KINECT`, 30 fps), its mean the
  file's own mean window; the posterior mean of every window (noise σ per joint and depth
  from the protocol: an oracle in its favour), averaged over the overlapping windows;
- ``mssa(trained)``: the ``mssa`` cleaner (Lou 2012) in joint-position space with bases
  trained on the same Kinect-mapped corpus (window ``--window``);
- ``partlet(kinect)``: the ``partlet_dictionary`` cleaner with its shipped Kinect model;
- ``blend a``: (1 − a) · kinect_skeleton + a · the prior's output, a = 0.2 (the best of
  0.2-0.5 on the first 4 files, seed 0);
- ``per-joint GCV`` / ``per-joint oracle``: per-joint Whittaker smooths (d = 3) of the
  raw file with the strength GCV picks, or the one the truth picks (one per joint, or per
  sample within ±5 frames): the best any per-joint smoother set from the data can do.

RMSE mm against the truth, mean over files, seed ``--seed``, and its ratio to the best
of the four baselines of the protocol (mean over files, and the worst file)::

    python benchmarks/studies/kinect_priors.py [--every 3] [--seed 0] [--window 8]

Measured with ``--every 1`` (all 11 files, seed 0; ~10 s; ``kinect_skeleton`` with its
rigid pairs, validated fills and time-varying strength, 0.719 before them, when the blends
were 0.694 and 0.706):

| method | RMSE mm | ÷ best baseline | worst file ÷ best |
|---|---|---|---|
| baseline(best) | 11.19 | 1.000 | 1.000 |
| kinect_skeleton | 7.64 | 0.682 | 0.763 (05_10) |
| window-wiener | 10.24 | 0.917 | 1.290 (cmu_131_03) |
| blend wiener | 7.48 | 0.667 | 0.733 (60_10) |
| mssa(trained) | 12.15 | 1.091 | 2.051 (cmu_131_03) |
| blend mssa | 7.61 | 0.680 | 0.787 (cmu_131_03) |
| partlet(kinect) | 16.99 | 1.459 | 2.766 (90_31) |
| per-joint GCV | 9.84 | 0.879 | 0.999 (143_35) |
| per-joint oracle (one strength) | 9.80 | 0.875 | 1.001 (143_35) |
| per-joint oracle (±5 frames) | 8.41 | 0.751 | 0.840 (61_10) |
| kinect_skeleton, final strength by the truth (±5 frames) | 7.27 | 0.649 | 0.739 (05_10) |
| kinect_skeleton without the wrist-thumb bones | 7.55 | 0.675 | 0.761 (05_10) |

A Gaussian mixture over windows of each body part, the strongest trained prior measured, is
in ``benchmarks/studies/kinect_gmm_prior.py`` (0.765 alone, 0.648 blended).

The priors trained on the 47 CMU dance/salsa/acrobatics trials do not carry to the
walks and to the BVH skeletons (131_01/03) alone; blended they gain 0.01-0.03 of the
best baseline (0.015 and 0.002 now), far from the 0.6 target, for a shipped model and a window solve per
frame: not shipped. The cleaner's own smoothing strength is not what stands between it and
0.6 either: chosen with the truth for every sample, it gives 0.649. The wrist-thumb links
cost 0.007 (0.8 mm on 60_10, where that distance varies by 15 % in the truth); they are
kept: on the five shared Kinect v2 recordings the wrist-thumb distance is among the most
varying links (std/mean 0.19-0.44 as read) and, left free, it keeps most of that
(0.13-0.36), raising the output's mean bone-length variation from 0.0003-0.0091 to
0.0135-0.0349.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

REPO = Path(__file__).resolve().parents[2]          # benchmarks/studies/ → the repository
DATA = REPO.parent / "shared" / "data"
TRAINING = REPO.parent / "shared" / "training" / "cmu-asfamc"


def _windows(P, L, root, hl, hr):
    """(N, L·J·3) pelvis-centred, hip-line-aligned windows and the transforms."""
    N = len(P) - L + 1
    W = P[np.arange(N)[:, None] + np.arange(L)[None]]
    c = W[:, :, root].mean(axis=1)
    hip = (W[:, :, hl] - W[:, :, hr]).mean(axis=1)
    ang = np.arctan2(hip[:, 2], hip[:, 0])
    cs, sn = np.cos(ang)[:, None, None], np.sin(ang)[:, None, None]
    X = W - c[:, None, None]
    R = X.copy()
    R[..., 0] = cs * X[..., 0] + sn * X[..., 2]
    R[..., 2] = -sn * X[..., 0] + cs * X[..., 2]
    return R.reshape(N, -1), (c, cs, sn)


def _unwindow(R, tf, T, L, J):
    c, cs, sn = tf
    N = len(R)
    R = R.reshape(N, L, J, 3)
    X = R.copy()
    X[..., 0] = cs * R[..., 0] - sn * R[..., 2]
    X[..., 2] = sn * R[..., 0] + cs * R[..., 2]
    X = X + c[:, None, None]
    out, cnt = np.zeros((T, J, 3)), np.zeros(T)
    for lag in range(L):
        out[lag:lag + N] += X[:, lag]
        cnt[lag:lag + N] += 1
    return out / cnt[:, None, None]


def oracle_bounds(P, truth, t, half=5):
    """RMSE mm of per-joint Whittaker smooths (d = 3) of ``P`` when the strength is chosen
    with the truth: one per joint (best of 16 cut-offs 0.5-15 Hz), and per sample by the
    least true error within ±``half`` frames -- what any per-joint smoother whose strength
    is set from the data can at best reach; plus the GCV choice the cleaner makes."""
    from scipy.ndimage import uniform_filter1d

    from mocapfix.solvers import whittaker

    h, w = float(np.median(np.diff(t))), np.ones(len(t))
    lams = whittaker.lambda_for_cutoff(np.geomspace(0.5, 15.0, 16), 1.0, h, 3)
    bands = whittaker.penalty_bands(t, 3)
    J = P.shape[1]
    Zs = np.stack([np.stack([whittaker.smooth(P[:, j], w, t, lam, order=3, bands=bands)
                             for j in range(J)], axis=1) for lam in lams])
    E = np.sum((Zs - truth[None]) ** 2, axis=-1)                      # (K, T, J)
    gcv = [np.sum((whittaker.smooth_gcv(P[:, j], w, t, lams[::-1], order=3, bands=bands,
                                        refine=True)[0] - truth[:, j]) ** 2, axis=-1)
           for j in range(J)]
    local = uniform_filter1d(E, 2 * half + 1, axis=1, mode="nearest")
    pick = np.take_along_axis(E, np.argmin(local, axis=0)[None], 0)
    return {"per-joint GCV": np.sqrt(np.mean(gcv)) * 1e3,
            "per-joint oracle (one strength)": np.sqrt(np.min(E.mean(axis=1), axis=0).mean()) * 1e3,
            f"per-joint oracle (±{half} frames)": np.sqrt(pick.mean()) * 1e3}


def truth_strength(motion, truth, half=5):
    """``kinect_skeleton`` with its final smooth's strength chosen by the truth: among 9
    strengths over the range its local Stein risk picks from, each sample takes the one of
    least true error within ±``half`` frames, its log averaged over the same window as the
    cleaner averages its own choice (the ceiling of any rule that sets that strength from
    the data). The smooth's joint is the truth joint nearest its samples."""
    from scipy.ndimage import uniform_filter1d

    from mocapfix.cleaners import build
    from mocapfix.solvers import whittaker

    shipped = whittaker.smooth_local_sure

    def by_truth(y, w, t, lams, *, order=2, bands=None, coefficients=None, **_):
        seen = np.where(w[:, None] > 0, y, np.nan)
        j = int(np.argmin(np.nanmean(np.linalg.norm(truth - seen[:, None], axis=2), axis=0)))
        grid = np.geomspace(np.min(lams), np.max(lams), 9)
        Zs, _ = whittaker.local_sure_candidates(y, w, t, grid, order=order, bands=bands)
        err = uniform_filter1d(np.sum((Zs - truth[None, :, j]) ** 2, axis=-1), 2 * half + 1,
                               axis=1, mode="nearest")
        pick = np.argmin(err, axis=0)
        lam = np.exp(uniform_filter1d(np.log(grid)[pick], 2 * half + 1, mode="nearest"))
        return whittaker.smooth_varying(y, w, t, lam, order=order,
                                        coefficients=coefficients), pick

    whittaker.smooth_local_sure = by_truth
    try:
        return build("kinect_skeleton").apply(motion)[0].positions
    finally:
        whittaker.smooth_local_sure = shipped


def without_links(motion, pairs):
    """``kinect_skeleton`` with the joint pairs ``pairs`` (names) left out of its bone
    projections: the Kinect v2 SDK links the thumb to the wrist, but in a CMU truth the
    thumb hangs off the hand, and the wrist-thumb distance varies (std/mean 0.5-15 % over
    the 11 files; hand-thumb and hand-tip are exactly rigid there)."""
    import mocapfix.cleaners.depth_skeleton as ds
    from mocapfix.cleaners import build

    drop = {frozenset((motion.index(a), motion.index(b))) for a, b in pairs}
    shipped = ds.project_lengths

    def kept(P, links, lengths, var, **kw):
        links = np.asarray(links)
        keep = np.array([frozenset(map(int, link)) not in drop for link in links], bool)
        return shipped(P, links[keep], np.asarray(lengths)[..., keep], var, **kw)

    ds.project_lengths = kept
    try:
        return build("kinect_skeleton").apply(motion)[0].positions
    finally:
        ds.project_lengths = shipped


def kinect_corpus() -> list[np.ndarray]:
    """The training corpus (``TRAINING``) mapped to the 25 Kinect v2 joints as the protocol
    maps its truth, at 30 fps (both phases of the 120 Hz frames): (T, 25, 3) m each."""
    from mocapfix.bench import kinect as bk
    from mocapfix.train import discover_training, read_all

    train = []
    for m in read_all(discover_training([str(TRAINING)])):
        idx = [m.index(bk.AMC_TO_KINECT[n]) for n in bk.kl.KINECT_V2]
        for off in (0, 2):
            train.append(m.positions[off::4, idx] * m.metres_per_unit)
    return train


def protocol_files() -> list[Path]:
    """The protocol's 11 files, in the order whose index seeds each file's corruption."""
    return sorted((DATA / "asfamc").glob("*.amc")) + sorted((DATA / "bvh").glob("cmu_*.bvh"))


def jitter_files(every, picks, seed):
    """(index, Motion read back from the Kinect v2 CSV, truth (T, 25, 3) m on its frames)
    of the jitter scenario for each picked file, built as ``mocapfix bench --protocol
    kinect`` builds them."""
    from mocapfix.bench import kinect as bk
    from mocapfix import formats
    from mocapfix.formats import kinect as kinect_format

    with tempfile.TemporaryDirectory() as tmp:
        for fi in picks:
            src = formats.read(every[fi])
            truth_all = bk.kinect_truth(src, np.random.default_rng([seed, fi]), 450)
            times_all = np.arange(len(truth_all)) / bk.KINECT_FPS
            coords, states, keep = bk.sensor_corruption(truth_all, "jitter", seed * 1000 + fi * 10)
            path = Path(tmp) / "x.csv"
            path.write_text(bk.kinect_v2_csv(coords[keep], states[keep], times_all[keep]))
            yield fi, kinect_format.read(path), truth_all[keep]


def print_table(rows: dict, names: list[str]) -> None:
    """Markdown rows: RMSE mm (mean over files), its ratio to ``rows["baseline(best)"]``
    (mean over files) and the worst file's ratio."""
    best = np.array(rows["baseline(best)"])
    print("| method | RMSE mm | ÷ best baseline | worst file ÷ best |\n|---|---|---|---|")
    for k, v in rows.items():
        ratio = np.array(v) / best
        print(f"| {k} | {np.mean(v):.2f} | {ratio.mean():.3f} | {ratio.max():.3f} "
              f"({names[int(np.argmax(ratio))]}) |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--every", type=int, default=3, help="every n-th of the 11 files "
                    "(3: 05_01, 13_39, 60_10, cmu_131_01; 1: all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--window", type=int, default=8)
    args = ap.parse_args()
    from mocapfix.bench import kinect as bk
    from mocapfix.cleaners import build
    from mocapfix.core.motion import Motion

    names = list(bk.kl.KINECT_V2)
    ix = {n: i for i, n in enumerate(names)}
    root, hl, hr, L, J = ix["SpineBase"], ix["HipLeft"], ix["HipRight"], args.window, len(names)
    bones = bk.kl.skeleton_for("kinect_v2").bone_array
    train = kinect_corpus()
    Xs = np.concatenate([_windows(P, L, root, hl, hr)[0][::2] for P in train])
    Xc = Xs - Xs.mean(axis=0)
    C = Xc.T @ Xc / len(Xc)
    # the files, numbered as the protocol numbers them (its seeds depend on the index)
    every = protocol_files()
    picks = list(range(0, len(every), args.every))
    mssa = None
    rows = {k: [] for k in ("baseline(best)", "kinect_skeleton", "window-wiener", "blend wiener",
                            "mssa(trained)", "blend mssa", "partlet(kinect)", "per-joint GCV",
                            "per-joint oracle (one strength)", "per-joint oracle (±5 frames)",
                            "kinect_skeleton, final strength by the truth (±5 frames)",
                            "kinect_skeleton without the wrist-thumb bones")}
    for fi, motion, truth in jitter_files(every, picks, args.seed):
        times, mpu = motion.times, motion.metres_per_unit

        def rmse(est, truth=truth, times=times):
            return bk.score(est, truth, times, bones)["rmse_mm"]

        base = bk._baseline_outputs(motion, times, truth, bones)
        rows["baseline(best)"].append(min(rmse(e) for e, _, _ in base.values()))
        out, _ = build("kinect_skeleton").apply(motion)
        Z = out.positions * mpu
        rows["kinect_skeleton"].append(rmse(Z))
        P = bk.interpolate_missing(motion.positions * mpu, times)
        sig = bk.JITTER_BASE_MM[None] * 1e-3 * P[..., 2] / 2.0
        X, tf = _windows(P, L, root, hl, hr)
        mu = X.mean(axis=0)
        d = np.repeat(np.tile(np.median(sig, axis=0) ** 2, L), 3)
        K = np.linalg.solve(C + np.diag(d), C).T            # C (C + D)^-1
        W = _unwindow((X - mu) @ K.T + mu, tf, len(P), L, J)
        rows["window-wiener"].append(rmse(W))
        rows["blend wiener"].append(rmse(0.8 * Z + 0.2 * W))
        if mssa is None:
            mssa = build("mssa", space="positions", window=L, window_step=2)
            mssa.fit([Motion(P / mpu, names, bk.KINECT_FPS, units=motion.units,
                             metres_per_unit=mpu, format="kinect") for P in train])
        M = mssa.apply(motion)[0].positions * mpu
        rows["mssa(trained)"].append(rmse(M))
        rows["blend mssa"].append(rmse(0.8 * Z + 0.2 * M))
        for k, v in oracle_bounds(P, truth, times).items():
            rows[k].append(v)
        rows["kinect_skeleton, final strength by the truth (±5 frames)"].append(
            rmse(truth_strength(motion, truth) * mpu))
        rows["kinect_skeleton without the wrist-thumb bones"].append(
            rmse(without_links(motion, [("WristLeft", "ThumbLeft"),
                                        ("WristRight", "ThumbRight")]) * mpu))
        rows["partlet(kinect)"].append(rmse(build("partlet_dictionary").apply(motion)[0].positions * mpu))
        print(f"{every[fi].name}: " + ", ".join(f"{k} {v[-1]:.2f}" for k, v in rows.items()))
    print_table(rows, [every[i].name for i in picks])


if __name__ == "__main__":
    main()
