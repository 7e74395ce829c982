"""Clean one motion or one file: run the pipeline, write rotations back for hierarchical
formats, write the output and its reports."""
from __future__ import annotations

import time
from pathlib import Path

from mocapfix import formats
from mocapfix.fileio import atomic_write_text
from mocapfix.motion import Motion
from mocapfix.pipeline import Pipeline
from mocapfix.report import CleanResult, build_report, to_html, to_json, to_markdown
from mocapfix.writeback import write_back

REPORT_KINDS = ("json", "md", "html")


def clean_motion(motion: Motion, pipeline: Pipeline) -> CleanResult:
    """Run ``pipeline`` on ``motion``. For BVH/AMC the cleaned positions are turned back
    into the file's channels and the written positions are their forward kinematics."""
    started = time.perf_counter()
    cleaned, records = pipeline.run(motion)
    residual = None
    if cleaned.rig is not None and cleaned.channels is not None:
        channels, positions, residual = write_back(cleaned)
        cleaned = cleaned.replace(channels=channels, positions=positions)
    return CleanResult(motion, cleaned, records, residual, time.perf_counter() - started)


def report_paths(output: Path, kinds) -> dict[str, Path]:
    stem = output.name[: -len(output.suffix)] if output.suffix else output.name
    return {k: output.with_name(f"{stem}.report.{k}") for k in kinds}


def clean_file(source: Path, output: Path, pipeline: Pipeline, reports=("json",),
               read_options: dict | None = None) -> dict:
    """Read, clean, write. Returns a JSON-able summary; raises MocapfixError on failure."""
    motion = formats.read(source, **(read_options or {}))
    result = clean_motion(motion, pipeline)
    written = formats.write(result.cleaned, output)
    report = build_report(result, pipeline.report)
    paths = report_paths(output, reports)
    writers = {"json": lambda: to_json(report), "md": lambda: to_markdown(report),
               "html": lambda: to_html(report, result)}
    for kind, path in paths.items():
        atomic_write_text(path, writers[kind]())
    f = report["file"]
    return {
        "input": str(source), "output": str(output), "written": [str(p) for p in written],
        "reports": [str(p) for p in paths.values()], "status": f["status"],
        "frames": f["frames"], "joints": f["joints"], "missing_before": f["missing_before"],
        "missing_after": f["missing_after"], "samples_filled": f["samples_filled"],
        "samples_flagged": f["samples_flagged"], "seconds": round(result.seconds, 4),
    }
