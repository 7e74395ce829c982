"""The clean batch: one :class:`CleanTask` per planned job (read, clean, write the output
and its reports: :func:`mocapfix.clean.clean_file`), each worker parsing the config once.
"""
from __future__ import annotations

import os
import threading
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Callable

from mocapfix.core.errors import MocapfixError, name_the_file
from mocapfix.batch.plan import Job
from mocapfix.batch.tasks import error_result, internal_error, run_tasks


@dataclass
class CleanTask:
    """Clean one job. Parses the pipeline once per worker process (cached)."""

    config: dict
    source: str
    reports: tuple = ("json",)
    read_options: dict | None = None

    def __call__(self, job: Job) -> dict:
        from mocapfix.clean import clean_file

        try:
            from mocapfix.batch.manifest import input_identity

            pipeline = _pipeline(self.config, self.source)
            try:
                before = input_identity(job.source)
            except OSError:
                before = None           # unreadable: clean_file names the cause
            # an AMC's skeleton copy was checked with the whole batch's (skeleton_conflicts)
            result = clean_file(job.source, job.output, pipeline, self.reports, self.read_options,
                                skeleton_checked=True)
            # for the manifest: the hashes of what was cleaned. Taken after the clean alone, a
            # file still being written (copied, synced) was recorded with its new content
            # against an output of the old one, and the next run skipped it as finished
            after = input_identity(job.source)
            if before is not None and after != before:
                what = ("the file" if after["input_sha256"] != before["input_sha256"]
                        else "a file read with it")
                return error_result(job, f"{job.source}: {what} changed while it was being "
                                         "cleaned (is it still being written?); run again")
            result.update(after)
            return result
        except MocapfixError as exc:
            return error_result(job, name_the_file(job.source, str(exc)))
        except Exception as exc:  # noqa: BLE001 — one bad file must not stop the batch
            return internal_error(error_result(
                job, f"{job.source}: internal error {type(exc).__name__}: {exc}"))


_PIPELINES: dict = {}
_PIPELINES_LOCK = threading.Lock()


def _pipeline(config: dict, source: str):
    """The parsed pipeline of ``config``, parsed once per process (a Dask worker's threads
    share it; models are cached per process by :mod:`mocapfix.core.models`) and again when one
    of its model files changed since: a process that outlives a run (a Dask worker, a
    library caller) kept cleaning with a model retrained at the same path."""
    import json

    from mocapfix.config import UNIT_WARNINGS, parse_config

    key = (source, json.dumps(config, sort_keys=True, default=str))
    with _PIPELINES_LOCK:
        cached = _PIPELINES.get(key)
        if cached is None or cached[1] != _stamps(cached[0].model_files()):
            _PIPELINES.clear()
            pipeline = parse_config(config, source)
            _PIPELINES[key] = pipeline, _stamps(pipeline.model_files())
            UNIT_WARNINGS.clear()          # the CLI printed them when it loaded the config
        return _PIPELINES[key][0]


def _stamps(paths) -> tuple:
    """(path, size, modification time) of each file, as :func:`mocapfix.core.models.load`
    caches them; None for a file that cannot be seen."""
    stamps = []
    for p in paths:
        try:
            st = os.stat(p)
            stamps.append((str(p), st.st_size, st.st_mtime_ns))
        except OSError:
            stamps.append((str(p), None))
    return tuple(stamps)


def run_batch(jobs: list[Job], config: dict, source: str, reports=("json",), workers: int = 1,
              read_options: dict | None = None, on_result: Callable | None = None,
              executor: Executor | None = None, spec=None) -> list[dict]:
    """Clean every job; results in job order. ``on_result(result)`` is called as each file
    finishes (for streaming output)."""
    task = CleanTask(config, source, tuple(reports), read_options)
    results: list[dict | None] = [None] * len(jobs)
    for n, result in run_tasks(task, jobs, workers, executor, spec):
        results[n] = result
        if on_result is not None:
            on_result(result)
    return results  # type: ignore[return-value]
