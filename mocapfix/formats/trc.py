"""TRC marker files (Motion Analysis "Track Row Column", as OpenSim reads and writes them).

Layout (OpenSim 4 documentation, "Marker (.trc) Files", simtk-confluence.stanford.edu
/display/OpenSim/Marker+(.trc)+Files; the same as Motion Analysis Corp.'s exporters and
BTK's ``btkTRCFileIO``), tab separated::

    PathFileType  4  (X/Y/Z)  <file name>
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  OrigDataStartFrame  OrigNumFrames
    <the values of line 2, in the same order>
    Frame#  Time  <marker 1>  <tab> <tab>  <marker 2> ...
            <tab> X1  Y1  Z1  X2  Y2  Z2 ...
    [blank line]
    1  0.000  x  y  z  x  y  z ...

Reading (decisions):

* Header keys are matched by name, in any order; extra keys are kept, absent ones default
  (no ``Units``: mm, with a note, as BTK does); trailing tabs are ignored. The rate is
  ``DataRate`` (else ``CameraRate``); a rate that is not a positive finite number is an
  error naming line 3. ``Units`` ``mm``/``cm``/``m`` (any case, also ``millimeters`` ...)
  set ``units`` and ``metres_per_unit``; an unknown unit is refused.
* Markers are the non-empty labels of line 4 after ``Frame#`` and ``Time``, surrounding
  spaces stripped (BTK's rule; ``btk_Knee.trc`` has `` genou1_NewMarker3 ``); marker ``k``
  is in columns ``2 + 3k .. 4 + 3k``. ``NumMarkers`` differing from the labels is noted
  (the labels win, as in BTK). A file with ``NumMarkers 0`` and no labels reads as a motion
  with no markers.
* Missing samples are empty (or blank) fields, ``NaN``/``nan`` too (an infinite value,
  ``1e999``, is missing as well, with a note); a row shorter than
  the labelled columns (writers that trim trailing empty fields) is missing there. A
  sample with any of X, Y, Z missing is missing. Values in columns beyond the labelled
  markers (unlabelled trajectories some exporters append, e.g. ``btk_Gait.trc``) are not
  read: a note counts them; they are kept in ``source`` and written back untouched.
* ``times`` is the Time column; ``NumFrames`` differing from the rows is noted (the rows
  win). A last line without a line break that is shorter than the row before it is a
  truncation: dropped with a note (and not written back), as the Kinect reader does.
* The text is UTF-8 (with or without a byte-order mark) or, when it is not, latin-1 (a
  lab's accented marker names); lines end in LF, CRLF or a lone CR (old Mac OS software),
  mixed too.
* Any other malformation (a header line missing, a non-numeric value, no data rows) is
  one :class:`UnreadableFileError` naming the line and what was expected.

The file is held as its bytes and the offsets of its lines
(:class:`~mocapfix.formats.textlines.TextLines`); one over 64 MB is never held whole: it
is scanned and its rows decoded a block at a time, and read again when written
(:mod:`mocapfix.formats.filebytes`). Parsing is vectorised: CHUNK rows at a time are
split once and their value fields go through one ``numpy`` float conversion.

Writing:

(a) A motion read from a TRC file, with the same markers and frame count, is written back
    as the original text with only the changed samples re-formatted: a moved or filled
    sample gets the decimals of the token it replaces (a filled sample, whose fields were
    empty, the decimals most common in the file); a sample made missing gets empty fields.
    An unchanged motion writes back byte-identical (line endings, trailing tabs, spaces,
    a latin-1 file's bytes: edited rows are encoded as the file was).
(b) Any other motion (markers of a C3D, joint positions of a BVH/AMC/Kinect file) is
    written as a fresh OpenSim 4 TRC: the header above with ``DataRate = CameraRate =
    OrigDataRate = fps``, ``OrigDataStartFrame 1``, the motion's units, ``Frame#`` from 1,
    ``Time`` = ``times - times[0]`` (else ``i / fps``) printed ``%.6f``, positions printed
    ``%.5f`` (a precision of 5e-6 units: 5 nm in mm files), missing samples as empty
    fields -- never carried forward. Points whose ``kinds`` entry is not ``"marker"`` (C3D
    angles, forces, moments) are not written. Tabs and line breaks in names are replaced
    by spaces. What a conversion leaves out is named, never dropped silently:
    :func:`losses` (what a TRC cannot hold) and :func:`kept_only_here` (what only a TRC
    source holds: unlabelled columns) feed :func:`mocapfix.formats.losses`, which
    ``mocapfix convert`` prints.

Why hand-written: TRC is a small tab-separated text layout, and no package that reads it
keeps the text for a change-only write-back (docs/formats.md, "Why the readers are
hand-written"). OpenSim's reader is the tests' independent check of the files we write
(dev extra). Data rows are converted CHUNK at a time and files written in pieces, so
that no whole-file join, token list or str per line is built.
"""
from __future__ import annotations

