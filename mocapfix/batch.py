"""Batches: find the input files, map them to output paths, run one task per file over an
executor, and hand back a typed result per file as each finishes.

Shape (DESIGN.md, "Batch as tasks over an injected executor"): :func:`discover_inputs`
(shared by clean, check and info) → :func:`plan_outputs` (clean) → :func:`run_tasks`
(``task(item) -> dict`` over a ``concurrent.futures`` executor; a local process pool by
default; any executor with ``submit`` can be injected) yielding results as they finish.

Discovery in folders skips, with a note: hidden files, our own reports and temporary
files, files whose suffix is no motion format, ``.csv``/``.txt``/``.tsv`` files whose content
is not motion data (Nexus/QTM exports, notes), special files (FIFOs, devices, sockets),
broken links and symlink loops, folders that cannot be listed and links to folders (named:
their files are not processed), and names filtered out by ``include``/``exclude``
patterns (case-insensitive). Files named explicitly are always taken (and fail with a
clear error if they cannot be read). Input trees are never written to.
"""
from __future__ import annotations

import errno
import fnmatch
import os
import stat
import tempfile
import threading
import warnings
from concurrent.futures import FIRST_COMPLETED, Executor, wait
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

from mocapfix.errors import ConfigError, MocapfixError, name_the_file
from mocapfix.fileio import is_stream
from mocapfix.formats import MOTION_SUFFIXES, suffixes

_SKIP_SUFFIXES = (".report.json", ".report.md", ".report.html")
_TEXT_SUFFIXES = suffixes("kinect")


@dataclass(frozen=True)
class Found:
    """An input file and the folder it was found in (None: named explicitly)."""

    path: Path
    root: Path | None = None

    @property
    def relative(self) -> Path:
        return self.path.relative_to(self.root) if self.root is not None else Path(self.path.name)


@dataclass(frozen=True)
class Job:
    source: Path
    output: Path


@dataclass
class Discovery:
    files: list
    skipped: list          # (path, why) of files passed over in folders


def _special_kind(mode: int) -> str | None:
    for test, name in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device")):
        if test(mode):
            return name
    return None if stat.S_ISREG(mode) else "not a regular file"


def regular_file_problem(path: Path) -> str | None:
    """Why ``path`` is not a readable regular file (None if it is). Never opens it, so a
    FIFO cannot block; a symlink loop or a dangling link is named."""
    try:
        st = os.stat(path)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            return "symlink loop"
        if path.is_symlink():
            return "broken symlink"
        return exc.strerror or str(exc)
    if stat.S_ISDIR(st.st_mode):
        return None
    return _special_kind(st.st_mode)


def _looks_like_motion(path: Path) -> bool:
    """Content sniff of a text file found in a folder: any format claims it."""
    from mocapfix.formats import NAMES, module

    try:
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return True          # let the reader report the problem
    return any(module(name).sniff(head) for name in NAMES)


def _matches(rel: str, patterns) -> bool:
    """``rel`` (a path relative to its input folder, ``/``-separated) or its file name
    matches one of the ``--include``/``--exclude`` globs, ignoring case on every OS: the
    formats are told by suffix in any case, and ``*.c3d`` left out ``take.C3D``."""
    rel = rel.lower()
    name = rel.rsplit("/", 1)[-1]
    return any(fnmatch.fnmatchcase(rel, p.lower()) or fnmatch.fnmatchcase(name, p.lower())
               for p in patterns)


