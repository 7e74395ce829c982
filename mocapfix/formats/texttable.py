"""Shared pieces of the vendor marker-table readers and writers (Vicon Nexus CSV, Qualisys
QTM TSV, OptiTrack Motive CSV): one row of text per frame, one separator character, the X, Y,
Z of each marker in three fixed columns.

What is shared: the file held once, as its bytes with the offsets of its lines, a file
over 64 MB read a block at a time, never whole (the readers open it with
:meth:`TextLines.read <mocapfix.formats.textlines.TextLines.read>`: UTF-8 with an optional
byte-order mark; UTF-16/32, undecodable bytes and fields over MAX_FIELD named and
refused), the vectorised parse of the data rows (:func:`parse_rows`: CHUNK rows at a time,
one ``split`` of the joined chunk and one numpy conversion, straight into the marker array;
a row with the wrong number of fields, a non-numeric value or a huge field is one
:class:`UnreadableFileError` naming its line), the source kept for writing back
(:class:`TableSource`), the write-back that re-formats only the changed samples
(:func:`patched_pieces`: with the decimals of the token they replace, the other bytes
copied from the source as slices; an unchanged motion writes back byte-identical),
fresh-table formatting (:func:`table_pieces`, CHUNK rows a piece) and the notes of what a
layout cannot carry (:func:`common_losses`).

Why lines are not ``str`` objects: one Python string per line, the joined block and one
string per field made a 50,000-frame take cost about 340 bytes a sample beyond its arrays
(issue 39); now only CHUNK rows are ever decoded at a time, and the write-back streams the
source's bytes to the output file.

Not a format module (no ``NAME``): the registry does not list it.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapfix.core.errors import UnreadableFileError
from mocapfix.core.fileio import write_output_pieces
from mocapfix.core.motion import Motion, missing_samples
from mocapfix.core.quantity import MAX_FRAME_RATE_HZ, MIN_FRAME_RATE_HZ
from mocapfix.formats.textenc import wide_encoding
from mocapfix.formats import textlines
from mocapfix.formats.textlines import TextLines

#: data rows decoded and converted at a time: their fields are Python strings only while
#: they are parsed or rewritten
CHUNK = 4096

#: the longest field quoted in a message
_QUOTE = 40
_NUMBER = re.compile(r"^\s*[+-]?(\d+\.?\d*([eE][+-]?\d+)?|\.\d+([eE][+-]?\d+)?|nan|inf)\s*$",
                     re.IGNORECASE)


def quote(token: str) -> str:
    """``token`` for a one-line message: shortened, control characters shown as ``?``."""
    token = "".join(c if c.isprintable() else "?" for c in token[:_QUOTE + 1])
    return repr(token if len(token) <= _QUOTE else token[:_QUOTE] + "...")


def first_line(text: TextLines, start: int, test) -> int:
    """Index of the first line at or after ``start`` for which ``test(line)`` is true, or
    ``len(text)``; lines are decoded CHUNK at a time, never all at once."""
    for a in range(start, len(text), CHUNK):
        for i, line in enumerate(text.lines_at(np.arange(a, min(a + CHUNK, len(text)))), a):
            if test(line):
                return i
    return len(text)


def lines_holding(text: TextLines, word: str) -> list[int]:
    """Indices of the lines in which ``word`` (ASCII, no line break) occurs: a search of
    the bytes, so that looking for a rare word (a section name) decodes no line."""
    found = find_all(text.raw, word.encode("ascii"), 0, len(text.raw))
    lines = np.searchsorted(text.starts, np.asarray(found, np.int64), side="right") - 1
    return sorted(set(lines[lines >= 0].tolist()))


def find_all(raw, needle: bytes, start: int, stop: int, first: bool = False) -> list[int]:
    """Offsets of every occurrence of ``needle`` in ``raw[start:stop]`` (bytes or a
    FileView; ``first``: the first one only), read a block at a time (each with the
    ``len(needle) - 1`` bytes after it, so that no occurrence across two is missed)."""
    found, size = [], textlines.BLOCK
    for a in range(start, stop, size):
        block = raw[a:min(a + size + len(needle) - 1, stop)]
        at = block.find(needle)
        while 0 <= at < size:
            found.append(a + at)
            if first:
                return found
            at = block.find(needle, at + 1)
    return found


def head_lines(head: bytes, n: int = 12) -> list[str]:
    """The first ``n`` complete lines of a file's first bytes (for sniffers), without line
    endings or byte-order mark."""
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff")
    lines = text.split("\n")
    if len(head) >= 4096 and len(lines) > 1:
        lines = lines[:-1]  # cut mid-line
    return [ln.rstrip("\r") for ln in lines[:n]]


def not_text(head: bytes) -> str | None:
    """Why ``head`` (a file's first bytes) is not UTF-8 text -- UTF-16/32, or the offset of
    an undecodable byte -- or None (a multi-byte character cut at the end is allowed)."""
    wide = wide_encoding(head)
    if wide is not None:
        return (f"text table is {wide} text; mocapfix reads ASCII/UTF-8 text tables: save it "
                "as UTF-8 (e.g. iconv -f UTF-16 -t UTF-8)")
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:
        if not (exc.start >= len(head) - 3 and len(head) >= 4096):
            return f"not a text file (undecodable byte at offset {exc.start})"
    return None


def unknown_layout(head: bytes) -> str:
    """The registry's reason for a text file no sniffer accepts."""
    lines = [ln for ln in head_lines(head, 50) if ln.strip()] or [""]
    return f"not a known layout (first line: {lines[0][:60]!r})"


def fields_of(line: str, sep: str) -> list[str]:
    """``line`` split at ``sep``, trailing empty fields dropped (spreadsheets pad rows)."""
    fields = line.split(sep)
    while fields and not fields[-1].strip():
        fields.pop()
    return fields


def max_decimals(tokens, default: int = 3) -> int:
    """The most decimals of a number among ``tokens`` (how a file writes numbers)."""
    return max([len(t) - t.index(".") - 1 for t in tokens if "." in t] or [default])


def positive_rate(path, token: str, line: int, what: str) -> float:
    """A frame rate read from ``token``: finite, in the accepted range, else an error."""
    try:
        rate = float(token)
    except ValueError:
        raise UnreadableFileError(path, f"{what} {quote(token)} is not a number", line=line) from None
    if not (np.isfinite(rate) and MIN_FRAME_RATE_HZ <= rate <= MAX_FRAME_RATE_HZ):
        raise UnreadableFileError(path, f"{what} {token.strip()} Hz is not a usable frame rate "
                                        f"(expected {MIN_FRAME_RATE_HZ:g} to "
                                        f"{MAX_FRAME_RATE_HZ:g} Hz)", line=line)
    return rate


# ---------------------------------------------------------------------------------------
# the vectorised row parse
# ---------------------------------------------------------------------------------------
def parse_rows(path, text: TextLines, first: int, stop: int, sep: str, n_fields: int,
               cols: np.ndarray, lead: int, what: str,
               missing_tokens=("",)) -> tuple[np.ndarray, np.ndarray]:
    """The fields ``cols`` of lines ``first`` .. ``stop - 1``, each of which must hold
    ``n_fields`` fields (one more, empty, is taken as a trailing separator), as float64:
    (n, lead) of the first ``lead`` columns and (n, len(cols) - lead) of the rest, each
    contiguous (the marker columns become the positions without a copy).
    ``missing_tokens`` read as NaN.

    Every row's field count is checked before any value is converted, so a file with both
    faults is refused for the same one as when the rows were parsed in one block."""
    n = stop - first
    trim = _trailing_separators(path, text, first, stop, sep, n_fields, what)
    keys, values = np.empty((n, lead)), np.empty((n, len(cols) - lead))
    for a in range(first, stop, CHUNK):
        b = min(stop, a + CHUNK)
        lines = text.lines_at(np.arange(a, b))
        for k in np.flatnonzero(trim[a - first:b - first]).tolist():
            lines[k] = lines[k][:-1]
        got = _parse_chunk(path, lines, a, first, sep, n_fields, cols, what, missing_tokens)
        keys[a - first:b - first], values[a - first:b - first] = got[:, :lead], got[:, lead:]
    return keys, values


def _trailing_separators(path, text: TextLines, first: int, stop: int, sep: str,
                         n_fields: int, what: str) -> np.ndarray:
    """(n,) True for the rows of lines ``first`` .. ``stop - 1`` that hold one field too
    many, the last empty (a trailing separator, dropped); an UnreadableFileError for the
    first row holding another count. Counted in the bytes: no line is decoded."""
    n, mark = stop - first, sep.encode("ascii")
    counts, last = np.empty(n, np.int64), np.zeros(n, np.uint8)
    for a in range(first, stop, CHUNK):         # a stretch of lines read at a time
        b = min(stop, a + CHUNK)
        base = int(text.starts[a])
        chunk = text.raw[base:int(text.stops[b - 1])]
        starts, stops = text.starts[a:b] - base, text.stops[a:b] - base
        counts[a - first:b - first] = np.fromiter(
            (chunk.count(mark, s, e) for s, e in zip(starts.tolist(), stops.tolist())),
            np.int64, b - a) + 1
        # each line's last byte (0 for an empty line): a trailing separator?
        view = np.frombuffer(chunk, np.uint8)
        if view.size:                           # (a stretch of empty lines has no bytes)
            last[a - first:b - first] = np.where(stops > starts, view[np.maximum(stops - 1, 0)], 0)
    trim = np.zeros(n, bool)
    if (counts != n_fields).any():
        extra = np.flatnonzero(counts == n_fields + 1)
        trim[extra] = last[extra] == mark[0]
        counts[trim] -= 1
        bad = np.flatnonzero(counts != n_fields)
        if len(bad):
            k = int(bad[0])
            tail = " (the file looks truncated)" if k == n - 1 and counts[k] < n_fields else ""
            raise UnreadableFileError(path, f"{counts[k]} fields where {n_fields} were expected "
                                            f"({what}){tail}", line=first + k + 1)
    return trim


def _parse_chunk(path, lines: list[str], first: int, block_first: int, sep: str, n_fields: int,
                 cols: np.ndarray, what: str, missing_tokens) -> np.ndarray:
    """(n, len(cols)) float64 of the fields ``cols`` of ``lines`` (the file's lines
    ``first``, ``first + 1``, ...; each holds ``n_fields`` fields) -- one ``split`` and one
    conversion when every field is a number; else the columns wanted, and an error naming
    the first that is not (``block_first``: the first line of the rows being read)."""
    n = len(lines)
    joined = sep.join(lines)   # rows of equal width: one split gives the (n, n_fields) grid
    if "" in missing_tokens:   # empty fields -> "nan" by two passes of a C-level replace
        double, filled = sep + sep, sep + "nan" + sep
        joined = joined.replace(double, filled).replace(double, filled)
        joined = ("nan" if joined.startswith(sep) else "") + joined + (
            "nan" if joined.endswith(sep) else "")
    try:                       # fast path: every field of the block is a number
        return np.array(joined.split(sep), dtype=np.float64).reshape(n, n_fields)[:, cols]
    except ValueError:         # a word somewhere (a time code column, or a bad value)
        pass
    tokens = np.array(sep.join(lines).split(sep), dtype=object).reshape(n, n_fields)[:, cols]
    for token in missing_tokens:
        tokens[tokens == token] = "nan"
    try:
        return tokens.astype(np.float64)
    except (ValueError, TypeError):
        for (r, c), token in np.ndenumerate(tokens):
            if len(token) > 64 or not _NUMBER.match(token):   # (no regex over a huge field)
                raise UnreadableFileError(path, f"{quote(token)} is not a number (column "
                                                f"{int(cols[c]) + 1} of {what})",
                                          line=first + r + 1) from None
        raise UnreadableFileError(path, f"non-numeric value in {what}",
                                  line=block_first + 1) from None


def markers(values: np.ndarray, notes: list[str]) -> np.ndarray:
    """(T, J, 3) positions from the parsed marker columns (reshaped in place: no copy); a
    sample with any coordinate empty, nan or inf is missing (all three NaN; the odd ones
    noted)."""
    positions = values.reshape(len(values), -1, 3)
    bad = ~np.isfinite(positions).all(axis=2)
    odd = bad & ~np.isnan(positions).all(axis=2)
    if odd.any():
        notes.append(f"{int(odd.sum())} samples with an inf or partly empty coordinate read "
                     "as missing")
    positions[bad] = np.nan
    return positions


def key_column(path, column: np.ndarray, first: int, what: str) -> np.ndarray:
    """A Frame or Time column: every value present and finite, else an error naming the row."""
    bad = ~np.isfinite(column)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise UnreadableFileError(path, f"{what} is empty or not finite", line=first + k + 1)
    return column


def block_end(text: TextLines, start: int, sep: str) -> int:
    """Index of the first blank line (nothing but separators and spaces) at or after
    ``start``, or ``len(text)``."""
    strip = sep + " \t"
    return first_line(text, start, lambda line: not line.strip(strip))


def frame_times(frames: np.ndarray, fps: float, notes: list[str]) -> np.ndarray:
    """Times in seconds from frame numbers; a non-consecutive numbering is noted."""
    steps = np.diff(frames)
    if len(steps) and not np.all(steps == steps[0]):
        notes.append(f"frame numbers are not evenly spaced ({int(np.sum(steps != 1))} "
                     "irregular steps): times follow the numbers")
    return (frames - frames[0]) / fps if len(frames) else frames


# ---------------------------------------------------------------------------------------
# writing back
# ---------------------------------------------------------------------------------------
@dataclass
class TableSource:
    """What a vendor-table writer needs to reproduce the file it was read from."""

    layout: str                  # "nexus_csv", "qtm_tsv", "motive_csv"
    text: TextLines              # the file's bytes and the offsets of its lines
    sep: str
    names: list[str]
    row_line: np.ndarray         # (T,) line index of each frame's row
    x_field: np.ndarray          # (J,) field index of each marker's X (Y, Z follow)
    original: np.ndarray         # (T, J, 3) as read (NaN: missing)
    missing_token: str           # what the layout writes for each coordinate of a missing sample
    decimals: int                # decimals of a number written where the file had none
    extra: dict = field(default_factory=dict)


def fits(source, motion: Motion, layout: str) -> bool:
    """``motion`` can be written by patching the file it came from."""
    return (isinstance(source, TableSource) and source.layout == layout
            and source.original.shape == motion.positions.shape
            and source.names == list(motion.names))


def format_like(value: float, token: str, decimals: int) -> str:
    """``value`` with as many decimals as ``token`` had (``decimals`` when it had none, or
    was a missing marker); exponent notation kept."""
    t = token.strip()
    if "e" in t.lower() and any(ch.isdigit() for ch in t):
        return f"{value:.9g}"
    dot = t.find(".")
    d = len(t) - dot - 1 if dot >= 0 and t.lower() != "nan" else decimals
    return f"{value:.{d}f}"


def changed_samples(source: TableSource, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, J) masks: the samples whose tokens must change, and the samples now missing."""
    return samples_to_rewrite(source.original, positions)


def samples_to_rewrite(original, positions: np.ndarray, was_missing: np.ndarray | None = None,
                       infinite_missing: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(T, J) masks of a text file's samples when ``positions`` are written over the
    coordinates it held (``original``): those whose tokens must change (filled, moved or
    removed), and those missing now (a NaN coordinate; with ``infinite_missing``, any
    coordinate not finite). ``was_missing``: the file's missing samples (default: a NaN
    in ``original``). A chunk of frames at a time: ``original`` may be kept on disk
    (:mod:`mocapfix.core.diskarray`), and the whole-take comparison made (T, J, 3)
    temporaries."""
    T, J = positions.shape[:2]
    changed, now_missing = np.empty((T, J), bool), np.empty((T, J), bool)
    for a in range(0, T, REWRITE_CHUNK):
        rows = slice(a, a + REWRITE_CHUNK)
        new, old = positions[rows], np.asarray(original[rows])
        now = ~np.isfinite(new).all(axis=2) if infinite_missing else missing_samples(new)
        was = missing_samples(old) if was_missing is None else was_missing[rows]
        same = np.all(new == old, axis=2)
        changed[rows] = np.where(was, ~now, ~same | now)
        now_missing[rows] = now
    return changed, now_missing


#: frames compared at a time by :func:`samples_to_rewrite`
REWRITE_CHUNK = 16384


def patched_pieces(source: TableSource, motion: Motion):
    """The source's bytes with the changed samples' tokens rewritten (moved and filled:
    numbers with the replaced tokens' decimals; removed: the layout's missing token),
    in pieces: every other byte is a slice of the source."""
    changed, now_missing = changed_samples(source, motion.positions)
    rows = np.flatnonzero(changed.any(axis=1))
    return _gathered(source.text.pieces(_patched_rows(source, motion, rows, changed, now_missing)))


def _gathered(pieces, size: int = 1 << 20):
    """``pieces`` with the small ones joined into runs of about ``size`` bytes: a smoother
    rewrites every row, and two writes a row (the slice before it, its new text) cost
    more than the one join the whole-text writer made; a large slice passes uncopied."""
    run, held = [], 0
    for piece in pieces:
        if len(piece) >= size:
            if run:
                yield b"".join(run)
                run, held = [], 0
            yield piece
            continue
        run.append(piece)
        held += len(piece)
        if held >= size:
            yield b"".join(run)
            run, held = [], 0
    if run:
        yield b"".join(run)


def _patched_rows(source: TableSource, motion: Motion, rows, changed, now_missing):
    """(line, new text) of the rows of frames ``rows``, decoded CHUNK rows at a time."""
    sep = source.sep
    for a in range(0, len(rows), CHUNK):
        frames = rows[a:a + CHUNK]
        at = source.row_line[frames]
        for t, li, line in zip(frames.tolist(), at.tolist(), source.text.lines_at(at)):
            fields = line.split(sep)
            for j in np.flatnonzero(changed[t]).tolist():
                f0 = int(source.x_field[j])
                if now_missing[t, j]:
                    fields[f0:f0 + 3] = [source.missing_token] * 3
                else:
                    for k, v in enumerate(motion.positions[t, j].tolist()):
                        fields[f0 + k] = format_like(v, fields[f0 + k], source.decimals)
            yield li, sep.join(fields)


def written_unit(motion: Motion, units) -> tuple[str, float]:
    """(unit, factor from the motion's unit to it) for a fresh file whose layout names one
    of ``units`` (length-unit names, first the fallback): the motion's own unit when the
    layout can name it, else ``units[0]`` -- the numbers converted, never relabelled."""
    from mocapfix.core.units import METRES_PER_UNIT

    unit = motion.units if motion.units in units else units[0]
    return unit, motion.metres_per_unit / METRES_PER_UNIT[unit]


def number_cells(values: np.ndarray, fmt: str, missing: str) -> np.ndarray:
    """(T, K) object array of formatted numbers, ``missing`` where NaN."""
    cells = np.char.mod(fmt, np.nan_to_num(values)).astype(object)
    cells[np.isnan(values)] = missing
    return cells


def table_pieces(head: list[str], keys: list[str], motion: Motion, factor: float, sep: str,
                 fmt: str):
    """A fresh table, UTF-8, CHUNK rows a piece: the ``head`` lines, then one row per
    frame -- its key fields (``keys[t]``: frame and time, already joined by ``sep``) and
    the motion's positions times ``factor`` formatted with ``fmt``, empty where NaN --
    each line ending in ``\n``."""
    yield ("\n".join(head) + "\n").encode("utf-8")
    T, J = motion.n_frames, motion.n_joints
    for a in range(0, T, CHUNK):
        chunk = motion.positions[a:a + CHUNK]
        values = chunk.reshape(len(chunk), 3 * J) * factor
        cells = number_cells(values, fmt, "")
        yield "".join(keys[t] + sep + sep.join(row) + "\n"
                      for t, row in enumerate(cells.tolist(), a)).encode("utf-8")


def write_table(motion: Motion, path, layout: str, fresh) -> list[Path]:
    """Write ``motion``: its source patched when it came from ``layout`` and fits, else
    the pieces of ``fresh(motion, path)``."""
    if fits(motion.source, motion, layout):
        return write_output_pieces(path, patched_pieces(motion.source, motion))
    return write_output_pieces(path, fresh(motion, Path(path)))


def common_losses(motion: Motion, layout: str) -> list[str]:
    """What no vendor marker table can hold of ``motion`` (read in another format; what
    only its own format keeps — rotations, tracking states, analog channels — is named by
    that format: :func:`mocapfix.formats.losses`)."""
    out = []
    if motion.skeleton is not None and motion.channels is None:
        out.append(f"{layout} stores no skeleton (bone hierarchy): dropped")
    if motion.kinds is not None and any(k != "marker" for k in motion.kinds):
        out.append(f"{layout} has no place for point kinds: model outputs are written as "
                   "marker trajectories")
    if motion.times is not None and len(motion.times) > 2:
        steps = np.diff(np.asarray(motion.times, dtype=np.float64))
        if np.ptp(steps) > 1e-3 * max(float(np.median(steps)), 1e-12):
            out.append(f"{layout} rows are evenly spaced: the irregular time stamps are "
                       f"replaced by frames at {motion.fps:g} Hz")
    return out


def kept_verbatim(motion: Motion, layout: str, what: str) -> list[str]:
    """What a motion read from ``layout`` holds besides its markers (``what``: "Devices,
    Model Outputs sections"), which its own layout writes back as read and no other
    format carries: the note for :func:`mocapfix.formats.losses` (``kept_only_here``)."""
    source = motion.source
    if not (isinstance(source, TableSource) and source.layout == layout and what):
        return []
    return [f"{what} are not carried (only a {layout} holds them)"]
