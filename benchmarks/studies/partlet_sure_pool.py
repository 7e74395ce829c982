"""Issue 10: can a combination of our denoisers reach Feng 2015's "Our" dance rows where
``partlet_dictionary`` alone does not (30 dB: 0.91 vs 0.86 cm; 10 dB: 4.94 vs 3.73)?

Three denoisers — ``partlet_dictionary`` (shipped model), its K-SVD ℓ2 variant (Xiao 2015,
the model of ``partlet_tables.ksvd_model``) and ``tsmc`` — each also smoothed along time by
a DCT Whittaker smoother of strength μ ∈ :data:`MUS` (μ = 0: the output itself), give a pool
of candidates f_k. Two ways to weight them, per file:

- ``sure pool``: weights on the simplex minimising Stein's unbiased risk estimate,
  ‖y − Σ w_k f_k‖² + 2σ² Σ w_k div f_k (Stein 1981; Blu & Luisier 2007, SURE-LET), with
  σ the cleaner's own noise estimate (``partlet.noise_level``) and each denoiser's
  divergence estimated by Monte Carlo — one more run on y + εb, b random ±1, ε = 0.2σ
  (Ramani, Blu & Unser 2008, eq. 9). SURE holds for Gaussian noise only, so when more
  than 1 % of the samples are suspect (``partlet.suspect_samples``: 5σ off a running
  median) the pool is not used and partlet's output is returned: the outlier settings
  are partlet's own.
- ``truth pool``: affine weights chosen by least squares against the truth — a bound on
  what any weighting of this pool can reach, not a method.

feng2015 protocol (uncentred SNR, U(±50 cm) outliers), 05_02 and 05_10 whole trials,
seeds 0–1, RMSE cm per marker (eq. 19), CPU seconds per file::

    python benchmarks/studies/partlet_sure_pool.py [--seeds 2] [--settings snr30 snr10 ...]

Measured (05_02 + 05_10, seeds 0–1; 2-core machine):

| method | snr30 | snr20 | snr10 | out20 | snr20+out10 | CPU s/file |
|---|---|---|---|---|---|---|
| paper: Our (dance) | 0.86 | 2.55 | 3.73 | 1.93 | 2.42 | |
| partlet_dictionary | 0.907 | 1.997 | 4.941 | 0.427 | 2.143 | 0.15 |
| sure pool | 0.845 | 1.946 | 4.765 | 0.427 | 2.143 | 0.39–0.40 (0.55 on noise-only input) |
| truth pool | 0.826 | 1.921 | 4.700 | 0.398 | 2.080 | – |

The SURE weights take 30 dB below the paper on the mean of the two trials (05_02 0.81,
05_10 0.876: above it) at 3.7× partlet's time on noise-only input. No weighting of these
denoisers — even one chosen with the truth — comes near 3.73 at 10 dB; a larger pool
chosen with the truth (these three plus the K-SVD ℓ1 variant and partlet without its
coarse scale, its local smoothing strength or its bone step, each at μ ∈ {0, 3, 30,
300}; one-off, script not kept) stopped at 4.67. Not shipped: the 30 dB margin is 2 % on
two trials and one of them stays above the paper, three denoisers run twice each cannot
hold the 1.5 s target at 4,500 frames, and the 10 dB cell does not move.
"""
from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.optimize import minimize  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # benchmarks/: partlet_tables

from partlet_tables import DATA, PAPER_DANCE, SETTINGS, ksvd_model  # noqa: E402

from mocapfix import formats  # noqa: E402
from mocapfix.bench import corrupt
from mocapfix.core import metrics
from mocapfix.bench import cleaner_input  # noqa: E402
from mocapfix.solvers.partlet import noise_level, suspect_samples  # noqa: E402
from mocapfix.config import parse_config  # noqa: E402
from mocapfix.solvers.dct import dct, eigenvalues, idct  # noqa: E402

#: strengths of the extra time smoothing of each denoiser's output (0: the output as is)
MUS = (0.0, 1.0, 3.0, 10.0, 30.0, 100.0, 300.0, 1000.0)
#: probe size of the Monte-Carlo divergence, × σ
EPS = 0.2
#: above this share of suspect samples the noise is not Gaussian: partlet alone
GATE = 0.01


def _pipes() -> dict:
    k = str(ksvd_model())
    step = lambda **kw: {"version": 1, "pipeline": [kw]}  # noqa: E731
    return {name: parse_config(cfg, name) for name, cfg in {
        "partlet": step(cleaner="partlet_dictionary"),
        "ksvd_l2": step(cleaner="partlet_dictionary", model=k, coding="ksvd", loss="l2"),
        "tsmc": step(cleaner="tsmc"),
    }.items()}


def _candidates(outputs: list[np.ndarray], T: int) -> np.ndarray:
    """(T·C, K) every output (T, C) smoothed with every μ of MUS."""
    lam2 = eigenvalues(T) ** 2
    cols = []
    for f in outputs:
        cf = dct(f)
        cols += [idct(cf / (1.0 + mu * lam2)[:, None]).ravel() for mu in MUS]
    return np.stack(cols, axis=1)


