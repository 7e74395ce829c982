"""Batch cleaning: find the input files, map them to output paths, run them in parallel
(process pool) with failure isolation, and summarise.

Input trees are never written to: an output path that is an input file is refused, and an
output folder inside an input folder needs ``allow_inside_input``.
"""
from __future__ import annotations

import os
import sys
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

from mocapfix.errors import ConfigError, MocapfixError
from mocapfix.formats import MOTION_SUFFIXES

_SKIP_SUFFIXES = (".report.json", ".report.md", ".report.html")


@dataclass(frozen=True)
class Job:
    source: Path
    output: Path


def _is_motion_file(path: Path) -> bool:
    name = path.name.lower()
    return (path.suffix.lower() in MOTION_SUFFIXES and not name.startswith(".")
            and not name.endswith(_SKIP_SUFFIXES) and not name.endswith(".part"))


def discover(inputs, outdir, allow_inside_input: bool = False) -> list[Job]:
    """Jobs for the given files and folders (folders are recursed; the output tree mirrors
    them). Raises ConfigError for a usage problem."""
    outdir = Path(outdir).resolve()
    jobs: list[Job] = []
    for raw in inputs:
        path = Path(raw)
        if not path.exists():
            raise ConfigError(f"{path}: no such file or folder")
        if path.is_dir():
            root = path.resolve()
            if (outdir == root or root in outdir.parents) and not allow_inside_input:
                raise ConfigError(
                    f"output folder {outdir} is inside input folder {root}; choose another "
                    "output folder or pass --allow-inside-input")
            for dirpath, dirnames, filenames in os.walk(root):
                here = Path(dirpath)
                dirnames[:] = sorted(d for d in dirnames if not d.startswith(".")
                                     and (here / d).resolve() != outdir)
                for name in sorted(filenames):
                    f = here / name
                    if _is_motion_file(f):
                        jobs.append(Job(f, outdir / f.relative_to(root)))
        else:
            jobs.append(Job(path.resolve(), outdir / path.name))
    seen: dict[Path, Path] = {}
    inputs_set = {j.source.resolve() for j in jobs}
    for job in jobs:
        if job.output.resolve() in inputs_set:
            raise ConfigError(f"{job.output}: would overwrite an input file; choose another output folder")
        if job.output in seen:
            raise ConfigError(f"{job.source} and {seen[job.output]} would both be written to {job.output}")
        seen[job.output] = job.source
    return jobs


def _run_one(job: Job, config: dict, source: str, reports, read_options) -> dict:
    from mocapfix.clean import clean_file
    from mocapfix.pipeline import parse_config

    try:
        pipeline = parse_config(config, source)
        return clean_file(job.source, job.output, pipeline, reports, read_options)
    except MocapfixError as exc:
        return {"input": str(job.source), "output": str(job.output), "status": "ERROR", "error": str(exc)}
    except Exception as exc:  # noqa: BLE001 — one bad file must not stop the batch
        return {"input": str(job.source), "output": str(job.output), "status": "ERROR",
                "error": f"{job.source}: internal error {type(exc).__name__}: {exc}"}


def run_batch(jobs: list[Job], config: dict, source: str, reports=("json",), workers: int = 1,
              read_options: dict | None = None, progress: bool | None = None) -> list[dict]:
    """Clean every job; results in job order. ``config`` is the pipeline config as a plain
    dict (it is re-validated in each worker process)."""
    if progress is None:
        progress = sys.stderr.isatty()
    bar = None
    if progress and jobs:
        from tqdm import tqdm
        bar = tqdm(total=len(jobs), unit="file", file=sys.stderr, leave=False)
    results: list[dict | None] = [None] * len(jobs)
    try:
        if workers <= 1 or len(jobs) <= 1:
            for n, job in enumerate(jobs):
                results[n] = _run_one(job, config, source, reports, read_options)
                if bar:
                    bar.update()
        else:
            with ProcessPoolExecutor(max_workers=workers) as pool:
                futures = {pool.submit(_run_one, job, config, source, reports, read_options): n
                           for n, job in enumerate(jobs)}
                for fut in as_completed(futures):
                    n = futures[fut]
                    try:
                        results[n] = fut.result()
                    except Exception as exc:  # noqa: BLE001 — e.g. a worker killed by the OS
                        results[n] = {"input": str(jobs[n].source), "output": str(jobs[n].output),
                                      "status": "ERROR", "error": f"worker failed: {exc}"}
                    if bar:
                        bar.update()
    finally:
        if bar:
            bar.close()
    return results  # type: ignore[return-value]
