"""A text file held once, as the bytes read, with the offsets of its lines: what a text
reader keeps for writing the file back.

Why hand-written: ``str.splitlines`` and ``io`` give one Python object per line (about
50 bytes each beyond the text, a second copy of the file), and ``str.split`` on the whole
file one per field (a 500,000-frame Kinect CSV: 50 million objects, gigabytes). Here the
file is one ``bytes`` object and two int64 arrays (start and end of each line); lines are
decoded one block at a time when a reader parses them, and the writer copies the runs of
unchanged lines as byte slices between the lines it rewrites, straight to the output file.
Once the reader is done (:meth:`TextLines.keep`), a large file's bytes are let go and read
again from the file when written (:mod:`mocapfix.formats.filebytes`). A reader may not
hold a large file at all: given a :class:`~mocapfix.formats.filebytes.FileView`
(:meth:`TextLines.open_large`; the Kinect, TRC and vendor-table readers), the file is
scanned and its lines parsed a block at a time, read from the file.

Lines are what ``text.split("\\n")`` gives after the UTF-8 byte-order mark: a ``\\r``
before the ``\\n`` is the line's ending, not its text, and an empty piece after a final
``\\n`` is no line. A reader may ask for a lone ``\\r`` to end a line too (``lone_cr``:
TRC files from old Mac OS software; then lines are what ``re.split(r"\\r\\n|\\n|\\r")``
gives), and for a file that is not UTF-8 to be decoded with another encoding
(``fallback``: latin-1 for TRC), its edits then encoded with it too.
"""
from __future__ import annotations

import re

import numpy as np

from mocapfix.core.errors import MAX_FIELD, UnreadableFileError
from mocapfix.core.fileio import read_input_bytes
from mocapfix.formats.filebytes import FileBytes, FileView, keep, large_view, runs_of
from mocapfix.formats.textenc import (UTF8_BOM, longest_field_bytes, refuse_long_fields,
                                      refuse_wide_text)

#: bytes of the file decoded at a time (cut at a line end, so never inside a character)
BLOCK = 1 << 22
#: bytes of a large file held while it is read (its first lines: :meth:`TextLines.open_large`)
HEAD = 1 << 20


def _block_to_line_end(raw, a: int, size: int, lone_cr: bool = False) -> bytes:
    """The bytes of ``raw`` from ``a`` to the end of the line that ends last within
    :data:`BLOCK` bytes (the rest of the file when it ends sooner; a line longer than a
    block whole). ``lone_cr``: a ``\\r`` not followed by ``\\n`` ends a line too (never
    cut between the two bytes of a ``\\r\\n``)."""
    if a + BLOCK >= size:
        return raw[a:size]
    data = raw[a:a + BLOCK + lone_cr]           # one byte more: is a last CR a CRLF's?
    cut = _after_last_end(data, BLOCK, lone_cr)
    if cut:
        return data[:cut]
    parts = [data[:BLOCK]]                          # one line longer than a block
    for c in range(a + BLOCK, size, BLOCK):
        more = raw[c:min(c + BLOCK + lone_cr, size)]
        cut = _after_first_end(more, BLOCK, lone_cr)
        parts.append(more[:cut] if cut else more[:BLOCK])
        if cut:
            break
    return b"".join(parts)


def _after_last_end(data: bytes, within: int, lone_cr: bool) -> int:
    """Offset just past the last line ending that starts in ``data[:within]`` (0: none)."""
    at = data.rfind(b"\n", 0, within)
    if lone_cr:
        cr = data.rfind(b"\r", 0, within)
        if cr > at:
            return cr + 1 + (data[cr + 1:cr + 2] == b"\n")
    return at + 1


def _after_first_end(data: bytes, within: int, lone_cr: bool) -> int:
    """Offset just past the first line ending that starts in ``data[:within]`` (0: none)."""
    at = data.find(b"\n", 0, within)
    if lone_cr:
        cr = data.find(b"\r", 0, within)
        if cr >= 0 and (at < 0 or cr < at):
            return cr + 1 + (data[cr + 1:cr + 2] == b"\n")
    return at + 1


#: a line ending where a lone CR ends a line too (old Mac OS files)
_ANY_EOL = re.compile(r"\r\n|\n|\r")


def line_end_bytes(view: np.ndarray, n: int) -> np.ndarray:
    """Offsets in ``view[:n]`` (uint8) of the bytes that end a line when LF, CRLF and a
    lone CR all do: every LF, and every CR not followed by a LF (``view`` may hold one
    byte past ``n`` to tell; a CR at its very end is lone)."""
    cr = np.flatnonzero(view[:n] == 13)
    lone = cr[(cr + 1 >= len(view)) | (view[np.minimum(cr + 1, len(view) - 1)] != 10)]
    return np.union1d(np.flatnonzero(view[:n] == 10), lone)