def discover_inputs(inputs, include=(), exclude=(), sniff: bool = True,
                    once_per_file: bool = False) -> Discovery:
    """Files to process from files and folders (folders recursed in sorted order).
    ``once_per_file``: a file found through two given paths is kept once even when its
    output names would differ (``check``, ``info``: it was checked, listed and counted
    twice, with two JUnit testcases)."""
    files: list[Found] = []
    skipped: list[tuple[str, str]] = []
    for raw in inputs:
        path = Path(raw)
        if not path.exists() and not path.is_symlink():
            raise ConfigError(f"{path}: no such file or folder")
        problem = regular_file_problem(path)
        if problem:
            raise ConfigError(f"{path}: cannot read: {problem}")
        if not path.is_dir():
            files.append(Found(Path(os.path.abspath(path))))
            continue
        root = path.resolve()

        def unlisted(exc: OSError):        # os.walk passes over a folder it cannot list
            skipped.append((exc.filename or str(root), "cannot read this folder: "
                            f"{exc.strerror or exc} (the files in it were not processed)"))

        for dirpath, dirnames, filenames in os.walk(root, onerror=unlisted):
            here = Path(dirpath)
            dirnames[:] = sorted(d for d in dirnames if not d.startswith("."))
            for d in [d for d in dirnames if (here / d).is_symlink()]:
                # os.walk does not follow it (a link to "/" or a loop would never end): say
                # so, or the takes behind it are silently left out
                skipped.append((str(here / d), "a link to a folder, not followed (name the "
                                               "folder itself to include it)"))
            for name in sorted(filenames):
                f = here / name
                rel = f.relative_to(root).as_posix()
                low = name.lower()
                if (low.startswith(".") or low.endswith(_SKIP_SUFFIXES) or low.endswith(".part")
                        or f.suffix.lower() not in MOTION_SUFFIXES):
                    continue
                if include and not _matches(rel, include):
                    skipped.append((str(f), "not matched by --include"))
                    continue
                if exclude and _matches(rel, exclude):
                    skipped.append((str(f), "matched by --exclude"))
                    continue
                problem = regular_file_problem(f)
                if problem:
                    skipped.append((str(f), problem))
                    continue
                if sniff and low.endswith(_TEXT_SUFFIXES) and not _looks_like_motion(f):
                    skipped.append((str(f), "not motion data (no known layout)"))
                    continue
                files.append(Found(f, root))
    return Discovery(*_once(files, skipped, once_per_file))


def _once(files: list, skipped: list, by_file: bool = False) -> tuple[list, list]:
    """Drop a file named a second time with the same output name (``clean in in/walk.bvh``,
    or one file given twice): it is processed once, and the skip says why."""
    seen: set = set()
    kept = []
    for f in files:
        key = (os.path.realpath(f.path), None if by_file else f.relative)
        if key in seen:
            skipped.append((str(f.path), "given more than once (processed once)"))
            continue
        seen.add(key)
        kept.append(f)
    return kept, skipped


def check_output_folder(outdir, create: bool = True) -> Path:
    """Create ``outdir`` if needed and make sure files can be written there; a path that
    runs through a file, or a folder we cannot write to, is a ConfigError.

    ``create=False`` (``clean --dry-run``) makes no folder: the nearest part of the path
    that exists must be a folder taking new entries, tried the same way and refused with
    the same messages, so a dry run refuses what the real run would."""
    outdir = Path(outdir)
    if not create:
        _check_future_folder(outdir)
        return outdir
    try:
        outdir.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise ConfigError(f"{outdir}: output folder is an existing file") from None
    except NotADirectoryError:
        raise ConfigError(f"{outdir}: cannot create the output folder: part of the path is a file") from None
    except OSError as exc:
        raise ConfigError(f"{outdir}: cannot create the output folder: {exc.strerror or exc}") from None
    try:
        _probe_write(outdir)
    except OSError as exc:
        raise ConfigError(f"{outdir}: cannot write to the output folder: {exc.strerror or exc}") from None
    return outdir


def _check_future_folder(outdir: Path) -> None:
    """:func:`check_output_folder` without creating ``outdir`` or its parents."""
    folder = outdir
    while not os.path.lexists(folder) and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise ConfigError(f"{outdir}: output folder is an existing file" if folder == outdir else
                          f"{outdir}: cannot create the output folder: part of the path is a file")
    try:
        _probe_write(folder)
    except OSError as exc:
        what = "write to" if folder == outdir else "create"
        raise ConfigError(f"{outdir}: cannot {what} the output folder: {exc.strerror or exc}") from None


def _probe_write(folder) -> None:
    """Create and remove a hidden file in ``folder``; an OSError when it cannot take one."""
    fd, probe = tempfile.mkstemp(prefix=".mocapfix-probe.", dir=folder)
    os.close(fd)
    os.unlink(probe)


