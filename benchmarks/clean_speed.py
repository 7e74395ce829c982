#!/usr/bin/env python3
"""End-to-end speed of ``mocapfix clean`` with the default config.

1. One 4,500-frame, 41-marker C3D (CMU 85_02 played forwards and backwards to length,
   with the ``mixed`` occlusion corruption so every step has work), timed through the CLI
   including reading, writing and the JSON report.
2. A batch of 20 corrupted captures (85_02 and a 1,500-frame slice of HDM05, 10 seeds
   each): wall time with ``-j 1`` and ``-j 2``.
3. Issue 16's case and its scaling: 85_02 looped to 1,125 / 4,500 / 18,000 frames, 25 %
   of the markers with 1–3 gaps of 0.1–1.5 s, 2 mm jitter, 2 % spikes of 20–100 mm
   (``occlusion`` ``mixed``), ``mocapfix clean`` end to end, with the peak resident memory
   of the process, each size run five times as it ships (the cores for the file's own
   parallel loops, :mod:`mocapfix.core.threads`) in turn with ``MOCAPFIX_THREADS=1``: the
   medians and the median of the paired ratios; and the start-up cost (``mocapfix
   --version`` against ``mocapfix cleaners``, which loads every cleaner module); and per
   step, the seconds each step of the default pipeline takes at each size (from the JSON
   report) beside the missing marker samples of the input and the rest of the wall time.
   That corruption puts ~21 gaps in a clip of any length. A second table keeps the rate
   of gaps per second instead, as a real capture has it: the four quarters of the
   4,500-frame case (its own gaps), and 18,000 frames whose four 4,500-frame stretches
   are corrupted in turn (seeds 0–3, 4× the gaps); wall time and the cleaning time
   ``clean`` prints for the file (the pipeline: start-up, imports, reading, writing and
   the report left out), medians of three runs.
4. A long BVH/AMC take: CMU 05_02 (ASF/AMC) written six times over (6,738 frames × 31
   joints, 56 s), ``mocapfix clean`` with the default config (rotation_outliers →
   rotation_denoise → write-back), best of three runs.

5. ``--markers``: many markers. CMU 85_02 (41 markers) side by side with copies of
   itself played from other frames, 1.5 m apart, to 41 / 82 / 164 / 328 markers, 2,000
   frames, the ``mixed`` corruption; ``mocapfix clean`` wall time, peak resident memory
   and each step's seconds (the swap search looks at every pair of markers on every
   frame: its time grows with the pairs, its memory must not grow with the take). Then a
   raw export: 85_02 looped to 4,000 frames with 1,000 unlabelled fragments (Vicon ``*N``
   names, each seen on 1–60 frames somewhere): ``clean``, ``check`` and ``info``, wall
   time and peak memory.

Every child process may write and use compiled bytecode (``PYTHONDONTWRITEBYTECODE`` is
dropped from its environment: an installed tool runs from its ``__pycache__``; compiling
mocapfix's modules from source costs ~0.2 s a run); case 1 and the start-up keep the best
of three runs.

    python benchmarks/clean_speed.py [--scaling | --animation | --single | --markers]
        (only case 3 / case 4 / case 1 / case 5)
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mocapfix import read, write
from mocapfix.bench.corrupt import occlusion

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "c3d"
#: the children's environment: bytecode cached as in an installed tool
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
#: runs per size in ``--scaling`` (medians are printed)
RUNS = 5


def _fresh(motion, positions):
    """A Motion the C3D writer writes as a new file (no source to splice into)."""
    return motion.replace(positions=positions, source=None, confidence=None)


def clean(inputs, out, jobs):
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "mocapfix.cli", "clean", *map(str, inputs), "-o", str(out),
                    "-j", str(jobs)], check=True, capture_output=True, env=ENV)
    return time.perf_counter() - t0


def single(tmp: Path) -> None:
    """Case 1: the 4,500-frame, 41-marker capture, best of three (``--single`` runs only
    this one)."""
    base = read(DATA / "cmu_85_02.c3d")
    long = np.concatenate([base.positions, base.positions[::-1]] * 3)[:4500]
    motion = _fresh(base, long)
    corrupted, _ = occlusion(motion.replace(positions=long), "mixed", 0)
    write(_fresh(base, corrupted.positions), tmp / "long.c3d")
    t = min(clean([tmp / "long.c3d"], tmp / f"out{k}", 1) for k in range(3))
    print("| capture | frames × markers | `mocapfix clean` wall time (s) |")
    print("|---|---:|---:|")
    print(f"| 85_02 ×6, mixed corruption | 4500 × {base.n_joints} | {t:.2f} |")


def main():
    base = read(DATA / "cmu_85_02.c3d")
    hdm = read(DATA / "hdm05_HDM_mm_01-02_03_120.c3d").slice_frames(0, 1500)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        single(tmp)

        batch = tmp / "batch"
        batch.mkdir()
        for seed in range(10):
            for name, m in (("cmu", base), ("hdm", hdm)):
                c, _ = occlusion(m, "mixed", seed)
                write(_fresh(m, c.positions), batch / f"{name}_{seed}.c3d")
        t1 = clean([batch], tmp / "j1", 1)
        t2 = clean([batch], tmp / "j2", 2)
        print("\n| batch | -j 1 (s) | -j 2 (s) | speed-up |")
        print("|---|---:|---:|---:|")
        print(f"| 20 corrupted captures | {t1:.1f} | {t2:.1f} | {t1 / t2:.2f}× |")


def _peak_mib_of(args, env=None) -> tuple[float, float]:
    """Wall time and peak RSS (MiB) of one child process."""
    code = ("import resource, subprocess, sys, time; t = time.perf_counter(); "
            "subprocess.run(sys.argv[1:], check=True, capture_output=True); "
            "print(time.perf_counter() - t, "
            "resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024)")
    out = subprocess.run([sys.executable, "-c", code, *args], check=True, capture_output=True,
                         text=True, env=env or ENV).stdout.split()
    return float(out[0]), float(out[1])


def scaling():
    base = read(DATA / "cmu_85_02.c3d")
    cli = [sys.executable, "-m", "mocapfix.cli"]
    start = {what: min(_peak_mib_of(cli + [what])[0] for _ in range(3))
             for what in ("--version", "cleaners")}
    version, cleaners = start.values()
    print(f"\nstart-up: `mocapfix --version` {version:.2f} s, `mocapfix cleaners` {cleaners:.2f} s")
    print("\n| frames × markers (85_02 looped, mixed corruption) | `mocapfix clean` wall (s) "
          "| with one task thread (s) | ratio | peak RSS (MiB) |")
    print("|---|---:|---:|---:|---:|")
    one = {**ENV, "MOCAPFIX_THREADS": "1"}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for T in (1125, 4500, 18000):
            reps = -(-T // (2 * base.n_frames))
            long = np.concatenate([base.positions, base.positions[::-1]] * reps)[:T]
            corrupted, _ = occlusion(_fresh(base, long), "mixed", 0)
            write(_fresh(base, corrupted.positions), tmp / f"c{T}.c3d")
            # the default (the cores of the machine for a single file) and one task thread,
            # run in turn so that a drift of the machine's speed hits both alike
            runs, single = [], []
            for k in range(RUNS):
                runs.append(_peak_mib_of(cli + ["clean", str(tmp / f"c{T}.c3d"), "-o",
                                                str(tmp / f"o{T}_{k}")]))
                single.append(_peak_mib_of(cli + ["clean", str(tmp / f"c{T}.c3d"), "-o",
                                                  str(tmp / f"s{T}_{k}")], one))
            ratio = np.median([a[0] / b[0] for a, b in zip(runs, single)])
            print(f"| {T} × {base.n_joints} | {np.median([r[0] for r in runs]):.2f} | "
                  f"{np.median([r[0] for r in single]):.2f} | {ratio:.2f} | "
                  f"{max(r[1] for r in runs):.0f} |")
        per_step(cli, tmp)
        same_gap_rate(base, cli, tmp)


def per_step(cli, tmp: Path):
    """Where the time of the three sizes goes: each step's seconds from the JSON report
    (median of three runs) and the rest of the wall time (start-up, imports, reading,
    writing, the report). The marker samples missing in the input show what the gap
    filler has to do: the corruption puts about as many gaps in a clip of any length."""
    import json

    rows = {}
    for T in (1125, 4500, 18000):
        src = tmp / f"c{T}.c3d"
        reps = []
        for k in range(3):
            out = tmp / f"steps{T}_{k}"
            t = time.perf_counter()
            subprocess.run(cli + ["clean", str(src), "-o", str(out), "--report", "json"],
                           check=True, capture_output=True, env=ENV)
            wall = time.perf_counter() - t
            report = json.loads(next(out.glob("*.report.json")).read_text())
            steps = report["files"][0]["steps"] if "files" in report else report["steps"]
            reps.append((wall, {s["cleaner"]: s.get("seconds", 0.0) for s in steps}))
        names = [n for n, v in reps[0][1].items() if v >= 0.001]
        secs = {n: float(np.median([r[1][n] for r in reps])) for n in names}
        wall = float(np.median([r[0] for r in reps]))
        missing = int(np.isnan(read(src).positions[..., 0]).sum())
        rows[T] = (missing, secs, wall)
    names = list(rows[4500][1])
    print("\n| frames | missing samples | " + " | ".join(f"{n} (s)" for n in names)
          + " | rest of the wall time (s) | wall (s) |")
    print("|---:|---:|" + "---:|" * (len(names) + 2))
    for T, (missing, secs, wall) in rows.items():
        print(f"| {T} | {missing} | " + " | ".join(f"{secs.get(n, 0.0):.3f}" for n in names)
              + f" | {wall - sum(secs.values()):.2f} | {wall:.2f} |")


def _clean_seconds(args) -> tuple[float, float]:
    """Wall time of one ``mocapfix clean`` of one file and the cleaning time it prints."""
    t = time.perf_counter()
    out = subprocess.run(args, check=True, capture_output=True, text=True, env=ENV).stdout
    wall = time.perf_counter() - t
    return wall, float(re.search(r"([0-9.]+) s\)", out).group(1))


def same_gap_rate(base, cli, tmp: Path):
    """The second table of case 3 (module docstring)."""
    long = base.positions
    long = np.concatenate([long, long[::-1]] * -(-18000 // (2 * base.n_frames)))[:18000]
    stretches = [occlusion(_fresh(base, long[k * 4500:(k + 1) * 4500]), "mixed", k)[0].positions
                 for k in range(4)]
    cases = {"4500": stretches[0], "18000": np.concatenate(stretches)}
    cases.update({f"1125 ({q + 1}/4)": stretches[0][q * 1125:(q + 1) * 1125] for q in range(4)})
    print("\n| same gap rate (frames) | gapped markers | `mocapfix clean` wall (s) "
          "| cleaning (s) | cleaning ÷ 4,500's |")
    print("|---|---:|---:|---:|---:|")
    own = {}
    for k, (name, P) in enumerate(cases.items()):
        write(_fresh(base, P), tmp / f"rate{k}.c3d")
        runs = [_clean_seconds(cli + ["clean", str(tmp / f"rate{k}.c3d"), "-o", str(tmp / f"r{k}_{r}")])
                for r in range(3)]
        own[name] = np.median([r[1] for r in runs])
        gapped = int(np.isnan(P[..., 0]).any(axis=0).sum())
        print(f"| {name} | {gapped} | {np.median([r[0] for r in runs]):.2f} | {own[name]:.2f} "
              f"| {own[name] / own['4500']:.2f} |")


def long_take():
    amc = DATA.parent / "asfamc" / "05_02.amc"
    take = read(amc)
    channels = np.concatenate([take.channels] * 6)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        write(take.replace(channels=channels, positions=take.rig.positions(channels)),
              tmp / "05_02x6.amc")
        t = min(clean([tmp / "05_02x6.amc"], tmp / f"out{k}", 1) for k in range(3))
    print("\n| take | frames × joints | `mocapfix clean` wall time (s) |")
    print("|---|---:|---:|")
    print(f"| CMU 05_02 ×6 (AMC) | {len(channels)} × {take.n_joints} | {t:.2f} |")


def many_markers():
    import json

    base = read(DATA / "cmu_85_02.c3d")
    T = 2000
    loop = np.concatenate([base.positions, base.positions[::-1]])
    cli = [sys.executable, "-m", "mocapfix.cli"]
    print("\n| frames × markers | `mocapfix clean` wall (s) | peak RSS (MiB) | "
          "swaps (s) | trust (s) | fill_ensemble (s) | tsmc (s) |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for copies in (1, 2, 4, 8):
            parts, names = [], []
            for c in range(copies):
                part = loop[(np.arange(T) + c * 97) % len(loop)].copy()
                part[..., 0] += 1500.0 * c
                parts.append(part)
                names += [f"S{c}:{n.split(':')[-1]}" for n in base.names]
            take = base.replace(positions=np.concatenate(parts, axis=1), names=names,
                                source=None, confidence=None)
            corrupted, _ = occlusion(take, "mixed", 0)
            src = tmp / f"m{copies}.c3d"
            write(_fresh(take, corrupted.positions), src)
            wall, peak = _peak_mib_of(cli + ["clean", str(src), "-o", str(tmp / f"o{copies}"),
                                             "--report", "json"])
            report = json.loads(next((tmp / f"o{copies}").glob("*.report.json")).read_text())
            secs = {s["cleaner"]: s.get("seconds", 0.0) for s in report["steps"]}
            print(f"| {T} × {take.n_joints} | {wall:.1f} | {peak:.0f} | "
                  + " | ".join(f"{secs.get(n, 0.0):.2f}" for n in
                               ("swaps", "trust", "fill_ensemble", "tsmc")) + " |")
        raw = tmp / "raw.c3d"
        T, U = 4000, 1000
        rng = np.random.default_rng(0)
        fragments = np.full((T, U, 3), np.nan)
        for u in range(U):
            start, n = int(rng.integers(0, T - 60)), int(rng.integers(1, 60))
            fragments[start:start + n, u] = (rng.normal(size=3) * 800
                                             + np.cumsum(rng.normal(size=(n, 3)), axis=0))
        take = base.replace(positions=np.concatenate([loop[np.arange(T) % len(loop)], fragments],
                                                     axis=1),
                            names=list(base.names) + [f"*{u}" for u in range(U)],
                            source=None, confidence=None)
        write(take, raw)
        print(f"\n| raw export, {T} frames × {base.n_joints} markers + {U} unlabelled fragments "
              "| wall (s) | peak RSS (MiB) |")
        print("|---|---:|---:|")
        for what, args in (("clean", ["clean", str(raw), "-o", str(tmp / "raw_out")]),
                           ("check", ["check", str(raw)]), ("info", ["info", str(raw)])):
            wall, peak = _peak_mib_of(cli + args)
            print(f"| `mocapfix {what}` | {wall:.1f} | {peak:.0f} |")


if __name__ == "__main__":
    if "--markers" in sys.argv:
        many_markers()
    elif "--scaling" in sys.argv:
        scaling()
    elif "--animation" in sys.argv:
        long_take()
    elif "--single" in sys.argv:
        with tempfile.TemporaryDirectory() as folder:
            single(Path(folder))
    else:
        main()
        scaling()
        long_take()
