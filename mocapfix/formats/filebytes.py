"""The bytes of an input file as a text reader keeps them for its writer: in memory when
the file is small, read again from the file when it is large.

A text reader keeps the file's bytes so that its writer copies the lines the cleaning did
not change exactly as they were (a faithful round trip: spacing, number spellings, line
endings). On a long take those bytes were held through the whole clean beside the take's
own arrays (a 500,000-frame BVH: 470 MB beside 760 MB of channels and positions). A file
over :data:`HELD_MAX` bytes is therefore kept as a :class:`FileBytes`: its path and its
identity (device, inode, size, modification time) as it was read. Slicing one reads that
range from the file again, after checking that the file is still the one read; the
writers copy long runs of unchanged lines through :func:`runs_of`, a block at a time.
A file that changed or went away since it was read is an
:class:`~mocapfix.core.errors.UnreadableFileError` naming it, never a silent mix of two
files. Smaller files stay in memory, so a motion read from one can be written after the
file is gone (a notebook's habit).

Written here because this is a reader's bookkeeping: the standard library's ``mmap``
would re-read pages as well, but a file truncated under a mapping kills the process
(SIGBUS) instead of raising an error.
"""
from __future__ import annotations

import os
import stat
import threading
from pathlib import Path

from mocapfix.core.errors import UnreadableFileError
from mocapfix.core.fileio import read_identity, stat_identity

#: a file larger than this (bytes) is read again by its writer, not held in memory
HELD_MAX = 64 << 20
#: bytes read from the file at a time when a run of it is copied
BLOCK = 4 << 20


_SEEK_LOCK = threading.Lock()


def _pread(fd: int, n: int, at: int) -> bytes:
    """``n`` bytes at offset ``at`` of ``fd`` (fewer at its end): ``os.pread`` where the
    system has it, else a seek and a read under a lock (Windows)."""
    if hasattr(os, "pread"):
        return os.pread(fd, n, at)
    with _SEEK_LOCK:
        os.lseek(fd, at, os.SEEK_SET)
        return os.read(fd, n)


class FileBytes:
    """The bytes of the file at ``path`` as they were read (``identity``: its
    :func:`os.stat` then): ``len()`` and slices (``data[a:b]``, bytes) as of ``bytes``."""

    def __init__(self, path, st: os.stat_result, reading: bool = False):
        self.path = str(path)
        self._where = os.path.abspath(path)     # the same file after a change of directory
        self.identity = stat_identity(st)
        self._fd: int | None = None
        self.reading = reading      # read by its reader (:func:`large_file`), not a writer yet

    def __len__(self) -> int:
        return self.identity[2]

    def __getitem__(self, key) -> bytes:
        if not isinstance(key, slice) or key.step not in (None, 1):
            raise TypeError("FileBytes takes slices with no step")
        a, b, _ = key.indices(len(self))
        return self._read(a, b) if b > a else b""

    def pieces(self, a: int, b: int):
        """The bytes of ``[a, b)``, :data:`BLOCK` at a time."""
        for s in range(a, b, BLOCK):
            yield self._read(s, min(s + BLOCK, b))

    def _read(self, a: int, b: int) -> bytes:
        fd = self._checked()
        parts, at = [], a
        while at < b:
            part = _pread(fd, b - at, at)
            if not part:
                raise self._changed("it is shorter now")
            parts.append(part)
            at += len(part)
        return parts[0] if len(parts) == 1 else b"".join(parts)

    def _checked(self) -> int:
        """The open file, checked to be the one read (opened on first use)."""
        if self._fd is None:
            try:
                self._fd = os.open(self._where, os.O_RDONLY | getattr(os, "O_BINARY", 0)
                                   | getattr(os, "O_CLOEXEC", 0))
            except OSError as exc:
                raise self._changed(exc.strerror or str(exc)) from None
        if stat_identity(os.fstat(self._fd)) != self.identity:
            self.close()
            raise self._changed("it is not the file that was read")
        return self._fd

    def _changed(self, why: str) -> UnreadableFileError:
        if self.reading:
            return UnreadableFileError(self.path, f"changed or moved while it was read ({why}); "
                                       "a file this large is read a block at a time: leave it "
                                       "as it is until its output is written, and run again")
        return UnreadableFileError(self.path, f"changed or moved since it was read ({why}); "
                                   "what the cleaning left unchanged is copied from a file "
                                   "this large when the output is written: leave it as it "
                                   "is until then, and run again (from Python: read it again)")

    def close(self) -> None:
        if self._fd is not None:
            fd, self._fd = self._fd, None
            os.close(fd)

    def __del__(self):
        try:
            self.close()
        except OSError:
            pass

    def __getstate__(self):
        return {"path": self.path, "where": self._where, "identity": self.identity}

    def __setstate__(self, state):
        self.path, self._where, self.identity = state["path"], state["where"], state["identity"]
        self._fd = None
        self.reading = False


