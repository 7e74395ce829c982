"""A text file held once, as the bytes read, with the offsets of its lines: what a text
reader keeps for writing the file back.

Why hand-written: ``str.splitlines`` and ``io`` give one Python object per line (about
50 bytes each beyond the text, a second copy of the file), and ``str.split`` on the whole
file one per field (a 500,000-frame Kinect CSV: 50 million objects, gigabytes). Here the
file is one ``bytes`` object and two int64 arrays (start and end of each line); lines are
decoded one block at a time when a reader parses them, and the writer copies the runs of
unchanged lines as byte slices between the lines it rewrites, straight to the output file.
Once the reader is done (:meth:`TextLines.keep`), a large file's bytes are let go and read
again from the file when written (:mod:`mocapfix.formats.filebytes`).

Lines are what ``text.split("\\n")`` gives after the UTF-8 byte-order mark: a ``\\r``
before the ``\\n`` is the line's ending, not its text, and an empty piece after a final
``\\n`` is no line.
"""
from __future__ import annotations

import numpy as np

from mocapfix.core.errors import MAX_FIELD, UnreadableFileError
from mocapfix.formats.filebytes import FileBytes, keep, runs_of
from mocapfix.formats.textenc import UTF8_BOM, longest_field_bytes, refuse_long_fields

#: bytes of the file decoded at a time (cut at a line end, so never inside a character)
BLOCK = 1 << 22


class TextLines:
    """The lines of ``raw`` (bytes): ``line(i)`` decodes one, ``pieces`` writes them back
    with edits. ``content`` marks the lines that are neither blank nor ``#`` comments."""

    def __init__(self, raw: bytes, starts: np.ndarray, stops: np.ndarray, content: np.ndarray):
        self.raw = raw
        self.bom = "\ufeff" if raw.startswith(UTF8_BOM) else ""
        self.starts, self.stops = starts, stops      # text of line i: raw[starts[i]:stops[i]]
        self.content = content

    @classmethod
    def scan(cls, path, raw: bytes) -> TextLines:
        """Index ``raw``: an UnreadableFileError at its first byte that is not UTF-8, or
        (after the whole file decoded) for a field longer than MAX_FIELD characters."""
        begin = len(UTF8_BOM) if raw.startswith(UTF8_BOM) else 0
        view = np.frombuffer(raw, np.uint8)
        newlines, content, long_line = [], [], None
        a, n_lines = begin, 0
        while a < len(raw):
            b = raw.rfind(b"\n", a, a + BLOCK) + 1 if a + BLOCK < len(raw) else len(raw)
            if b <= a:                              # one line longer than a block
                b = raw.find(b"\n", a + BLOCK)
                b = len(raw) if b < 0 else b + 1
            try:
                text = raw[a:b].decode("utf-8")
            except UnicodeDecodeError as exc:
                raise UnreadableFileError(path, f"not a text file (undecodable byte at offset "
                                                f"{a + exc.start})") from None
            pieces = text.split("\n")
            if b < len(raw) or pieces[-1] == "":
                pieces.pop()                        # what follows the block's last newline
            content.append(np.fromiter((bool(p.strip()) and not p.lstrip().startswith("#")
                                        for p in pieces), bool, len(pieces)))
            if (long_line is None and len(text) > MAX_FIELD
                    and longest_field_bytes(view[a:b]) > MAX_FIELD):
                long_line = cls._long_field(path, pieces, n_lines,
                                             b == len(raw) and raw[-1:] != b"\n")
            newlines.append(a + np.flatnonzero(view[a:b] == 10))
            n_lines += len(pieces)
            a = b
        nl = np.concatenate(newlines) if newlines else np.zeros(0, np.int64)
        starts = np.concatenate([[begin], nl + 1])[:n_lines].astype(np.int64)
        stops = np.empty(n_lines, np.int64)
        ended = min(len(nl), n_lines)               # lines with a newline after them
        stops[:ended] = nl[:ended]
        if ended < n_lines:
            stops[ended:] = len(raw)
        cr = np.flatnonzero((view[np.maximum(stops[:ended] - 1, 0)] == 13)
                            & (stops[:ended] > starts[:ended]))
        stops[cr] -= 1
        lines = cls(raw, starts, stops, np.concatenate(content) if content else
                    np.zeros(0, bool))
        lines.long_field = long_line
        return lines

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
        return self.raw[self.starts[i]:self.stops[i]].decode("utf-8")

    def lines_at(self, indices) -> list[str]:
        raw, starts, stops = self.raw, self.starts[indices], self.stops[indices]
        if isinstance(raw, FileBytes) and len(starts):
            # one read of the stretch that holds them, when they lie close together
            a, b = int(starts.min()), int(stops.max())
            if b - a <= max(BLOCK, 4 * int((stops - starts).sum())):
                raw, starts, stops = raw[a:b], starts - a, stops - a
        return [raw[s:e].decode("utf-8") for s, e in zip(starts.tolist(), stops.tolist())]

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
                yield text.encode("utf-8") + eol
                at[1] = True

        k = 0
        for i, text in edits:
            while k < len(marks) and marks[k] < i:
                yield from marked(marks[k])
                k += 1
            if i in dropped:
                continue
            yield from upto(int(starts[i]))
            piece = text.encode("utf-8")
            if piece:
                at[1] = piece[-1] in (10, 13)
            yield piece
            at[0] = int(stops[i])
        while k < len(marks):
            yield from marked(marks[k])
            k += 1
        yield from upto(len(raw))
