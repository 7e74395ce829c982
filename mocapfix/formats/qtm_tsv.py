"""Qualisys Track Manager TSV exports of 3D data (File > Export > To TSV).

Layout (QTM user manual, "Export to TSV format" / "3D data in TSV"; a real export is
``tests/data/vendor/qtm_hand_embodiment_recording.tsv``): tab-separated; a header of
``KEY<TAB>value...`` lines -- ``NO_OF_FRAMES``, ``NO_OF_CAMERAS``, ``NO_OF_MARKERS``,
``FREQUENCY``, ``NO_OF_ANALOG``, ``ANALOG_FREQUENCY``, ``DESCRIPTION``, ``TIME_STAMP``,
``DATA_INCLUDED<TAB>3D``, ``MARKER_NAMES<TAB>name<TAB>name...``, optionally
``TRAJECTORY_TYPES`` and ``EVENT`` lines -- then

* newer QTM (``Write column header`` on): a row ``Frame<TAB>Time<TAB>name X<TAB>name Y<TAB>
  name Z...`` then rows ``frame<TAB>time<TAB>x<TAB>y<TAB>z...``;
* older QTM (no column header): the rows directly, ``x y z`` per marker, with or without
  leading frame and time columns (``Export time data for every frame``).

Missing samples (decision): in the headed (newer) layout an empty field or ``NaN`` is
missing and an exact ``0, 0, 0`` triple is read as a position (a note counts them; pass
``zero_missing=True`` to read them as missing); in the older layout without a column
header, whose QTM versions wrote gaps as zeros, an exact ``0, 0, 0`` triple is missing
(``zero_missing=False`` turns that off). Writing back uses the file's own representation
(zeros with the file's decimals, ``NaN``, or empty fields).

Reading: names from ``MARKER_NAMES`` (as written), ``fps`` from ``FREQUENCY`` (``EXT``,
which QTM writes for an external timebase in edge triggered mode: frames per second between
the first and last rows' Frame and Time, noted; without those columns refused), units mm
(QTM exports 3D data in millimetres), ``times`` from the Time column or the frame count.
``NO_OF_MARKERS`` must equal the number of names; a ``NO_OF_FRAMES`` that differs from the
rows present is noted. Columns the column header names after the markers' X, Y, Z are not
read (noted; kept as read and written back unchanged); rows without them are read too.
Every other header line is kept verbatim for writing back. Malformations are one UnreadableFileError naming the line.

Why hand-written: the layout is a plain table behind a key/value header; no dependency
reads it and writes it back unchanged. The file is held once, as its bytes with the offsets
of its lines; the rows are parsed CHUNK at a time, vectorised, and written back as slices
of those bytes between the rewritten rows (:mod:`mocapfix.formats.texttable`).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from mocapfix.core.errors import UnreadableFileError
from mocapfix.formats.textlines import TextLines
from mocapfix.core.motion import Motion
from mocapfix.formats import texttable as tt

NAME = "qtm_tsv"
SUFFIXES = (".tsv",)
#: what its points are (configs and rule files may name the family: ``formats: [markers]``)
FAMILY = "markers"
SNIFF_ORDER = 1

LAYOUT = "qtm_tsv"
_KEY = re.compile(r"^[A-Z][A-Z0-9_]*$")
#: the header keys this reader needs
_REQUIRED = ("NO_OF_FRAMES", "NO_OF_MARKERS", "FREQUENCY", "MARKER_NAMES")
#: what a data row holds for a missing coordinate
_MISSING = ("", "NaN", "nan")


def sniff(head: bytes) -> bool:
    """The first line is ``NO_OF_FRAMES<TAB>n`` (or ``FILE_VERSION``, then it) and a
    ``MARKER_NAMES`` or ``NO_OF_MARKERS`` key follows."""
    lines = tt.head_lines(head, 40)
    keys = [ln.split("\t", 1)[0] for ln in lines if "\t" in ln]
    if not keys:
        return False
    first = 1 if keys[0] == "FILE_VERSION" else 0
    return (len(keys) > first and keys[first] == "NO_OF_FRAMES"
            and ("NO_OF_MARKERS" in keys or "MARKER_NAMES" in keys))


def read(path, fps: float | None = None, units: str | None = None,
         zero_missing: bool | None = None, default_fps: float | None = None,
         **options) -> Motion:
    path = Path(path)
    text = TextLines.read(path, "QTM TSV")
    header, i = _header(text)
    for key in _REQUIRED:
        if key not in header:
            raise UnreadableFileError(path, f"QTM TSV header has no {key} line (expected "
                                            f"NO_OF_FRAMES, NO_OF_MARKERS, FREQUENCY, "
                                            "MARKER_NAMES before the data)", line=i + 1)
    notes: list[str] = []
    rate_line, rate_fields = header["FREQUENCY"]
    token = (rate_fields or [""])[0]
    external = token.strip().upper() == "EXT"   # external timebase, edge triggered: no rate
    rate = None if external else tt.positive_rate(path, token, rate_line + 1, "FREQUENCY")
    names_line, names = header["MARKER_NAMES"]
    names = [n for n in names]
    while names and not names[-1].strip():
        names.pop()
    J = len(names)
    count = _count(path, header, "NO_OF_MARKERS")
    if count != J:
        raise UnreadableFileError(path, f"NO_OF_MARKERS says {count} but MARKER_NAMES lists {J}",
                                  line=header["NO_OF_MARKERS"][0] + 1)
    if J == 0:
        raise UnreadableFileError(path, "MARKER_NAMES lists no marker", line=names_line + 1)
    included = header.get("DATA_INCLUDED", (0, ["3D"]))[1]
    if included and included[0].strip() != "3D":
        raise UnreadableFileError(path, f"DATA_INCLUDED is {tt.quote(included[0])}: only 3D "
                                        "marker exports are read", line=header["DATA_INCLUDED"][0] + 1)
    headed = i < len(text) and text.line(i).split("\t", 1)[0] == "Frame"
    column_line = i if headed else None
    first = tt.first_line(text, i + 1 if headed else i, str.strip)
    stop = tt.block_end(text, first, "\t")
    if stop == first:
        raise UnreadableFileError(path, "QTM TSV holds no data rows", line=first + 1)
    resumed = tt.first_line(text, stop, str.strip)
    if resumed < len(text):
        raise UnreadableFileError(path, "data rows resume after a blank line (expected one "
                                        "block of rows)", line=resumed + 1)
    first_row = text.line(first)
    if headed:
        columns = tt.fields_of(text.line(column_line), "\t")
        expected = ["Frame", "Time"] + [f"{n} {a}" for n in names for a in "XYZ"]
        if columns[:2 + 3 * J] != expected:
            bad = next(k for k, (a, b) in enumerate(zip(columns + [""] * len(expected), expected))
                       if a != b)
            raise UnreadableFileError(path, f"column {bad + 1} of the column header is "
                                            f"{tt.quote(columns[bad] if bad < len(columns) else '')}"
                                            f", expected {expected[bad]!r}", line=column_line + 1)
        lead, n_fields = 2, len(columns)
        beyond = columns[2 + 3 * J:]
    else:
        width = first_row.rstrip("\t").count("\t") + 1
        lead = 2 if width == 2 + 3 * J else 0
        n_fields, beyond = lead + 3 * J, []
    cols = np.arange(lead + 3 * J)
    keys, flat = _rows(path, text, first, stop, n_fields, cols, lead)
    if beyond:
        many = len(beyond) > 1
        notes.append(f"{len(beyond)} column{'s' if many else ''} after the markers "
                     f"({tt.quote(beyond[0])}{', ...' if many else ''}) not read: kept as read")
    T = len(flat)
    positions = tt.markers(flat, notes)
    zeros = np.all(positions == 0.0, axis=2)
    as_missing = (not headed) if zero_missing is None else bool(zero_missing)
    decimals = tt.max_decimals(first_row.split("\t")[lead:lead + 3 * J])
    token = _missing_token(text, first, stop, as_missing, decimals)
    if zeros.any():
        if as_missing:
            positions[zeros] = np.nan
            notes.append(f"{int(zeros.sum())} samples are exactly (0, 0, 0): read as missing "
                         "(the QTM layout without a column header writes gaps as zeros)")
        else:
            notes.append(f"{int(zeros.sum())} samples are exactly (0, 0, 0): kept as positions "
                         "(pass zero_missing=True if this QTM version wrote gaps as zeros)")
    declared = _count(path, header, "NO_OF_FRAMES")
    if declared != T:
        notes.append(f"NO_OF_FRAMES says {declared} but the file holds {T} rows")
    if lead:
        times = tt.key_column(path, keys[:, 1], first, "Time") - keys[0, 1]
    assumed = False
    if fps is not None:
        rate = float(fps)
    elif external and not lead and default_fps is not None:
        # the command line's --fps: the rate of a file that stores none
        rate, assumed = float(default_fps), True
        notes.append(f"FREQUENCY is EXT (external timebase) and the file has no Frame and Time "
                     f"columns: {rate:g} Hz (--fps) used")
    elif external:
        rate = _time_rate(path, keys if lead else None, rate_line + 1, notes)
    if not lead:
        times = np.arange(T) / rate
    text.keep(path)                 # parsed: a large file is read again when written
    source = tt.TableSource(
        layout=LAYOUT, text=text, sep="\t", names=names,
        row_line=np.arange(first, stop), x_field=lead + 3 * np.arange(J),
        original=positions.copy(), missing_token=token,
        decimals=decimals, extra={"headed": headed, "zero_missing": as_missing,
                                  **({"rate_assumed": True} if assumed else {})})
    return Motion(positions, names, rate, units="mm", metres_per_unit=0.001, times=times,
                  source=source, notes=notes, kinds=["marker"] * J)


def _rows(path, text, first: int, stop: int, n_fields: int, cols: np.ndarray, lead: int):
    """(keys, marker columns) of the data rows: ``n_fields`` fields each, as the column
    header names (columns after the markers -- any the header names -- are not read),
    else exactly the ``lead + 3J`` the frame, time and markers need; when neither fits,
    the error for ``n_fields``."""
    width = len(cols)
    try:
        return tt.parse_rows(path, text, first, stop, "\t", n_fields, cols, lead,
                             f"a data row of {n_fields} fields", _MISSING)
    except UnreadableFileError as exc:
        if n_fields == width:
            raise
        error = exc
    try:
        return tt.parse_rows(path, text, first, stop, "\t", width, cols, lead,
                             f"a data row of {width} fields", _MISSING)
    except UnreadableFileError:
        raise error from None


def _time_rate(path, keys, line: int, notes: list[str]) -> float:
    """The frame rate of a file whose FREQUENCY is ``EXT`` (QTM's external timebase in edge
    triggered mode, line ``line``): frames per second between its first and last rows, by
    their Frame and Time columns (``keys``; None when it has none)."""
    frames = keys[-1] - keys[0] if keys is not None and len(keys) > 1 else np.zeros(2)
    if keys is None or not (frames[0] > 0 and frames[1] > 0):
        why = ("the file has no Frame and Time columns" if keys is None else
               "the file holds one row" if len(keys) < 2 else
               "its Frame and Time columns do not increase from the first row to the last")
        raise UnreadableFileError(path, f"FREQUENCY is EXT (external timebase) and {why}: no "
                                        "frame rate to read (give it with --fps)", line=line)
    rate = tt.positive_rate(path, f"{frames[0] / frames[1]:.9g}", line,
                            "FREQUENCY EXT: the Frame and Time columns' rate")
    notes.append(f"FREQUENCY is EXT (external timebase): {rate:g} Hz taken from the Frame "
                 "and Time columns")
    return rate


def _header(text) -> tuple[dict[str, tuple[int, list[str]]], int]:
    """The ``KEY<TAB>value...`` lines before the data (key -> (line, values); the first of
    a repeated key), and the index of the line after them."""
    header: dict[str, tuple[int, list[str]]] = {}
    i = 0
    while i < len(text):
        line = text.line(i)
        key = line.split("\t", 1)[0]
        if not line.strip():
            i += 1
            continue
        if key in ("Frame", "Time") or not _KEY.match(key):
            break
        header.setdefault(key, (i, line.split("\t")[1:]))
        i += 1
    return header, i


def _count(path, header: dict, key: str) -> int:
    line, fields = header[key]
    token = (fields or [""])[0].strip()
    if not token.isdigit() or len(token) > 12:
        raise UnreadableFileError(path, f"{key} {tt.quote(token)} is not a count", line=line + 1)
    return int(token)


def _missing_token(text, first: int, stop: int, zeros: bool, decimals: int) -> str:
    """What this file writes for a missing coordinate (``NaN`` when a data row, lines
    ``first`` .. ``stop - 1``, holds one: looked for in the bytes)."""
    if zeros:
        return f"{0:.{decimals}f}"
    if tt.find_all(text.raw, b"NaN", int(text.starts[first]), int(text.stops[stop - 1]), first=True):
        return "NaN"
    return ""


def write(motion: Motion, path, **options) -> list[Path]:
    """Write back the file ``motion`` came from (changed samples only), or a fresh one."""
    return tt.write_table(motion, path, LAYOUT, fresh_pieces)


def fresh_pieces(motion: Motion, path: Path | None = None):
    """A headed (newer) QTM TSV of ``motion`` in mm, 3 decimals, missing as empty fields,
    in pieces."""
    T, J = motion.n_frames, motion.n_joints
    _, factor = tt.written_unit(motion, ("mm",))
    names = [n.replace("\t", " ") for n in motion.names]
    head = [f"NO_OF_FRAMES\t{T}", "NO_OF_CAMERAS\t0", f"NO_OF_MARKERS\t{J}",
            f"FREQUENCY\t{motion.fps:g}", "NO_OF_ANALOG\t0", "ANALOG_FREQUENCY\t0",
            "DESCRIPTION\t--", "TIME_STAMP\t--", "DATA_INCLUDED\t3D",
            "MARKER_NAMES\t" + "\t".join(names),
            "Frame\tTime\t" + "\t".join(f"{n} {a}" for n in names for a in "XYZ")]
    keys = [f"{t + 1}\t{t / motion.fps:.5f}" for t in range(T)]
    return tt.table_pieces(head, keys, motion, factor, "\t", "%.3f")


def kept_only_here(motion: Motion) -> list[str]:
    """The header lines of a QTM TSV, which only a QTM TSV written back holds."""
    return tt.kept_verbatim(motion, LAYOUT, "the header lines (time stamp, description, "
                                            "trajectory types, events)")


def losses(motion: Motion) -> list[str]:
    out = tt.common_losses(motion, "a QTM TSV")
    if motion.units != "mm":
        out.append(f"QTM TSV stores millimetres: positions in {motion.units} are converted")
    return out
