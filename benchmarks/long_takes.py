#!/usr/bin/env python3
"""Long takes: time and peak memory of ``mocapfix clean`` (default config) at 5,000, 50,000
and 500,000 frames per format, and what cleaning in windows changes (issue 39).

The takes are built from shared captures, not by repeating one: pieces of 5–20 s cut at
random from several takes of one subject or sensor (C3D: the one CMU capture with its
41 markers), each played forwards and then backwards (so the turn is continuous), joined
with the root (markers: every point) moved so each piece starts where the last ended,
plus small noise (0.2 mm; BVH/AMC channels 0.01). The pose still jumps where two pieces
meet; where most joints jump over 5 cm (every join of the AMC take, a third of the Kinect
take's, none of the BVH and C3D takes') the join is a cut (:mod:`mocapfix.pipeline.cuts`)
and the default cleans the take as the pieces between. Markers then get the ``occlusion``
protocol's ``mixed`` corruption on every 4,500-frame stretch (gaps, jitter, spikes at the
rate a real capture has them), so that every step has work.

- Kinect v2 CSV: the four ``kv2_laban_Ges0*`` recordings (25 joints, 30 Hz).
- BVH: ``cmu_cgspeed_131_01`` and ``131_03`` (one skeleton, 120 Hz).
- ASF/AMC: ``05_01``, ``05_02``, ``05_10`` with ``05.asf`` (120 Hz).
- C3D: ``cmu_85_02`` (41 markers, 120 Hz).

Each clean runs in its own process (``python -m mocapfix.cli clean FILE -o OUT``, the
default config, so the ``memory_budget`` of 1 GB decides the windows); wall time and
the peak resident memory of the child (``getrusage``) are printed with the time per
sample and the 500k / 50k ratio.

``--seams``: on the 5,000-frame files, the default cleaned whole against the same cleaned
in windows of 2,500 and of 1,000 frames (6 s of overlap: one and four seams where the
default would make none), and on the 50,000-frame files whole against the windows the
default ``memory_budget`` picks (what a user gets), through
:func:`mocapfix.cleaning.clean_motion`: the distance between the two
outputs (mm; max and percentiles) over the samples within one overlap of a seam and over
the rest, and whether the report's file summary (status, samples filled and flagged,
gaps left) is the same.

    python benchmarks/long_takes.py [--formats c3d,bvh,amc,kinect] [--sizes 5000,50000]
                                    [--seams] [--keep DIR]
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mocapfix import read, write
from mocapfix.bench.corrupt import occlusion

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
ENV = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
SOURCES = {
    "kinect": [DATA / "kinect" / f"kv2_laban_Ges0{k}_{n}.csv" for k, n in
               ((1, "wavehand"), (2, "balancinghands"), (3, "drawlines"), (4, "comehere"))],
    "bvh": [DATA / "bvh" / "cmu_cgspeed_131_01.bvh", DATA / "bvh" / "cmu_cgspeed_131_03.bvh"],
    "amc": [DATA / "asfamc" / f"05_{k}.amc" for k in ("01", "02", "10")],
    "c3d": [DATA / "c3d" / "cmu_85_02.c3d"],
}
SUFFIX = {"kinect": ".csv", "bvh": ".bvh", "amc": ".amc", "c3d": ".c3d"}
STRETCH = 4500


def _pieces(takes, n_frames: int, fps: float, rng) -> list[tuple[int, int, int]]:
    """(take, start, stop) of the pieces, each played forwards then backwards, to length."""
    out, total = [], 0
    while total < n_frames:
        k = int(rng.integers(len(takes)))
        T = takes[k]
        length = min(int(rng.uniform(5, 20) * fps), T - 1)
        start = int(rng.integers(0, T - length))
        out.append((k, start, start + length))
        total += 2 * length
    return out


def _ping_pong(arrays, pieces, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """The pieces of ``arrays`` (one per take), each forwards then backwards, joined to
    ``n_frames``; and per frame the take it came from."""
    parts = []
    for k, a, b in pieces:
        piece = arrays[k][a:b]
        parts.append(np.concatenate([piece, piece[::-1]]))
    return np.concatenate(parts)[:n_frames]


def _continuous(values: np.ndarray, pieces, n_frames: int, columns) -> np.ndarray:
    """``values`` (T, C, 3) with ``columns`` (the root's position; markers: every point,
    all by the same step, their centroid's) moved piece by piece so that each piece starts
    where the one before ended."""
    out = values.copy()
    at = 0
    for _, a, b in pieces:
        n = 2 * (b - a)
        if at and at < n_frames:
            step = out[at - 1, columns] - out[at, columns]
            delta = np.nanmean(step, axis=0) if np.isfinite(step).any() else 0.0
            out[at:at + n, columns] += np.nan_to_num(delta)
        at += n
    return out


def build(fmt: str, n_frames: int, folder: Path, seed: int = 0) -> Path:
    """A long take of ``fmt`` with ``n_frames`` frames, written in ``folder``."""
    rng = np.random.default_rng(seed)
    takes = [read(p) for p in SOURCES[fmt]]
    base = takes[0]
    pieces = _pieces([t.n_frames for t in takes], n_frames, base.fps, rng)
    path = folder / f"{fmt}_{n_frames}{SUFFIX[fmt]}"
    if base.channels is not None:                   # BVH, AMC: the channels
        channels = _ping_pong([t.channels for t in takes], pieces, n_frames)
        root = [int(c) for c in base.rig.trans_columns[0] if c >= 0]
        channels[:, root] = _continuous(channels[:, None, root], pieces, n_frames, [0])[:, 0]
        channels += rng.normal(0, 0.01, channels.shape)
        motion = base.replace(channels=channels, positions=base.rig.positions(channels),
                              confidence=None, times=None)
        write(motion, path)
        return path
    positions = _ping_pong([t.positions for t in takes], pieces, n_frames)
    positions = _continuous(positions, pieces, n_frames, np.arange(positions.shape[1]))
    positions += rng.normal(0, 0.2e-3 / base.metres_per_unit, positions.shape)
    if fmt == "kinect":
        confidence = _ping_pong([t.confidence for t in takes], pieces, n_frames)
        motion = base.replace(positions=positions, confidence=confidence, source=None,
                              times=np.arange(n_frames) / base.fps)
    else:
        motion = corrupted(base.replace(positions=positions, source=None, confidence=None), seed)
    write(motion, path)
    return path


def corrupted(motion, seed: int = 0):
    """``motion`` with the ``occlusion`` protocol's ``mixed`` corruption on every stretch
    of :data:`STRETCH` frames (seeds ``seed``, ``seed + 1``, ...)."""
    out = motion.positions.copy()
    for k, a in enumerate(range(0, motion.n_frames, STRETCH)):
        part = motion.slice_frames(a, min(a + STRETCH, motion.n_frames))
        if part.n_frames >= 4:
            out[a:a + part.n_frames] = occlusion(part, "mixed", seed + k)[0].positions
    return motion.replace(positions=out)


def measure(path: Path, out: Path) -> tuple[float, float, float, str]:
    """Wall time (s), peak resident memory (GB) and CPU time (s) of ``mocapfix clean path
    -o out``, and the failure line ("" when it succeeded)."""
    code = ("import resource, subprocess, sys, time; t = time.perf_counter(); "
            "r = subprocess.run(sys.argv[1:], capture_output=True, text=True); "
            "u = resource.getrusage(resource.RUSAGE_CHILDREN); "
            "print(time.perf_counter() - t, u.ru_maxrss * 1024, r.returncode, "
            "u.ru_utime + u.ru_stime); "
            "sys.stderr.write(r.stdout[-2000:] + r.stderr[-2000:])")
    done = subprocess.run([sys.executable, "-c", code, sys.executable, "-m", "mocapfix.cli",
                           "clean", str(path), "-o", str(out)],
                          check=False, capture_output=True, text=True, env=ENV)
    wall, peak, rc, cpu = done.stdout.split()
    line = next((s for s in done.stderr.splitlines() if path.name in s), done.stderr.strip()[-200:])
    return float(wall), float(peak) / 1e9, float(cpu), line if rc != "0" else ""


def speed_table(formats, sizes, folder: Path) -> None:
    print("| format | frames × joints | file (MB) | wall (s) | CPU (s) | peak memory (GB) "
          "| µs per sample (wall) |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    walls: dict = {}
    cpus: dict = {}
    for fmt in formats:
        for n in sizes:
            path = build(fmt, n, folder)
            J = read(path).n_joints if n <= 50_000 else _joints(fmt)
            wall, peak, cpu, failed = measure(path, folder / f"out_{fmt}_{n}")
            walls[fmt, n], cpus[fmt, n] = wall, cpu
            print(f"| {fmt} | {n:,} × {J} | {path.stat().st_size / 1e6:.0f} | {wall:.1f} | {cpu:.1f} "
                  f"| {peak:.2f} | {wall / (n * J) * 1e6:.2f} |"
                  + (f" FAILED: {failed}" if failed else ""), flush=True)
            for p in folder.glob(f"*{fmt}_{n}*"):
                shutil.rmtree(p) if p.is_dir() else p.unlink()
    for fmt in formats:
        if (fmt, 50_000) in walls and (fmt, 500_000) in walls:
            print(f"\n{fmt}: 500k / 50k wall time {walls[fmt, 500_000] / walls[fmt, 50_000]:.1f}×, "
                  f"CPU time {cpus[fmt, 500_000] / cpus[fmt, 50_000]:.1f}×")


def _joints(fmt: str) -> int:
    return read(SOURCES[fmt][0]).n_joints


def seams(formats, folder: Path, frames: int | None, take: int = 5000) -> None:
    """The windowed-vs-whole table: takes of ``take`` frames cleaned whole and in windows
    of ``frames`` frames (None: the windows the default ``memory_budget`` picks)."""
    from mocapfix.cleaning import clean_motion
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config
    from mocapfix.pipeline.windows import OVERLAP_S, Windows, point_cuts, window_for
    from mocapfix.quality.report import build_report

    pipeline = load_config(resolve_config("default"))
    what = "the memory_budget's windows" if frames is None else f"windows of {frames}"
    print(f"\n| format | {take:,} frames: whole vs {what} | near a seam: max / p99 / "
          "median (mm) | elsewhere: max / p99 / median (mm) | summary the same |")
    print("|---|---|---:|---:|---|")
    keys = ("status", "samples_filled", "samples_flagged", "gaps_unfilled", "missing_after")
    for fmt in formats:
        motion = read(build(fmt, take, folder))
        windows = (Windows(frames, round(OVERLAP_S * motion.fps)) if frames is not None else
                   window_for(pipeline.memory_budget, motion.n_frames, motion.n_joints, motion.fps))
        if windows is None:
            print(f"| {fmt} | fits the budget whole: no seams | | | |")
            continue
        t0 = time.perf_counter()
        whole = clean_motion(motion, pipeline, windows=None)
        t1 = time.perf_counter()
        cut = clean_motion(motion, pipeline, windows=windows)
        t2 = time.perf_counter()
        d = np.linalg.norm(whole.cleaned.positions - cut.cleaned.positions, axis=-1)
        d *= motion.metres_per_unit * 1e3
        cuts = point_cuts(motion.missing, windows.cuts(motion.n_frames), windows.overlap)
        near = np.zeros(d.shape, bool)
        for row in cuts[1:-1]:
            for j, c in enumerate(row):
                near[max(c - windows.overlap, 0):c + windows.overlap, j] = True
        fa, fb = build_report(whole, pipeline.report)["file"], build_report(cut, pipeline.report)["file"]
        differ = [f"{k} {fa[k]} → {fb[k]}" for k in keys if fa[k] != fb[k]]

        def stats(mask, d=d):
            x = d[mask & np.isfinite(d)]
            return "–" if not x.size else f"{x.max():.3f} / {np.percentile(x, 99):.3f} / {np.median(x):.4f}"
        n_windows = len(windows.cuts(motion.n_frames)) - 1
        print(f"| {fmt} | {motion.n_joints} points, whole {t1 - t0:.1f} s, {n_windows} windows "
              f"of {windows.frames} {t2 - t1:.1f} s "
              f"| {stats(near)} | {stats(~near)} | {'yes' if not differ else '; '.join(differ)} |",
              flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--formats", default="kinect,bvh,amc,c3d")
    ap.add_argument("--sizes", default="5000,50000,500000")
    ap.add_argument("--seams", action="store_true", help="only the windowed-vs-whole table")
    ap.add_argument("--keep", type=Path, help="build the takes here (default: a temp folder)")
    args = ap.parse_args()
    formats = args.formats.split(",")
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        if args.seams:
            for frames in (2500, 1000):
                seams(formats, folder, frames)
            seams(formats, folder, None, take=50_000)
        else:
            speed_table(formats, [int(s) for s in args.sizes.split(",")], folder)


if __name__ == "__main__":
    main()