class TextLines:
    """The lines of ``raw`` (bytes): ``line(i)`` decodes one, ``pieces`` writes them back
    with edits. ``content`` marks the lines that are neither blank nor (when the reader
    has them) ``#`` comments. ``encoding``: what the lines are decoded and edits encoded
    with (UTF-8, or a reader's fallback for a file that is not)."""

    def __init__(self, raw, starts: np.ndarray, stops: np.ndarray, content: np.ndarray,
                 encoding: str = "utf-8"):
        self.raw = raw
        self.encoding = encoding
        self.bom = "\ufeff" if encoding == "utf-8" and raw[:len(UTF8_BOM)] == UTF8_BOM else ""
        self.starts, self.stops = starts, stops      # text of line i: raw[starts[i]:stops[i]]
        self.content = content

    @classmethod
    def scan(cls, path, raw, *, lone_cr: bool = False, comments: bool = True,
             fallback: str | None = None, encoding: str = "utf-8") -> TextLines:
        """Index ``raw`` (bytes, or a large file's
        :class:`~mocapfix.formats.filebytes.FileView`: read a block at a time, never
        whole): an UnreadableFileError at its first byte that is not UTF-8 (or, given a
        ``fallback`` encoding, the whole file decoded with that one), or (after the whole
        file decoded) for a field longer than MAX_FIELD characters. ``lone_cr``: a CR not
        followed by LF ends a line too; ``comments``: ``#`` lines are not ``content``."""
        size = len(raw)
        begin = len(UTF8_BOM) if encoding == "utf-8" and raw[:len(UTF8_BOM)] == UTF8_BOM else 0
        line_ends, carriage, content, long_line = [], [], [], None
        a, n_lines = begin, 0
        solid = begin > 0               # a byte that is not ASCII whitespace (the mark is)
        while a < size:
            data = _block_to_line_end(raw, a, size, lone_cr)
            b = a + len(data)
            solid = solid or bool(data.strip())
            try:
                text = data.decode(encoding)
            except UnicodeDecodeError as exc:
                if fallback:
                    return cls.scan(path, raw, lone_cr=lone_cr, comments=comments,
                                    encoding=fallback)
                raise UnreadableFileError(path, f"not a text file (undecodable byte at offset "
                                                f"{a + exc.start})") from None
            if lone_cr and text.count("\r") != text.count("\r\n"):
                pieces = _ANY_EOL.split(text)
            else:   # no lone CR: a CRLF's CR stays on its piece, which the blank and
                pieces = text.split("\n")      # long-field tests strip (the regex is slower)
            if b < size or pieces[-1] == "":
                pieces.pop()                        # what follows the block's last line end
            content.append(np.fromiter((bool(p.strip()) and not (comments and
                                                                  p.lstrip().startswith("#"))
                                        for p in pieces), bool, len(pieces)))
            view = np.frombuffer(data, np.uint8)
            if (long_line is None and len(text) > MAX_FIELD
                    and longest_field_bytes(view) > MAX_FIELD):
                long_line = cls._long_field(path, pieces, n_lines,
                                             b == size and data[-1:] != b"\n")
            ends = line_end_bytes(view, len(view)) if lone_cr else np.flatnonzero(view == 10)
            # a CR before a newline ends the line with it (a block starts a line, and is
            # never cut between the two)
            carriage.append((ends > 0) & (view[np.maximum(ends - 1, 0)] == 13)
                            & (view[ends] == 10))
            line_ends.append(a + ends)
            n_lines += len(pieces)
            a = b
        if not solid:       # as read_input_bytes says of a file it reads whole
            raise UnreadableFileError(path, "file is empty")
        nl = np.concatenate(line_ends) if line_ends else np.zeros(0, np.int64)
        cr = np.concatenate(carriage) if carriage else np.zeros(0, bool)
        starts = np.concatenate([[begin], nl + 1])[:n_lines].astype(np.int64)
        stops = np.empty(n_lines, np.int64)
        ended = min(len(nl), n_lines)               # lines with a line end after them
        stops[:ended] = nl[:ended]
        if ended < n_lines:
            stops[ended:] = size
        stops[np.flatnonzero(cr[:ended])] -= 1
        lines = cls(raw, starts, stops, np.concatenate(content) if content else
                    np.zeros(0, bool), encoding)
        lines.long_field = long_line
        return lines

    @classmethod
    def read(cls, path, what: str, **scan) -> TextLines:
        """The lines of the file at ``path`` (one over
        :data:`~mocapfix.formats.filebytes.HELD_MAX` bytes read a block at a time:
        :meth:`open_large`); UTF-16/32 text (named as ``what``), undecodable bytes and a
        field over MAX_FIELD characters refused, in that order, as each was found first
        when the file was decoded whole. ``scan``: :meth:`scan`'s options."""
        raw = cls.open_large(path) or read_input_bytes(path)
        refuse_wide_text(path, raw[:4096], what)
        text = cls.scan(path, raw, **scan)
        if text.long_field is not None:
            raise text.long_field
        return text

    @staticmethod
    def open_large(path) -> FileView | None:
        """A file over :data:`~mocapfix.formats.filebytes.HELD_MAX` bytes as a
        :class:`~mocapfix.formats.filebytes.FileView` holding its first :data:`HEAD`
        bytes, for :meth:`scan` and the reader to read a block at a time (never whole);
        None for a smaller file."""
        return large_view(path, HEAD)

    @staticmethod
    def _long_field(path, pieces, first, last_open):
        """The UnreadableFileError for the block's first field over MAX_FIELD, or None
        (``last_open``: the last piece is the file's last line, without a newline)."""
        last = len(pieces) - 1
        lines = [p[:-1] if p.endswith("\r") and (k < last or not last_open) else p
                 for k, p in enumerate(pieces)]
        try:
            refuse_long_fields(path, lines, first_line=first)
        except UnreadableFileError as exc:
            return exc
        return None

    def __len__(self) -> int:
        return len(self.starts)

    def line(self, i: int) -> str:
        return self.raw[self.starts[i]:self.stops[i]].decode(self.encoding)

    def lines_at(self, indices) -> list[str]:
        raw, starts, stops = self.raw, self.starts[indices], self.stops[indices]
        if isinstance(raw, (FileBytes, FileView)) and len(starts):
            # one read of the stretch that holds them, when they lie close together
            a, b = int(starts.min()), int(stops.max())
            if b - a <= max(BLOCK, 4 * int((stops - starts).sum())):
                raw, starts, stops = raw[a:b], starts - a, stops - a
        return [raw[s:e].decode(self.encoding) for s, e in zip(starts.tolist(), stops.tolist())]

    def keep(self, path) -> None:
        """After the reader is done with the text: the bytes kept as
        :func:`mocapfix.formats.filebytes.keep` keeps them (a large file is read again
        when written, not held)."""
        self.raw = keep(path, self.raw)

    def end(self, i: int) -> int:
        """Offset just past line ``i``'s ending."""
        return int(self.starts[i + 1]) if i + 1 < len(self.starts) else len(self.raw)

    @property
    def lines(self) -> list[str]:
        """Every line as a str (for tests and small files: one object per line)."""
        return self.lines_at(np.arange(len(self)))

    @property
    def endings(self) -> list[str]:
        return [self.raw[int(e):self.end(i)].decode("utf-8") for i, e in enumerate(self.stops)]

    def eol(self) -> bytes:
        """The first line ending of the file ("\\n" when it has none)."""
        for i, e in enumerate(self.stops.tolist()):
            if self.end(i) > e:
                return self.raw[e:self.end(i)]
        return b"\n"

    def pieces(self, edits, deleted=(), inserted=None):
        """The file's bytes with ``edits`` applied, in pieces to write one after another.

        ``edits``: (line, new text) in increasing line order, the text without its ending
        (the line keeps its own); ``deleted``: lines left out with their endings;
        ``inserted``: line -> texts written after it, each with the file's first ending
        (and one before them when what was written last has none)."""
        raw, starts, stops = self.raw, self.starts, self.stops
        inserted = inserted or {}
        dropped = set(deleted)
        marks = sorted(dropped | set(inserted))
        eol = self.eol()
        at = [0, False]                     # offset copied up to; whether output ends a line

        def upto(stop):
            if stop <= at[0]:
                return
            start, at[0] = at[0], stop
            for piece in runs_of(raw, start, stop):
                yield piece
            at[1] = piece[-1] in (10, 13)

        def marked(i):
            if i in dropped:
                yield from upto(int(starts[i]))
                at[0] = self.end(i)
            else:
                yield from upto(self.end(i))
            for text in inserted.get(i, ()):
                if not at[1]:
                    yield eol
                yield text.encode(self.encoding) + eol
                at[1] = True

        k = 0
        for i, text in edits:
            while k < len(marks) and marks[k] < i:
                yield from marked(marks[k])
                k += 1
            if i in dropped:
                continue
            yield from upto(int(starts[i]))
            piece = text.encode(self.encoding)
            if piece:
                at[1] = piece[-1] in (10, 13)
            yield piece
            at[0] = int(stops[i])
        while k < len(marks):
            yield from marked(marks[k])
            k += 1
        yield from upto(len(raw))
