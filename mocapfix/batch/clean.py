"""The clean batch: the policy of ``mocapfix clean`` as library functions, and one
:class:`CleanTask` per planned job (read, clean, write the output and its reports:
:func:`mocapfix.cleaning.clean_file`), each worker parsing the config once.

:func:`plan_clean` decides what a run does before anything is written: the jobs, which are
skipped (finished earlier by the same config, models, report kinds and inputs — recorded in
the output folder's manifest, :mod:`mocapfix.batch.manifest` — or kept by
``policy="skip"``), and refuses with one :class:`~mocapfix.core.errors.MocapfixError` what
the run must not do (outputs of another run in the way without a policy, two configs or
models mixed in one folder by ``"skip"``, an AMC whose ASF copy would pair it with the
wrong skeleton, an output folder that cannot be written, or one another run holds: the
folder's run lock, :func:`~mocapfix.batch.manifest.lock_output_folder`, held from the plan
to the end of the run). :func:`run_clean` runs the plan:
it records each finished file in the manifest (a killed run resumes), leaves nothing of a
file that failed, takes back the folders it made when nothing ran, and writes the run's
effective config beside the outputs. :func:`clean_batch` is both in one call, for a
notebook or a script; the CLI prints around the same two steps.
"""
from __future__ import annotations

import contextlib
import os
import stat
import threading
from concurrent.futures import Executor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from mocapfix.batch.discovery import discover_inputs
from mocapfix.batch.manifest import Manifest, lock_output_folder, run_key, unlock_output_folder
from mocapfix.batch.plan import (Job, check_output_folder, plan_outputs, skeleton_conflicts,
                                 skeleton_written)
from mocapfix.batch.tasks import error_result, internal_error, run_tasks
from mocapfix.cleaning import output_files, remove_outputs
from mocapfix.core.errors import MocapfixError, WriteError, name_the_file
from mocapfix.core.fileio import atomic_write_text, refuse_stream, remove_stale_temporaries
from mocapfix.pipeline.steps import Pipeline

#: what a run may do with outputs of an earlier run in its way (None: refuse)
POLICIES = (None, "overwrite", "skip")


@dataclass
class CleanTask:
    """Clean one job. Parses the pipeline once per worker process (cached)."""

    config: dict
    source: str
    reports: tuple = ("json",)
    read_options: dict | None = None
    #: the output format (None: the input's)
    to: str | None = None

    def __call__(self, job: Job) -> dict:
        from mocapfix.cleaning import clean_file

        try:
            from mocapfix.batch.manifest import input_identity

            pipeline = _pipeline(self.config, self.source)
            try:
                before = input_identity(job.source)
            except OSError:
                before = None           # unreadable: clean_file names the cause
            # an AMC's skeleton copy was checked with the whole batch's (skeleton_conflicts)
            result = clean_file(job.source, job.output, pipeline, self.reports, self.read_options,
                                skeleton_checked=True, to=self.to)
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
              executor: Executor | None = None, spec=None, to: str | None = None) -> list[dict]:
    """Clean every job (written in format ``to``, None: the input's); results in job order.
    ``on_result(result)`` is called as each file finishes (for streaming output)."""
    task = CleanTask(config, source, tuple(reports), read_options, to)
    results: list[dict | None] = [None] * len(jobs)
    for n, result in run_tasks(task, jobs, workers, executor, spec):
        results[n] = result
        if on_result is not None:
            on_result(result)
    return results  # type: ignore[return-value]


# -- the policy of a clean run ----------------------------------------------------------------

@dataclass
class CleanPlan:
    """What a clean run will do (:func:`plan_clean`)."""

    pipeline: Pipeline
    outdir: Path
    reports: tuple
    read_options: dict | None
    manifest: Manifest
    #: the run's effective config, and where it is written
    config_text: str
    config_file: Path
    todo: list
    #: (job, why) of the jobs left alone: "finished earlier" or "output exists"
    skipped: list
    #: the folders this run makes (taken back, empty, when nothing runs)
    made: list = field(default_factory=list)
    #: the output format (None: each input's own)
    to: str | None = None
    #: what :func:`run_clean` could not write besides the files (the manifest, the config
    #: record: a full disk), one line each; the run's files went on
    problems: list = field(default_factory=list)
    #: the output folder's run lock, held from the plan to the end of :func:`run_clean`
    #: (:func:`~mocapfix.batch.manifest.lock_output_folder`; None: a dry run)
    lock: int | None = None

    def release(self) -> None:
        """Release the output folder's run lock (:func:`run_clean` does, when it ends)."""
        unlock_output_folder(self.outdir, self.lock)
        self.lock = None

    @property
    def resumed(self) -> bool:
        """Some outputs were finished by an earlier run of the same config."""
        return any(why == "finished earlier" for _, why in self.skipped)


