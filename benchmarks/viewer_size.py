#!/usr/bin/env python3
"""Size and load time of ``mocapfix view`` pages (issue 38's budget: a 4,500-frame ×
41-marker capture in ≤ 3 MB of HTML, interactive in ≤ 2 s in headless Chromium).

Cases: CMU 85_02 played forwards and backwards to 4,500 frames (as ``clean_speed.py``),
alone and as a before/after overlay of its ``mixed`` occlusion corruption and the default
cleaner's output (``mocapfix clean``); and the largest shared file (bytes on disk) of
each format alone.

Per page: HTML bytes, the frame stride the size budget imposed (1 = every frame), the
seconds Python took to write the page (``mocapfix view`` in-process, reading excluded), and
time to interactive: ``performance.now()`` when the viewer's script has decoded the data,
wired its controls and drawn the first frame (the page's ``data-ready``), in headless
Chromium with the network blocked, median of ``--repeat`` runs; the whole Chromium process
(start-up included) beside it. Prints Markdown."""
from __future__ import annotations

import argparse
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mocapfix import read, write
from mocapfix.bench.corrupt import occlusion
from mocapfix.quality import viewer

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--hide-scrollbars", "--host-resolver-rules=MAP * ~NOTFOUND",
         "--window-size=1200,800"]


def largest(folder: str) -> Path:
    files = [p for p in (DATA / folder).iterdir() if p.suffix.lower() != ".asf"]
    return max(files, key=lambda p: p.stat().st_size)


def load_time(browser: str, page: Path, profile: Path, repeat: int) -> tuple[float, float]:
    """(median ms to data-ready, median s of the whole Chromium run)."""
    ready, wall = [], []
    for k in range(repeat):
        t0 = time.perf_counter()
        dom = subprocess.run([browser, *FLAGS, f"--user-data-dir={profile}{k}", "--dump-dom",
                              page.as_uri()], capture_output=True, text=True, timeout=300,
                             check=True).stdout
        wall.append(time.perf_counter() - t0)
        m = re.search(r'data-ready="([\d.]+)"', dom)
        if not m:
            raise SystemExit(f"{page.name}: the viewer did not become ready")
        ready.append(float(m.group(1)))
    return statistics.median(ready), statistics.median(wall)


def cases(tmp: Path):
    """(name, frames × points, a function writing the page) per case."""
    base = read(DATA / "c3d" / "cmu_85_02.c3d")
    long = np.concatenate([base.positions, base.positions[::-1]] * 3)[:4500]
    fresh = base.replace(positions=long, source=None, confidence=None)
    corrupted, _ = occlusion(fresh, "mixed", 0)
    write(fresh.replace(positions=corrupted.positions), tmp / "long.c3d")
    subprocess.run([sys.executable, "-m", "mocapfix.cli", "clean", str(tmp / "long.c3d"), "-o",
                    str(tmp / "out"), "-q"], check=True)
    before, after = read(tmp / "long.c3d"), read(tmp / "out" / "long.c3d")
    shape = f"{long.shape[0]} × {long.shape[1]}"
    yield "85_02 ×6 (4,500 × 41), alone", shape, lambda: viewer.single([fresh])
    yield "85_02 ×6, mixed corruption, before/after clean", shape, \
        lambda: viewer.before_after(before, after)
    for folder in ("c3d", "bvh", "asfamc", "kinect"):
        path = largest(folder)
        motion = read(path)
        yield f"largest {folder}: `{path.name}`", f"{motion.n_frames} × {motion.n_joints}", \
            lambda motion=motion: viewer.single([motion])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=3, help="Chromium runs per page (median).")
    args = ap.parse_args()
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        raise SystemExit("headless Chromium is not installed (apt-get install chromium)")
    print("| page | frames × points | HTML (MB) | stride | write (s) | interactive (ms) | Chromium run (s) |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for n, (name, shape, make) in enumerate(cases(tmp)):
            t0 = time.perf_counter()
            page = make()
            seconds = time.perf_counter() - t0
            path = tmp / f"page{n}.html"
            path.write_text(page, encoding="utf-8")
            stride = re.search(r'"stride":(\d+),"budget"', page).group(1)
            ready, wall = load_time(browser, path, tmp / f"profile{n}-", args.repeat)
            print(f"| {name} | {shape} | {path.stat().st_size / 1e6:.2f} | {stride} | "
                  f"{seconds:.2f} | {ready:.0f} | {wall:.1f} |", flush=True)


if __name__ == "__main__":
    main()
