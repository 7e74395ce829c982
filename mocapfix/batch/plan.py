"""Map a batch's input files to output paths and refuse, before anything runs, what the
run could not do safely: an output folder that cannot be made or written, an output that
would replace an input, an AMC whose ASF copy would pair it with the wrong skeleton.
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from mocapfix.core.errors import ConfigError
from mocapfix.core.fileio import is_stream
from mocapfix.formats import MOTION_SUFFIXES
from mocapfix.batch.discovery import TEXT_SUFFIXES, looks_like_motion


@dataclass(frozen=True)
class Job:
    source: Path
    output: Path


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
    capture = suffix in (*MOTION_SUFFIXES, ".asf") and (suffix not in TEXT_SUFFIXES
                                                          or looks_like_motion(real))
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


def plan_outputs(found: list, outdir, allow_inside_input: bool = False, inputs=(),
                 suffix: str | None = None) -> list[Job]:
    """Output path of each input: ``OUTDIR/<path relative to its input folder>``, its
    suffix made ``suffix`` when one is given (a conversion)."""
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
    jobs = [Job(f.path, _with_suffix(outdir / f.relative, suffix)) for f in found
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


def _with_suffix(path: Path, suffix: str | None) -> Path:
    """``take.c3d`` → ``take.trc``; a name with no suffix gets one."""
    return path if suffix is None else path.with_name(path.stem + suffix if path.suffix else path.name + suffix)


def _check_shared_skeletons(jobs: list[Job]) -> None:
    """An AMC is written beside a copy of its ASF; two AMCs from different folders whose
    ASFs have one name (in any letter case: ``05.asf`` and ``05.ASF`` pair alike) but
    different content would overwrite each other's skeleton in the output folder (files
    named one by one land side by side): a ConfigError naming both."""
    skeletons: dict[Path, tuple[Path, Path]] = {}
    for job in jobs:
        found = skeleton_written(job)
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

    copies = {job: skeleton_written(job) for job in jobs}
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


def skeleton_written(job: Job) -> tuple[Path, Path] | None:
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