def _output_there(job: Job) -> bool:
    """An earlier output (or anything but a folder) is at ``job.output``."""
    return job.output.exists() and not job.output.is_dir()


def _config_body(text: str) -> str:
    return "\n".join(line for line in text.splitlines() if not line.startswith("#"))


def plan_clean(files, outdir, pipeline: Pipeline, *, inputs=(), reports=("json",),
               policy: str | None = None, fps: float | None = None,
               allow_inside_input: bool = False, dry_run: bool = False,
               to: str | None = None) -> CleanPlan:
    """Plan cleaning ``files`` (found by :func:`~mocapfix.batch.discovery.discover_inputs`
    in ``inputs``) into ``outdir`` with ``pipeline``, writing format ``to`` (a name of
    :data:`mocapfix.formats.NAMES`; None: each input's own); see the module docstring.
    Raises :class:`~mocapfix.core.errors.MocapfixError` for what the run must not do; a
    dry run makes no folder and writes nothing, and refuses what the real run would."""
    from mocapfix import formats

    if policy not in POLICIES:
        raise ValueError(f"policy must be one of {POLICIES}, got {policy!r}")
    if to is not None and to not in formats.NAMES:
        raise MocapfixError(f"unknown output format {to!r}; known: {', '.join(formats.NAMES)}")
    outdir = Path(outdir)
    jobs = plan_outputs(files, outdir, allow_inside_input, inputs,
                        suffix=formats.suffixes(to)[0] if to else None)
    if not jobs:
        raise MocapfixError("no motion files found in " + ", ".join(map(str, inputs or files)))
    config_file = outdir / "mocapfix-config.yaml"
    config_text = f"# effective config of this run (from {pipeline.source})\n" + pipeline.dump()
    # the run lock before anything of the folder is read (a folder made below, or one that
    # takes no file: after check_output_folder)
    lock = [None if dry_run or not outdir.is_dir() else lock_output_folder(outdir, soft=True)]
    try:
        return _plan(outdir, pipeline, jobs, config_file, config_text, lock, reports=reports,
                     policy=policy, fps=fps, dry_run=dry_run, to=to)
    except BaseException:
        unlock_output_folder(outdir, lock[0])
        raise


def _plan(outdir: Path, pipeline: Pipeline, jobs, config_file: Path, config_text: str,
          lock: list, *, reports, policy, fps, dry_run, to) -> CleanPlan:
    """The body of :func:`plan_clean`; ``lock``: ``[the folder's run lock]``, taken here
    when the folder is made here."""
    manifest = Manifest(outdir, run_key(config_text, reports, {"fps": fps} if fps else None,
                                        pipeline.model_files(), to))
    finished = set() if policy == "overwrite" else {j for j in jobs if manifest.finished(j)}
    # a folder where an output would go is not an earlier output: that file fails
    # ("cannot write: Is a directory"); --skip-existing skipped it as "output exists"
    existing = [j for j in jobs if _output_there(j) and j not in finished
                and not manifest.interrupted(j)]
    if existing and policy is None:
        shown = ", ".join(str(j.output) for j in existing[:3]) + (" …" if len(existing) > 3 else "")
        other = any(manifest.knows(j.source) for j in existing)
        raise MocapfixError(f"{len(existing)} output(s) exist already ({shown}); pass --overwrite "
                            "to replace them or --skip-existing to keep them"
                            + ("; the folder's manifest records them made with another config, "
                               "model, report kinds, --fps, version, input or skeleton"
                               if other else ""))
    if policy == "skip" and existing and config_file.exists() and \
            _config_body(_recorded_config(config_file)) != _config_body(config_text):
        raise MocapfixError(f"{config_file}: the outputs there were made with another config; "
                            "--skip-existing would mix two configs in one folder (use --overwrite "
                            "or another output folder)")
    if policy == "skip" and any(manifest.made_with_other_models(j) for j in existing):
        raise MocapfixError(f"{outdir}: the outputs there were made with other contents of the "
                            "model file(s) this config reads; --skip-existing would mix two "
                            "models in one folder (use --overwrite or another output folder)")
    made = [p for p in (outdir, *outdir.parents) if not os.path.lexists(p)]
    check_output_folder(outdir, create=not dry_run)
    if lock[0] is None and not dry_run:
        lock[0] = lock_output_folder(outdir)
    if config_file.is_dir():
        raise MocapfixError(f"{config_file}: is a folder; the run's config record "
                            "cannot be written there (move it away)")
    # "skip" keeps what an earlier run finished: an output whose replacement a run started
    # and never finished (killed) is redone, as without the option -- kept, an AMC there
    # could sit beside the new copy of an ASF its batch-mates had replaced
    todo = [j for j in jobs if j not in finished
            and not (policy == "skip" and _output_there(j) and not manifest.interrupted(j))]
    skipped = [(j, "finished earlier" if j in finished else "output exists")
               for j in jobs if j not in todo]
    conflicts = skeleton_conflicts(todo)
    if conflicts:
        unlock_output_folder(outdir, lock[0])
        lock[0] = None
        _take_back(made)
        more = f" (and {len(conflicts) - 1} more)" if len(conflicts) > 1 else ""
        raise MocapfixError(conflicts[0] + more + "; nothing was cleaned")
    return CleanPlan(pipeline, outdir, tuple(reports), {"default_fps": fps} if fps else None,
                     manifest, config_text, config_file, todo, skipped, made, to, lock=lock[0])


