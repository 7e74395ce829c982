#!/usr/bin/env python3
"""Cleaning cost per sample of every shared capture with the default config (issue 39).

Cleans every capture of ``shared/data`` (every format, found as ``mocapfix clean`` finds
them) with the default config through :func:`mocapfix.api.clean`, in one process with
the thread policy of ``mocapfix clean -j 1`` (BLAS on one thread, the file's own parallel
loops on the cores: :mod:`mocapfix.core.threads`). The cleaning seconds are the report's
``file.seconds`` (the pipeline's steps; reading, writing and the report left out); over
the file's frames × markers (joints) they are its cost per sample. One file of each
format is cleaned first, untimed, so that the modules a step imports on first use are
not charged to whichever file needs them first. Prints a Markdown table sorted by cost
per sample, with each file's ratio to the median cost over the set; a file above
:data:`LIMIT` × the median is flagged (and the script exits 1).

    python benchmarks/cost_per_sample.py [--data ../shared/data] [--repeat 3]

``--repeat N`` cleans the set N times, in turn, and keeps each file's fastest run
(timings on a shared machine are noisy).
"""
from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

from mocapfix import api
from mocapfix.batch.discovery import discover_inputs
from mocapfix.core import threads

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
#: most a file may cost per sample, in medians of the set
LIMIT = 5.0


def captures(data: Path) -> list[Path]:
    """The captures ``mocapfix clean`` finds under ``data``."""
    return [f.path for f in discover_inputs([data]).files]


def clean_seconds(files: list[Path]) -> dict[Path, tuple[float, int, int]]:
    """Per capture: cleaning seconds, frames, markers (the default config's report)."""
    out = {}
    for path in files:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _, report = api.clean(path)
        f = report["file"]
        out[path] = (float(f["seconds"]), int(f["frames"]), int(f["joints"]))
    return out


def table(runs: list[dict]) -> tuple[str, float]:
    """The Markdown table (fastest run per file, sorted by cost per sample) and the
    largest ratio to the median."""
    names = sorted(set.intersection(*(set(r) for r in runs)))
    rows = []
    for name in names:
        seconds = min(r[name][0] for r in runs)
        _, frames, markers = runs[0][name]
        rows.append((name, frames, markers, seconds, seconds / max(frames * markers, 1)))
    rows.sort(key=lambda r: r[4])
    median = float(np.median([r[4] for r in rows]))
    lines = ["| file | frames × markers | clean (s) | µs per sample | × median |",
             "|---|---:|---:|---:|---:|"]
    for name, frames, markers, seconds, cost in rows:
        ratio = cost / median
        flag = " **over 5×**" if ratio > LIMIT else ""
        lines.append(f"| {name} | {frames} × {markers} | {seconds:.3f} | {cost * 1e6:.2f} | "
                     f"{ratio:.2f}{flag} |")
    worst = max(r[4] for r in rows) / median
    lines.append(f"\nmedian {median * 1e6:.2f} µs per sample over {len(rows)} files; "
                 f"worst {worst:.2f}× the median (limit {LIMIT:g}×)")
    return "\n".join(lines), worst


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", type=Path, default=DATA)
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    blas = threads.blas_threads(1)
    threads.limit_blas(blas)
    threads.set_task_threads(threads.single_process_task_threads(blas))
    files = captures(args.data)
    clean_seconds(list({p.suffix.lower(): p for p in reversed(files)}.values()))   # warm-up
    runs = [clean_seconds(files) for _ in range(max(1, args.repeat))]
    root = args.data.resolve()
    runs = [{str(Path(p).resolve().relative_to(root)): v for p, v in r.items()} for r in runs]
    text, worst = table(runs)
    print(text)
    return 1 if worst > LIMIT else 0


if __name__ == "__main__":
    sys.exit(main())
