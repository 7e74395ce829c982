#!/usr/bin/env python3
"""Run time of the ``lowrank_isometry`` cleaner (Yang et al. 2019) against the number of
frames T, next to the paper's MATLAB times (Table VI: 24.7 s for 272 frames, 60.8 s for
584, 148.8 s for 1,100 and 586.3 s for 6,784, on an i5-4690K). Target (issue 5): under 1 %
of the paper's time on a 2-core machine. Prints a Markdown table.

Input: a CMU ASF/AMC capture (31 joints, 30 bones — the paper used 25 joints, so ours is
the larger problem), played forwards then backwards until it has T frames (no jump at the
joins), corrupted with the ``yang2019`` protocol at 10 % (seed 0), handed to the cleaner
as ``mocapfix bench`` does (no rig: bone lengths are estimated from the data). The time
is the whole ``apply`` (unit conversion, length estimation, solver), best of ``--repeat``.

    python benchmarks/yang_speed.py [--amc PATH] [--repeat 3] [--threads N] [-p key=value ...]

``--threads 1`` limits BLAS to one thread (needs ``threadpoolctl``): the matrices here are
small (3T × 31), and on a busy machine a multithreaded BLAS can be several times slower.
"""
from __future__ import annotations

import argparse
import contextlib
import time
from pathlib import Path

import numpy as np

from mocapfix import read
from mocapfix.bench import corrupt
from mocapfix.bench import cleaner_input
from mocapfix.cleaners import build

REPO = Path(__file__).resolve().parents[1]
DEFAULT_AMC = REPO.parent / "shared" / "data" / "asfamc" / "143_35.amc"
#: Yang et al. 2019, Table VI ("Ours"): frames → seconds.
PAPER = {272: 24.7055, 584: 60.7618, 1100: 148.7628, 6784: 586.2765}


def tiled(motion, T: int):
    """``motion`` played forwards, backwards, forwards … to exactly T frames."""
    pos = motion.positions
    loop = np.concatenate([pos, pos[::-1]], axis=0)
    reps = -(-T // len(loop))
    return motion.replace(positions=np.concatenate([loop] * reps, axis=0)[:T],
                          channels=None, rig=None, times=None, confidence=None)


def parse_value(text: str):
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--amc", type=Path, default=DEFAULT_AMC)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("-p", "--param", action="append", default=[],
                    help="cleaner parameter key=value (default: the paper's settings)")
    args = ap.parse_args()
    params = dict(kv.split("=", 1) for kv in args.param)
    params = {k: parse_value(v) for k, v in params.items()}
    limit = contextlib.nullcontext()
    if args.threads:
        from threadpoolctl import threadpool_limits
        limit = threadpool_limits(args.threads)

    base = read(args.amc)
    cleaner = build("lowrank_isometry", **params)
    print(f"{args.amc.name}: {base.n_joints} joints, yang2019 10 %, params {params or 'paper defaults'}"
          f", BLAS threads {args.threads or 'default'}\n")
    print("| T | time (s) | iterations | ms / iteration | paper (s) | % of paper |")
    print("|---:|---:|---:|---:|---:|---:|")
    with limit:
        for T in sorted(PAPER):
            clean = tiled(base, T)
            noisy, _ = corrupt.apply_protocol(clean, "yang2019", "10%", seed=0)
            inp = cleaner_input(clean, noisy)
            best, info = float("inf"), {}
            for _ in range(args.repeat):
                t0 = time.perf_counter()
                _, info = cleaner.apply(inp)
                best = min(best, time.perf_counter() - t0)
            it = info["iterations"]
            print(f"| {T} | {best:.3f} | {it} | {1000 * best / it:.1f} | {PAPER[T]:.1f} "
                  f"| {100 * best / PAPER[T]:.2f} |", flush=True)


if __name__ == "__main__":
    main()
