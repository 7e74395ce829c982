"""Atomic file output: write to a temporary file in the target directory, then rename.

A crash or an error half-way leaves either the old file or no file, never a truncated one.
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import stat
import tempfile
import threading
from pathlib import Path


@contextlib.contextmanager
def atomic_open(path, mode: str = "wb"):
    """Open a temporary sibling of ``path`` for writing; rename it over ``path`` on success
    (a character device or a pipe, such as /dev/null, is written in place instead).

    An OS failure of our own (the folder cannot be made or written, the disk is full, the
    rename fails) is a :class:`~mocapfix.core.errors.WriteError` naming ``path``."""
    path = Path(path)
    stream = _open_stream(path, mode)
    if stream is not None:          # a device or pipe: written in place (see _open_stream)
        try:
            with stream as fh:
                yield fh
                fh.flush()
        except OSError as exc:      # /dev/full, a pipe whose reader left
            raise _write_error(path, exc) from None
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{_temp_stem(path.name)}.", suffix=".part",
                                   dir=path.parent)
    except OSError as exc:
        raise _write_error(path, exc) from None
    try:
        try:
            with os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": ""})) as fh:
                yield fh
                try:
                    fh.flush()
                    os.fsync(fh.fileno())
                except OSError as exc:
                    raise _write_error(path, exc) from None
        except OSError as exc:      # the caller's writes, or the flush as the file closed
            if exc.errno not in WRITE_FAILURES:
                raise
            raise _write_error(path, exc) from None
        try:
            os.chmod(tmp, 0o666 & ~current_umask())   # mkstemp made it 0600: honour the umask
            os.replace(tmp, path)
        except OSError as exc:
            raise _write_error(path, exc) from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


#: errno values of a write that the disk or file system refused (full, over quota, failing,
#: read-only, file too large): raised inside :func:`atomic_open`, they are a WriteError
WRITE_FAILURES = frozenset(getattr(errno, n) for n in
                           ("ENOSPC", "EDQUOT", "EIO", "EROFS", "EFBIG") if hasattr(errno, n))


def refuse_stream(path) -> None:
    """Raise a :class:`~mocapfix.core.errors.WriteError` when ``path`` is (or links to) a
    character device or a pipe: a file of an output folder written there would be
    swallowed (``/dev/null``) or sent away while the run records it as written."""
    if is_stream(path):
        from mocapfix.core.errors import WriteError
        raise WriteError(path, "cannot write: it is a device or a named pipe (FIFO), or a link "
                               "to one, not a file; remove it from the output folder")


def is_stream(path) -> bool:
    """True when ``path`` exists and is a character device or a pipe (/dev/null, /dev/stdout
    into a pipe, a FIFO), or names one of this process's open descriptors (/dev/stdout
    redirected to a file): :func:`atomic_open` writes into it in place."""
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return stat.S_ISCHR(mode) or stat.S_ISFIFO(mode) or _names_a_descriptor(path)


#: a path of an open descriptor: /proc/self/fd/N, /proc/PID/fd/N, /dev/fd/N
_DESCRIPTOR = re.compile(r"^/(?:proc/(?:self|\d+)|dev)/fd/\d+$")


def _names_a_descriptor(path) -> bool:
    """Whether ``path`` is, or links (through any chain of links) to, an open descriptor's
    path (``/dev/stdout`` → ``/proc/self/fd/1``). With the descriptor on a regular file
    (``--junit /dev/stdout > report.xml``) the temporary-then-rename replaced the link
    itself, /dev/stdout, with a regular file (run as root) and left the redirected file
    empty."""
    p = os.fspath(path)
    for _ in range(40):                        # a loop of links ends here, not in a hang
        if _DESCRIPTOR.match(os.path.normpath(p)):
            return True
        try:
            target = os.readlink(p)
        except OSError:                        # not a link (or gone): the chain ends
            return False
        p = os.path.join(os.path.dirname(p), target)
    return False


def _open_stream(path: Path, mode: str):
    """An existing ``path`` that is not a regular file or a folder, opened for writing in
    place, or None. A character device or a pipe (``--junit /dev/null``, ``/dev/stdout``,
    a FIFO with a reader) is written into: the temporary-then-rename of :func:`atomic_open`
    would replace the device or link itself with a regular file (run as root, it did so to
    /dev/null). A FIFO without a reader, a block device or a socket is a WriteError."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    if stat.S_ISREG(st.st_mode) and _names_a_descriptor(path):
        # /dev/stdout redirected to a file: appended to, after what the run printed there
        try:
            fd = os.open(path, os.O_WRONLY | os.O_APPEND)
        except OSError as exc:
            raise _write_error(path, exc) from None
        return os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": ""}))
    if stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode):
        return None
    if not (stat.S_ISCHR(st.st_mode) or stat.S_ISFIFO(st.st_mode)):
        from mocapfix.core.errors import WriteError
        kind = "a block device" if stat.S_ISBLK(st.st_mode) else "not a file"
        raise WriteError(path, f"cannot write: {kind}; give the path of a file")
    fifo = stat.S_ISFIFO(st.st_mode)
    try:
        # a FIFO opened without O_NONBLOCK waits for a reader forever; with it, ENXIO
        fd = os.open(path, os.O_WRONLY | (os.O_NONBLOCK if fifo else 0))
    except OSError as exc:
        if fifo and exc.errno == errno.ENXIO:
            from mocapfix.core.errors import WriteError
            raise WriteError(path, "cannot write: a named pipe (FIFO) that nothing reads") from None
        raise _write_error(path, exc) from None
    if fifo:
        os.set_blocking(fd, True)
    return os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": ""}))