def check_output_file(path, option: str, inputs=(), configs=()) -> Path:
    """Make sure a single output file (``--junit``, ``bench --json``, a trained model) can
    be written before the work that produces it starts, creating nothing: its folder, or
    the nearest folder above it that exists, must take a new file, and it must not be a
    capture among ``inputs`` (a named input, or a motion or ASF file in an input folder
    or beside a named input: ``check take.c3d --junit take.c3d`` replaced the capture
    with XML). A ConfigError naming ``option`` and the path otherwise (exit 2, nothing
    processed). Nor may it be one of ``configs``, the config and rules files the run reads
    (``check -r rules.yaml --junit rules.yaml`` replaced the rules with XML)."""
    path = Path(path)
    _refuse_overwriting_inputs(path, option, inputs)
    for given in configs:
        if given and path.exists() and os.path.realpath(path) == os.path.realpath(given):
            raise ConfigError(f"{option} {path}: would overwrite the config {given}; choose another path")
    folder = path.parent
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    if path.is_dir():
        raise ConfigError(f"{option} {path}: is a folder, not a file")
    if not folder.is_dir():
        raise ConfigError(f"{option} {path}: cannot write there: part of the path is a file")
    if is_stream(path):             # /dev/null, /dev/stdout: written in place, no folder needed
        return path
    try:
        _probe_write(folder)
    except OSError as exc:
        raise ConfigError(f"{option} {path}: cannot write there: {exc.strerror or exc}") from None
    return path


def _refuse_overwriting_inputs(path: Path, option: str, inputs) -> None:
    if not path.exists():
        return
    real = Path(os.path.realpath(path))
    suffix = real.suffix.lower()
    # a capture as discovery sees one (text files only when their content is motion data)
    capture = suffix in (*MOTION_SUFFIXES, ".asf") and (suffix not in _TEXT_SUFFIXES
                                                          or _looks_like_motion(real))
    for raw in inputs:
        given = Path(os.path.realpath(raw))
        if real == given:
            what = f"the input {raw}"
        elif capture and given.is_dir() and _under(real, given):
            what = f"a capture in the input folder {raw}"
        elif capture and not given.is_dir() and _under(real, given.parent):
            what = f"a capture beside the input {raw}"
        else:
            continue
        raise ConfigError(f"{option} {path}: would overwrite {what}; choose another path")


