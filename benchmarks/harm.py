#!/usr/bin/env python3
"""What the shipped configs do to the shared takes exactly as read: the ``harm`` protocol
(:mod:`mocapfix.bench.harm`) on every file of ``../shared/data``, each with the configs
meant for its format, and a page that draws every case (every change over 10 mm, with the
take's evidence for it).

    python benchmarks/harm.py [--data ../shared/data] [-j 2] [--markdown benchmarks/results/harm.md]
        [--plots harm-cases.html] [--folders bvh,asfamc,c3d,kinect]

Writes ``benchmarks/results/harm.md`` (generated: this script owns it; do not edit by hand) and,
with ``--plots``, one self-contained HTML page: per case, the path of the point it moved
most (x, y, z, input grey, output in colour, the change below) over the case and 0.15 s
(at least 6 frames) on each side, and for a rotation re-made on a BVH/AMC rig that joint's channels.
About a minute on 2 cores.
"""
from __future__ import annotations

import argparse
import html
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from mocapfix import bench, formats  # noqa: E402
from mocapfix.bench import harm as bench_harm
from mocapfix.core import presets
from mocapfix.batch.executors import ExecutorSpec  # noqa: E402
from mocapfix.config import load_config  # noqa: E402
from mocapfix.quality.plots import rotation_channels, svg_trajectory  # noqa: E402

#: folder of ../shared/data → the shipped configs run on its files
FOLDERS = {"bvh": ["default", "animation-bvh"], "asfamc": ["default", "animation-bvh"],
           "c3d": ["default", "optical-c3d"], "kinect": ["default", "kinect"]}
SUFFIXES = {".bvh", ".amc", ".c3d", ".txt", ".csv"}
#: cases drawn per file and config (the table lists them all)
DRAWN = 40


def _files(data: Path, folder: str) -> list[Path]:
    return sorted(p for p in (data / folder).iterdir() if p.suffix.lower() in SUFFIXES)


def _methods(names) -> list[bench.Method]:
    return [bench.Method(f"config:{n}", "config", load_config(presets.resolve_config(n))) for n in names]


def _window(case: dict, T: int, fps: float) -> slice:
    pad = max(int(round(0.15 * fps)), 6)
    return slice(max(case["frame"] - pad, 0), min(case["frame"] + case["frames"] + pad, T))


def _draw(path: Path, method: bench.Method, cases: list[dict]) -> str:
    """The figures of one file's cases under one method."""
    result = bench_harm.clean(method, formats.read(path))
    before, after = result.original, result.cleaned
    mm = before.metres_per_unit * 1000.0
    T, fps = before.n_frames, before.fps
    parts = []
    for n, case in enumerate(cases[:DRAWN], 1):
        win = _window(case, T, fps)
        k = before.names.index(case["moved_most"])
        title = (f"{path.name} — {method.name} — case {n}: {case['point'] or 'smoothing'} frames "
                 f"{case['frame']}–{case['frame'] + case['frames'] - 1}, moved "
                 f"{case['moved_max_mm']:.1f} mm at {case['moved_most']} (frame "
                 f"{case['moved_most_frame']}); acceleration {case['accel_in_ms2']:.0f} → "
                 f"{case['accel_out_ms2']:.0f} m/s², {'supported' if case['supported'] else 'NOT supported'}")
        parts.append(f"<h3>{html.escape(title)}</h3>")
        parts.append(svg_trajectory(before.positions[win, k], after.positions[win, k],
                                    np.zeros(win.stop - win.start, bool), before.missing[win, k],
                                    fps, title, mm, start_s=win.start / fps))
        cols, axes, unit = rotation_channels(before, case["point"] or "")
        if len(cols) == 3:
            parts.append(f"<p>{html.escape(case['point'])} rotation channels "
                         f"({''.join(axes)}, degrees)</p>")
            parts.append(svg_trajectory(
                before.channels[win][:, cols] * unit, after.channels[win][:, cols] * unit,
                np.zeros(win.stop - win.start, bool), np.zeros(win.stop - win.start, bool),
                fps, title, 1.0, labels=tuple(f"{a} (°)" for a in axes) + ("change (°)",),
                start_s=win.start / fps))
    if len(cases) > DRAWN:
        parts.append(f"<p>… and {len(cases) - DRAWN} more cases (see the table).</p>")
    return "".join(parts)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data")
    ap.add_argument("-j", "--jobs", type=int, default=2)
    ap.add_argument("--markdown", type=Path, default=REPO / "benchmarks" / "results" / "harm.md",
                    help="the generated tables (default: %(default)s)")
    ap.add_argument("--plots", type=Path, default=None)
    ap.add_argument("--folders", default=",".join(FOLDERS),
                    help="comma-separated folders of --data to run (default: all)")
    args = ap.parse_args(argv)
    sections, figures = ["# Harm on the shared takes as read", "",
                         "Generated by `python benchmarks/harm.py`; do not edit. What each "
                         "shipped config changes on the files of `../shared/data` exactly as "
                         "read (protocol: `mocapfix/bench/harm.py`).", ""], []
    for folder in args.folders.split(","):
        configs = FOLDERS[folder]
        files = _files(args.data, folder)
        methods = _methods(configs)
        result = bench.run([str(f) for f in files], "harm", methods, seeds=1,
                           spec=ExecutorSpec(args.jobs))
        sections += [f"# {folder}", "", bench_harm.to_markdown(result).split("\n", 2)[2], ""]
        if args.plots:
            for r in result.runs:
                if r.get("cases"):
                    method = next(m for m in methods if m.name == r["method"])
                    figures.append(_draw(Path(r["file"]), method, r["cases"]))
    args.markdown.write_text("\n".join(sections))
    if args.plots:
        args.plots.write_text(
            "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>mocapfix harm "
            "cases</title><style>body{font-family:sans-serif;max-width:1100px;margin:2em auto}"
            "h3{font-size:13px}</style></head><body><h1>Every change over 10 mm on the shared "
            "takes as read</h1><p>grey: input; colour: output; the last panel of each figure "
            "is the distance between them.</p>" + "".join(figures) + "</body></html>")
    return 0


if __name__ == "__main__":
    sys.exit(main())