import re
from collections import Counter
from dataclasses import dataclass, field
from itertools import chain
from pathlib import Path

import numpy as np

from mocapfix.core.errors import (
    UnreadableFileError,
    UnsupportedFeatureError,
    WriteError,
)
from mocapfix.core.fileio import write_output_pieces
from mocapfix.core.motion import Motion, missing_samples
from mocapfix.core.quantity import MAX_FRAME_RATE_HZ, MIN_FRAME_RATE_HZ
from mocapfix.core.units import METRES_PER_UNIT, normalise_unit_name
from mocapfix.formats.textlines import TextLines
from mocapfix.formats.texttable import samples_to_rewrite

NAME = "trc"
SUFFIXES = (".trc",)
#: what its points are (configs and rule files may name the family: ``formats: [markers]``)
FAMILY = "markers"
#: where its sniffer runs when the suffix does not tell (a fixed first word: strict)
SNIFF_ORDER = 1

#: decimals of the values of a fresh file
DECIMALS = 5
_HEADER_KEYS = ("DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units",
                "OrigDataRate", "OrigDataStartFrame", "OrigNumFrames")
#: a field of blanks only (a missing coordinate), between tabs
_BLANK_FIELD = re.compile(r"\t +(?=\t|\Z)")


@dataclass
class TRCSource:
    """What the writer needs to reproduce the file."""

    text: TextLines              # the file's bytes (a large file: read again) and its lines
    data_lines: np.ndarray       # (T,) index in ``text`` of each frame's row
    names: list[str]
    header: dict                 # key -> value text of lines 2-3
    original: np.ndarray         # (T, J, 3) values as read (NaN where missing)
    missing: np.ndarray          # (T, J) missing when read
    decimals: int                # the most common decimals of the file's values
    skip_lines: list[int] = field(default_factory=list)   # a truncated last fragment
    unlabelled_values: int = 0   # values beyond the labelled columns (kept, not read)


# ---------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------
def sniff(head: bytes) -> bool:
    return head.lstrip(b"\xef\xbb\xbf").startswith(b"PathFileType")


def _fields(line: str) -> list[str]:
    """Tab-separated fields of a header line, trailing empty ones dropped."""
    fields = line.split("\t")
    while fields and not fields[-1].strip():
        fields.pop()
    return fields


