#!/usr/bin/env python3
"""Time on degenerate takes: is ``mocapfix clean`` linear in the take's length when the
take repeats itself (issue 39: "periodic, constant, repeated-frame and real takes")?

Methods that compare a stretch with the rest of the take, sort, rank or take medians can
turn quadratic on takes that repeat themselves (``glitches.recurring`` was, on periodic
takes) or fail on takes with no variance at all. Four shapes per format, each at 5,000
and 50,000 frames, built from one shared capture:

- ``real``: :func:`long_takes.build` (pieces of several takes, forwards and backwards);
- ``periodic``: one 2 s stretch of the capture played over and over, exactly;
- ``constant``: the capture's first frame held (a perfectly still pose);
- ``repeated``: every frame of the capture written twice in a row (a 60 Hz container
  fed at 30 Hz), played forwards and backwards to length.

Markers (C3D) get the ``occlusion`` protocol's ``mixed`` corruption on every 4,500
frames, as in :mod:`long_takes`, so the fills and the outlier tests have work on these
shapes too (``repeated``: the capture is corrupted first and its frames then written
twice, as a recorder repeats what it measured); BVH and Kinect are cleaned as built. Each clean is ``mocapfix clean FILE -o
OUT`` (default config) in its own process: the CPU time, the 50k / 5k ratio (linear: about
10×) and whether it succeeded.

``--held``: what the default does to shared captures as they are and with every frame
written twice (:mod:`mocapfix.pipeline.held`), in process: the report's status and samples
flagged, the samples seen in the input and missing in the output, the distance from the
input of the samples in both (mm), and whether the doubled take's output is the
capture's output with every frame twice.

    python benchmarks/degenerate_takes.py [--formats c3d,bvh,kinect] [--sizes 5000,50000]
    python benchmarks/degenerate_takes.py --held
    python benchmarks/degenerate_takes.py --cuts

``--cuts``: takes joined (:mod:`mocapfix.pipeline.cuts`): each capture's first 2 s played
over and over to 3,000 frames, and two takes of one subject joined (C3D: the capture's
two halves, the second moved 50 cm), cleaned in process with the default as one take (the
cut detection turned off) and as the default does: the cuts found against the joins made,
the report's status and samples flagged, the distance from the input, and the distance
from the take's parts each cleaned alone (0: nothing reached across a join).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import long_takes  # noqa: E402  (a sibling script)
from mocapfix import read, write  # noqa: E402

SHAPES = ("real", "periodic", "constant", "repeated")


def frames_of(shape: str, T: int, n_frames: int, fps: float) -> np.ndarray:
    """The source frame of each of ``n_frames`` frames of a take of ``shape`` drawn from a
    capture of ``T`` frames."""
    if shape == "periodic":
        period = min(int(2 * fps), T)
        return np.arange(n_frames) % period
    if shape == "constant":
        return np.zeros(n_frames, np.intp)
    there_and_back = np.concatenate([np.arange(T), np.arange(T)[::-1]])
    twice = np.repeat(there_and_back, 2)
    return np.resize(twice, n_frames)


def build(fmt: str, shape: str, n_frames: int, folder: Path) -> Path:
    """The take of ``fmt`` and ``shape`` with ``n_frames`` frames, written in ``folder``."""
    if shape == "real":
        return long_takes.build(fmt, n_frames, folder)
    base = read(long_takes.SOURCES[fmt][0])
    pick = frames_of(shape, base.n_frames, n_frames, base.fps)
    path = folder / f"{fmt}_{shape}_{n_frames}{long_takes.SUFFIX[fmt]}"
    if base.channels is not None:
        channels = base.channels[pick]
        motion = base.replace(channels=channels, positions=base.rig.positions(channels),
                              confidence=None, times=None)
    elif fmt == "kinect":
        motion = base.replace(positions=base.positions[pick], confidence=base.confidence[pick],
                              source=None, times=np.arange(n_frames) / base.fps)
    elif shape == "repeated":
        # the capture corrupted, then every frame held: a recorder repeats what it measured
        motion = long_takes.corrupted(base.replace(source=None, confidence=None))
        motion = motion.replace(positions=motion.positions[pick])
    else:
        motion = long_takes.corrupted(base.replace(positions=base.positions[pick], source=None,
                                         confidence=None))
    write(motion, path)
    return path



HELD = ("c3d/cmu_85_02.c3d", "c3d/hdm05_HDM_mm_01-02_03_120.c3d",
        "bvh/cmu_cgspeed_131_03.bvh", "asfamc/05_02.amc")


def held() -> None:
    """The ``--held`` table."""
    from mocapfix import api

    print("| capture | take | frames | status | samples flagged | seen → missing | moved max / "
          "p99 (mm) | = the capture's output, doubled |")
    print("|---|---|---:|---|---:|---:|---:|---|")
    for rel in HELD:
        base = read(long_takes.DATA / rel)
        once = None
        for shape, pick in (("as read", np.arange(base.n_frames)),
                            ("every frame twice", np.repeat(np.arange(base.n_frames), 2))):
            motion = base.replace(
                positions=base.positions[pick], source=None, confidence=None,
                channels=None if base.channels is None else base.channels[pick])
            cleaned, report = api.clean(motion)
            moved = np.linalg.norm(cleaned.positions - motion.positions, axis=-1)
            moved *= motion.metres_per_unit * 1e3
            lost = int((np.isnan(cleaned.positions).any(-1) & ~motion.missing).sum())
            same = "" if once is None else (
                "yes" if np.array_equal(cleaned.positions, once.repeat(2, axis=0), equal_nan=True)
                else "no")
            once = cleaned.positions if once is None else once
            f = report["file"]
            print(f"| {rel} | {shape} | {motion.n_frames} | {f['status']} | {f['samples_flagged']} "
                  f"| {lost} | {np.nanmax(moved):.1f} / {np.nanpercentile(moved, 99):.2f} | {same} |",
                  flush=True)


#: a loop of each capture's first 2 s, and two takes joined (C3D: the capture's halves,
#: the second 50 cm away: no two shared C3D captures have one marker set)
JOINED = (("c3d/cmu_85_02.c3d", None), ("c3d/hdm05_HDM_mm_01-02_03_120.c3d", None),
          ("bvh/cmu_cgspeed_131_03.bvh", "bvh/cmu_cgspeed_131_01.bvh"),
          ("asfamc/05_02.amc", "asfamc/05_01.amc"),
          ("kinect/kv2_laban_Ges01_wavehand.csv", "kinect/kv2_laban_Ges02_balancinghands.csv"))


def _as_take(base, positions, channels, frames):
    return base.replace(positions=positions, channels=channels, source=None, times=None,
                        confidence=None if base.confidence is None else base.confidence[frames])


def _joined_takes(rel: str, other: str | None):
    """``(name, take, parts)``: the 2 s loop over 3,000 frames, and two takes joined; each
    with the frame ranges of its parts."""
    base = read(long_takes.DATA / rel)
    period = int(2 * base.fps)
    pick = np.arange(3000) % period
    loop = _as_take(base, base.positions[pick],
                    None if base.channels is None else base.channels[pick], pick)
    yield "2 s loop", loop, [(a, min(a + period, 3000)) for a in range(0, 3000, period)]
    if other is None:
        half = base.n_frames // 2
        shift = np.array([500.0, 0.0, 0.0]) / 1000.0 / base.metres_per_unit
        P = np.concatenate([base.positions[:half], base.positions[half:2 * half] + shift])
        yield "halves, 50 cm apart", _as_take(base, P, None, np.arange(2 * half)), \
            [(0, half), (half, 2 * half)]
        return
    second = read(long_takes.DATA / other)
    T1 = base.n_frames
    if base.channels is not None:
        channels = np.concatenate([base.channels, second.channels])
        take = base.replace(channels=channels, positions=base.rig.positions(channels),
                            source=None, times=None, confidence=None)
    else:
        take = base.replace(positions=np.concatenate([base.positions, second.positions]),
                            confidence=np.concatenate([base.confidence, second.confidence]),
                            source=None, times=None)
    yield f"+ {Path(other).stem}", take, [(0, T1), (T1, take.n_frames)]


def joined() -> None:
    """The ``--cuts`` table."""
    import mocapfix.cleaning as cleaning
    from mocapfix import api
    from mocapfix.pipeline import cuts

    print("| capture | take | frames | cuts found / joins | cleaned as | status | samples "
          "flagged | moved max / p99 (mm) | from the parts cleaned alone, max (mm) |")
    print("|---|---|---:|---:|---|---|---:|---:|---:|")
    real = cuts.take_cuts
    for rel, other in JOINED:
        for name, take, parts in _joined_takes(rel, other):
            alone = np.concatenate([api.clean(take.slice_frames(a, b))[0].positions
                                    for a, b in parts])
            found = len(real(take))
            for how in ("one take", "default"):
                cuts_of = (lambda m: np.zeros(0, np.intp)) if how == "one take" else real
                cleaning.take_cuts = cuts_of
                try:
                    cleaned, report = api.clean(take)
                finally:
                    cleaning.take_cuts = real
                mm = take.metres_per_unit * 1e3
                moved = np.linalg.norm(cleaned.positions - take.positions, axis=-1) * mm
                apart = np.linalg.norm(cleaned.positions - alone, axis=-1) * mm
                f = report["file"]
                print(f"| {rel} | {name} | {take.n_frames} | {found} / {len(parts) - 1} | {how} "
                      f"| {f['status']} | {f['samples_flagged']} | {np.nanmax(moved):.1f} / "
                      f"{np.nanpercentile(moved, 99):.2f} | {np.nanmax(apart):.1f} |", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--formats", default="c3d,bvh,kinect")
    ap.add_argument("--sizes", default="5000,50000")
    ap.add_argument("--held", action="store_true", help="only the held-frames table")
    ap.add_argument("--cuts", action="store_true", help="only the joined-takes table")
    args = ap.parse_args()
    if args.held:
        held()
        return
    if args.cuts:
        joined()
        return
    sizes = [int(s) for s in args.sizes.split(",")]
    print("| format | take | " + " | ".join(f"CPU {n:,} (s)" for n in sizes)
          + f" | {sizes[-1] // 1000}k / {sizes[0] // 1000}k |")
    print("|---|---|" + "---:|" * (len(sizes) + 1))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for fmt in args.formats.split(","):
            for shape in SHAPES:
                cpu, failed = [], []
                for n in sizes:
                    path = build(fmt, shape, n, folder)
                    _, _, seconds, line = long_takes.measure(path, folder / "out")
                    cpu.append(seconds)
                    if line:
                        failed.append(f"{n}: {line}")
                    path.unlink()
                ratio = cpu[-1] / cpu[0]
                print(f"| {fmt} | {shape} | " + " | ".join(f"{c:.1f}" for c in cpu)
                      + f" | {ratio:.1f}× |" + (f" FAILED {'; '.join(failed)}" if failed else ""),
                      flush=True)


if __name__ == "__main__":
    main()
