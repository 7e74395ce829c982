"""Kinect skeleton text files: three dataset layouts and two layouts users export.

Layouts (detected from content, never from the name):

``kinect_v2_csv``
    Microsoft LabanotationSuite / KinectReader CSV, no header: a whole-number timestamp
    in 100 ns ticks (milliseconds when its median step is below 1000, as the suite's own
    reader takes such stamps), then 25 x ``X,Y,Z,TrackingState`` (metres, camera space; state 0 NotTracked,
    1 Inferred, 2 Tracked), usually a trailing comma. Joint order = Kinect SDK 2.0
    ``JointType``. The same layout with 20 joints (Kinect SDK 1.x order) is accepted
    as ``kinect_v1_csv``.
``utkinect``
    UTKinect-Action3D ``joints_sXX_eXX.txt``: whitespace separated, a frame index then
    20 x ``x y z`` (metres), Kinect SDK 1.x order. The indices count 30 Hz camera frames
    but rows are irregular (mostly every 2-8 indices, some indices repeated), so
    ``times = (index - first index) / 30`` and ``fps`` is the median row rate.
``msr_action3d``
    MSR Action3D ``aXX_sXX_eXX_skeleton3D.txt`` (the *real_world_coordinates* variant):
    rows ``x y z c``, 20 rows per frame, metres. Known: 20 rows per frame, c in [0, 1],
    nominal 15 fps (the dataset's stated rate; the file holds no timing). Assumed: the
    joint order, taken from the bone list of the dataset's ``drawskt.m`` viewer (see
    :mod:`mocapfix.core.kinect_joints`) -- the bone-length tests on the real files
    confirm it. The other variant (screen u, v, depth) is refused. ``c`` becomes the
    confidence directly. About a quarter of rows have ``c = 0``; on the shared files these
    are always plausible positions of joints the tracker inferred (shoulder centre, spine,
    hip centre, feet), never zeros, so ``c = 0`` is a low confidence, NOT missing. Only a
    row whose x, y, z are all 0 (or not finite) is missing.
``wide_csv``
    A header row with ``<Joint>_X, <Joint>_Y, <Joint>_Z`` columns (also ``<Joint>.X``,
    ``<Joint> X``, any case, optional unit tag ``(mm)``/``[mm]``), optional
    ``<Joint>_State``/``_TrackingState`` (0/1/2) or ``_Confidence`` (0..1) columns and an
    optional time/timestamp/frame column (numbers, or ISO dates and times
    ``2020-07-03 16:01:47.123``); separator ``,``, ``;`` or tab. Other columns are
    kept untouched. Empty cells are missing; so is a sample at exactly (0, 0, 0) with
    confidence 0 (LSL-Kinect's frames without a body). Up to 5 lines of text may precede
    the header when its joint names belong to a built-in set (LSL-Kinect's settings
    line); they are kept as they are.
``long_csv``
    A header ``frame, joint, x, y, z[, state]`` (``time``/``timestamp`` instead of frame,
    ``name`` instead of joint accepted), one row per joint per frame; a joint without a
    row in some frame is missing there.

More than one body per frame (a body/user column -- ``id``, ``BodyId``, ``TrackingId``,
... -- holding two values at one time stamp or frame: Nuitrack's CSV recorder writes a
row per tracked user) is refused naming the column; a body whose id changes between
frames is still one body.

Joint sets: a headed file whose joint names all belong to a built-in set (Kinect v1/v2,
Azure Kinect, any spelling) gets that set's topology as ``motion.skeleton``; unknown
names give no skeleton.

Tracking state -> confidence: Tracked 2 -> 1.0, Inferred 1 -> 0.5, NotTracked 0 ->
missing (NaN) with confidence 0; the file's coordinates of NotTracked samples are kept in
``motion.source`` so that writing back reproduces them.

Missing/odd values (decisions): ``nan``/``inf`` text in a coordinate -> that sample is
missing (noted); a non-numeric token -> one UnreadableFileError naming file and line; a
row with the wrong number of values in the middle -> error naming the line; an incomplete
LAST line (or incomplete last MSR frame) -> the complete part is read and a note says the
file looks truncated (the fragment is not written back); empty file / header only -> error.

Timing: timestamps (ticks, seconds, ms) or frame indices give ``motion.times`` in seconds
from 0 and ``fps`` = 1 / median positive interval. Intervals > 1.5 x the median are
reported as dropped-frame gaps, intervals of 0 as repeated frames, negative ones as
backward steps -- in ``motion.notes``; rows are never inserted or removed. A lone stamp
far out of order with the rows around it (a corrupt field) is read as lying between them,
with a note (:func:`_mend_lone_times`).

Units: metres (``units="m"``) for the dataset layouts. A headed CSV uses its unit tag if
it has one, else the unit is guessed from magnitude (median bone length when the
skeleton is known, else the body's spread around its centroid) and a note says so
(``units=`` option overrides).

Writing back (same layout as read): every line is kept as read; only samples whose
position changed are re-formatted (at least 6 decimals, more when the original token had
more), so an unchanged motion writes back byte-identical (trailing comma, number format,
whitespace, line endings, BOM). A sample a cleaner FILLED (missing when read, present
now) gets TrackingState 1 (Inferred) in the Kinect CSVs and state columns, ``c = 0.5`` in
MSR files; a sample still missing keeps its original tokens and state; a sample a cleaner
REMOVED (present when read, NaN now) is written as NotTracked (state 0, coordinates kept)
where the layout has a state, as ``0 0 0 0`` in MSR files, as ``nan`` in UTKinect files,
as empty cells in a headed CSV without state and as an absent row in the long layout.
Confidence changes alone are not written (the state follows the position rules above).
If the motion has no Kinect source (built in Python) or its frame count/joints differ
from the source, a headed wide CSV is written (``time`` + ``<Joint>_X/_Y/_Z`` [+ ``_State``]).

Why hand-written: these are ad-hoc research/export layouts with no library that reads
them. The file is held once, as its bytes with the offsets of its lines
(:class:`~mocapfix.formats.textlines.TextLines`); data lines are parsed CHUNK at a time
straight into the float arrays (blocks of plain numbers by ``np.fromstring``, others by one
``split`` per line and one numpy conversion), and written back as slices of the source
between the rewritten lines: besides the whole-take arrays, memory does not grow with the
take by more than a few bytes a sample.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from itertools import repeat
from pathlib import Path

import numpy as np

from mocapfix.core import kinect_joints as kl
from mocapfix.core.errors import UnreadableFileError, UnsupportedFeatureError, excerpt
from mocapfix.core.fileio import read_input_bytes, write_output_pieces
from mocapfix.core.motion import Motion, Skeleton
from mocapfix.core.quantity import MAX_FRAME_RATE_HZ, MIN_FRAME_RATE_HZ
from mocapfix.core.units import METRES_PER_UNIT, normalise_unit_name
from mocapfix.formats.textlines import TextLines
from mocapfix.formats.texttable import samples_to_rewrite

NAME = "kinect"
SUFFIXES = (".csv", ".txt", ".tsv")
#: what its points are (configs and rule files may name the family: ``formats: [skeletons]``)
FAMILY = "skeletons"
#: where its sniffer runs when the suffix does not tell (lower first: the stricter tests)
SNIFF_ORDER = 3

STATE_CONFIDENCE = {0: 0.0, 1: 0.5, 2: 1.0}
UTKINECT_FPS = 30.0
MSR_FPS = 15.0
DEFAULT_FPS = 30.0
GAP_FACTOR = 1.5

_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*([eE][+-]?\d+)?|\.\d+([eE][+-]?\d+)?|nan|inf|infinity)$",
                     re.IGNORECASE)
_AXIS_COLUMN = re.compile(
    r"^(?P<joint>.*?\S)[\s_.:\-]+(?P<role>x|y|z|state|tracking[\s_]?state|trackingstate|"
    r"confidence|conf)(?:\s*[\[(](?P<unit>[a-z]+)[\])])?$", re.IGNORECASE)
_TIME_NAMES = {"time", "times", "timestamp", "timestamps", "t", "seconds", "sec", "secs",
               "timems", "timestampms", "ms", "ticks", "timeus", "timestampus",
               "us", "relativetime", "elapsed", "elapsedtime"}
_FRAME_NAMES = {"frame", "frames", "frameindex", "frameno", "framenumber", "framenum",
                "frameid", "index", "idx"}
_JOINT_NAMES = {"joint", "jointname", "name", "jointtype", "label", "bone", "marker"}
_STATE_NAMES = {"state", "trackingstate", "tracking"}
#: a column naming the body/user a row belongs to (Nuitrack's CSV recorder: "id")
_BODY_NAMES = {"id", "userid", "user", "body", "bodyid", "bodyindex", "bodynumber",
               "trackingid", "skeletonid", "skeleton", "skeletonindex", "player", "playerid",
               "playerindex", "person", "personid"}
_CONF_NAMES = {"confidence", "conf"}


def _norm(name: str) -> str:
    return re.sub(r"[\s_.\-:\"']+", "", name.strip().lower())


# ---------------------------------------------------------------------------------------
# source kept for writing back
# ---------------------------------------------------------------------------------------
@dataclass
class KinectSource:
    """Everything the writer needs to reproduce the file (see the module docstring)."""

    layout: str
    text: TextLines              # the file's bytes and the offsets of its lines
    sep: str | None              # field separator; None = runs of whitespace
    names: list[str]
    # (read-only broadcast views where a layout's lines all look alike)
    line_of: np.ndarray          # (T, J) line index of each sample; -1: no row (long layout)
    coord_field: np.ndarray      # (T, J, 3) field index of X, Y, Z in its line
    state_field: np.ndarray      # (T, J) field index of the state / confidence; -1: none
    state_kind: str | None       # "tracking" (0/1/2), "confidence" (0..1) or None
    original: np.ndarray         # (T, J, 3) coordinates as written (NotTracked kept)
    missing: np.ndarray          # (T, J) samples the reader made missing
    skip_lines: list[int] = field(default_factory=list)   # truncated fragments, not written
    extra: dict = field(default_factory=dict)              # layout-specific (long layout rows)

    @property
    def bom(self) -> str:
        return self.text.bom

    @property
    def lines(self) -> list[str]:
        """Every line, without its ending (one str each: for tests and small files)."""
        return self.text.lines

    @property
    def endings(self) -> list[str]:
        return self.text.endings


# ---------------------------------------------------------------------------------------
# text helpers
# ---------------------------------------------------------------------------------------
def _decode(raw: bytes, path) -> tuple[str, str]:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise UnreadableFileError(path, f"not a text file (undecodable byte at offset "
                                        f"{exc.start})") from None
    bom = "\ufeff" if text.startswith("\ufeff") else ""
    return bom, text[len(bom):]


def _split_lines(text: str) -> tuple[list[str], list[str]]:
    pieces = text.split("\n")
    lines, endings = [], []
    for i, piece in enumerate(pieces):
        last = i == len(pieces) - 1
        if last and piece == "":
            break
        if piece.endswith("\r") and not last:
            lines.append(piece[:-1])
            endings.append("\r\n")
        else:
            lines.append(piece)
            endings.append("" if last else "\n")
    return lines, endings


def _content_indices(lines: list[str]) -> list[int]:
    """Indices of lines that hold data or a header (not blank, not ``#`` comments)."""
    return [i for i, line in enumerate(lines)
            if line.strip() and not line.lstrip().startswith("#")]


def _is_number(token: str) -> bool:
    return bool(_NUMBER.match(token.strip()))


def _numbers(tokens: list[str], token_lines: np.ndarray, path, empty_is_nan=False) -> np.ndarray:
    """One vectorised conversion; on failure, name the line of the first bad token."""
    if empty_is_nan:
        tokens = [t if t.strip() else "nan" for t in tokens]
    try:
        return np.array(tokens, dtype=np.float64)
    except ValueError:
        for k, token in enumerate(tokens):
            if not _is_number(token):
                raise UnreadableFileError(path, f"non-numeric value {excerpt(token.strip())}",
                                          line=int(token_lines[k]) + 1) from None
        raise UnreadableFileError(path, "non-numeric value") from None


def _check_counts(counts: np.ndarray, idx: np.ndarray, expected: int, path, notes,
                  what: str) -> tuple[np.ndarray, list[int]]:
    """Rows (``counts`` fields each, on lines ``idx``) must hold ``expected`` fields; a
    short LAST row is a truncation: dropped, noted. Returns the lines kept and dropped."""
    bad = np.nonzero(counts != expected)[0]
    skipped: list[int] = []
    if len(bad) and bad[0] == len(counts) - 1 and counts[-1] < expected:
        notes.append(f"last line (line {idx[-1] + 1}) is incomplete ({counts[-1]} of "
                     f"{expected} {what}): the file looks truncated; that line was dropped")
        skipped = [int(idx[-1])]
        idx = idx[:-1]
    elif len(bad):
        k = int(bad[0])
        raise UnreadableFileError(path, f"{counts[k]} {what} where {expected} were expected",
                                  line=int(idx[k]) + 1)
    return idx, skipped


#: data lines split at a time: their fields are Python strings only while they are parsed
CHUNK = 4096


def _parse_rows(path, text: TextLines, idx: np.ndarray, split, n_fields: int, groups,
                clean: bool = False, label: int | None = None, plain: bytes | None = None):
    """Split the lines ``idx`` into fields, CHUNK lines at a time, and convert the fields
    of each group of columns (None: every field) into a float array (rows, columns); a
    row without ``n_fields`` fields is left NaN (:func:`_check_counts` then refuses it or
    drops it as a truncated last line). ``clean``: fields stripped of blanks and quotes,
    empty ones NaN. ``label``: the column of a name, numbered in order of appearance.

    Returns the field counts, per group (values, the UnreadableFileError of its first
    non-numeric field, or None: raised where the reader used to convert that group), and
    the label numbers and names.

    ``plain`` (every field wanted, one group): the separator, "," or " " (runs of blanks),
    of a layout whose blocks of consecutive lines made of digits, signs, points,
    exponents and separators only are converted by :func:`_plain_block` without
    splitting them into strings; a block it cannot vouch for is split as above."""
    n = len(idx)
    counts = np.zeros(n, np.intp)
    values = [np.full((n, n_fields if g is None else len(g)), np.nan) for g in groups]
    errors: list = [None] * len(groups)
    numbers: dict[str, int] = {}
    labels = np.full(n, -1, np.intp)
    for a in range(0, n, CHUNK):
        at = idx[a:a + CHUNK]
        if plain and at[-1] - at[0] == len(at) - 1:
            got = _plain_block(text, at, n_fields, plain)
            if got is not None:
                values[0][a:a + len(at)] = got
                counts[a:a + len(at)] = n_fields
                continue
        rows = [split(line) for line in text.lines_at(at)]
        c = np.fromiter(map(len, rows), np.intp, len(rows))
        counts[a:a + len(rows)] = c
        good = np.flatnonzero(c == n_fields)
        if len(good) < len(rows):
            rows = [rows[k] for k in good.tolist()]
        if label is not None:
            labels[a + good] = [numbers.setdefault(row[label].strip().strip('"'), len(numbers))
                                for row in rows]
        for g, cols in enumerate(groups):
            if errors[g] is not None or not rows:
                continue
            width = values[g].shape[1]
            if cols is None:
                tokens = [t for row in rows for t in row]
            elif clean:
                tokens = [row[c].strip().strip('"') for row in rows for c in cols]
            else:
                tokens = [row[c] for row in rows for c in cols]
            lines = at[good]
            try:
                got = _numbers(tokens, np.repeat(lines, width), path, empty_is_nan=clean)
            except UnreadableFileError as exc:
                # the rows before the bad one are read (a dropped truncated end may hold it)
                r = 0 if exc.line is None else int(np.searchsorted(lines, exc.line - 1))
                if r:
                    values[g][a + good[:r]] = _numbers(tokens[:r * width], np.repeat(lines[:r], width),
                                                       path, clean).reshape(r, width)
                errors[g] = (exc, a + int(good[min(r, len(good) - 1)]))
                continue
            values[g][a + good] = got.reshape(len(rows), width)
    return counts, list(zip(values, errors)), (labels, list(numbers))


#: the bytes of a plain block (:func:`_plain_block`) besides its separator
_PLAIN_BYTES = b"0123456789.eE+-\n"


def _plain_block(text: TextLines, at: np.ndarray, n_fields: int, sep: str) -> np.ndarray | None:
    """The (lines, n_fields) values of the consecutive lines ``at`` when every byte of them
    is one of ``_PLAIN_BYTES``, the separator (``" "``: blanks and tabs) or a CR of a CRLF,
    every line holds ``n_fields`` fields (a trailing empty one dropped, as
    :func:`_strip_trailing_empty` does) and ``np.fromstring`` reads each field as one
    number (the count tells); else None. ``np.fromstring`` parses with Python's own
    ``PyOS_string_to_double``, so the values are those ``float`` gives."""
    block = text.raw[int(text.starts[at[0]]):int(text.stops[at[-1]])]
    keep = _PLAIN_BYTES + (b"," if sep == "," else b" \t")
    if block.translate(None, keep + b"\r") or block.count(b"\r") != block.count(b"\r\n"):
        return None
    if b"\r" in block:
        block = block.replace(b"\r\n", b"\n")
    raw = np.frombuffer(block, np.uint8)
    ends = np.flatnonzero(raw == 10)
    if len(ends) != len(at) - 1:
        return None
    bounds = np.concatenate([ends, [len(raw)]])
    if sep == ",":
        commas = np.searchsorted(np.flatnonzero(raw == 44), bounds)
        trailing = raw[bounds - 1] == 44
        fields = np.diff(commas, prepend=0) + 1 - trailing
        if trailing.any():
            block = block.replace(b",\n", b"\n").removesuffix(b",")
        block = block.replace(b"\n", b",")
    else:
        gap = (raw == 32) | (raw == 9) | (raw == 10)
        first = np.flatnonzero(~gap & np.concatenate([[True], gap[:-1]]))
        fields = np.diff(np.searchsorted(first, bounds), prepend=0)
    if (fields != n_fields).any():
        return None
    try:
        values = np.fromstring(block, sep=sep)
    except ValueError:
        return None
    return values.reshape(len(at), n_fields) if values.size == len(at) * n_fields else None


def _kept(parsed, n: int) -> np.ndarray:
    """The values of one group of :func:`_parse_rows` for the first ``n`` rows, or the
    error of a non-numeric field among them."""
    values, error = parsed
    if error is not None and error[1] < n:
        raise error[0]
    return values[:n]


def _csv_fields(line: str) -> list[str]:
    return _strip_trailing_empty(line.split(","))


# ---------------------------------------------------------------------------------------
# layout detection
# ---------------------------------------------------------------------------------------
def _strip_trailing_empty(fields: list[str]) -> list[str]:
    return fields[:-1] if fields and not fields[-1].strip() else fields


def _classify(content: list[str]) -> str | None:
    """Layout name of a file from its first content lines, or None."""
    if not content:
        return None
    first = content[0]
    if "," in first:
        fields = _strip_trailing_empty(first.split(","))
        if all(_is_number(f) for f in fields):
            return _classify_headerless_csv(fields)
    tokens = first.split()
    if tokens and all(_is_number(t) for t in tokens):
        if len(tokens) == 61 and float(tokens[0]).is_integer():
            return "utkinect"
        if len(tokens) == 4 and _looks_msr(content):
            return "msr_action3d"
        return None
    found = _header_at(content)
    return found[1] if found else None


#: lines an exporter writes before a headed file's header (LSL-Kinect: a settings line
#: "Software : LSL_Kinect,Version : 1.0.4.1,Stream nominal rate : 15,Sequence Name : ..."
#: and a blank line)
MAX_PREAMBLE = 5


def _header_at(content: list[str]) -> tuple[int, str] | None:
    """(position among ``content``, layout) of a headed file's header: the first content
    line, or one after at most ``MAX_PREAMBLE`` lines of text (none of them all numbers)
    when it is a wide header whose joint names all belong to a built-in set -- the
    preamble is kept as it is, like any line the reader does not use."""
    for k, line in enumerate(content[:MAX_PREAMBLE + 1]):
        sep = _header_sep(line)
        fields = _splitter(sep)(line)
        if k and all(_is_number(f) for f in _strip_trailing_empty(fields)):
            return None
        layout = _header_layout(fields)
        if layout is None:
            continue
        if k and (layout != "wide_csv" or not _known_joint_set(fields)):
            return None
        return k, layout
    return None


def _known_joint_set(fields: list[str]) -> bool:
    joints, _, _ = _wide_columns([_clean_header(f) for f in fields])
    return kl.match_joint_set([j for j, r in joints.items() if "x" in r]) is not None


def _classify_headerless_csv(fields: list[str]) -> str | None:
    n = len(fields) - 1
    if n % 4 or n // 4 not in (20, 25):
        return None
    try:
        states = {float(f) for f in fields[4::4]}
        stamp = float(fields[0])
    except ValueError:
        return None
    if not states <= {0.0, 1.0, 2.0} or not stamp.is_integer():
        return None
    return "kinect_v2_csv" if n // 4 == 25 else "kinect_v1_csv"


def _looks_msr(content: list[str]) -> bool:
    rows = [line.split() for line in content[:40]]
    if len(rows) > 1:
        rows = rows[:-1]  # the last line of a 4 KiB head may be cut
    for row in rows:
        if len(row) != 4 or not all(_is_number(t) for t in row):
            return False
        c = float(row[3])
        if not 0.0 <= c <= 1.0:
            return False
    return True


def _header_layout(fields: list[str]) -> str | None:
    columns = [_clean_header(f) for f in fields]
    if _long_columns(columns) is not None:
        return "long_csv"
    joints, _, _ = _wide_columns(columns)
    if any({"x", "y", "z"} <= set(roles) for roles in joints.values()):
        return "wide_csv"
    return None


def sniff(head: bytes) -> bool:
    """True when ``head`` (first bytes of a file) looks like one of the layouts."""
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff")
    lines = text.split("\n")
    if len(head) >= 4096 and len(lines) > 1:
        lines = lines[:-1]  # cut mid-line
    content = [ln.rstrip("\r") for ln in lines
               if ln.strip() and not ln.lstrip().startswith("#")]
    try:
        return _classify(content[:40]) is not None
    except (ValueError, IndexError):
        return False


# ---------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------
def read(path, fps: float | None = None, units: str | None = None,
         default_fps: float | None = None, **options) -> Motion:
    """Read any of the layouts (see the module docstring) into a :class:`Motion`.

    ``fps`` overrides the file's rate; ``default_fps`` (the command line's ``--fps``) is the
    rate of a file that stores none (its :class:`RateAssumed` layouts) and leaves a stored
    rate alone. Each layout uses the rate it is given only where it would assume one, so
    one parse serves both cases."""
    path = Path(path)
    text = TextLines.scan(path, TextLines.open_large(path) or read_input_bytes(path))
    idx = np.flatnonzero(text.content)
    if not len(idx):
        raise UnreadableFileError(path, "file holds no data lines")
    if text.long_field is not None:
        raise text.long_field
    layout = options.get("layout") or _classify(text.lines_at(idx[:40]))
    if layout not in _READERS and layout is not None:
        raise UnreadableFileError(path, f"unknown Kinect layout {layout!r}; known: "
                                        f"{', '.join(sorted(_READERS))}")
    if layout is None:
        raise UnreadableFileError(path, _why_unknown(text.line(idx[0])), line=int(idx[0]) + 1)
    reader = _READERS[layout]
    notes: list[str] = []
    if layout in ("wide_csv", "long_csv"):
        found = _header_at(text.lines_at(idx[:MAX_PREAMBLE + 1]))
        if found and found[0]:
            notes.append(f"{found[0]} line(s) before the header (line {idx[found[0]] + 1}) "
                         "kept as they are")
            idx = idx[found[0]:]
    for rate in (fps, default_fps):
        if rate is not None and not (np.isfinite(float(rate)) and float(rate) > 0):
            raise UnreadableFileError(path, f"fps must be a positive number, got {rate}")
    given = fps if fps is not None else default_fps
    parts = reader(path, text, idx, notes, layout=layout, fps=given, units=units)
    text.keep(path)                 # parsed: a large file's bytes go before the take is built
    if not MIN_FRAME_RATE_HZ <= parts.file_fps <= MAX_FRAME_RATE_HZ:
        # time stamps 1e300 apart gave "90 frames at 0 fps", and cleaning overflowed
        # (internal error OverflowError); the BVH reader refuses such rates too
        raise UnreadableFileError(path, f"the time column gives {parts.file_fps:.4g} frames per "
                                        f"second, outside {MIN_FRAME_RATE_HZ:g}-"
                                        f"{MAX_FRAME_RATE_HZ:g} Hz (a corrupt time column?)")
    parts.extra["rate_assumed"] = any(isinstance(n, RateAssumed) for n in notes)
    if given is not None and parts.extra["rate_assumed"]:
        notes[:] = [n for n in notes if not isinstance(n, RateAssumed)]
        fps = given
    motion = _assemble(parts, layout, text, notes, fps)
    motion.path = str(path)
    return motion


class RateAssumed(str):
    """The note of a layout reader that found no rate in the file and assumed one (made
    whether or not ``fps`` was given, so every such layout is known to store none): its
    type, not its wording, tells :func:`read` the file stores no rate (``--fps`` then sets
    it) and lets a given ``fps`` drop the note."""


def _why_unknown(first: str) -> str:
    n_comma = len(_strip_trailing_empty(first.split(",")))
    n_space = len(first.split())
    return ("not a Kinect skeleton layout: first line has "
            f"{n_comma if ',' in first else n_space} values (expected 1 + 25 x 4 for a "
            "Kinect v2 CSV, 61 for UTKinect, 4 for MSR Action3D, or a header with "
            "<Joint>_X/_Y/_Z or frame,joint,x,y,z columns)")


@dataclass
class _Parsed:
    """What a layout reader hands to :func:`_assemble`."""

    names: list[str]
    coords: np.ndarray            # (T, J, 3) as written
    missing: np.ndarray           # (T, J)
    confidence: np.ndarray | None
    line_of: np.ndarray
    coord_field: np.ndarray
    state_field: np.ndarray
    state_kind: str | None
    sep: str | None
    times: np.ndarray | None      # seconds from the first row, or None (uniform)
    file_fps: float
    units: str = "m"
    skeleton: Skeleton | None = None
    skip_lines: list[int] = field(default_factory=list)
    extra: dict = field(default_factory=dict)


def _assemble(p: _Parsed, layout, text: TextLines, notes, fps) -> Motion:
    positions = p.coords.copy()
    positions[p.missing] = np.nan
    motion_fps = p.file_fps
    if fps is not None:
        fps = float(fps)
        if p.extra.get("rate_assumed"):
            notes.append(f"fps {fps:g} given by the user (the file stores no rate)")
        elif abs(fps - p.file_fps) > 0.01 * p.file_fps:
            notes.append(f"fps {fps:g} given by the user overrides the file's {p.file_fps:.4g} fps")
        motion_fps = fps
    source = KinectSource(
        layout=layout, text=text, sep=p.sep, names=list(p.names),
        line_of=p.line_of, coord_field=p.coord_field, state_field=p.state_field,
        state_kind=p.state_kind, original=p.coords, missing=p.missing,
        skip_lines=p.skip_lines, extra=p.extra)
    return Motion(positions=positions, names=list(p.names), fps=motion_fps, units=p.units,
                  metres_per_unit=METRES_PER_UNIT[p.units], format=NAME,
                  confidence=p.confidence, skeleton=p.skeleton, times=p.times,
                  source=source, notes=notes)


def _nonfinite_missing(coords: np.ndarray, notes: list[str]) -> np.ndarray:
    bad = ~np.isfinite(coords).all(axis=2)
    if bad.any():
        notes.append(f"{int(bad.sum())} samples with nan/inf coordinates read as missing")
    return bad


#: a time stamp this many median frame intervals out of order with both rows around it
#: (which are in order) is a corrupt field, not a clock: read as midway between them
LONE_TIME_FACTOR = 100.0


def _mend_lone_times(times: np.ndarray, notes: list[str]) -> np.ndarray:
    """``times`` with each lone corrupt stamp (one row far out of order while the rows
    before and after it are in order: 1e23 in a tick column made "3e17 dropped frames")
    read as midway between its neighbours, the first or last row one median interval
    from its neighbour; noted. Returns seconds from the first row. The file's rows and
    stamps are written back as read."""
    dt = np.diff(times)
    positive = dt[dt > 0]
    if len(times) < 3 or not len(positive):
        return times - times[0] if len(times) else times
    median = float(np.median(positive))
    limit = LONE_TIME_FACTOR * median
    t = times.copy()
    inner = np.arange(1, len(t) - 1)
    before, after = t[inner - 1], t[inner + 1]
    out = np.maximum(before - t[inner], t[inner] - after)
    lone = inner[(out > limit) & (after >= before)]
    t[lone] = (t[lone - 1] + t[lone + 1]) / 2
    ends = []
    if abs(t[1] - t[0]) > limit and 0 < t[2] - t[1] <= limit:
        t[0] = t[1] - median
        ends.append(0)
    if abs(t[-1] - t[-2]) > limit and 0 < t[-2] - t[-3] <= limit:
        t[-1] = t[-2] + median
        ends.append(len(t) - 1)
    mended = sorted([*lone.tolist(), *ends])
    if mended:
        rows = ", ".join(str(r + 1) for r in mended[:5]) + (" …" if len(mended) > 5 else "")
        notes.append(f"{len(mended)} time stamps far out of order with the rows around them "
                     f"(data rows {rows}): read as corrupt, placed between their neighbours "
                     "(written back as they were)")
    return t - t[0]


def _timing(raw: np.ndarray, notes: list[str], unit_label="frame") -> tuple[np.ndarray, float]:
    """(the time axis, seconds from the first row, fps): lone corrupt stamps mended
    (:func:`_mend_lone_times`), fps from the median positive interval,
    dropped/repeated/backward frames noted. ``raw``: seconds from any origin."""
    times = _mend_lone_times(raw, notes)
    if len(times) < 2:
        return times, float("nan")
    dt = np.diff(times)
    positive = dt[dt > 0]
    if not len(positive):
        notes.append("all rows have the same time stamp; rate unknown")
        return times, float("nan")
    median = float(np.median(positive))
    gaps = dt > GAP_FACTOR * median
    if gaps.any():
        notes.append(f"{int(gaps.sum())} dropped-frame gaps, longest {1000 * dt.max():.0f} ms "
                     f"(interval > {GAP_FACTOR}x the median {1000 * median:.1f} ms)")
    repeated = int(np.sum(dt == 0))
    if repeated:
        notes.append(f"{repeated} repeated frames (same {unit_label} as the row before)")
    backward = int(np.sum(dt < 0))
    if backward:
        notes.append(f"{backward} backward time steps (rows out of time order)")
    return times, 1.0 / median


def _state_confidence(states: np.ndarray, missing: np.ndarray) -> np.ndarray:
    confidence = np.select([states == 2, states == 1], [1.0, 0.5], 0.0)
    confidence[missing] = 0.0
    return confidence


# -- headerless Kinect v2 / v1 CSV --------------------------------------------------------
def _read_kinect_csv(path, text, idx, notes, layout, fps, units) -> _Parsed:
    names = kl.KINECT_V2 if layout == "kinect_v2_csv" else kl.KINECT_V1
    n = len(names)
    counts, (parsed,), _ = _parse_rows(path, text, idx, _csv_fields, 1 + 4 * n, [None],
                                       plain=",")
    idx, skipped = _check_counts(counts, idx, 1 + 4 * n, path, notes, "values")
    if not len(idx):
        raise UnreadableFileError(path, "no complete data line")
    values = _kept(parsed, len(idx))
    ticks, block = values[:, 0], values[:, 1:].reshape(len(idx), n, 4)
    states = block[..., 3]
    bad_state = ~np.isin(states, (0.0, 1.0, 2.0))
    if bad_state.any():
        t, j = np.argwhere(bad_state)[0]
        raise UnreadableFileError(path, f"tracking state {states[t, j]:g} of {names[j]} is not "
                                        f"0, 1 or 2", line=int(idx[t]) + 1)
    if not np.isfinite(ticks).all():
        t = int(np.nonzero(~np.isfinite(ticks))[0][0])
        raise UnreadableFileError(path, "timestamp is not a number", line=int(idx[t]) + 1)
    coords = block[..., :3]
    missing = (states == 0) | _nonfinite_missing(coords, notes)
    fractional = ticks != np.round(ticks)
    if fractional.any():
        t = int(np.flatnonzero(fractional)[0])
        raise UnreadableFileError(path, f"time stamp {ticks[t]:g} is not a whole number (100 ns "
                                        "ticks or milliseconds expected)", line=int(idx[t]) + 1)
    times, file_fps = _timing((ticks - np.median(ticks)) * _stamp_scale(ticks, notes), notes)
    T = len(idx)
    j = np.arange(n)
    return _Parsed(
        names=list(names), coords=coords, missing=missing,
        confidence=_state_confidence(states.astype(int), missing),
        line_of=np.broadcast_to(idx[:, None], (T, n)),
        coord_field=np.broadcast_to(1 + 4 * j[:, None] + np.arange(3), (T, n, 3)),
        state_field=np.broadcast_to(4 + 4 * j, (T, n)), state_kind="tracking",
        sep=",", times=times, file_fps=_or_default(file_fps, DEFAULT_FPS, notes),
        skeleton=kl.skeleton_for("kinect_v2" if n == 25 else "kinect_v1"), skip_lines=skipped,
        extra={"ticks0": float(ticks[0])})


#: a median step of the headerless CSV's stamps below this is not 100 ns ticks (that
#: would be over 10 kHz) but milliseconds
MS_STAMP_STEP = 1000.0


def _stamp_scale(stamps: np.ndarray, notes: list[str]) -> float:
    """Seconds per unit of the headerless Kinect CSV's time stamps: 100 ns ticks (the
    KinectReader's), or milliseconds when their median step is below ``MS_STAMP_STEP`` --
    the LabanotationSuite's own reader (``LabanEditor/src/kinect.py``) takes such stamps
    ("yamada data", 0, 33, 67, ...) as milliseconds; as ticks they gave ~300 000 fps and
    the file was refused as a corrupt time column."""
    dt = np.diff(stamps)
    dt = dt[dt > 0]
    if len(dt) and float(np.median(dt)) < MS_STAMP_STEP:
        notes.append(f"time stamps read as milliseconds (median step {float(np.median(dt)):g}; "
                     "as 100 ns ticks that would be over 10 kHz)")
        return 1e-3
    return 1e-7


def _or_default(value: float, default: float, notes: list[str]) -> float:
    if np.isfinite(value) and value > 0:
        return float(value)
    notes.append(RateAssumed(f"frame rate unknown; assumed {default:g} fps"))
    return default


# -- UTKinect -------------------------------------------------------------------------------
def _read_utkinect(path, text, idx, notes, layout, fps, units) -> _Parsed:
    names = kl.KINECT_V1
    n = len(names)
    counts, (parsed,), _ = _parse_rows(path, text, idx, str.split, 1 + 3 * n, [None],
                                       plain=" ")
    idx, skipped = _check_counts(counts, idx, 1 + 3 * n, path, notes, "values")
    if not len(idx):
        raise UnreadableFileError(path, "no complete data line")
    values = _kept(parsed, len(idx))
    index = values[:, 0]
    bad = ~(np.isfinite(index) & (index == np.round(index)))
    if bad.any():
        k = int(np.nonzero(bad)[0][0])
        raise UnreadableFileError(path, "frame index is not an integer", line=int(idx[k]) + 1)
    coords = values[:, 1:].reshape(len(idx), n, 3)
    missing = _nonfinite_missing(coords, notes)
    jumps = np.diff(index)
    if len(jumps):
        notes.append(f"frame index (30 Hz camera frames) runs {index[0]:.0f}-{index[-1]:.0f}: "
                     f"{int(np.sum(jumps > 1))} jumps > 1 (largest {jumps.max():.0f}), "
                     f"{int(np.sum(jumps == 0))} repeated indices")
    times, file_fps = _timing((index - np.median(index)) / UTKINECT_FPS, notes,
                              unit_label="frame index")
    T = len(idx)
    j = np.arange(n)
    return _Parsed(
        names=list(names), coords=coords, missing=missing, confidence=None,
        line_of=np.broadcast_to(idx[:, None], (T, n)),
        coord_field=np.broadcast_to(1 + 3 * j[:, None] + np.arange(3), (T, n, 3)),
        state_field=np.broadcast_to(-1, (T, n)), state_kind=None, sep=None, times=times,
        file_fps=_or_default(file_fps, UTKINECT_FPS, notes),
        skeleton=kl.skeleton_for("kinect_v1"), skip_lines=skipped,
        extra={"index0": float(index[0])})


# -- MSR Action3D -----------------------------------------------------------------------
def _read_msr(path, text, idx, notes, layout, fps, units) -> _Parsed:
    names = kl.MSR_ACTION3D
    n = len(names)
    counts, (parsed,), _ = _parse_rows(path, text, idx, str.split, 4, [None], plain=" ")
    idx, skipped = _check_counts(counts, idx, 4, path, notes, "values")
    partial = len(idx) % n
    if partial:
        notes.append(f"last frame is incomplete ({partial} of {n} rows): the file looks "
                     "truncated; that frame was dropped")
        skipped += idx[len(idx) - partial:].tolist()
        idx = idx[:len(idx) - partial]
    if not len(idx):
        raise UnreadableFileError(path, f"no complete frame of {n} rows")
    block = _kept(parsed, len(idx)).reshape(-1, n, 4)
    coords, conf = block[..., :3], block[..., 3]
    finite = np.isfinite(coords).all(axis=2)
    if finite.any() and np.median(np.abs(coords[finite][:, :2])) > 20:
        raise UnsupportedFeatureError(path, "MSR Action3D screen-coordinates variant (u, v, "
                                            "depth): only the real-world (metres) files are read")
    bad_conf = ~((conf >= 0) & (conf <= 1))
    if bad_conf.any():
        k = int(np.argwhere(bad_conf)[0][0] * n + np.argwhere(bad_conf)[0][1])
        raise UnreadableFileError(path, "confidence (4th value) is not in [0, 1]",
                                  line=int(idx[k]) + 1)
    zero = finite & (coords == 0).all(axis=2)
    missing = ~finite | zero
    if (~finite).any():
        notes.append(f"{int((~finite).sum())} samples with nan/inf coordinates read as missing")
    if zero.any():
        notes.append(f"{int(zero.sum())} samples at (0, 0, 0) read as missing")
    low = int(np.sum((conf == 0) & ~missing))
    if low:
        notes.append(f"{low} samples with confidence 0 kept as low-confidence (not missing)")
    notes.append(RateAssumed(f"MSR Action3D files hold no timing; nominal {MSR_FPS:g} fps assumed"))
    confidence = conf.copy()
    confidence[missing] = 0.0
    T = block.shape[0]
    line_of = np.asarray(idx).reshape(T, n)
    return _Parsed(
        names=list(names), coords=coords, missing=missing, confidence=confidence,
        line_of=line_of, coord_field=np.broadcast_to(np.arange(3), (T, n, 3)),
        state_field=np.broadcast_to(3, (T, n)), state_kind="confidence", sep=None, times=None,
        file_fps=MSR_FPS, skeleton=kl.skeleton_for("msr_action3d"), skip_lines=skipped)


# -- headed layouts: shared helpers ---------------------------------------------------------
def _clean_header(name: str) -> str:
    return name.strip().strip('"').strip("'").strip()


def _header_sep(line: str) -> str:
    return max((",", ";", "\t"), key=line.count) if any(c in line for c in ",;\t") else " "


def _wide_columns(columns: list[str]):
    """joint -> {role: column}, the time/frame column (index, kind), unit tags seen."""
    joints: dict[str, dict[str, int]] = {}
    unit_tags = set()
    clocks = []
    for c, name in enumerate(columns):
        key = _norm(re.sub(r"[\[(][a-z]+[\])]\s*$", "", name, flags=re.I))
        if key in _TIME_NAMES or key in _FRAME_NAMES or key.startswith("time"):
            clocks.append((c, _time_kind(name)))
            continue
        m = _AXIS_COLUMN.match(name)
        if not m:
            continue
        role = _norm(m.group("role"))
        role = {"trackingstate": "state", "conf": "confidence"}.get(role, role)
        joints.setdefault(m.group("joint").strip(), {})[role] = c
        if m.group("unit") and role in "xyz":
            unit_tags.add(m.group("unit").lower())
    timed = [clock for clock in clocks if clock[1] != "frame"]
    time_col = (timed or clocks or [None])[0]
    return joints, time_col, unit_tags


def _time_kind(name: str) -> str:
    """'frame', 's', 'ms', 'us', 'ticks' or 'auto' (decide by magnitude)."""
    key = _norm(name)
    if key in _FRAME_NAMES:
        return "frame"
    if "tick" in key:
        return "ticks"
    if key.endswith("ms") or "(ms)" in name.lower() or "[ms]" in name.lower():
        return "ms"
    if key.endswith("us"):
        return "us"
    if key in ("seconds", "sec", "secs") or key.endswith("(s)") or "[s]" in name.lower() \
            or key in ("times", "ts"):
        return "s"
    return "auto"


def _times_from_column(values: np.ndarray, kind: str, fps: float | None, notes) -> np.ndarray:
    """Seconds from an arbitrary origin (:func:`_timing` puts the first row at 0):
    relative to the median stamp, so one corrupt stamp (1e23) costs no precision."""
    rel = values - np.median(values)
    if kind == "frame":
        rate = fps or DEFAULT_FPS
        notes.append(RateAssumed(f"frame numbers but no time column: {DEFAULT_FPS:g} fps assumed"))
        return rel / rate
    scale = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ticks": 1e-7}.get(kind)
    if scale is None:
        dt = np.diff(values)
        dt = dt[dt > 0]
        median = float(np.median(dt)) if len(dt) else 1.0
        if median < 1.0:
            scale, label = 1.0, "seconds"
        elif median < 1e3:
            scale, label = 1e-3, "milliseconds"
        elif median < 1e5:
            scale, label = 1e-6, "microseconds"
        else:
            scale, label = 1e-7, "100 ns ticks (Kinect)"
        notes.append(f"time column unit not stated; read as {label} from its median step "
                     f"{median:g}")
    return rel * scale


def _seen_bone_lengths(coords: np.ndarray, missing: np.ndarray, bones: np.ndarray) -> np.ndarray:
    """(T, B) length of each bone, NaN where either end is missing: a bone at a time (the
    whole-take positions with NaN, both ends' (T, B, 3) and their difference were ~100
    bytes a sample at the reader's peak)."""
    def seen(j):
        return np.where(missing[:, j, None], np.nan, coords[:, j])
    lengths = np.empty((coords.shape[0], len(bones)))
    for b, (parent, child) in enumerate(bones.tolist()):
        lengths[:, b] = np.linalg.norm(seen(parent) - seen(child), axis=-1)
    return lengths


def _guess_units(coords, missing, skeleton, tags, units, notes, path) -> str:
    """Length unit of a headed file: ``units=`` option > header tag > magnitude guess."""
    if units:
        unit = normalise_unit_name(units)
        if unit is None:
            raise UnreadableFileError(path, f"unknown length unit {units!r}")
        return unit
    if tags:
        unit = normalise_unit_name(sorted(tags)[0])
        if unit is None or len(tags) > 1:
            raise UnreadableFileError(path, f"unknown or mixed unit tags in header: {sorted(tags)}")
        return unit
    if skeleton is not None and len(skeleton.bones):
        lengths = _seen_bone_lengths(coords, missing, skeleton.bone_array)
        scale, what, limits = np.nanmedian(lengths), "median bone length", (2.0, 100.0)
    else:
        pts = np.where(missing[..., None], np.nan, coords)
        centre = np.nanmean(pts, axis=1, keepdims=True) if pts.shape[1] > 2 else 0.0
        scale = np.nanmedian(np.linalg.norm(pts - centre, axis=2))
        what, limits = "median spread of the joints", (3.0, 150.0)
    if not np.isfinite(scale):
        return "m"
    unit = "m" if scale < limits[0] else ("cm" if scale < limits[1] else "mm")
    notes.append(f"units not stated; {unit} guessed from the {what} ({scale:.3g}); "
                 "pass units= to override")
    return unit


def _data_rows(path, text, idx, sep, n_columns, notes, groups, label=None):
    """:func:`_parse_rows` of a headed layout's data lines (a trailing empty field past
    the header's columns dropped), then :func:`_check_counts`."""
    def split(line):
        r = _splitter(sep)(line)
        return r[:-1] if len(r) == n_columns + 1 and not r[-1].strip() else r

    counts, parsed, labels = _parse_rows(path, text, idx, split, n_columns, groups,
                                         clean=True, label=label)
    idx, skipped = _check_counts(counts, idx, n_columns, path, notes, "columns")
    return idx, skipped, parsed, labels


# -- headed wide CSV ------------------------------------------------------------------------
def _read_wide(path, text, idx, notes, layout, fps, units) -> _Parsed:
    header_i, data_idx = int(idx[0]), idx[1:]
    header = text.line(header_i)
    sep = _header_sep(header)
    columns = [_clean_header(c) for c in _splitter(sep)(header)]
    joints, time_col, tags = _wide_columns(columns)
    for joint, roles in joints.items():
        lacking = {"x", "y", "z"} - set(roles)
        if lacking and lacking != {"x", "y", "z"}:
            raise UnreadableFileError(path, f"joint {joint!r} lacks column(s) "
                                            f"{', '.join(sorted(lacking)).upper()}",
                                      line=header_i + 1)
    names = [j for j, r in joints.items() if "x" in r]
    if not len(data_idx):
        raise UnreadableFileError(path, "header but no data rows")
    coord_cols = np.array([[joints[n][a] for a in "xyz"] for n in names]).reshape(-1, 3)
    state = next(((kind, role) for kind, role in (("tracking", "state"),
                                                  ("confidence", "confidence"))
                  if any(role in joints[n] for n in names)), None)
    have = [j for j, n in enumerate(names) if state and state[1] in joints[n]]
    state_cols = [joints[names[j]][state[1]] for j in have]
    groups = [coord_cols.ravel(), state_cols, [] if time_col is None else [time_col[0]]]
    data_idx, skipped, (coord_values, state_values, time_values), _ = _data_rows(
        path, text, data_idx, sep, len(columns), notes, groups)
    if not len(data_idx):
        raise UnreadableFileError(path, "no complete data row")
    if time_col is not None:
        _refuse_bodies_sharing_a_time(path, text, data_idx, sep, columns, time_col[0])
    T, J = len(data_idx), len(names)
    coords = _kept(coord_values, T).reshape(T, J, 3)
    missing = ~np.isfinite(coords).all(axis=2)
    empty_or_nan = int(missing.sum())
    state_kind, state_field, confidence = _wide_states(state_values, state, have, state_cols,
                                                        data_idx, names, path,
                                                        missing,  # NotTracked -> missing
                                                        coords=coords, notes=notes)
    if empty_or_nan:
        notes.append(f"{empty_or_nan} samples with empty/nan/inf cells read as missing")
    match = kl.match_joint_set(names)
    skeleton = match[1] if match else None
    if match:
        notes.append(f"joint names match the {match[0]} set: its bone topology is used")
    unit = _guess_units(coords, missing, skeleton, tags, units, notes, path)
    times, file_fps = _wide_times(time_values, data_idx, time_col, fps, path, notes,
                                  text=text, sep=sep)
    extra_cols = len(columns) - 3 * J - (time_col is not None) - int(np.sum(state_field[0] >= 0))
    if extra_cols > 0:
        notes.append(f"{extra_cols} other columns kept as they are")
    return _Parsed(
        names=names, coords=coords, missing=missing, confidence=confidence,
        line_of=np.broadcast_to(data_idx[:, None], (T, J)),
        coord_field=np.broadcast_to(coord_cols, (T, J, 3)), state_field=state_field,
        state_kind=state_kind, sep=None if sep == " " else sep, times=times, file_fps=file_fps,
        units=unit, skeleton=skeleton, skip_lines=skipped)


def _splitter(sep: str):
    """The fields of a line of a file separated by ``sep`` (``" "``: any run of blanks)."""
    return str.split if sep == " " else (lambda line: line.split(sep))


def _column_cells(text: TextLines, idx, sep, cols: tuple[int, ...]):
    """The cells of the columns ``cols`` of the lines ``idx`` (a tuple a line), blanks and
    quotes stripped, a list per :data:`CHUNK` lines (a long file is not held as lines)."""
    split = _splitter(sep)
    for a in range(0, len(idx), CHUNK):
        rows = (split(line) for line in text.lines_at(idx[a:a + CHUNK]))
        yield [tuple(cells[c].strip().strip('"') for c in cols) for cells in rows]


def _refuse_bodies_sharing_a_time(path, text: TextLines, idx, sep, columns, key_col: int):
    """Refuse a file whose body/user column (``_BODY_NAMES``) holds two bodies at one
    time stamp or frame: one row per body per frame (Nuitrack's CSV recorder, one row per
    tracked user) was read as one body jumping between them, with "repeated frames". A
    column with a different value on every row is a row number, not a body."""
    body_cols = [c for c, name in enumerate(columns) if _norm(name) in _BODY_NAMES]
    if not body_cols:
        return
    col = body_cols[0]
    pairs = [pair for chunk in _column_cells(text, idx, sep, (key_col, col)) for pair in chunk]
    keys, bodies = [k for k, _ in pairs], [b for _, b in pairs]
    if len(set(bodies)) in (1, len(bodies)):
        return
    seen: dict[str, str] = {}
    for k, (key, body) in enumerate(zip(keys, bodies)):
        first = seen.setdefault(key, body)
        if first != body:
            raise UnsupportedFeatureError(
                path, f"more than one body per frame: column {columns[col]!r} holds "
                      f"{first!r} and {body!r} at {columns[key_col]} {key}; one body per "
                      f"file is read (split the file by {columns[col]!r} first)",
                line=int(idx[k]) + 1)


def _wide_states(parsed, state, have, cols, idx, names, path, missing, coords=None, notes=None):
    """Per-joint state (0/1/2) or confidence columns (``state``: (kind, role) of the
    first role any joint has; ``have``: the joints with one, at columns ``cols``); joints
    without one count as tracked. A sample at exactly (0, 0, 0) with confidence 0 is
    missing (LSL-Kinect writes a frame without its body as zeros with confidence 0: the
    body read as present at the camera's origin)."""
    T, J = missing.shape
    if state is not None:
        kind = state[0]
        values = _kept(parsed, T).reshape(T, len(have))
        field_index = np.full(J, -1, dtype=np.intp)
        field_index[have] = cols
        field_index = np.broadcast_to(field_index, (T, J))
        confidence = np.ones((T, J))
        if kind == "tracking":
            bad = ~np.isin(values, (0.0, 1.0, 2.0)) & ~missing[:, have]
            if bad.any():
                t, k = np.argwhere(bad)[0]
                raise UnreadableFileError(path, f"tracking state {values[t, k]:g} of "
                                                f"{names[have[k]]} is not 0, 1 or 2",
                                          line=int(idx[t]) + 1)
            states = np.nan_to_num(values, nan=0.0).astype(int)
            missing[:, have] |= states == 0
            confidence[:, have] = _state_confidence(states, missing[:, have])
        else:
            confidence[:, have] = np.clip(np.nan_to_num(values, nan=0.0), 0.0, 1.0)
            if coords is not None:
                zero = (values == 0) & (coords[:, have] == 0).all(axis=2) & ~missing[:, have]
                if zero.any():
                    missing[:, have] |= zero
                    if notes is not None:
                        notes.append(f"{int(zero.sum())} samples at (0, 0, 0) with confidence 0 "
                                     "read as missing")
        confidence[missing] = 0.0
        return kind, field_index, confidence
    return None, np.broadcast_to(-1, (T, J)), None


#: a date and time in a time column (LSL-Kinect's "TimeSpan": 2020-07-03 16:01:47.123)
_DATE_TIME = re.compile(r"^\d{4}-\d\d-\d\d[ T]\d\d:\d\d(:\d\d(\.\d+)?)?$")


def _date_times(text: TextLines, idx: np.ndarray, sep, col: int) -> np.ndarray | None:
    """Seconds since the first row's stamp of a time column of ISO dates and times, or
    None when a cell of it is not one."""
    stamps = np.empty(len(idx), "datetime64[us]")
    a = 0
    for chunk in _column_cells(text, idx, sep, (col,)):
        cells = [c for c, in chunk]
        if not all(_DATE_TIME.match(c) for c in cells):
            return None
        stamps[a:a + len(cells)] = np.array(cells, dtype="datetime64[us]")
        a += len(cells)
    return (stamps - stamps[0]) / np.timedelta64(1, "us") * 1e-6


def _wide_times(parsed, idx, time_col, fps, path, notes, text=None, sep=None):
    if time_col is None:
        rate = fps or DEFAULT_FPS
        notes.append(RateAssumed(f"no time column: {DEFAULT_FPS:g} fps assumed"))
        return None, rate
    kind = time_col[1]
    error = parsed[1]
    clock = None
    if error is not None and error[1] < len(idx) and text is not None:
        clock = _date_times(text, idx, sep, time_col[0])
        if clock is not None:
            kind = "s"
            notes.append("time column holds dates and times (yyyy-mm-dd hh:mm:ss.fff): "
                         "read to the microsecond")
    values = _kept(parsed, len(idx))[:, 0] if clock is None else clock
    if not np.isfinite(values).all():
        k = int(np.nonzero(~np.isfinite(values))[0][0])
        raise UnreadableFileError(path, "empty or non-numeric time/frame value",
                                  line=int(idx[k]) + 1)
    times, file_fps = _timing(_times_from_column(values, kind, fps, notes), notes)
    return times, _or_default(file_fps, fps or DEFAULT_FPS, notes)


# -- long layout (one row per joint per frame) --------------------------------------------
def _long_columns(columns: list[str]) -> dict | None:
    keys = [_norm(re.sub(r"[\[(][a-z]+[\])]\s*$", "", c, flags=re.I)) for c in columns]
    roles: dict[str, int] = {}
    for c, key in enumerate(keys):
        if key in ("x", "y", "z", "posx", "posy", "posz", "positionx", "positiony", "positionz"):
            roles.setdefault(key[-1], c)
        elif key in _JOINT_NAMES:
            roles.setdefault("joint", c)
        elif key in _FRAME_NAMES:
            roles.setdefault("frame", c)
        elif key in _TIME_NAMES or key.startswith("time"):
            roles.setdefault("time", c)
        elif key in _STATE_NAMES:
            roles.setdefault("state", c)
        elif key in _CONF_NAMES:
            roles.setdefault("confidence", c)
    if not {"x", "y", "z", "joint"} <= set(roles) or not ({"frame", "time"} & set(roles)):
        return None
    return roles


def _read_long(path, text, idx, notes, layout, fps, units) -> _Parsed:
    header_i, data_idx = int(idx[0]), idx[1:]
    header = text.line(header_i)
    sep = _header_sep(header)
    columns = [_clean_header(c) for c in _splitter(sep)(header)]
    roles = _long_columns(columns)
    if not len(data_idx):
        raise UnreadableFileError(path, "header but no data rows")
    key_col = roles.get("frame", roles.get("time"))
    state_col = roles.get("state", roles.get("confidence", -1))
    groups = [[key_col], [roles["x"], roles["y"], roles["z"]], [state_col] if state_col >= 0 else []]
    data_idx, skipped, (key_values, xyz_values, state_values), (joint_of_row, names) = \
        _data_rows(path, text, data_idx, sep, len(columns), notes, groups, label=roles["joint"])
    if not len(data_idx):
        raise UnreadableFileError(path, "no complete data row")
    n_rows = len(data_idx)
    keys = _kept(key_values, n_rows)[:, 0]
    if not np.isfinite(keys).all():
        k = int(np.nonzero(~np.isfinite(keys))[0][0])
        raise UnreadableFileError(path, "empty or non-numeric frame value",
                                  line=int(data_idx[k]) + 1)
    frame_keys, frame_of_row = np.unique(keys, return_inverse=True)
    joint_of_row = joint_of_row[:n_rows]
    names = names[:int(joint_of_row.max()) + 1]
    T, J = len(frame_keys), len(names)
    line_of = np.full((T, J), -1, dtype=np.intp)
    flat = frame_of_row * J + joint_of_row
    dup = np.nonzero(np.bincount(flat, minlength=T * J) > 1)[0]
    if len(dup):
        row = int(np.nonzero(flat == dup[0])[0][1])
        bodies = [c for c in columns if _norm(c) in _BODY_NAMES]
        if bodies:
            _refuse_bodies_sharing_a_time(path, text, data_idx, sep, columns, key_col)
        raise UnreadableFileError(path, f"second row for joint {names[joint_of_row[row]]!r} in "
                                        "the same frame", line=int(data_idx[row]) + 1)
    line_of.ravel()[flat] = np.asarray(data_idx)
    values = _kept(xyz_values, n_rows)
    coords = np.full((T, J, 3), np.nan)
    coords.reshape(T * J, 3)[flat] = values.reshape(-1, 3)
    absent = line_of < 0
    missing = ~np.isfinite(coords).all(axis=2)
    if absent.any():
        notes.append(f"{int(absent.sum())} joint samples have no row (missing)")
    state_kind, confidence = None, None
    if state_col >= 0:
        state_kind = "tracking" if "state" in roles else "confidence"
        raw = np.full(T * J, np.nan)
        raw[flat] = _kept(state_values, n_rows)[:, 0]
        raw = raw.reshape(T, J)
        if state_kind == "tracking":
            bad = ~np.isin(raw, (0.0, 1.0, 2.0)) & ~absent & ~np.isnan(raw)
            if bad.any():
                t, j = np.argwhere(bad)[0]
                raise UnreadableFileError(path, f"tracking state {raw[t, j]:g} is not 0, 1 or 2",
                                          line=int(line_of[t, j]) + 1)
            states = np.nan_to_num(raw, nan=0.0).astype(int)
            missing |= states == 0
            confidence = _state_confidence(states, missing)
        else:
            confidence = np.clip(np.nan_to_num(raw, nan=0.0), 0.0, 1.0)
            confidence[missing] = 0.0
    match = kl.match_joint_set(names)
    skeleton = match[1] if match else None
    if match:
        notes.append(f"joint names match the {match[0]} set: its bone topology is used")
    unit = _guess_units(coords, missing, skeleton, _long_unit_tags(columns, roles), units,
                        notes, path)
    kind = "frame" if "frame" in roles else _time_kind(columns[key_col])
    times, file_fps = _timing(_times_from_column(frame_keys, kind, fps, notes), notes)
    file_fps = _or_default(file_fps, fps or DEFAULT_FPS, notes)
    last_line = np.full(T, -1, dtype=np.intp)
    np.maximum.at(last_line, frame_of_row, np.asarray(data_idx))
    _, first_row = np.unique(keys, return_index=True)
    split = _splitter(sep)
    frame_tokens = [split(line)[key_col].strip() for line in text.lines_at(data_idx[first_row])]
    return _Parsed(
        names=names, coords=coords,
        missing=missing, confidence=confidence, line_of=line_of,
        coord_field=np.broadcast_to(np.array([roles["x"], roles["y"], roles["z"]]), (T, J, 3)),
        state_field=np.broadcast_to(state_col, (T, J)), state_kind=state_kind,
        sep=None if sep == " " else sep, times=times, file_fps=file_fps, units=unit,
        skeleton=skeleton, skip_lines=skipped,
        extra={"frame_last_line": last_line, "frame_tokens": frame_tokens,
               "n_columns": len(columns), "key_col": key_col, "joint_col": roles["joint"]})


def _long_unit_tags(columns, roles) -> set:
    tags = set()
    for axis in "xyz":
        m = re.search(r"[\[(]([a-z]+)[\])]\s*$", columns[roles[axis]], flags=re.I)
        if m:
            tags.add(m.group(1).lower())
    return tags


#: layout name -> reader (used by :func:`read`)
_READERS = {
    "kinect_v2_csv": _read_kinect_csv, "kinect_v1_csv": _read_kinect_csv,
    "utkinect": _read_utkinect, "msr_action3d": _read_msr,
    "wide_csv": _read_wide, "long_csv": _read_long,
}


# ---------------------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------------------
def kept_only_here(motion: Motion) -> list[str]:
    """What of a motion read from a Kinect file no other format carries: the tracking
    state (or confidence) of each sample. For :func:`mocapfix.formats.losses`."""
    source = motion.source
    if isinstance(source, KinectSource) and source.state_kind is not None:
        return [f"the {source.state_kind} {'state' if source.state_kind == 'tracking' else 'value'}"
                " of each sample is not carried (inferred samples are written as positions)"]
    return []


def write(motion: Motion, path, **options) -> list[Path]:
    """Write ``motion`` in the layout it was read from (see the module docstring)."""
    path = Path(path)
    source = motion.source
    if isinstance(source, KinectSource) and _fits(source, motion):
        return write_output_pieces(path, _patched_pieces(source, motion))
    return write_output_pieces(path, _wide_csv_pieces(motion))


def _fits(source: KinectSource, motion: Motion) -> bool:
    return source.original.shape == motion.positions.shape and source.names == list(motion.names)


def _format_like(value: float, token: str) -> str:
    """``value`` with at least 6 decimals, and at least as many as ``token`` had."""
    token = token.strip()
    decimals = len(token.split(".", 1)[1]) if "." in token and "e" not in token.lower() else 0
    if "e" in token.lower():
        return f"{value:.9g}"
    return f"{value:.{max(6, decimals)}f}"


def _changed(source: KinectSource, motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """(T, J) masks: the samples whose stored tokens must change (moved, filled or
    removed), and the samples missing in ``motion``."""
    return samples_to_rewrite(source.original, motion.positions, source.missing)


#: what keeps a line of a headerless Kinect CSV out of :func:`_fast_csv_text`'s bulk
#: rewrite: a character other than digits, signs, points and commas (an exponent, a blank
#: around a cell, "nan"). On the other lines each rewritten coordinate is exactly
#: ``f"{v:.{max(6, d)}f}"`` with ``d`` the characters after its old token's first point,
#: and each state cell a bare digit.
_NOT_PLAIN = re.compile(r"[^0-9.,+\n-]")


def _all_bare(tokens: list[str]) -> bool:
    """True when no token has an exponent or a blank (``str.isspace``) in it: ASCII text
    searched for each such character (a scan in C each), anything else not vouched for."""
    joined = "".join(tokens)
    return joined.isascii() and not any(c in joined for c in "eE \t\r\x0b\x0c\x1c\x1d\x1e\x1f")

#: a number with more than 6 decimals: its rewrite keeps its own count (the others get 6)
_LONG_DECIMALS = re.compile(r"\.[0-9]{7}")


def _plain_lines(lines: list[str], pattern: re.Pattern = _NOT_PLAIN) -> np.ndarray:
    """(len(lines),) True where a line has nothing ``pattern`` matches (one scan of the
    joined text: a regex call per line costs more than the rewrite it guards)."""
    text = "\n".join(lines)
    sizes = np.fromiter(map(len, lines), np.int64, len(lines)) + 1
    starts = np.cumsum(sizes) - sizes
    hits = [m.start() for m in pattern.finditer(text)]
    plain = np.ones(len(lines), bool)
    plain[np.searchsorted(starts, hits, side="right") - 1] = False
    return plain


def _rewrite_whole_rows(fields: list[list[str]], values: np.ndarray, J: int) -> list[str]:
    """Lines whose every sample moved (states kept) and whose numbers have at most 6
    decimals: each coordinate token becomes ``%.6f`` of its new value, in one format call
    for all of them, placed by list slices (no per-token object)."""
    text = ("%.6f," * values.size) % tuple(values.ravel().tolist())
    parts = text.split(",")
    out = []
    for k, tokens in enumerate(fields):
        at = 3 * J * k
        tokens[1:1 + 4 * J:4] = parts[at:at + 3 * J:3]
        tokens[2:2 + 4 * J:4] = parts[at + 1:at + 3 * J:3]
        tokens[3:3 + 4 * J:4] = parts[at + 2:at + 3 * J:3]
        out.append(",".join(tokens))
    return out


def _fast_csv_edits(source: KinectSource, motion: Motion):
    """(line, new text) of :func:`_edited_pieces` for the headerless Kinect CSVs (one line
    per frame, fields at fixed places), CHUNK changed lines at a time, without a Python
    object per sample. Lines whose tokens are plain numbers (see ``_NOT_PLAIN``) are
    rewritten in bulk -- one ``%`` format per number of decimals for all their new
    coordinates, cells placed by numpy indexing; the others token by token
    (:func:`_patch_csv_line`)."""
    new = motion.positions
    changed, new_missing = _changed(source, motion)
    J = new.shape[1]
    for a in range(0, len(changed), CHUNK):
        rows = a + np.flatnonzero(changed[a:a + CHUNK].any(axis=1))
        if not len(rows):
            continue
        line_of = source.line_of[rows, 0]
        lines = source.text.lines_at(line_of)
        yield from zip(line_of.tolist(), _fast_csv_lines(lines, rows, source, new, changed,
                                                          new_missing, J))


def _fast_csv_lines(lines, rows, source, new, changed, new_missing, J) -> list[str]:
    """The new text of ``lines``, the lines of frames ``rows``."""
    fields = [line.split(",") for line in lines]
    lines = list(lines)
    bulk = _plain_lines(lines)
    bulk &= np.array([len(f) >= 1 + 4 * J for f in fields], bool)
    for r in np.flatnonzero(~bulk):
        lines[r] = _patch_csv_line(fields[r], new[rows[r]], new_missing[rows[r]],
                                   source.missing[rows[r]], changed[rows[r]])
    # lines where every sample moved and no state changes: rewritten whole
    whole = bulk & changed[rows].all(axis=1) & ~new_missing[rows].any(axis=1)
    whole &= ~source.missing[rows].any(axis=1)
    if whole.any():
        w = np.flatnonzero(whole)
        w = w[_plain_lines([lines[i] for i in w], _LONG_DECIMALS)]
        for i, line in zip(w, _rewrite_whole_rows([fields[i] for i in w], new[rows[w]], J)):
            lines[i] = line
        bulk[w] = False
    if bulk.any():
        b = np.flatnonzero(bulk)
        cells = np.array([f[:1 + 4 * J] for f in (fields[i] for i in b)], dtype=object)
        edit = changed[rows[b]]
        removed = edit & new_missing[rows[b]]
        moved = edit & ~removed
        r, j = np.nonzero(moved)
        r, coords = np.repeat(r, 3), ((1 + 4 * j)[:, None] + np.arange(3)).ravel()
        cells[r, coords] = _formatted(cells[r, coords].tolist(), new[rows[b]][moved].ravel())
        r, j = np.nonzero(removed)
        cells[r, 4 + 4 * j] = "0"
        r, j = np.nonzero(moved & source.missing[rows[b]])
        cells[r, 4 + 4 * j] = "1"
        for k, i in enumerate(b):
            lines[i] = ",".join(cells[k].tolist() + fields[i][1 + 4 * J:])
    return lines


def _formatted(old: list[str], values: np.ndarray) -> list[str]:
    """``values`` as :func:`_format_like` writes them in place of the plain number tokens
    ``old`` (no exponent, no blanks): one ``%`` format per number of decimals."""
    dot = np.fromiter(map(str.find, old, repeat(".")), np.int64, len(old))
    size = np.fromiter(map(len, old), np.int64, len(old))
    decimals = np.maximum(np.where(dot < 0, 0, size - dot - 1), 6)
    out = np.empty(len(old), object)
    for d in np.unique(decimals):
        at = np.flatnonzero(decimals == d)
        text = (f"%.{d}f," * len(at)) % tuple(values[at].tolist())
        out[at] = text.split(",")[:-1]
    return out.tolist()


def _patch_csv_line(fields: list[str], values, removed, filled, edit) -> str:
    """One headerless Kinect CSV line with the edited samples' tokens rewritten (joint j
    at fields 1 + 4j .. 4 + 4j: x, y, z, tracking state)."""
    for j in np.flatnonzero(edit).tolist():
        f0 = 1 + 4 * j
        if removed[j]:                                      # removed: NotTracked
            fields[f0 + 3] = _pad(fields[f0 + 3], "0")
            continue
        v = values[j].tolist()
        for k in range(3):
            tok = fields[f0 + k]
            if "e" in tok or "E" in tok or tok != tok.strip():
                fields[f0 + k] = _pad(tok, _format_like(v[k], tok))
            else:
                dot = tok.find(".")
                d = 0 if dot < 0 else len(tok) - dot - 1
                fields[f0 + k] = f"{v[k]:.{d if d > 6 else 6}f}"
        if filled[j]:                                       # filled: Inferred
            fields[f0 + 3] = _pad(fields[f0 + 3], "1")
    return ",".join(fields)


def _patched_pieces(source: KinectSource, motion: Motion):
    if source.layout in ("kinect_v2_csv", "kinect_v1_csv") and source.sep == ",":
        return source.text.pieces(_fast_csv_edits(source, motion), source.skip_lines)
    return _edited_pieces(source, motion)


def _patched_text(source: KinectSource, motion: Motion) -> str:
    """What :func:`write` writes for a motion that fits its source, as one string."""
    return b"".join(_patched_pieces(source, motion)).decode("utf-8")


def _fast_csv_text(source: KinectSource, motion: Motion) -> str:
    return b"".join(source.text.pieces(_fast_csv_edits(source, motion),
                                       source.skip_lines)).decode("utf-8")


def _edited_text(source: KinectSource, motion: Motion) -> str:
    return b"".join(_edited_pieces(source, motion)).decode("utf-8")


def _edited_pieces(source: KinectSource, motion: Motion):
    """The source's bytes with every changed sample's tokens rewritten (any layout; rows
    of the long layout inserted or deleted): the lines CHUNK at a time, the moved
    coordinates of all of them formatted together (:func:`_formatted`)."""
    changed, new_missing = _changed(source, motion)
    removed = changed & new_missing
    line_of = source.line_of
    deleted = set(source.skip_lines)
    inserted: dict[int, list[str]] = {}
    if source.layout == "long_csv":
        gone = removed & (line_of >= 0)
        if source.state_kind == "tracking":
            gone &= source.state_field < 0
        deleted.update(line_of[gone].tolist())
        for t, j in np.argwhere(changed & ~new_missing & (line_of < 0)):
            inserted.setdefault(int(source.extra["frame_last_line"][t]), []).append(
                _new_long_row(source, motion, int(t), int(j)))
        changed = changed & ~gone
    edits = (_edited_lines(source, motion, t, j, lines, new_missing)
             for t, j, lines in _changed_samples(changed & (line_of >= 0), line_of))
    return source.text.pieces((e for chunk in edits for e in chunk), deleted, inserted)


def _changed_samples(changed: np.ndarray, line_of: np.ndarray):
    """The samples ``changed`` (T, J) as (t, j, line) arrays sorted by line, CHUNK lines
    at a time. Where every frame's lines follow the previous frame's (one line a frame:
    the wide layouts) the frames are taken CHUNK at a time: sorted for the whole take
    at once, the indices of a take whose every sample moved were ~56 bytes a sample at
    the writer's peak. Else (the long layout's rows) all at once."""
    T = changed.shape[0]
    for frames in (_frame_chunks(T) if _lines_follow_frames(line_of) else [slice(0, T)]):
        t, j = np.nonzero(changed[frames])
        t += frames.start
        lines = line_of[t, j]
        order = np.argsort(lines, kind="stable")
        t, j, lines = t[order], j[order], lines[order]
        cuts = np.flatnonzero(np.diff(lines)) + 1
        starts = np.concatenate([[0], cuts]) if len(lines) else cuts   # each edited line's first
        for a, b in _spans(starts, len(lines)):
            yield t[a:b], j[a:b], lines[a:b]


def _frame_chunks(T: int) -> list[slice]:
    return [slice(a, min(a + CHUNK, T)) for a in range(0, T, CHUNK)]


def _lines_follow_frames(line_of: np.ndarray) -> bool:
    """Every sample has a line and each frame's lines come after the previous frame's."""
    if not line_of.size:
        return False
    first, last = line_of.min(axis=1), line_of.max(axis=1)
    return bool(first.min() >= 0 and (first[1:] > last[:-1]).all())


def _spans(starts: np.ndarray, n: int):
    """(first, stop) sample ranges covering CHUNK edited lines each."""
    for k in range(0, len(starts), CHUNK):
        yield int(starts[k]), int(starts[k + CHUNK]) if k + CHUNK < len(starts) else n


def _edited_lines(source, motion, t, j, lines, new_missing) -> list[tuple[int, str]]:
    """(line, new text) for the lines holding the samples (t, j) (sorted by line)."""
    numbers = np.unique(lines)
    k = np.searchsorted(numbers, lines)
    order = [_Line(text, source.sep) for text in source.text.lines_at(numbers)]
    # the parts of all the lines in one object array; field f of a line is its part
    # slots[0] + 2 f (separators, or runs of blanks, alternate with the fields)
    sizes = np.array([len(c.parts) for c in order])
    offsets = np.cumsum(sizes) - sizes
    parts = np.empty(int(sizes.sum()), object)
    parts[:] = [p for c in order for p in c.parts]
    lead = np.array([c.slots[0] if c.slots else 0 for c in order])
    gone = new_missing[t, j]
    put = ~gone
    at = ((offsets + lead)[k[put]][:, None] + 2 * source.coord_field[t[put], j[put]]).ravel()
    values = motion.positions[t[put], j[put]].ravel()
    old = parts[at].tolist()
    if not _all_bare(old):
        plain = np.fromiter(("e" not in s and "E" not in s and s == s.strip() for s in old),
                            bool, len(old))
    else:
        plain = np.ones(len(old), bool)
    out = np.empty(len(old), object)
    if plain.any():
        out[plain] = _formatted([s for s, p in zip(old, plain) if p], values[plain])
    for i in np.flatnonzero(~plain).tolist():
        out[i] = _pad(old[i], _format_like(float(values[i]), old[i]))
    parts[at] = out
    for n, c in enumerate(order):
        c.parts = parts[offsets[n]:offsets[n] + sizes[n]].tolist()
    filled = put & source.missing[t, j] & (source.state_field[t, j] >= 0)
    for s in np.flatnonzero(filled | gone).tolist():
        line = order[k[s]]
        state = int(source.state_field[t[s], j[s]])
        if gone[s]:
            _remove_sample(source, line, [int(f) for f in source.coord_field[t[s], j[s]]],
                           state if state >= 0 else None)
        else:
            line[state] = _pad(line[state], "1" if source.state_kind == "tracking"
                               else _format_like(0.5, line[state]))
    return [(int(n), c.text()) for n, c in zip(numbers, order)]
def _eol(source: KinectSource) -> str:
    return next((e for e in source.endings if e), "\n")


class _Line:
    """A line cut into fields and separators, so that joining gives it back exactly."""

    def __init__(self, line: str, sep: str | None):
        if sep is None:
            self.parts = re.split(r"(\s+)", line)
            self.slots = [k for k in range(0, len(self.parts), 2) if self.parts[k] != ""]
        else:
            fields = line.split(sep)
            self.parts = [sep] * (2 * len(fields) - 1)
            self.parts[::2] = fields
            self.slots = list(range(0, len(self.parts), 2))

    def __getitem__(self, field_index: int) -> str:
        return self.parts[self.slots[field_index]]

    def __setitem__(self, field_index: int, value: str) -> None:
        self.parts[self.slots[field_index]] = value

    def text(self) -> str:
        return "".join(self.parts)


def _edit_sample(source, line: _Line, t, j, action, value) -> bool:
    """Rewrite the tokens of one sample in ``line``. False: delete the whole line."""
    fields = [int(f) for f in source.coord_field[t, j]]
    state = int(source.state_field[t, j]) if source.state_field[t, j] >= 0 else None
    if action == "remove":
        return _remove_sample(source, line, fields, state)
    for f, v in zip(fields, value):
        line[f] = _pad(line[f], _format_like(float(v), line[f]))
    if action == "fill" and state is not None:
        line[state] = _pad(line[state], "1" if source.state_kind == "tracking"
                           else _format_like(0.5, line[state]))
    return True


def _pad(old: str, new: str) -> str:
    """Keep the leading/trailing blanks a CSV cell had around its number."""
    stripped = old.strip()
    if not stripped:
        return new
    start = old.index(stripped)
    return old[:start] + new + old[start + len(stripped):]


def _remove_sample(source, line: _Line, fields, state) -> bool:
    if source.state_kind == "tracking" and state is not None:
        line[state] = _pad(line[state], "0")
        return True
    if source.layout == "msr_action3d":
        for f in fields + [state]:
            line[f] = _format_like(0.0, line[f])
        return True
    if source.layout == "long_csv":
        return False
    for f in fields:
        line[f] = "nan" if source.sep is None else ""
    if state is not None:  # confidence column
        line[state] = _pad(line[state], _format_like(0.0, line[state]))
    return True


def _new_long_row(source: KinectSource, motion: Motion, t: int, j: int) -> str:
    fields = [""] * source.extra["n_columns"]
    fields[source.extra["key_col"]] = source.extra["frame_tokens"][t]
    fields[source.extra["joint_col"]] = source.names[j]
    for f, v in zip(source.coord_field[t, j], motion.positions[t, j]):
        fields[int(f)] = f"{v:.6f}"
    if source.state_field[t, j] >= 0:
        fields[int(source.state_field[t, j])] = "1" if source.state_kind == "tracking" else "0.5"
    return (source.sep or " ").join(fields)


def _wide_csv_pieces(motion: Motion):
    """Headed wide CSV: time, <Joint>_X, _Y, _Z [, _State] per joint; CHUNK frames at a
    time."""
    T = motion.n_frames
    tag = "" if motion.units == "m" else f" ({motion.units})"
    with_state = motion.confidence is not None
    header = ["time"]
    for name in motion.names:
        header += [f"{name}_X{tag}", f"{name}_Y{tag}", f"{name}_Z{tag}"]
        if with_state:
            header.append(f"{name}_State")
    yield (",".join(header) + "\n").encode("utf-8")
    times = motion.times if motion.times is not None else np.arange(T) / motion.fps
    times = np.asarray(times, dtype=np.float64)
    missing = motion.missing
    J = motion.n_joints
    for a in range(0, T, CHUNK):
        P = motion.positions[a:a + CHUNK]
        n = len(P)
        cells = np.empty((n, J, 4 if with_state else 3), object)
        cells[..., :3] = np.array(("%.6f," * P.size % tuple(P.ravel().tolist())).split(",")[:-1],
                                  object).reshape(n, J, 3)
        cells[missing[a:a + n], :3] = ""
        if with_state:
            conf = motion.confidence[a:a + n]
            state = np.select([conf >= 0.75, conf > 0], ["2", "1"], "0")
            cells[..., 3] = np.where(missing[a:a + n], "0", state)
        stamps = ("%.9f," * n % tuple(times[a:a + n].tolist())).split(",")
        yield "".join(f"{stamps[r]},{','.join(cells[r].ravel().tolist())}\n"
                      for r in range(n)).encode("utf-8")


def _wide_csv_text(motion: Motion) -> str:
    return b"".join(_wide_csv_pieces(motion)).decode("utf-8")
