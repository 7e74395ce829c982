#!/usr/bin/env python3
"""Batch scaling of ``mocapfix clean`` over executors, and the parent's memory on a large batch.

1. Wall time of one ``mocapfix clean`` command on 20 corrupted captures (the first 400
   of the 810 frames of CMU 85_02, 41 markers, ``mixed`` occlusion with seeds 0-19; the bundled sample C3D
   if the shared data is absent), default config, with 1, 2 and 4 local worker processes
   (``-j``) and 1, 2 and 4 workers of a local Dask cluster (``--dask-workers``; the time
   includes starting the cluster). Every run's outputs are compared with the ``-j 1`` run
   (motion files byte for byte).
2. Peak resident memory (``ru_maxrss``) of the parent process of ``mocapfix clean -j 2``
   on 100, 300 and 1,000 small generated files (120 frames of the sample C3D, fill only):
   it must not grow with the number of files (tasks are submitted in a bounded window and
   only small per-file summaries are kept).

    python benchmarks/batch_scaling.py            # full (several minutes)
    python benchmarks/batch_scaling.py --quick    # 8 files, 2 workers, 50/200 files
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path


from mocapfix import read, write
from mocapfix.bench.corrupt import occlusion

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data" / "c3d" / "cmu_85_02.c3d"
SAMPLE = REPO / "sample_data" / "walk_markers.c3d"
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
RSS = ("import atexit, resource, sys; atexit.register(lambda: print('MAXRSS', "
       "resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)); "
       "from mocapfix.cli import main; main()")


def _fresh(motion, positions):
    return motion.replace(positions=positions, source=None, confidence=None)


def make_captures(folder: Path, n: int, frames: int) -> Path:
    base = read(SHARED if SHARED.exists() else SAMPLE)
    cut = base.slice_frames(0, min(frames, base.n_frames))
    folder.mkdir(parents=True)
    for seed in range(n):
        corrupted, _ = occlusion(cut, "mixed", seed)
        write(_fresh(cut, corrupted.positions), folder / f"take{seed:02d}.c3d")
    return folder


def make_small(folder: Path, n: int) -> Path:
    base = read(SAMPLE)
    small = _fresh(base, base.positions[:120].copy())
    folder.mkdir(parents=True)
    write(small, folder / "f0000.c3d")
    data = (folder / "f0000.c3d").read_bytes()
    for k in range(1, n):
        (folder / f"f{k:04d}.c3d").write_bytes(data)
    return folder


def clean(inputs: Path, out: Path, *extra, config=None) -> tuple[float, str]:
    cmd = [sys.executable, "-c", RSS, "clean", str(inputs), "-o", str(out), "-q", *extra]
    if config:
        cmd += ["-c", str(config)]
    t0 = time.perf_counter()
    p = subprocess.run(cmd, env=ENV, capture_output=True, text=True)
    if p.returncode != 0:
        raise SystemExit(f"{cmd}: exit {p.returncode}\n{p.stderr}")
    return time.perf_counter() - t0, p.stderr


def motion_bytes(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*.c3d"))}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--frames", type=int, default=400, help="frames per capture of part 1")
    args = ap.parse_args()
    n_files, workers = (8, (1, 2)) if args.quick else (20, (1, 2, 4))
    sizes = (50, 200) if args.quick else (100, 300, 1000)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        src = make_captures(tmp / "in", n_files, args.frames)
        print(f"{n_files} corrupted copies of {SHARED.name if SHARED.exists() else SAMPLE.name} "
              f"({args.frames} frames), "
              f"default config, os.cpu_count() = {os.cpu_count()}, 1-min load average "
              f"{os.getloadavg()[0]:.1f}\n")
        print("| executor | workers | wall time (s) | speed-up | outputs = -j 1 |\n|---|---|---|---|---|")
        reference = None
        base_time = None
        for kind in ("local", "dask"):
            for w in workers:
                out = tmp / f"out-{kind}-{w}"
                opt = ["-j", str(w)] if kind == "local" else ["--dask-workers", str(w)]
                t, _ = clean(src, out, *opt)
                got = motion_bytes(out)
                if reference is None:
                    reference, base_time = got, t
                print(f"| {kind} | {w} | {t:.1f} | {base_time / t:.2f}× | "
                      f"{'yes' if got == reference else 'NO'} |", flush=True)
        cfg = tmp / "fill.yaml"
        cfg.write_text("pipeline:\n  - cleaner: fill\n    max_gap: 0.5 s\n")
        print("\n| files | parent peak RSS (MB) | wall time (s) |\n|---|---|---|")
        for n in sizes:
            small = make_small(tmp / f"small{n}", n)
            t, err = clean(small, tmp / f"sout{n}", "-j", "2", "--report", "none", config=cfg)
            rss = int(err.rsplit("MAXRSS", 1)[1].split()[0]) / 1024
            print(f"| {n} | {rss:.0f} | {t:.1f} |", flush=True)


if __name__ == "__main__":
    main()