def _number(text: str, path, line: int, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise UnreadableFileError(path, f"{what} {text.strip()!r} is not a number", line=line) from None


def _header(lines: list[str], path, notes: list[str]) -> dict:
    if not lines[0].startswith("PathFileType"):
        raise UnreadableFileError(path, "not a TRC file: line 1 does not start with "
                                        "'PathFileType'", line=1)
    needed = ("the header keys (DataRate, CameraRate, NumFrames, ...)", "the header values",
              "the marker labels (Frame#, Time, ...)", "the coordinate labels (X1, Y1, Z1, ...)")
    for k, what in enumerate(needed):
        if len(lines) < k + 2:
            raise UnreadableFileError(path, f"file ends after line {k + 1}; expected {what} "
                                            f"on line {k + 2}")
    keys = [k.strip() for k in _fields(lines[1])]
    values = [v.strip() for v in _fields(lines[2])]
    if "DataRate" not in keys and "CameraRate" not in keys:
        raise UnreadableFileError(path, "no DataRate or CameraRate key on line 2", line=2)
    if len(values) < len(keys):
        notes.append(f"line 3 has {len(values)} header values for {len(keys)} keys; "
                     f"the last keys have none")
    return dict(zip(keys, values))


def _rate(header: dict, path) -> float:
    key = "DataRate" if header.get("DataRate") else "CameraRate"
    if not header.get(key):
        raise UnreadableFileError(path, "DataRate has no value (expected frames per second)",
                                  line=3)
    rate = _number(header.get(key, ""), path, 3, key)
    if not (MIN_FRAME_RATE_HZ <= rate <= MAX_FRAME_RATE_HZ):
        raise UnreadableFileError(path, f"{key} {header[key]} is not a frame rate (expected "
                                        f"a number of frames per second > 0)", line=3)
    return rate


def _count(header: dict, key: str, path) -> int | None:
    text = header.get(key, "")
    if not text:
        return None
    value = _number(text, path, 3, key)
    if not value.is_integer() or value < 0:
        raise UnreadableFileError(path, f"{key} {text} is not a count (expected a whole "
                                        f"number >= 0)", line=3)
    return int(value)


def _units(header: dict, path, notes: list[str]) -> str:
    text = header.get("Units", "")
    if not text:
        notes.append("no Units in the header: millimetres assumed (as BTK does)")
        return "mm"
    unit = normalise_unit_name(text)
    if unit is None or unit not in METRES_PER_UNIT:
        raise UnsupportedFeatureError(path, f"unknown Units {text!r} (expected mm, cm or m)", line=3)
    return unit


def _labels(line: str) -> list[str]:
    fields = line.split("\t")
    return [f.strip() for f in fields[2:] if f.strip()]


def _is_data_row(line: str) -> bool:
    first = line.split("\t", 1)[0].strip()
    try:
        float(first)
    except ValueError:
        return False
    return True


def _nan_for_empty(block: str) -> str:
    """``block`` (tab-separated fields) with every empty or blank field made ``nan``."""
    if " " in block:
        block = _BLANK_FIELD.sub("\t", block)
        if block.startswith(" ") and block.lstrip(" ").startswith("\t"):   # a blank first field
            block = block.lstrip(" ")
    block = block.replace("\t\t", "\tnan\t").replace("\t\t", "\tnan\t")
    if block.startswith("\t"):
        block = "nan" + block
    return block + "nan" if block.endswith("\t") else block


def _floats(block: str, count: int) -> np.ndarray | None:
    """The ``count`` fields of ``block`` as floats, or None if one is not a number."""
    try:
        out = np.array(_nan_for_empty(block).split("\t"), dtype=np.float64)
    except ValueError:
        return None
    return out if out.size == count else None


def _bad_token(rows, line_numbers, path) -> UnreadableFileError:
    for row, line_no in zip(rows, line_numbers):
        for token in row.split("\t"):
            try:
                float(token.strip() or "nan")
            except ValueError:
                return UnreadableFileError(path, f"{token.strip()[:40]!r} is not a number "
                                                 f"(expected a coordinate, or an empty field "
                                                 f"for a missing one)", line=line_no)
    return UnreadableFileError(path, "malformed data rows")


#: data rows converted at a time
CHUNK = 4096


def _table(text: TextLines, data_lines: np.ndarray, J: int, path) -> tuple[np.ndarray, int]:
    """(T, 2 + 3J) floats of the data rows (lines ``data_lines`` of ``text``; NaN where
    empty), and how many values lie beyond the labelled columns, decoded and converted
    CHUNK rows at a time. When every row has one number of fields, at least the labelled
    ones (most files), rows are converted as they are; else (found in any chunk) the rows
    are converted again from the first, each cut or padded to the labelled columns."""
    T, width = len(data_lines), 2 + 3 * J
    out = np.empty((T, width))
    extra, columns = 0, None
    for a in range(0, T, CHUNK):
        rows = text.lines_at(data_lines[a:a + CHUNK])
        tabs = {row.count("\t") for row in rows}
        n = tabs.pop() + 1 if len(tabs) == 1 else 0         # the rows' one field count
        if n < width or columns not in (None, n):
            break
        columns = n
        values = _floats("\t".join(rows), len(rows) * columns)
        if values is None:
            break
        values = values.reshape(len(rows), columns)
        out[a:a + len(rows)] = values[:, :width]
        extra += int(np.count_nonzero(~np.isnan(values[:, width:])))
    else:
        return out, extra
    extra = 0
    for a in range(0, T, CHUNK):
        rows = []
        for row in text.lines_at(data_lines[a:a + CHUNK]):
            f = row.split("\t")
            if len(f) < width:
                f += [""] * (width - len(f))
            elif len(f) > width:
                extra += sum(1 for v in f[width:] if v.strip())
            rows.append("\t".join(f[:width]))
        values = _floats("\t".join(rows), len(rows) * width)
        if values is None:
            rest = (r for b in range(a + CHUNK, T, CHUNK)
                    for row in text.lines_at(data_lines[b:b + CHUNK])
                    for r in ["\t".join((row.split("\t") + [""] * width)[:width])])
            raise _bad_token(chain(rows, rest), (data_lines[a:] + 1).tolist(), path)
        out[a:a + len(rows)] = values.reshape(len(rows), width)
    return out, extra


def read(path, fps: float | None = None, **options) -> Motion:
    """Read a TRC file (see the module docstring)."""
    path = Path(path)
    text = TextLines.read(path, "TRC", lone_cr=True, comments=False, fallback="latin-1")
    n_lines = len(text)
    head = text.lines_at(np.arange(min(n_lines, 5)))
    notes: list[str] = []
    header = _header(head, path, notes)
    rate = _rate(header, path)
    units = _units(header, path, notes)
    declared_markers = _count(header, "NumMarkers", path)
    declared_frames = _count(header, "NumFrames", path)
    names = _labels(head[3])
    J = len(names)
    if declared_markers is not None and declared_markers != J:
        notes.append(f"NumMarkers says {declared_markers} but line 4 labels {J} markers; "
                     f"the labels were read")
    first = 5 if n_lines > 4 and not _is_data_row(head[4]) else 4
    data_lines = first + np.flatnonzero(text.content[first:])     # the lines not blank
    skip: list[int] = []
    if len(data_lines) > 1 and data_lines[-1] == n_lines - 1 and text.end(n_lines - 1) == \
            text.stops[-1]:                                         # no line break after it
        last, before = text.lines_at(data_lines[-2:])[::-1]
        if len(last.split("\t")) < len(before.split("\t")):
            skip = [int(data_lines[-1])]
            data_lines = data_lines[:-1]
            notes.append(f"last line (line {skip[0] + 1}) is shorter than the one before and "
                         f"has no line break: the file looks truncated; that line was dropped")
    if not len(data_lines):
        raise UnreadableFileError(path, f"no data rows after the header (expected rows "
                                        f"'frame<TAB>time<TAB>x<TAB>y<TAB>z...' from line {first + 1})")
    T = len(data_lines)
    values, extra = _table(text, data_lines, J, path)
    decimals = _common_decimals(text, data_lines)
    text.keep(path)                 # parsed: a large file's bytes are read again when written
    times = values[:, 1].copy()
    if not np.isfinite(times).all():
        k = int(np.flatnonzero(~np.isfinite(times))[0])
        raise UnreadableFileError(path, "empty or non-finite Time (expected seconds in "
                                        "column 2)", line=int(data_lines[k]) + 1)
    positions = np.ascontiguousarray(values[:, 2:]).reshape(T, J, 3)
    del values
    infinite = np.isinf(positions).any(axis=2)
    if infinite.any():
        t, j = np.argwhere(infinite)[0]
        notes.append(f"{int(infinite.sum())} samples hold an infinite value (first: line "
                     f"{data_lines[t] + 1}, {names[j]}): read as missing")
    missing = missing_samples(positions) | infinite
    positions[missing] = np.nan
    if declared_frames is not None and declared_frames != T:
        notes.append(f"NumFrames says {declared_frames} but the file has {T} data rows; "
                     f"the rows were read")
    if extra:
        notes.append(f"{extra} values lie beyond the {J} labelled markers (unlabelled "
                     f"columns); they were not read and are written back unchanged")
    if T > 1 and not (np.diff(times) > 0).all():
        notes.append("the Time column does not increase on every row")
    source = TRCSource(text=text, data_lines=data_lines.astype(np.intp), names=list(names),
                       header=header, original=positions.copy(), missing=missing,
                       decimals=decimals, skip_lines=skip, unlabelled_values=extra)
    return Motion(positions, list(names), float(fps) if fps else rate, units=units,
                  metres_per_unit=METRES_PER_UNIT[units], format=NAME, times=times,
                  source=source, notes=notes)


def _common_decimals(text: TextLines, data_lines: np.ndarray, enough: int = 300) -> int:
    """The most common number of decimals among the first ``enough`` values of the rows
    (lines ``data_lines`` of ``text``)."""
    counts: Counter = Counter()
    for a in range(0, len(data_lines), 64):
        for row in text.lines_at(data_lines[a:a + 64]):
            counts.update(len(t) - t.index(".") - 1 for t in map(str.strip, row.split("\t")[2:])
                          if "." in t and "e" not in t.lower())
            if counts.total() >= enough:
                return counts.most_common(1)[0][0]
    return counts.most_common(1)[0][0] if counts else DECIMALS


# ---------------------------------------------------------------------------------------
# what a TRC cannot hold
# ---------------------------------------------------------------------------------------
def _markers(motion: Motion) -> np.ndarray:
    """Indices of the points a TRC file holds (every point unless ``kinds`` says)."""
    if motion.kinds is None:
        return np.arange(motion.n_joints)
    return np.array([j for j, k in enumerate(motion.kinds) if k == "marker"], dtype=np.intp)


def _clean_name(name: str, j: int) -> str:
    name = re.sub(r"[\t\r\n]", " ", str(name)).strip()
    return name or f"M{j + 1}"


def kept_only_here(motion: Motion) -> list[str]:
    """What of a motion read from a TRC file no other format carries: the values in
    columns beyond the labelled markers. For :func:`mocapfix.formats.losses`."""
    source = motion.source
    if isinstance(source, TRCSource) and source.unlabelled_values:
        note = f"{source.unlabelled_values} value(s) in unlabelled columns of the TRC file"
        return [f"{note} are not carried"]
    return []


def losses(motion: Motion) -> list[str]:
    """What a fresh TRC file changes or leaves out of ``motion``, one note each, beyond
    what :func:`mocapfix.formats.losses` already names (the source format's
    ``kept_only_here``: a C3D's analog channels, events and model outputs, a Kinect file's
    tracking states; the rotations of a rig): points that are not markers (of a motion not
    read from a C3D, whose own note names them), a unit TRC cannot name (converted to mm),
    and names with tabs, line breaks or surrounding blanks (changed)."""
    source = motion.source
    if isinstance(source, TRCSource) and _fits(source, motion):
        return []
    out = []
    if motion.kinds is not None and motion.format != "c3d":
        other = Counter(k for k in motion.kinds if k != "marker")
        if other:
            kinds = ", ".join(f"{n} {k}{'s' if n > 1 else ''}" for k, n in sorted(other.items()))
            out.append(f"{sum(other.values())} points that are not markers ({kinds}) are "
                       f"left out: a TRC file holds marker positions only")
    if motion.units not in METRES_PER_UNIT:
        out.append(f"positions are converted from the unit {motion.units!r} "
                   f"({motion.metres_per_unit:g} m) to mm: a TRC file names its unit")
    renamed = [motion.names[j] for j in _markers(motion).tolist()
               if _clean_name(motion.names[j], j) != motion.names[j]]
    if renamed:
        out.append(f"{len(renamed)} marker names with tabs, line breaks, surrounding blanks "
                   f"or no text are written changed: {', '.join(repr(n) for n in renamed[:5])}")
    return out


# ---------------------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------------------
def write(motion: Motion, path, **options) -> list[Path]:
    """Write ``motion`` as TRC (see the module docstring); returns ``[path]``."""
    path = Path(path)
    source = motion.source
    if isinstance(source, TRCSource) and _fits(source, motion):
        return write_output_pieces(path, _patched_pieces(source, motion))
    return write_output_pieces(path, _fresh_pieces(motion, path))


def _fits(source: TRCSource, motion: Motion) -> bool:
    return source.original.shape == motion.positions.shape and source.names == list(motion.names)


def _changed(source: TRCSource, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """(T, J) masks: samples whose fields must change, and samples missing now."""
    return samples_to_rewrite(source.original, motion.positions, source.missing,
                              infinite_missing=True)


def _patched_pieces(source: TRCSource, motion: Motion):
    """The file's bytes with the rows holding changed samples rewritten (CHUNK rows
    at a time) and a truncated last fragment left out, in pieces to write."""
    changed, now_missing = _changed(source, motion)
    rows = np.flatnonzero(changed.any(axis=1))

    def edits():
        for a in range(0, len(rows), CHUNK):
            at = source.data_lines[rows[a:a + CHUNK]]
            yield from zip(at.tolist(), _patched_rows(source, motion, rows[a:a + CHUNK], at,
                                                      changed, now_missing))
    return source.text.pieces(edits(), deleted=source.skip_lines)


def _patched_rows(source: TRCSource, motion: Motion, rows, at, changed, now_missing):
    """The new text of lines ``at``, the data rows of frames ``rows``."""
    J = motion.n_joints
    R, width = len(rows), 2 + 3 * J
    fields = [line.split("\t") for line in source.text.lines_at(at)]
    short = {}                              # trimmed rows: index -> their field count
    for k, f in enumerate(fields):
        if len(f) < width:
            short[k] = len(f)
            f += [""] * (width - len(f))
    cells = np.array(list(chain.from_iterable(f[2:width] for f in fields)),
                     dtype=object).reshape(R, J, 3)
    edit = changed[rows]
    gone = edit & now_missing[rows]
    moved = edit & ~gone
    if moved.any():
        new = _format_like(motion.positions[rows][moved].ravel(),
                           cells[moved].ravel().tolist(), source.decimals)
        cells[moved] = np.array(new, dtype=object).reshape(-1, 3)
    cells[gone] = ""
    out = []
    for k, f in enumerate(fields):
        values = cells[k].ravel().tolist()
        if k in short:                      # stays trimmed after its last value
            while len(values) > short[k] - 2 and values[-1] == "":
                values.pop()
        out.append("\t".join(f[:2] + values + f[width:]))
    return out


#: a character that no plain decimal number nor the tab between two has
_NOT_PLAIN = re.compile(r"[^0-9.+\t-]")


def _all_plain(old: list[str], decimals: int) -> bool:
    """True when every token of ``old`` (valid numbers, as read) is empty or a plain
    decimal number with ``decimals`` decimals: no blanks, exponents or ``nan``, one point
    in each non-empty token, followed by ``decimals`` digits."""
    joined = "\t".join(old)
    if _NOT_PLAIN.search(joined):
        return False
    points = joined.count(".")
    return (points == len(old) - old.count("")
            and len(re.findall(rf"\.[0-9]{{{decimals}}}(?![0-9])", joined)) == points)


def _format_like(values: np.ndarray, old: list[str], default: int) -> list[str]:
    """``values`` as text, each with the decimals of the token it replaces (``default``
    where that token was empty, a whole number or not plain decimal), blanks around the
    token kept. When every old token has ``default`` decimals or is empty (the usual
    file), one format call does them all."""
    if _all_plain(old, default):
        return ((f"%.{default}f\t" * len(values)) % tuple(values.tolist())).split("\t")[:-1]
    out = []
    for value, token in zip(values.tolist(), old):
        core = token.strip()
        dot = core.find(".")
        digits = core[dot + 1:] if dot >= 0 else ""
        text = f"{value:.{len(digits) if digits.isdigit() else default}f}"
        if core and core != token:
            start = token.index(core)
            text = token[:start] + text + token[start + len(core):]
        out.append(text)
    return out


def _written_units(motion: Motion, path) -> tuple[str, float]:
    """The unit name a fresh file states, and the factor from the motion's unit to it: the
    motion's own unit where TRC can name it, else millimetres (a BVH of unknown unit whose
    size the reader guessed)."""
    if motion.units in METRES_PER_UNIT:
        return motion.units, 1.0
    mpu = float(motion.metres_per_unit)
    if not (np.isfinite(mpu) and mpu > 0):
        raise WriteError(path, f"unit {motion.units!r} has no known size: a TRC file must "
                               f"state its unit")
    return "mm", mpu / METRES_PER_UNIT["mm"]


def _rate_text(fps: float) -> str:
    """``100.00`` as TRC writers print rates, or every digit where two decimals lose some."""
    return f"{fps:.2f}" if float(f"{fps:.2f}") == fps else repr(float(fps))


def _fresh_pieces(motion: Motion, path: Path):
    """A fresh OpenSim 4 TRC of ``motion`` (UTF-8), CHUNK rows a piece; its checks run
    before the first piece."""
    keep = _markers(motion)
    if len(keep) == 0:
        raise WriteError(path, "no markers to write: a TRC file holds marker positions")
    if not (np.isfinite(motion.fps) and motion.fps > 0):
        raise WriteError(path, f"frame rate {motion.fps} is not positive")
    names = [_clean_name(motion.names[j], int(j)) for j in keep]
    units, scale = _written_units(motion, path)
    T, J = motion.n_frames, len(keep)
    if motion.times is not None and len(motion.times) == T:
        times = np.asarray(motion.times, dtype=np.float64) - float(motion.times[0])
    else:
        times = np.arange(T) / motion.fps
    rate = _rate_text(motion.fps)
    head = [f"PathFileType\t4\t(X/Y/Z)\t{_clean_name(path.name, 0)}",
            "\t".join(_HEADER_KEYS),
            f"{rate}\t{rate}\t{T}\t{J}\t{units}\t{rate}\t1\t{T}",
            "Frame#\tTime\t" + "".join(f"{n}\t\t\t" for n in names),
            "\t\t" + "".join(f"X{k}\tY{k}\tZ{k}\t" for k in range(1, J + 1)),
            ""]
    return _fresh_rows(motion, keep, scale, times, "\n".join(head) + "\n")


def _fresh_rows(motion, keep, scale, times, head: str):
    yield head.encode("utf-8")
    J = len(keep)
    for a in range(0, motion.n_frames, CHUNK):
        pos = motion.positions[a:a + CHUNK, keep]
        pos = pos * scale if scale != 1.0 else pos
        T = len(pos)
        values = pos.reshape(T, 3 * J)
        gaps = ~np.isfinite(values)
        cells = (f"%.{DECIMALS}f\t" * values.size) % tuple(np.where(gaps, 0.0, values).ravel().tolist())
        cells = np.array(cells.split("\t")[:-1], dtype=object).reshape(T, 3 * J)
        cells[np.repeat(missing_samples(pos), 3, axis=1)] = ""
        stamps = (("%d\t%.6f\n" * T) % tuple(x for t in range(T)
                                             for x in (a + t + 1, times[a + t]))).split("\n")
        # every row ends with a tab, as Motion Analysis writes them: OpenSim's reader drops
        # one trailing empty field, so a row ending in a missing sample would lose a column
        yield "".join("\t".join([stamps[t]] + cells[t].tolist()) + "\t\n"
                      for t in range(T)).encode("utf-8")
