#!/usr/bin/env python3
"""Peak memory and wall time of the readers and writers on long takes (issue 39: nothing
but the whole-take arrays may cost more than a small constant per sample).

For each format a long take is built from the shared files — pieces of different takes
(different files of one skeleton where the data has them), some reversed, with small
noise — and written with :func:`mocapfix.write` (the Kinect v2 CSV, which mocapfix only
writes back in a layout it read, is formatted here line by line as the LabanotationSuite
files are; the marker formats -- C3D, TRC and the vendor tables Vicon Nexus CSV, OptiTrack
Motive CSV and Qualisys QTM TSV -- hold the markers of three C3D takes, in mm). Then,
each in a fresh process, three cases are measured:

``read``   ``mocapfix.read(path)`` alone
``write``  read + write back unchanged
``move``   read + move 1 % of the samples (of the channels for BVH/AMC: what the writer
           gets after a cleaner's rotation write-back) + write back

and a baseline process that only imports mocapfix. The table gives the peak RSS above the
baseline, the whole-take arrays of the motions alive (positions, confidence, times,
channels; the moved copy in ``move``), and what is left over per sample (frame × joint):
what the reader and writer cost beyond the arrays. Wall time is the operation alone
(imports excluded). The generated files live in a temporary folder, removed per format.

    python benchmarks/formats_memory.py [--frames 50000 500000] [--formats kinect bvh amc c3d trc
                                         nexus_csv motive_csv qtm_tsv]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DATA = REPO.parent / "shared" / "data"
if not DATA.is_dir():
    DATA = Path("/work/shared/data")
FORMATS = ("kinect", "bvh", "amc", "c3d", "trc", "nexus_csv", "motive_csv", "qtm_tsv")
SUFFIX = {"kinect": ".csv", "bvh": ".bvh", "amc": ".amc", "c3d": ".c3d", "trc": ".trc",
          "nexus_csv": ".csv", "motive_csv": ".csv", "qtm_tsv": ".tsv"}

#: run in a child: build the take of one format (keeps the parent small, so that the
#: measured children do not inherit a large address space)
BUILD = textwrap.dedent(r"""
    import sys, shutil
    from pathlib import Path
    import numpy as np
    import mocapfix
    from mocapfix.core.motion import Motion
    fmt, frames, out, data = sys.argv[1], int(sys.argv[2]), Path(sys.argv[3]), Path(sys.argv[4])
    rng = np.random.default_rng(39)

    def pieces(arrays, frames, noise):
        # random pieces of the given takes, every other one reversed, plus gaussian noise
        out, n, k = [], 0, 0
        while n < frames:
            a = arrays[k % len(arrays)]
            size = int(rng.integers(min(200, len(a)), len(a) + 1))
            start = int(rng.integers(0, len(a) - size + 1))
            piece = a[start:start + size]
            out.append(piece[::-1] if k % 2 else piece)
            n += size
            k += 1
        joined = np.concatenate(out)[:frames]
        return joined + rng.normal(0, noise, joined.shape) * np.isfinite(joined)

    if fmt == "kinect":
        files = sorted(data.glob("kinect/kv2_*.csv"))
        blocks = []
        for f in files:
            m = mocapfix.read(f)
            state = np.select([m.confidence >= 1, m.confidence > 0], [2.0, 1.0], 0.0)
            blocks.append(np.concatenate([m.source.original, state[..., None]], axis=2))
        B = pieces([b.reshape(len(b), -1) for b in blocks], frames, 0.0)
        xyz = B.reshape(frames, 25, 4)
        xyz[..., :3] += rng.normal(0, 0.0005, xyz[..., :3].shape)
        ticks = 289810293609 + 333333 * np.arange(frames)
        row = "%d," + "%.6g,%.6g,%.6g,%d," * 25 + "\n"
        with open(out, "w") as fh:
            for s in range(0, frames, 5000):
                chunk = np.concatenate([ticks[s:s + 5000, None], B[s:s + 5000]], axis=1)
                fh.write((row * len(chunk)) % tuple(chunk.ravel().tolist()))
    elif fmt in ("bvh", "amc"):
        if fmt == "bvh":
            takes = [mocapfix.read(data / "bvh" / f"cmu_cgspeed_131_0{i}.bvh") for i in (1, 3)]
        else:
            takes = [mocapfix.read(data / "asfamc" / f"05_{i}.amc") for i in ("01", "02", "10")]
        C = pieces([t.channels for t in takes], frames, 0.01)
        m = takes[0]
        m = m.replace(channels=C, positions=m.rig.positions(C), times=None, confidence=None)
        mocapfix.write(m, out)
    else:
        names = None
        arrays = []
        for f in ("cmu_85_02.c3d", "hdm05_HDM_mm_01-02_03_120.c3d", "btk_Gait.c3d"):
            m = mocapfix.read(data / "c3d" / f)
            P = m.positions * (m.metres_per_unit / 0.001)
            arrays.append(P)
        J = min(p.shape[1] for p in arrays)
        P = pieces([p[:, :J].reshape(len(p), -1) for p in arrays], frames, 0.05)
        first = mocapfix.read(data / "c3d" / "cmu_85_02.c3d")
        m = Motion(P.reshape(frames, J, 3), list(first.names[:J]), 120.0, units="mm",
                   metres_per_unit=0.001)
        mocapfix.write(m, out, format=fmt)   # .csv: the vendor layouts are written when named