def _under(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def plan_outputs(found: list, outdir, allow_inside_input: bool = False, inputs=()) -> list[Job]:
    """Output path of each input: ``OUTDIR/<path relative to its input folder>``."""
    outdir = Path(os.path.abspath(outdir))
    real_out = outdir.resolve() if outdir.exists() else outdir
    for raw in inputs:
        p = Path(raw)
        if p.is_dir():
            root = p.resolve()
            if _under(real_out, root) and not allow_inside_input:
                raise ConfigError(
                    f"output folder {outdir} is inside input folder {root}; choose another "
                    "output folder or pass --allow-inside-input")
    jobs = [Job(f.path, outdir / f.relative) for f in found
            if not _under(f.path, real_out) or f.root is None]
    if found and not jobs:          # (it said "no motion files found in IN")
        raise ConfigError(f"every motion file found in {', '.join(map(str, inputs))} is inside the "
                          f"output folder {outdir}, whose files are not cleaned again; choose "
                          "another output folder")
    sources = {os.path.realpath(j.source) for j in jobs}
    seen: dict[Path, Path] = {}
    for job in jobs:
        if os.path.realpath(job.output) in sources:
            raise ConfigError(f"{job.output}: would overwrite an input file; choose another output folder")
        if job.output in seen:
            raise ConfigError(f"{job.source} and {seen[job.output]} would both be written to {job.output}")
        seen[job.output] = job.source
    _check_shared_skeletons(jobs)
    return jobs


def _check_shared_skeletons(jobs: list[Job]) -> None:
    """An AMC is written beside a copy of its ASF; two AMCs from different folders whose
    ASFs have one name (in any letter case: ``05.asf`` and ``05.ASF`` pair alike) but
    different content would overwrite each other's skeleton in the output folder (files
    named one by one land side by side): a ConfigError naming both."""
    skeletons: dict[Path, tuple[Path, Path]] = {}
    for job in jobs:
        found = _skeleton_written(job)
        if found is None:
            continue
        target, asf = found
        first = skeletons.setdefault(target.with_name(target.name.casefold()), (asf, job.source))
        if first[0] != asf and not _same_bytes(first[0], asf):
            raise ConfigError(f"{first[1]} and {job.source} would both write their skeleton to "
                              f"{target}, but {first[0]} and {asf} differ; clean them into "
                              "separate output folders (or name the folder above theirs)")


def skeleton_conflicts(jobs: list[Job]) -> list[str]:
    """What the AMC writer would refuse for ``jobs`` (those that run), checked for all of
    them together before any runs (:func:`mocapfix.formats.asfamc.skeleton_conflict`): an
    ASF copy that would pair an AMC in its output folder with the wrong skeleton or none,
    given every copy and AMC the run writes there. One message per job; the run refuses
    before any file is touched (``--dry-run`` with it), and its writers skip the check."""
    from mocapfix.formats.asfamc import file_names, skeleton_conflict

    copies = {job: _skeleton_written(job) for job in jobs}
    folders: dict[Path, dict] = {}
    for job, found in copies.items():
        if found is not None:
            f = folders.setdefault(found[0].parent, {"planned": {}, "rewriting": set()})
            f["planned"].setdefault(found[0].name, found[1])
            f["rewriting"].add(job.output.name)
    for folder, f in folders.items():
        f["present"] = file_names(folder)
        f["outsiders"] = sorted(n for n in f["present"]
                                if n.lower().endswith(".amc") and n not in f["rewriting"])
    contents: dict[Path, bytes | None] = {}     # one read per ASF, however many AMCs use it
    out = []
    for job, found in copies.items():
        if found is None:
            continue
        target, asf = found
        if asf not in contents:
            try:
                contents[asf] = asf.read_bytes()
            except OSError:
                contents[asf] = None
        content = contents[asf]
        if content is None:
            continue                # unreadable: reading the AMC names the cause
        f = folders[target.parent]
        amc = job.output if job.source.suffix.lower() == ".amc" else None
        why = skeleton_conflict(amc, asf, content, rewriting=f["rewriting"], target=target,
                                planned={n: a for n, a in f["planned"].items() if n != target.name},
                                present=f["present"], outsiders=f["outsiders"])
        if why:
            what = "its skeleton cannot be written" if amc is not None else "cannot be written there"
            out.append(f"{job.source}: {what}: {why}")
    return out


def _skeleton_written(job: Job) -> tuple[Path, Path] | None:
    """(the ASF file ``job`` writes, the ASF it copies): an AMC's copy beside its output,
    or an ASF named as an input itself; None for other files."""
    from mocapfix.formats.asfamc import skeleton_output

    suffix = job.source.suffix.lower()
    if suffix == ".asf":
        return job.output, job.source
    return skeleton_output(job.source, job.output) if suffix == ".amc" else None


def _same_bytes(a: Path, b: Path) -> bool:
    try:
        return a.stat().st_size == b.stat().st_size and a.read_bytes() == b.read_bytes()
    except OSError:
        return True                 # unreadable: reading the AMC reports it


def discover(inputs, outdir, allow_inside_input: bool = False, include=(), exclude=()) -> list[Job]:
    """Jobs for the given files and folders (kept for callers of the old API)."""
    found = discover_inputs(inputs, include, exclude)
    return plan_outputs(found.files, outdir, allow_inside_input, inputs)


# -- running ------------------------------------------------------------------------------

def error_result(item, message: str) -> dict:
    source = getattr(item, "source", None) or getattr(item, "path", item)
    out = {"input": str(source), "status": "ERROR", "error": message}
    if hasattr(item, "output"):
        out["output"] = str(item.output)
    return out


def run_tasks(task: Callable, items: list, workers: int = 1,
              executor: Executor | None = None, spec=None,
              window: int | None = None) -> Iterator[tuple[int, dict]]:
    """Run ``task(item)`` for every item; yield ``(index, result)`` as each finishes.

    Where: an injected ``executor`` (anything with ``submit``), else ``spec``
    (:class:`mocapfix.executors.ExecutorSpec`: local processes or Dask), else ``workers``
    local processes. With one worker (or one item) and no executor the tasks run in this
    process, in order, each with the cores for its own parallel loops; in worker
    processes every task runs with one BLAS thread and one task thread
    (:mod:`mocapfix.threads`). At most ``window`` tasks (default: twice the executor's
    slots) are in flight, so memory does not grow with the number of items.

    ``task`` must be picklable for a process pool and must turn its own failures into an
    ``ERROR`` result; a task that raises anyway (a killed worker) becomes one here.
    """
    from mocapfix.executors import ExecutorSpec, open_executor

    if executor is not None:
        yield from _run_on(executor, task, items, window or max(2, 2 * workers))
        return
    with open_executor(spec or ExecutorSpec(jobs=workers), len(items)) as running:
        if running.executor is None:
            from mocapfix.memory import release_freed_memory
            from mocapfix.threads import (blas_threads, limit_blas, set_task_threads,
                                          single_process_task_threads, task_threads)

            blas = blas_threads(1)
            limit_blas(blas)
            before = task_threads()
            set_task_threads(single_process_task_threads(blas))
            try:
                for n, item in enumerate(items):
                    result = _guarded(task, item)
                    release_freed_memory()
                    yield n, result
            finally:
                set_task_threads(before)
            return
        yield from _run_on(running.executor, task, items, window or 2 * running.slots)


@dataclass(frozen=True)
class InWorker:
    """``task`` run in a batch worker: BLAS held to ``threads`` threads and the task's
    own loops to one thread first."""

    task: Callable
    threads: int = 1

    def __call__(self, item):
        from mocapfix.memory import release_freed_memory
        from mocapfix.threads import limit_blas, set_task_threads

        limit_blas(self.threads)
        set_task_threads(1)
        try:
            return self.task(item)
        finally:
            release_freed_memory()


def _run_on(pool: Executor, task, items: list, window: int) -> Iterator[tuple[int, dict]]:
    work = InWorker(task)
    pending: dict = {}
    it = iter(enumerate(items))
    try:
        while True:
            while len(pending) < max(1, window):
                nxt = next(it, None)
                if nxt is None:
                    break
                try:
                    pending[pool.submit(work, nxt[1])] = nxt[0]
                except Exception as exc:  # noqa: BLE001 — a pool broken by a killed worker
                    yield nxt[0], error_result(nxt[1], f"worker failed: {exc}")
            if not pending:
                return
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                n = pending.pop(fut)
                try:
                    result = fut.result()
                except Exception as exc:  # noqa: BLE001 — e.g. a worker killed by the OS
                    result = error_result(items[n], f"worker failed: {exc}")
                yield n, result
    finally:
        for fut in pending:
            fut.cancel()


def internal_error(result: dict) -> dict:
    """``result`` (an ERROR for an unforeseen exception, inside its ``except``) with the
    traceback under ``"traceback"``, which the CLI prints with ``--debug``."""
    import traceback

    result["traceback"] = traceback.format_exc()
    return result


#: NumPy's floating-point warnings ("overflow encountered in multiply"): a file holding
#: values near 1e300 printed a dozen of them naming no file; the code takes the inf and NaN
#: they make for what they are (not finite: reported as missing or as no value)
_FLOAT_NOISE = r"(overflow|invalid value|divide by zero|underflow) encountered"


def quiet_float_warnings() -> None:
    """Hide :data:`_FLOAT_NOISE` in this process (idempotent: one filter however often)."""
    warnings.filterwarnings("ignore", message=_FLOAT_NOISE, category=RuntimeWarning)


def _guarded(task, item) -> dict:
    quiet_float_warnings()          # in the process that runs the task (pool, Dask worker)
    try:
        return task(item)
    except Exception as exc:  # noqa: BLE001 — one bad file must not stop the batch
        return internal_error(error_result(item, f"internal error {type(exc).__name__}: {exc}"))


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
            from mocapfix.manifest import input_identity

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
    share it; models are cached per process by :mod:`mocapfix.models`) and again when one
    of its model files changed since: a process that outlives a run (a Dask worker, a
    library caller) kept cleaning with a model retrained at the same path."""
    import json

    from mocapfix.pipeline import UNIT_WARNINGS, parse_config

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
    """(path, size, modification time) of each file, as :func:`mocapfix.models.load`
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
