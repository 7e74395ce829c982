"""Vicon Nexus CSV exports (File > Export ASCII / "Export CSV"): the Trajectories section.

Layout (Vicon Nexus 2 documentation, "Export data to ASCII/CSV files"; the same layout
appears in pyomeca's test file ``tests/data/markers.csv``, kept in
``tests/data/vendor/``): a file is one or more *sections* separated by blank lines; each
section is

1. its name (``Trajectories``, ``Devices``, ``Model Outputs``, ``Joints``, ``Segments``),
2. its rate in Hz (``100``),
3. a names row: ``Subject:Marker`` in every third column from column 3
   (``,,Subject:LASI,,,Subject:RASI,,,...``; unlabelled trajectories are ``*12``),
4. a column row ``Frame,Sub Frame,X,Y,Z,X,Y,Z,...``,
5. a units row ``,,mm,mm,mm,...``,
6. one row per frame: ``1,0,x,y,z,...``; a missing sample is three empty fields.

Spreadsheet round trips pad every row with commas to the widest row (``Trajectories,,,,``);
that is accepted. The Trajectories section is read as the markers; every other section
(analog ``Devices`` data at a higher rate, model outputs) and every other byte is kept
verbatim in ``motion.source`` so that writing back changes only the samples that changed.

Reading: names as written (``Subject:Marker``, ``*12``), ``fps`` from the section's rate,
units from the units row (mm when it names none, with a note), ``times`` from the Frame
column. Malformations (no Trajectories section, a rate that is not a positive number, a
names/columns row that does not match, a row with the wrong number of fields, a
non-numeric value, a truncated last row) are one UnreadableFileError naming the line.

Writing: the same file with only changed samples re-formatted (decimals of the replaced
token; removed samples become empty fields; filled ones numbers) when the motion came
from a Nexus CSV and still has its frames and markers; otherwise a fresh file holding one
Trajectories section.

Why hand-written: no maintained Python library reads these exports without pandas, and
none writes them back keeping the other sections. The file is held once, as its bytes with
the offsets of its lines; the rows are parsed CHUNK at a time, vectorised, and written back
as slices of those bytes between the rewritten rows (:mod:`mocapfix.formats.texttable`).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from mocapfix.core.errors import UnreadableFileError
from mocapfix.formats.textlines import TextLines
from mocapfix.core.motion import Motion
from mocapfix.core.units import METRES_PER_UNIT, normalise_unit_name
from mocapfix.formats import texttable as tt

NAME = "nexus_csv"
SUFFIXES = (".csv",)
#: what its points are (configs and rule files may name the family: ``formats: [markers]``)
FAMILY = "markers"
SNIFF_ORDER = 1

SECTIONS = ("Trajectories", "Devices", "Model Outputs", "Joints", "Segments")
LAYOUT = "nexus_csv"


def _cell(line: str) -> str:
    return line.split(",", 1)[0].strip()


def sniff(head: bytes) -> bool:
    """A section name alone on the first content line, a number alone on the next."""
    lines = [ln for ln in tt.head_lines(head, 8) if ln.strip(", \t")]
    if len(lines) < 2 or _cell(lines[0]) not in SECTIONS or lines[0].strip(", \t") != _cell(lines[0]):
        return False
    try:
        float(lines[1].strip(", \t"))
    except ValueError:
        return False
    return True


def read(path, fps: float | None = None, units: str | None = None, **options) -> Motion:
    path = Path(path)
    text = TextLines.read(path, "Nexus CSV")
    starts = _section_starts(text)
    sections = [text.line(i).strip(", \t") for i in starts]
    traj = next((i for i, name in zip(starts, sections) if name == "Trajectories"), None)
    if traj is None:
        found = ", ".join(sections) or "none"
        raise UnreadableFileError(path, f"Nexus CSV has no Trajectories section (sections "
                                        f"found: {found})")
    if traj + 4 >= len(text):
        raise UnreadableFileError(path, "Trajectories section ends before its units row "
                                        "(expected rate, names, Frame/Sub Frame and units rows)",
                                  line=len(text))
    notes: list[str] = []
    rate = tt.positive_rate(path, text.line(traj + 1).strip(", \t"), traj + 2, "Trajectories rate")
    names_row = text.line(traj + 2).split(",")
    column_row = text.line(traj + 3)
    columns = tt.fields_of(column_row, ",")
    if columns[:2] != ["Frame", "Sub Frame"] or (len(columns) - 2) % 3:
        raise UnreadableFileError(path, f"expected 'Frame,Sub Frame,X,Y,Z,...' after the names "
                                        f"row, found {tt.quote(column_row[:60])}",
                                  line=traj + 4)
    J = (len(columns) - 2) // 3
    if columns[2:] != ["X", "Y", "Z"] * J:
        raise UnreadableFileError(path, "the column row must repeat X,Y,Z for every marker",
                                  line=traj + 4)
    names = [names_row[2 + 3 * j].strip() if 2 + 3 * j < len(names_row) else "" for j in range(J)]
    if not all(names):
        j = names.index("")
        raise UnreadableFileError(path, f"no marker name above column {3 + 3 * j} (expected "
                                        "Subject:Marker in every third column)", line=traj + 3)
    unit_row = text.line(traj + 4).split(",")
    unit_tag = unit_row[2].strip() if len(unit_row) > 2 else ""
    if _is_number(unit_tag):
        raise UnreadableFileError(path, "expected the units row (',,mm,mm,mm,...') after the "
                                        "Frame/Sub Frame row, found a data row", line=traj + 5)
    unit = normalise_unit_name(units or unit_tag or "mm")
    if unit is None:
        raise UnreadableFileError(path, f"unknown length unit {tt.quote(unit_tag)} in the units "
                                        "row", line=traj + 5)
    if not unit_tag:
        notes.append("the units row names no unit: millimetres assumed")
    first = traj + 5
    stop = tt.block_end(text, first, ",")
    if stop == first:
        raise UnreadableFileError(path, "Trajectories section holds no data rows", line=first + 1)
    frames, flat = _trajectories(path, text, first, stop, len(column_row.split(",")), J)
    positions = tt.markers(flat, notes)
    frames = tt.key_column(path, frames, first, "Frame number")
    rate = float(fps) if fps is not None else rate
    text.keep(path)                 # parsed: a large file is read again when written
    source = tt.TableSource(
        layout=LAYOUT, text=text, sep=",", names=names,
        row_line=np.arange(first, stop), x_field=2 + 3 * np.arange(J),
        original=positions.copy(), missing_token="",
        decimals=tt.max_decimals(text.line(first).split(",")[2:]),
        extra={"sections": sections})
    others = [s for s in sections if s != "Trajectories"]
    if others:
        notes.append(f"sections kept as read (not cleaned): {', '.join(others)}")
    return Motion(positions, names, rate, units=unit, metres_per_unit=METRES_PER_UNIT[unit],
                  times=tt.frame_times(frames, rate, notes), source=source, notes=notes,
                  kinds=["marker"] * J)


def _section_starts(text) -> list[int]:
    """The lines that open a section: a section name alone (separators around it allowed),
    first in the file or after a blank line. The names are looked for in the bytes -- no
    data row holds one -- so that only the lines holding them are decoded."""
    found = sorted(set().union(*(tt.lines_holding(text, name) for name in SECTIONS)))
    return [i for i in found if text.line(i).strip(", \t") in SECTIONS
            and (i == 0 or not text.line(i - 1).strip(", \t"))]


def _trajectories(path, text, first: int, stop: int, n_fields: int, J: int):
    """(frame numbers, (T, 3J) marker columns) of the Trajectories rows: ``n_fields``
    fields each, as the column row has (spreadsheet padding), else exactly the
    ``2 + 3J`` the markers need."""
    cols = np.arange(2 + 3 * J)
    what = f"a Trajectories row of {2 + 3 * J} columns"
    try:
        keys, flat = tt.parse_rows(path, text, first, stop, ",", n_fields, cols, 2, what)
    except UnreadableFileError:
        if n_fields == 2 + 3 * J:
            raise
        keys, flat = tt.parse_rows(path, text, first, stop, ",", 2 + 3 * J, cols, 2, what)
    return keys[:, 0], flat


def _is_number(token: str) -> bool:
    try:
        float(token)
    except ValueError:
        return False
    return True


def write(motion: Motion, path, **options) -> list[Path]:
    """Write back the file ``motion`` came from (changed samples only), or a fresh one."""
    return tt.write_table(motion, path, LAYOUT, fresh_pieces)


def fresh_pieces(motion: Motion, path: Path | None = None):
    """One Trajectories section holding ``motion`` (numbers with 6 decimals), in pieces."""
    T, J = motion.n_frames, motion.n_joints
    unit, factor = tt.written_unit(motion, ("mm", *METRES_PER_UNIT))
    head = ["Trajectories", f"{motion.fps:g}",
            ",," + ",".join(f"{name},," for name in motion.names)[:-1],
            "Frame,Sub Frame" + ",X,Y,Z" * J, ",," + ",".join([unit] * (3 * J))]
    keys = [f"{t + 1},0" for t in range(T)]
    return tt.table_pieces(head, keys, motion, factor, ",", "%.6f")


def kept_only_here(motion: Motion) -> list[str]:
    """The sections of a Nexus CSV besides Trajectories (Devices, Model Outputs ...), which
    only a Nexus CSV written back holds."""
    if isinstance(motion.source, tt.TableSource) and motion.source.layout == LAYOUT:
        others = [x for x in motion.source.extra["sections"] if x != "Trajectories"]
        return tt.kept_verbatim(motion, LAYOUT, others and f"the {', '.join(others)} sections")
    return []


def losses(motion: Motion) -> list[str]:
    out = tt.common_losses(motion, "a Nexus CSV")
    if motion.units not in METRES_PER_UNIT:
        out.append(f"positions in {motion.units} are converted to mm (a Nexus CSV names its "
                   "unit per column: mm, cm or m)")
    return out