#: the longest file name (bytes) of common Linux, macOS and Windows file systems
NAME_MAX = 255
_TEMP_EXTRA = len("..XXXXXXXX.part")          # the dots, mkstemp's 8 characters, .part


def _temp_stem(name: str) -> str:
    """The part of ``name`` in its temporary's name ``.STEM.XXXXXXXX.part``: the whole name,
    or as much of it as keeps the temporary within :data:`NAME_MAX` bytes (a legal output
    name of 241-255 bytes must not fail on its temporary's length)."""
    raw, room = os.fsencode(name), NAME_MAX - _TEMP_EXTRA
    if len(raw) <= room:
        return name
    cut = raw[:room]
    while cut:                                 # do not split a UTF-8 character
        try:
            cut.decode("utf-8")
            break
        except UnicodeDecodeError as exc:
            if exc.start < len(cut) - 3:       # not UTF-8 before the cut: bytes as they are
                break
            cut = cut[:exc.start]
    return os.fsdecode(cut)


def _write_error(path: Path, exc: OSError):
    from mocapfix.core.errors import WriteError

    why = exc.strerror or str(exc)
    if isinstance(exc, (FileExistsError, NotADirectoryError)):
        why = "part of the folder path is a file"
    return WriteError(path, f"cannot write: {why}")


def remove_stale_temporaries(paths) -> int:
    """Remove the temporary siblings :func:`atomic_open` leaves for each of ``paths`` when
    the process writing it was killed (``.NAME.XXXXXXXX.part``; a crash between writing
    and renaming cannot clean up after itself). Only names of that exact pattern, for
    these paths, are touched; each folder is listed once. Returns how many were removed."""
    by_folder: dict[Path, set[str]] = {}
    for p in map(Path, paths):
        by_folder.setdefault(p.parent, set()).add(_temp_stem(p.name))
    removed = 0
    for folder, names in by_folder.items():
        try:
            entries = [e for e in os.scandir(folder) if e.name.startswith(".")
                       and e.name.endswith(".part")]
        except OSError:
            continue
        for e in entries:
            name, _, middle = e.name[1:-len(".part")].rpartition(".")
            if (name in names and len(middle) == 8 and middle.replace("_", "").isalnum()
                    and e.is_file(follow_symlinks=False)):
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(e.path)
                    removed += 1
    return removed