def _recorded_config(config_file: Path) -> str:
    """The text of an earlier run's config record, for ``--skip-existing`` to compare: read
    only from a regular file and at most a config's size (``read_text`` of a folder there
    was an internal IsADirectoryError, of a FIFO a wait forever, of a link to /dev/zero a
    memory blow-up); bytes that are not UTF-8 read as U+FFFD (another config, then)."""
    from mocapfix.core.yamlsafe import MAX_BYTES

    try:
        st = os.stat(config_file)
    except OSError as exc:
        raise MocapfixError(f"{config_file}: cannot read the config record of the outputs "
                            f"there: {exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        what = "a folder" if stat.S_ISDIR(st.st_mode) else \
            "not a file (a device, a FIFO or a link to one)"
        raise MocapfixError(f"{config_file}: is {what}; --skip-existing cannot tell which "
                            "config made the outputs there (move it away, or use --overwrite "
                            "or another output folder)")
    try:
        with open(config_file, "rb") as fh:
            data = fh.read(MAX_BYTES + 1)
    except OSError as exc:
        raise MocapfixError(f"{config_file}: cannot read the config record of the outputs "
                            f"there: {exc.strerror or exc}") from None
    return data.decode("utf-8", errors="replace")


def convert_pipeline() -> Pipeline:
    """The pipeline of ``mocapfix convert``: no step (read, write in another format)."""
    from mocapfix.config import parse_config

    return parse_config({"version": 1, "pipeline": []}, "convert (no cleaning)")


def _take_back(folders) -> None:
    """Remove the ``folders`` a run made, where they are empty, innermost first."""
    for folder in folders:
        with contextlib.suppress(OSError):
            folder.rmdir()


def would_do(plan: CleanPlan) -> list[dict]:
    """A dry run's account of the plan: per file to clean, its output and whether it
    replaces one (or would fail: its output path is a folder)."""
    return [{"input": str(j.source), "output": str(j.output), "replaces": _output_there(j),
             **({"output_is_folder": True} if j.output.is_dir() else {})} for j in plan.todo]


def run_clean(plan: CleanPlan, *, workers: int = 1, spec=None,
              on_result: Callable | None = None) -> list[dict]:
    """Run a :func:`plan_clean` plan; results in job order, ``on_result(result)`` as each
    file finishes. A file that failed leaves nothing behind, not even an output of an
    earlier run; each finished file is recorded in the manifest; the effective config is
    written when this config produced (or kept) at least one output. When the batch cannot
    start (e.g. a Dask scheduler that cannot be reached) before any file finished, the
    manifest and the folders the run made are taken back and the error raised. The output
    folder's run lock taken by the plan is released when it returns or raises."""
    try:
        return _run(plan, workers, spec, on_result)
    finally:
        plan.release()


def _written_anew(job: Job) -> list[Path]:
    """The files cleaning ``job`` writes: its output, its reports and, for an AMC, the
    copy of its ASF beside it."""
    skeleton = skeleton_written(job)
    return [*output_files(job.output), *([skeleton[0]] if skeleton else [])]


def _run(plan: CleanPlan, workers: int, spec, on_result) -> list[dict]:
    # a killed run leaves its half-written temporaries; the files this run writes anew
    # take theirs away (never anything else; another run's are safe: the run lock)
    remove_stale_temporaries(f for j in plan.todo for f in _written_anew(j))
    finished_here: list[str] = []

    def noted(write, *args):
        """``write(*args)``; a WriteError (a full disk) is one of the run's problems."""
        try:
            write(*args)
        except WriteError as exc:
            if str(exc) not in plan.problems:
                plan.problems.append(str(exc))

    def record(result):
        finished_here.append(result["input"])
        if result["status"] == "ERROR":
            remove_outputs(output_files(Path(result["output"])))
        noted(plan.manifest.record, result)     # resumable: one record per finished file
        if on_result is not None:
            on_result(result)

    noted(plan.manifest.start, plan.todo)
    try:
        results = run_batch(plan.todo, plan.pipeline.config(), str(plan.pipeline.source),
                            plan.reports, workers, plan.read_options, on_result=record, spec=spec,
                            to=plan.to)
    except MocapfixError:
        if not finished_here:               # nothing ran: leave the folder as it was
            plan.manifest.abandon()
            plan.release()
            _take_back(plan.made)
        raise
    noted(plan.manifest.close)
    if "html" in plan.reports and plan.manifest.records:
        noted(_write_index, plan)
    failed = sum(r["status"] == "ERROR" for r in results)
    if failed < len(results) or plan.resumed:
        noted(_write_config_record, plan)
    return results


def _write_config_record(plan: CleanPlan) -> None:
    refuse_stream(plan.config_file)
    atomic_write_text(plan.config_file, plan.config_text)


def _write_index(plan: CleanPlan) -> None:
    """``OUTDIR/index.html``: every file of the folder's manifest (:mod:`mocapfix.quality.index`)."""
    from mocapfix.quality.index import index_html

    path = plan.outdir / "index.html"
    refuse_stream(path)
    atomic_write_text(path, index_html(list(plan.manifest.records.values()), plan.outdir))


def clean_batch(inputs, outdir, config="default", *, reports=("json",), policy: str | None = None,
                fps: float | None = None, workers: int = 1, include=(), exclude=(),
                allow_inside_input: bool = False, on_result: Callable | None = None,
                to: str | None = None) -> dict:
    """Clean files and folders (``inputs``: a path, or a list of them) into ``outdir`` as
    ``mocapfix clean`` does: ``config`` is a preset name, a YAML path or a
    :class:`~mocapfix.pipeline.steps.Pipeline` (``"convert"``: no cleaning, as ``mocapfix
    convert``); ``policy`` None, ``"overwrite"`` or ``"skip"``
    (the CLI's ``--overwrite`` and ``--skip-existing``); ``to`` the output format (None:
    each input's own). Returns ``{"files": [result per file cleaned], "skipped":
    [(input, why), ...], "ignored": [(path, why) of files discovery passed over],
    "problems": [what the run could not write besides the files (:attr:`CleanPlan.problems`)]}``;
    raises :class:`~mocapfix.core.errors.MocapfixError` for what the run refuses."""
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config

    if isinstance(inputs, (str, bytes, os.PathLike)):
        # one path, not a list of them: "takes" was the inputs "t", "a", "k", ...; an
        # absolute path's first "/" walked the whole file system
        inputs = [inputs]
    inputs = [os.fsdecode(i) for i in inputs]
    pipeline = (config if isinstance(config, Pipeline) else convert_pipeline()
                if config == "convert" else load_config(resolve_config(config)))
    found = discover_inputs(inputs, include, exclude)
    plan = plan_clean(found.files, outdir, pipeline, inputs=inputs,
                      reports=reports, policy=policy, fps=fps,
                      allow_inside_input=allow_inside_input, to=to)
    results = run_clean(plan, workers=workers, on_result=on_result)
    return {"files": results, "skipped": [(str(j.source), why) for j, why in plan.skipped],
            "ignored": [(str(p), why) for p, why in found.skipped], "problems": plan.problems}