def _simplex_sure(F: np.ndarray, y: np.ndarray, div: np.ndarray, s2: float) -> np.ndarray:
    """Weights w ≥ 0, Σw = 1 minimising ‖y − Fw‖² + 2σ² div·w."""
    R = y[:, None] - F
    Q = R.T @ R
    scale = np.trace(Q) / len(div)
    Q, c = Q / scale, s2 * div / scale
    K = len(div)
    res = minimize(lambda w: w @ Q @ w + 2 * c @ w, np.full(K, 1.0 / K),
                   jac=lambda w: 2 * Q @ w + 2 * c, bounds=[(0.0, 1.0)] * K,
                   constraints=[{"type": "eq", "fun": lambda w: w.sum() - 1.0,
                                 "jac": lambda w: np.ones(K)}],
                   method="SLSQP", options={"ftol": 1e-12, "maxiter": 500})
    return res.x


def run_all(motion, pipes: dict) -> tuple[dict, dict]:
    """Each denoiser's output positions on ``motion`` and the CPU seconds it took."""
    outputs, spent = {}, {}
    for name, pipe in pipes.items():
        t = time.process_time()
        outputs[name] = pipe.run(motion)[0].positions
        spent[name] = time.process_time() - t
    return outputs, spent


def sure_pool(motion, pipes: dict, outputs: dict, seed: int = 12345) -> tuple[np.ndarray, bool]:
    """The SURE-weighted pool's output positions (module docstring) from the denoisers'
    ``outputs`` on ``motion`` (:func:`run_all`), and whether the gate kept partlet's alone
    (then only partlet's output is needed)."""
    y = motion.positions
    T = len(y)
    if suspect_samples(y * motion.metres_per_unit, 5.0, 0.04).mean() > GATE:
        return outputs["partlet"], True
    s = noise_level(y.reshape(T, -1))
    b = np.random.default_rng(seed).choice([-1.0, 1.0], size=y.shape)
    probed = motion.replace(positions=y + EPS * s * b)
    slopes = [(pipe.run(probed)[0].positions - outputs[name]).reshape(T, -1) / (EPS * s)
              for name, pipe in pipes.items()]
    F = _candidates([outputs[name].reshape(T, -1) for name in pipes], T)
    div = _candidates(slopes, T).T @ b.ravel()
    w = _simplex_sure(F, y.ravel(), div, s * s)
    return (F @ w).reshape(y.shape), False


def truth_pool(outputs: dict, truth: np.ndarray) -> np.ndarray:
    """Affine weights of the same pool by least squares against the truth (a bound)."""
    T = len(truth)
    F = _candidates([o.reshape(T, -1) for o in outputs.values()], T)
    B = F[:, 1:] - F[:, :1]
    w, *_ = np.linalg.lstsq(B, truth.ravel() - F[:, 0], rcond=None)
    return (F[:, 0] + B @ w).reshape(truth.shape)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--settings", nargs="+", default=SETTINGS)
    args = ap.parse_args()
    pipes = _pipes()
    names = ("partlet_dictionary", "sure pool", "truth pool")
    err = {n: {s: [] for s in args.settings} for n in names}
    cpu = {n: [] for n in names[:2]}
    for trial in ("05_02", "05_10"):
        clean = formats.read(DATA / "asfamc" / f"{trial}.amc").replace(rig=None, channels=None)
        cm = 100 * clean.metres_per_unit
        for s in args.settings:
            for seed in range(args.seeds):
                noisy, _ = corrupt.apply_protocol(clean, "feng2015", s, seed)
                inp = cleaner_input(clean, noisy)
                outputs, spent = run_all(inp, pipes)
                t = time.process_time()
                pooled, gated = sure_pool(inp, pipes, outputs)
                # the pool's cost: partlet, the other two unless the gate closed, the probes
                cpu["sure pool"].append(time.process_time() - t + spent["partlet"] + (
                    0.0 if gated else spent["ksvd_l2"] + spent["tsmc"]))
                cpu["partlet_dictionary"].append(spent["partlet"])
                for n, out in zip(names, (outputs["partlet"], pooled,
                                          truth_pool(outputs, clean.positions))):
                    err[n][s].append(cm * metrics.rmse(out, clean.positions))
                print(trial, s, seed, *(f"{n} {err[n][s][-1]:.3f}" for n in names), flush=True)
    print("\n| method | " + " | ".join(args.settings) + " | CPU s/file |")
    print("|---" * (len(args.settings) + 2) + "|")
    print("| paper: Our (dance) | " + " | ".join(f"{PAPER_DANCE[s]:.2f}" for s in args.settings) + " | |")
    for n in names:
        t = f"{np.mean(cpu[n]):.2f}" if n in cpu else "–"
        print(f"| {n} | " + " | ".join(f"{np.mean(err[n][s]):.3f}" for s in args.settings) + f" | {t} |")


if __name__ == "__main__":
    main()
