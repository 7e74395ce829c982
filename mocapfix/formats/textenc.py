"""Text encodings the text readers (BVH, ASF/AMC) do not read, named instead of being
reported as garbage.

The formats are ASCII in practice; UTF-8 (with or without a byte-order mark) and Latin-1
bytes in names are read. UTF-16 and UTF-32 (what some Windows editors and Excel's
"Unicode text" save) are recognised by their byte-order mark, or without one by the NUL
byte in every other (or every fourth) position of ASCII text, and refused with a message
saying how to convert the file.
"""
from __future__ import annotations

import re

import numpy as np

from mocapfix.core.errors import MAX_FIELD, UnreadableFileError, excerpt

UTF8_BOM = b"\xef\xbb\xbf"
_BOMS = (
    (b"\xff\xfe\x00\x00", "UTF-32 (little-endian)"),
    (b"\x00\x00\xfe\xff", "UTF-32 (big-endian)"),
    (b"\xff\xfe", "UTF-16 (little-endian)"),
    (b"\xfe\xff", "UTF-16 (big-endian)"),
)


def wide_encoding(data: bytes) -> str | None:
    """Name of the UTF-16/32 encoding ``data`` is in, or None."""
    for bom, name in _BOMS:
        if data.startswith(bom):
            return name
    head = data[:512]
    if len(head) >= 16 and head.count(0) >= len(head) // 3:
        for phase, name in ((1, "UTF-16 (little-endian, no byte-order mark)"),
                            (0, "UTF-16 (big-endian, no byte-order mark)")):
            zeros = head[phase::2]
            if zeros.count(0) >= 0.9 * len(zeros) and head[1 - phase::2].count(0) < 0.1 * len(zeros):
                return name
        if head[1::4].count(0) >= 0.9 * len(head[1::4]) and head[::4].count(0) < 0.1 * len(head[::4]):
            return "UTF-32 (little-endian, no byte-order mark)"
    return None


def refuse_wide_text(path, data: bytes, what: str) -> None:
    """Raise UnreadableFileError naming the encoding when ``data`` is UTF-16/32 text."""
    name = wide_encoding(data)
    if name is not None:
        raise UnreadableFileError(path, f"{what} file is {name} text; mocapfix reads ASCII/UTF-8 "
                                        f"{what}: save it as UTF-8 (e.g. iconv -f UTF-16 -t UTF-8)")


def refuse_long_fields(path, lines, first_line: int = 0) -> None:
    """An UnreadableFileError naming the line of a field (a number, a name) longer than
    :data:`~mocapfix.core.errors.MAX_FIELD` characters, quoting an excerpt: no text format
    has one, and a 5 MB "number" made the Kinect writer ask for a 211 GiB array. Only
    lines longer than that are split. ``first_line``: the index of ``lines[0]`` in the file."""
    for i, line in enumerate(lines):
        if len(line) > MAX_FIELD:
            long = next((t for t in _FIELD_SEP.split(line) if len(t) > MAX_FIELD), None)
            if long is not None:
                raise UnreadableFileError(path, f"a field longer than {MAX_FIELD:,} characters: "
                                                f"{excerpt(long)}", line=first_line + i + 1)


_FIELD_SEP = re.compile(r"[,;\t ]")
#: the bytes that end a field for :func:`refuse_long_fields`: its separators and the newline
_ENDS_FIELD = np.zeros(256, bool)
_ENDS_FIELD[[ord(c) for c in ",; \t\n"]] = True


def longest_field_bytes(raw, block: int = 1 << 22) -> int:
    """The most bytes in a row of ``raw`` (bytes, or a uint8 array) with no field
    separator or newline, looked at ``block`` bytes at a time: text where it is at most
    MAX_FIELD holds no field over MAX_FIELD characters (a character is a byte or more),
    so :func:`refuse_long_fields` need not split its lines (a 50,000-line TRC: 1.0 s)."""
    view = raw if isinstance(raw, np.ndarray) else np.frombuffer(raw, np.uint8)
    longest = run = 0                   # run: bytes since the last field end, across blocks
    for a in range(0, len(view), block):
        ends = np.flatnonzero(_ENDS_FIELD[view[a:a + block]])
        size = min(block, len(view) - a)
        if not len(ends):
            run += size
            longest = max(longest, run)
            continue
        longest = max(longest, run + int(ends[0]), int(np.diff(ends).max(initial=1)) - 1)
        run = size - 1 - int(ends[-1])
        longest = max(longest, run)
    return longest