def current_umask() -> int:
    """The process umask (read by setting and restoring it)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def atomic_write_bytes(path, data: bytes) -> Path:
    with atomic_open(path, "wb") as fh:
        fh.write(data)
    return Path(path)


def atomic_write_pieces(path, pieces) -> Path:
    """:func:`atomic_write_bytes` of the ``bytes`` pieces, each written as it comes (a long
    take's output is never held whole)."""
    with atomic_open(path, "wb") as fh:
        for piece in pieces:
            fh.write(piece)
    return Path(path)


def atomic_write_text(path, text: str) -> Path:
    """Write ``text`` as UTF-8. A file name that is not UTF-8 (bytes on Linux, decoded by
    Python to lone surrogates such as ``\\udcff``) is written as that escape, so reports
    and JUnit XML that quote it stay valid UTF-8 text."""
    return atomic_write_bytes(path, text.encode("utf-8", errors="backslashreplace"))


def write_output_text(path, text: str) -> list:
    """Write a text output (UTF-8) atomically; any OS failure is a
    :class:`~mocapfix.core.errors.WriteError` naming ``path``. Returns ``[path]``, as a
    format's writer does."""
    try:
        atomic_write_bytes(path, text.encode("utf-8"))
    except OSError as exc:
        raise _write_error(Path(path), exc) from None
    return [Path(path)]


def write_output_pieces(path, pieces) -> list:
    """:func:`write_output_text` of text given as UTF-8 ``bytes`` pieces, each written as
    it comes (a long take's output is never held whole)."""
    try:
        atomic_write_pieces(path, pieces)
    except OSError as exc:
        raise _write_error(Path(path), exc) from None
    return [Path(path)]


def read_input_bytes(path) -> bytes:
    """The bytes of an input file; any OS failure or an empty (or whitespace-only) file is
    an :class:`~mocapfix.core.errors.UnreadableFileError` naming the file."""
    from mocapfix.core.errors import UnreadableFileError

    path = Path(path)
    try:
        with open(path, "rb") as fh:
            before = os.fstat(fh.fileno())
            data = fh.read()
            after = os.fstat(fh.fileno())
    except FileNotFoundError:
        raise UnreadableFileError(path, "no such file") from None
    except IsADirectoryError:
        raise UnreadableFileError(path, "is a directory, not a file") from None
    except OSError as exc:
        raise UnreadableFileError(path, f"cannot open: {exc.strerror or exc}") from None
    if not data.strip():
        raise UnreadableFileError(path, "file is empty")
    if stat_identity(before) == stat_identity(after) and before.st_size == len(data):
        with _READ_STATS_LOCK:
            _READ_STATS[id(data)] = (str(path), before)
            while len(_READ_STATS) > _READ_STATS_KEPT:
                del _READ_STATS[next(iter(_READ_STATS))]
    return data


#: the file status of the last inputs read, by the id of the bytes read
#: (:func:`read_identity`); the oldest are forgotten
_READ_STATS: dict = {}
_READ_STATS_KEPT = 64
_READ_STATS_LOCK = threading.Lock()


def stat_identity(st: os.stat_result) -> tuple:
    """What tells one state of a file from another: device, inode, size and modification
    time (ns)."""
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns


def read_identity(data: bytes, path) -> os.stat_result | None:
    """The status of the file ``path`` as :func:`read_input_bytes` read ``data`` from it,
    when it did (its size and modification time the same before and after the read) and
    the file at ``path`` is still that file now; else None (the file cannot be shown to
    hold ``data``)."""
    with _READ_STATS_LOCK:
        path_was, st = _READ_STATS.pop(id(data), (None, None))
    if st is None or path_was != str(path):
        return None
    try:
        now = os.stat(path)
    except OSError:
        return None
    return st if stat_identity(now) == stat_identity(st) else None


def file_sha256(path) -> str:
    """SHA-256 of a file's bytes (read in 1 MiB blocks), as hex."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _special_kind(mode: int) -> str | None:
    for test, name in ((stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device")):
        if test(mode):
            return name
    return None if stat.S_ISREG(mode) else "not a regular file"


def regular_file_problem(path: Path) -> str | None:
    """Why ``path`` is not a readable regular file (None if it is, or a folder: the
    callers tell folders apart). Never opens it, so a FIFO cannot block; a symlink loop
    or a dangling link is named."""
    path = Path(path)
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
