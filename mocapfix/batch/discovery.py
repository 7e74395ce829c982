"""Find the input files of a batch (shared by clean, check, info and train-dictionary).

Discovery in folders skips, with a note: hidden files, our own reports and temporary
files, files whose suffix is no motion format, ``.csv``/``.txt``/``.tsv`` files whose content
matches no known layout (two kinds: a table of numbers is data in a layout we do not
read — reported plainly, listed by ``check`` as a skipped testcase and failed by ``check
--strict`` — anything else is a note, passed over quietly), special files (FIFOs, devices, sockets),
broken links and symlink loops, folders that cannot be listed and links to folders (named:
their files are not processed), and names filtered out by ``include``/``exclude``
patterns (case-insensitive). Files named explicitly are always taken (and fail with a
clear error if they cannot be read). Input trees are never written to.
"""
from __future__ import annotations

import dataclasses
import errno
import fnmatch
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

from mocapfix.core.errors import ConfigError, UnreadableFileError
from mocapfix.core.fileio import regular_file_problem
from mocapfix.formats import MOTION_SUFFIXES, TEXT_SUFFIXES

_SKIP_SUFFIXES = (".report.json", ".report.md", ".report.html")


@dataclass(frozen=True)
class Found:
    """An input file and the folder it was found in (None: named explicitly)."""

    path: Path
    root: Path | None = None

    @property
    def relative(self) -> Path:
        return self.path.relative_to(self.root) if self.root is not None else Path(self.path.name)


@dataclass
class Discovery:
    files: list
    skipped: list          # (path, why) of files passed over in folders
    #: the text files among ``skipped`` that hold a table of numbers in no layout we read
    #: (``Found``, why): data, not notes
    unknown: list = dataclasses.field(default_factory=list)


#: fields of a row of numbers: separated by commas, semicolons, tabs or spaces
_FIELDS = re.compile(r"[,;\t ]+")
_NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")


def refuse_special_file(path) -> None:
    """An UnreadableFileError for an existing ``path`` that is a FIFO, a device or a
    socket (or a link to one), as discovery skips it: reading a FIFO waits for a writer
    forever, a link to /dev/zero never ends. A missing path is left to the reader."""
    path = Path(path)
    problem = os.path.exists(path) and regular_file_problem(path)
    if problem:
        raise UnreadableFileError(path, f"cannot read: {problem}")


def _head(path: Path) -> bytes | None:
    try:
        with open(path, "rb") as fh:
            return fh.read(4096)
    except OSError:
        return None


def looks_like_motion(path: Path) -> bool:
    """Content sniff of a text file found in a folder: any format claims it."""
    from mocapfix.formats import NAMES, module

    head = _head(path)
    if head is None:
        return True          # let the reader report the problem
    return any(module(name).sniff(head) for name in NAMES)


def unknown_layout(path: Path) -> str | None:
    """Why a text file no format claims is data all the same: at least three of the
    complete lines of its first 4 KB are rows of three or more numbers (a vendor export we
    do not read, a layout of our formats gone wrong). None for a note (prose, a list)."""
    head = _head(path)
    if head is None:
        return None
    from mocapfix.formats import texttable

    lines = head.decode("utf-8", errors="replace").lstrip("\ufeff").splitlines()[:-1] or []
    rows = sum(sum(bool(_NUMBER.fullmatch(f)) for f in _FIELDS.split(line.strip())) >= 3
               for line in lines)
    return texttable.unknown_layout(head) if rows >= 3 else None


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
    unknown: list[tuple[Found, str]] = []
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
                if sniff and low.endswith(TEXT_SUFFIXES) and not looks_like_motion(f):
                    why = unknown_layout(f)
                    if why is None:
                        skipped.append((str(f), "not motion data (a note: no table of numbers)"))
                    else:
                        skipped.append((str(f), why))
                        unknown.append((Found(f, root), why))
                    continue
                files.append(Found(f, root))
    return Discovery(*_once(files, skipped, once_per_file), unknown)


def _once(files: list, skipped: list, by_file: bool = False) -> tuple[list, list]:
    """Drop a file named a second time with the same output name (``clean in in/walk.bvh``,
    or one file given twice): it is processed once, and the skip says why."""
    seen: dict = {}
    kept = []
    for f in files:
        key = (os.path.realpath(f.path), None if by_file else f.relative)
        if key in seen:
            # a link in a folder to a file beside it was "given more than once" too
            first = seen[key]
            skipped.append((str(f.path), "given more than once (processed once)" if first == f.path
                            else f"the same file as {first} (processed once)"))
            continue
        seen[key] = f.path
        kept.append(f)
    return kept, skipped