""")

#: run in a child per case: prints one JSON line
CASE = textwrap.dedent(r"""
    import json, resource, sys, time
    import numpy as np
    import mocapfix
    mode, path, out = sys.argv[1], sys.argv[2], sys.argv[3]
    if mode == "baseline":
        print(json.dumps({"maxrss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss}))
        raise SystemExit
    started = time.perf_counter()
    m = mocapfix.read(path)
    alive = [m]
    if mode == "write":
        mocapfix.write(m, out)
    elif mode == "move":
        rng = np.random.default_rng(1)
        if m.channels is not None:
            C = m.channels.copy()
            pick = rng.random(C.shape) < 0.01
            C[pick] += 0.05
            moved = m.replace(channels=C)
        else:
            P = m.positions.copy()
            pick = (rng.random(P.shape[:2]) < 0.01) & np.isfinite(P).all(axis=2)
            P[pick] += 1e-3 / m.metres_per_unit
            moved = m.replace(positions=P)
        alive.append(moved)
        mocapfix.write(moved, out)
    seconds = time.perf_counter() - started
    arrays = sum(a.nbytes for x in alive for a in (x.positions, x.confidence, x.times, x.channels)
                 if a is not None)
    print(json.dumps({"maxrss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss,
                      "seconds": seconds, "arrays": arrays, "frames": m.n_frames,
                      "joints": m.n_joints}))
""")


def child(code: str, *args) -> dict:
    done = subprocess.run([sys.executable, "-c", code, *map(str, args)], check=False,
                          capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"child failed ({args}):\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, nargs="+", default=[50_000, 500_000])
    ap.add_argument("--formats", nargs="+", default=list(FORMATS), choices=FORMATS)
    ap.add_argument("--cases", nargs="+", default=["read", "write", "move"])
    args = ap.parse_args()
    base = child(CASE, "baseline", "-", "-")["maxrss_kb"] * 1024
    print(f"baseline (python + import mocapfix): {base / 2**20:.0f} MB\n")
    print("| format | frames × joints | file MB | case | wall s | peak above baseline MB | "
          "arrays MB | beyond arrays, bytes/sample |")
    print("|---|---|---:|---|---:|---:|---:|---:|")
    for fmt in args.formats:
        for frames in args.frames:
            with tempfile.TemporaryDirectory(prefix="mocapfix-mem-") as tmp:
                path = Path(tmp) / f"long{SUFFIX[fmt]}"
                if fmt == "amc":
                    path = Path(tmp) / "05_long.amc"
                child(BUILD + "\nprint('{}')", fmt, frames, path, DATA)
                size = path.stat().st_size
                for case in args.cases:
                    out = Path(tmp) / "out" / path.name
                    r = child(CASE, case, path, out)
                    peak = r["maxrss_kb"] * 1024 - base
                    samples = r["frames"] * r["joints"]
                    beyond = (peak - r["arrays"]) / samples
                    print(f"| {fmt} | {r['frames']:,} × {r['joints']} | {size / 1e6:.0f} | "
                          f"{case} | {r['seconds']:.1f} | {peak / 2**20:.0f} | "
                          f"{r['arrays'] / 2**20:.0f} | {beyond:.0f} |", flush=True)


if __name__ == "__main__":
    main()
