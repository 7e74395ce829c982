"""OptiTrack Motive CSV exports (File > Export Tracking Data > CSV), format versions 1.1x-1.2x.

Layout (OptiTrack Motive documentation, "Data Export: CSV" -- the header rows and
column groups described there): line 1 holds ``key,value`` pairs --
``Format Version,1.23,Take Name,...,Capture Frame Rate,120.000000,Export Frame Rate,
120.000000,...,Total Exported Frames,n,Rotation Type,Quaternion,Length Units,Millimeters,
Coordinate Space,Global``; a blank line; header rows whose second field names them --
``,Type,...`` (``Rigid Body``, ``Rigid Body Marker``, ``Marker``, ``Bone``, ...),
``,Name,...``, ``,ID,...``, optionally ``,Parent,...`` -- and the component row
``,,Rotation,...,Position,...,Mean Marker Error,...,Marker Quality``; then the axis row
``Frame,Time (Seconds),X,Y,Z,W,X,Y,Z,,...`` and one data row per frame (frames from 0); a
missing value is an empty field. Exports with a ``TimeCode`` column after the time are
accepted (columns are found by their header, not by position).

Reading: every ``Marker`` column group with ``Position`` X, Y, Z is a marker (labelled
markers ``Subject:M1``; ``Unlabeled 1000`` ones are unlabelled trajectories), names as
written; rigid bodies, rigid-body markers, bones, errors and qualities are NOT read as
markers and are kept verbatim for writing back (:func:`losses` names them). ``fps`` is
the Export Frame Rate (else the Capture Frame Rate); units from ``Length Units`` (metres
assumed, with a note, when absent); ``times`` from the Time column. No real Motive export
with a licence allowing redistribution was found: the fixture
``tests/data/vendor/motive_doc.csv`` was written from the documentation.

Writing: the same file with only changed marker samples re-formatted (see
:mod:`mocapfix.formats.texttable`) when the motion came from a Motive CSV and still has its
frames and markers; otherwise a fresh Motive CSV holding only Marker columns.

Why hand-written: the layout is a table behind five header rows; no dependency reads it,
and none writes it back keeping the rigid bodies. The file is held once, as its bytes with
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

NAME = "motive_csv"
SUFFIXES = (".csv",)
#: what its points are (configs and rule files may name the family: ``formats: [markers]``)
FAMILY = "markers"
SNIFF_ORDER = 1

LAYOUT = "motive_csv"
_UNIT_WORDS = {"mm": "Millimeters", "cm": "Centimeters", "m": "Meters"}


def sniff(head: bytes) -> bool:
    """Line 1 starts ``Format Version,<number>`` and names a frame rate."""
    lines = tt.head_lines(head, 1)
    fields = lines[0].split(",") if lines else []
    if len(fields) < 2 or fields[0] != "Format Version":
        return False
    try:
        float(fields[1])
    except ValueError:
        return False
    return "Capture Frame Rate" in fields or "Export Frame Rate" in fields


def _settings(line: str) -> dict[str, str]:
    fields = line.split(",")
    return {fields[k].strip(): fields[k + 1].strip() for k in range(0, len(fields) - 1, 2)}


def read(path, fps: float | None = None, units: str | None = None, **options) -> Motion:
    path = Path(path)
    text = TextLines.read(path, "Motive CSV")
    settings = _settings(text.line(0))
    if "Format Version" not in settings:
        raise UnreadableFileError(path, "line 1 does not start with 'Format Version,'", line=1)
    key = "Export Frame Rate" if settings.get("Export Frame Rate") else "Capture Frame Rate"
    if not settings.get(key):
        raise UnreadableFileError(path, "line 1 names no Capture/Export Frame Rate", line=1)
    notes: list[str] = []
    rate = tt.positive_rate(path, settings[key], 1, key)
    unit_word = settings.get("Length Units", "")
    unit = normalise_unit_name(units or unit_word or "m")
    if unit is None:
        raise UnreadableFileError(path, f"unknown Length Units {tt.quote(unit_word)}", line=1)
    if not unit_word and not units:
        notes.append("line 1 names no Length Units: metres assumed")
    head = text.lines_at(np.arange(min(len(text), 64)))
    axis = next((i for i in range(1, len(head)) if head[i].split(",", 1)[0] == "Frame"), None)
    if axis is None:
        raise UnreadableFileError(path, "no 'Frame,Time (Seconds),X,Y,Z,...' row in the header "
                                        "(expected within the first lines after line 1)")
    rows = {}
    for i in range(1, axis):
        fields = head[i].split(",")
        if len(fields) > 1 and head[i].strip(","):
            rows.setdefault(fields[1].strip(), (i, fields))
    for label in ("Type", "Name", ""):
        if label not in rows:
            what = f"',{label},...'" if label else "',,Position,...' (component)"
            raise UnreadableFileError(path, f"header row {what} is missing before the "
                                            "Frame row", line=axis + 1)
    axes = head[axis].split(",")
    n_fields = len(axes)
    for label, (i, fields) in rows.items():
        if len(fields) != n_fields:
            raise UnreadableFileError(path, f"header row has {len(fields)} fields, the Frame row "
                                            f"{n_fields}", line=i + 1)
    kinds, names, parts = rows["Type"][1], rows["Name"][1], rows[""][1]
    x_fields = [c for c in range(2, n_fields - 2)
                if kinds[c] == "Marker" and parts[c] == "Position" and axes[c:c + 3] == ["X", "Y", "Z"]
                and names[c] == names[c + 1] == names[c + 2]]
    J = len(x_fields)
    if J == 0:
        raise UnreadableFileError(path, "no Marker Position X/Y/Z columns (rigid bodies alone "
                                        "are not read)", line=rows["Type"][0] + 1)
    first = axis + 1
    stop = tt.block_end(text, first, ",")
    if stop == first:
        raise UnreadableFileError(path, "no data rows after the Frame row", line=first + 1)
    resumed = tt.first_line(text, stop, lambda line: line.strip(","))
    if resumed < len(text):
        raise UnreadableFileError(path, "data rows resume after a blank line", line=resumed + 1)
    x = np.array(x_fields)
    cols = np.concatenate([[0, 1], (x[:, None] + np.arange(3)).ravel()])
    keys, flat = tt.parse_rows(path, text, first, stop, ",", n_fields, cols, 2,
                               f"a data row of {n_fields} fields")
    positions = tt.markers(flat, notes)
    tt.key_column(path, keys[:, 0], first, "Frame number")
    tt.key_column(path, keys[:, 1], first, "Time")
    others = sorted({kinds[c] for c in range(2, n_fields) if kinds[c] and kinds[c] != "Marker"})
    if others:
        notes.append(f"columns kept as read (not cleaned): {', '.join(others)}")
    rate = float(fps) if fps is not None else rate
    marker_names = [names[c] for c in x_fields]
    text.keep(path)                 # parsed: a large file is read again when written
    source = tt.TableSource(
        layout=LAYOUT, text=text, sep=",", names=marker_names,
        row_line=np.arange(first, stop), x_field=x, original=positions.copy(),
        missing_token="", decimals=tt.max_decimals(text.line(first).split(",")[2:], 6),
        extra={"other_kinds": others, "settings": settings})
    return Motion(positions, marker_names, rate, units=unit, metres_per_unit=METRES_PER_UNIT[unit],
                  times=keys[:, 1] - keys[0, 1], source=source, notes=notes,
                  kinds=["marker"] * J)


def write(motion: Motion, path, **options) -> list[Path]:
    """Write back the file ``motion`` came from (changed samples only), or a fresh one."""
    return tt.write_table(motion, path, LAYOUT, fresh_pieces)


def fresh_pieces(motion: Motion, path: Path | None = None):
    """A Motive CSV (format version 1.23) holding ``motion`` as Marker columns, in pieces."""
    T, J = motion.n_frames, motion.n_joints
    unit, factor = tt.written_unit(motion, ("mm", *_UNIT_WORDS))
    names = [n.replace(",", ";") for n in motion.names]
    take = (path.stem if path is not None else "mocapfix").replace(",", ";")
    head = [(f"Format Version,1.23,Take Name,{take},Capture Frame Rate,{motion.fps:.6f},"
             f"Export Frame Rate,{motion.fps:.6f},Total Exported Frames,{T},"
             f"Rotation Type,Quaternion,Length Units,{_UNIT_WORDS[unit]},Coordinate Space,Global"),
            "",
            ",Type" + ",Marker" * (3 * J),
            ",Name" + "".join(f",{n},{n},{n}" for n in names),
            ",ID" + "".join(f",{j + 1},{j + 1},{j + 1}" for j in range(J)),
            "," + ",Position" * (3 * J),
            "Frame,Time (Seconds)" + ",X,Y,Z" * J]
    keys = [f"{t},{t / motion.fps:.6f}" for t in range(T)]
    return tt.table_pieces(head, keys, motion, factor, ",", "%.6f")


def kept_only_here(motion: Motion) -> list[str]:
    """The columns of a Motive CSV besides its markers (rigid bodies ...), which only a
    Motive CSV written back holds."""
    if isinstance(motion.source, tt.TableSource) and motion.source.layout == LAYOUT:
        kept = ", ".join(motion.source.extra["other_kinds"])
        return tt.kept_verbatim(motion, LAYOUT, kept and f"the {kept} columns")
    return []


def losses(motion: Motion) -> list[str]:
    out = tt.common_losses(motion, "a Motive CSV")
    if motion.units not in _UNIT_WORDS:
        out.append(f"Motive stores m, cm or mm: positions in {motion.units} are converted to mm")
    return out