class FileView:
    """A large file as a reader uses it without reading it whole: its first ``head`` bytes
    held (a C3D's header and parameter section, a BVH's hierarchy, a text file's first
    lines), every other range read from the file when sliced (:class:`FileBytes`, checked
    to be the file first seen): ``len()``, ``view[i]`` and ``view[a:b]`` as of ``bytes``.
    ``view.head`` is those bytes, for parsers that need a buffer (``struct.unpack_from``,
    a regular expression)."""

    def __init__(self, file: FileBytes, head: int):
        self.file = file
        self.head = file[0:head]

    def __len__(self) -> int:
        return len(self.file)

    def __getitem__(self, key):
        if isinstance(key, slice):
            if key.step not in (None, 1):
                raise TypeError("FileView takes slices with no step")
            a, b, _ = key.indices(len(self))
            return self.head[a:b] if b <= len(self.head) else self.file[a:b]
        i = key + len(self) if key < 0 else key
        if not 0 <= i < len(self):
            raise IndexError("FileView index out of range")
        return self.head[i] if i < len(self.head) else self.file[i:i + 1][0]


def large_file(path) -> FileBytes | None:
    """The regular file at ``path`` as a :class:`FileBytes` when it is larger than
    :data:`HELD_MAX` (its identity as it is now), else None (and None when it cannot be
    looked at: the reader's own read says why)."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    if not stat.S_ISREG(st.st_mode) or st.st_size <= HELD_MAX:
        return None
    return FileBytes(path, st, reading=True)


def large_view(path, head: int) -> FileView | None:
    """The regular file at ``path`` as a :class:`FileView` holding its first ``head``
    bytes when it is larger than :data:`HELD_MAX` (a reader then reads it a block at a
    time, never whole), else None (:func:`large_file`)."""
    file = large_file(path)
    return None if file is None else FileView(file, min(head, len(file)))


def keep(path, data):
    """What a reader keeps of ``data``, the bytes it read from ``path``: ``data`` itself
    when it is at most :data:`HELD_MAX` bytes, or when the file cannot be shown to be
    the one read (:func:`mocapfix.core.fileio.read_identity`); else a :class:`FileBytes`
    (a :class:`FileView`'s own, closed: the writer opens it again, and then sees a file
    replaced since the read)."""
    if isinstance(data, FileView):
        data.file.close()
        data.file.reading = False
        return data.file
    if not isinstance(data, bytes) or len(data) <= HELD_MAX:
        return data
    st = read_identity(data, Path(path))
    return data if st is None else FileBytes(path, st)


def runs_of(data, a: int, b: int):
    """The bytes ``[a, b)`` of ``data`` (bytes or :class:`FileBytes`) as pieces to write:
    a view of held bytes (no copy), or the file's blocks."""
    if b <= a:
        return ()
    if isinstance(data, FileBytes):
        return data.pieces(a, b)
    return (memoryview(data)[a:b],)


def kept_values(values, shared: bool):
    """The values a BVH or AMC source keeps for its writer to tell which lines changed: a
    copy (the motion's own array may be changed in place, and the writer must see that),
    or, ``shared`` (:func:`mocapfix.formats.read`'s ``share_values``), the array itself
    made read-only."""
    if not shared:
        return values.copy()
    values.flags.writeable = False
    return values
