"""BVH (Biovision Hierarchy) reader and writer.

What is handled
---------------
* Any rotation order per joint (CMU "cgspeed" conversions mix ZXY and ZYX in one file).
  Rotations are intrinsic in the listed order: ``CHANNELS 3 Zrotation Xrotation Yrotation``
  gives ``Rig.rot_axes == "ZXY"``, i.e. ``Rz · Rx · Ry`` (see :mod:`mocapfix.core.kinematics`).
* Position channels on any joint (Bandai-Namco files give every joint 6 channels),
  ``CHANNELS 0``, joints without a ``CHANNELS`` line, several ``ROOT`` trees, joint names
  with spaces, CHANNELS before OFFSET, unknown channel types (carried through, ignored by FK).
* ``End Site`` blocks become joints named ``<parent>_End`` (made unique), so that
  ``Motion.positions`` includes the end effectors.
* CRLF, LF and CR line endings mixed in one file, tabs, any amount of whitespace, blank
  lines, a UTF-8 byte-order mark, a last line without a line ending.

Translation channels
--------------------
``Xposition``/``Yposition``/``Zposition`` REPLACE the joint's OFFSET (component-wise), for
the root and for every other joint: ``Rig.trans_adds_offset`` is False everywhere. This is
what bvhio (``_deserializeMotion`` starts from the offset and overwrites it) and Blender's
importer (pose location = channel − rest_head_local) do, and what the data say: the PyMO
file's root OFFSET is (11.3, 35.4, −54.3) and its root Yposition ≈ 35.5 (adding would double
the hip height); the Bandai files repeat each joint's OFFSET in its position channels.
The tests check every shared file against bvhio's world positions.

Units
-----
BVH has no unit field. The unit is guessed from the rest skeleton's size (largest axis
extent with every rotation zero, ~ body height or arm span): 0.8–2.5 → m, 80–250 → cm,
800–2500 → mm, 40–80 → in; 18–40 → "unknown" with the CMU ASF unit (1/0.45 inch — the CMU
cgspeed conversions measure ~24); anything else → "unknown" with ``metres_per_unit`` of the
closest guess. A note always says it is a guess.

Malformed files
---------------
Every failure is one :class:`UnreadableFileError` naming the file, the line and the cause.
No loop runs longer than the file has tokens or lines, so nothing can hang.
A truncated motion block (``Frames: N`` but fewer complete frame lines) is REFUSED by
default — a silently shortened clip is worse than a clear error in a batch cleaner. Pass
``allow_truncated=True`` to read the complete frames instead (a note says how many were
missing). Lines after the declared frames that are frames of the hierarchy (one finite
number per channel each: an exporter that under-counts) are read, and the written file
declares them; other lines there are ignored with a note (and not written back).

Writing
-------
:func:`write` needs ``motion.source`` from :func:`read`: the hierarchy is written back byte
for byte, the ``Frames:`` and ``Frame Time:`` lines keep their spelling (the numbers change
only when the frame count or rate changed), and every frame line keeps its whitespace and
line ending. A value equal to the one read is written as its ORIGINAL token, so an
unchanged motion round-trips byte-identical; a changed value is written with ``%.6f``
(trailing zeros trimmed), i.e. within 5e-7 of the float64 value. When ``motion.fps`` is no
longer 1 / Frame Time (a user override at read, a resampling cleaner) the Frame Time number
is rewritten. Only channels are written: rig or offset changes are not (the hierarchy text
is the source's).

Why hand-written instead of bvhio
---------------------------------
bvhio (a dependency, used by the tests as an independent reference) loops forever on a
truncated file and is slow on long takes (docs/formats.md, "Why the readers are
hand-written"). Here the hierarchy is parsed by a small tokenizer (an explicit stack, no
recursion) and the motion block scanned as byte offsets (line ends, blank lines, token
counts: numpy over blocks of the file) and converted CHUNK frames at a time into one array,
so that a long take costs its arrays, not a Python object per line or value, nor the
file's bytes when it is large (read a block at a time from the file: :func:`_large`); FK
is the vectorised :class:`kinematics.Rig`.
"""
from __future__ import annotations

import itertools
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapfix.core.errors import MAX_FIELD, UnreadableFileError, WriteError, excerpt
from mocapfix.core.fileio import atomic_write_pieces, read_input_bytes
from mocapfix.formats.filebytes import FileView, keep, kept_values, large_view, runs_of
from mocapfix.formats.textenc import refuse_wide_text
from mocapfix.formats.textlines import line_end_bytes
from mocapfix.core.kinematics import Rig, positions_in_chunks
from mocapfix.core.motion import Motion, Skeleton
from mocapfix.core.quantity import MAX_FRAME_RATE_HZ, MIN_FRAME_RATE_HZ

NAME = "bvh"
SUFFIXES = (".bvh",)
#: what its points are (configs and rule files may name the family: ``formats: [rotations]``)
FAMILY = "rotations"
#: where its sniffer runs when the suffix does not tell (lower first: the stricter tests)
SNIFF_ORDER = 1

_BOM = b"\xef\xbb\xbf"
_TOKEN = re.compile(rb"\S+")
_MOTION_LINE = re.compile(rb"(?i)(?:(?<=[\r\n])|\A)[ \t]*MOTION[ \t]*(?=[\r\n]|\Z)")
_FRAMES_LINE = re.compile(rb"(?i)^(\s*Frames\s*:\s*)(\S+)(\s*)$")
_FRAME_TIME_LINE = re.compile(rb"(?i)^(\s*Frame\s+Time\s*:\s*)(\S+)(\s*)$")
_WHITESPACE_SPLIT = re.compile(rb"(\s+)")
_POSITION_CHANNELS = {"XPOSITION": 0, "YPOSITION": 1, "ZPOSITION": 2}
_ROTATION_CHANNELS = {"XROTATION": "X", "YROTATION": "Y", "ZROTATION": "Z"}

#: (unit, metres per unit, plausible rest-skeleton size in that unit, what it looks like).
#: CMU "cgspeed" BVH conversions keep the ASF unit (1/0.45 inch): their rest skeleton is
#: ~24 units (femur ~7.3 units = 0.41 m); there is no unit name for it, so "unknown".
_UNIT_GUESSES = (
    ("m", 1.0, (0.8, 2.5), "metres"),
    ("cm", 0.01, (80.0, 250.0), "centimetres"),
    ("mm", 0.001, (800.0, 2500.0), "millimetres"),
    ("in", 0.0254, (40.0, 80.0), "inches"),
    ("unknown", 0.0254 / 0.45, (18.0, 40.0), "CMU ASF units (1/0.45 inch, cgspeed BVH)"),
)
_TYPICAL_SIZE_M = 1.7


def sniff(head: bytes) -> bool:
    """True when the file starts (after a BOM and whitespace) with ``HIERARCHY``."""
    text = head[len(_BOM):] if head.startswith(_BOM) else head
    return text.lstrip()[:9].upper() == b"HIERARCHY"


# ---------------------------------------------------------------------------------------
# data kept for the writer
# ---------------------------------------------------------------------------------------
@dataclass
class BvhSource:
    """Everything :func:`write` needs to reproduce the file (never touched by cleaners).

    ``head`` is the file from its first byte to the end of the line before ``Frames:``
    (hierarchy, ``MOTION`` line, any blank lines). Frame ``i``'s raw text, including blank
    lines before it and its line ending, is ``data[frame_ends[i - 1]:frame_ends[i]]``
    (frame 0 from ``frames_start``): the file is held once, not a bytes object per line
    (a large file not at all: read again when written, :mod:`mocapfix.formats.filebytes`);
    ``values`` the numbers read from them. ``tail`` is the whitespace after the last frame.
    """

    head: bytes
    frames_line: bytes
    frame_time_line: bytes
    data: bytes
    frames_start: int
    frame_ends: np.ndarray
    values: np.ndarray
    tail: bytes
    newline: bytes
    frame_time: float
    n_channels: int
    channel_names: list[str] = field(default_factory=list)
    end_sites: list[bool] = field(default_factory=list)  # per joint: is it an End Site

    def frame_start(self, i: int) -> int:
        return int(self.frame_ends[i - 1]) if i else self.frames_start

    def frame_line(self, i: int) -> bytes:
        return self.data[self.frame_start(i):int(self.frame_ends[i])]

    @property
    def frame_lines(self) -> list[bytes]:
        """Every frame's raw text (one bytes object each: for tests and small files)."""
        return [self.frame_line(i) for i in range(len(self.frame_ends))]


@dataclass
class _Joint:
    name: str
    parent: int
    offset: tuple[float, float, float] | None = None
    channels: list[str] = field(default_factory=list)
    first_column: int = 0
    is_end_site: bool = False
    line: int = 0


class _Tokens:
    """Whitespace-separated tokens of the hierarchy with their 1-based line numbers."""

    def __init__(self, path, data: bytes, start: int):
        self.path = path
        self.words: list[bytes] = []
        self.lines: list[int] = []
        self.line_ends: list[bool] = []  # True when the token is the last on its line
        line, last = 1 + _count_lines(data, 0, start), start
        for match in _TOKEN.finditer(data, start):
            line += _count_lines(data, last, match.start())
            last = match.start()
            if self.lines and self.lines[-1] != line:
                self.line_ends[-1] = True
            if match.end() - match.start() > MAX_FIELD:
                raise UnreadableFileError(path, f"a word longer than {MAX_FIELD:,} bytes: "
                                                f"{excerpt(_text(match.group()))}", line=line)
            self.words.append(match.group())
            self.lines.append(line)
            self.line_ends.append(False)
        if self.line_ends:
            self.line_ends[-1] = True
        self.end_line = 1 + _count_lines(data, 0, len(data))
        self.pos = 0

    def at_end(self) -> bool:
        return self.pos >= len(self.words)

    def peek(self) -> bytes | None:
        return None if self.at_end() else self.words[self.pos]

    def line(self) -> int:
        return self.lines[self.pos] if not self.at_end() else self.end_line

    def fail(self, reason: str, line: int | None = None):
        raise UnreadableFileError(self.path, reason, line=line or self.line())

    def take(self, what: str) -> bytes:
        if self.at_end():
            self.fail(f"hierarchy ends early (file truncated?): expected {what}")
        word = self.words[self.pos]
        self.pos += 1
        return word

    def expect(self, keyword: bytes) -> None:
        line = self.line()
        word = self.take(repr(keyword.decode()))
        if word.upper() != keyword.upper():
            self.fail(f"expected {keyword.decode()!r}, found {excerpt(_text(word))}", line)

    def rest_of_line(self, what: str) -> list[bytes]:
        """The tokens up to the end of the current line (at least one)."""
        words = [self.take(what)]
        while not self.line_ends[self.pos - 1] and self.peek() != b"{":
            words.append(self.take(what))
        return words

    def number(self, what: str) -> float:
        line = self.line()
        word = self.take(what)
        try:
            value = float(word)
        except ValueError:
            self.fail(f"{what}: {excerpt(_text(word))} is not a number", line)
        if not math.isfinite(value):
            self.fail(f"{what}: {excerpt(_text(word))} is not a finite number", line)
        return value


def _count_lines(data: bytes, start: int, end: int) -> int:
    """Line breaks in ``data[start:end]``: LF, CRLF and a lone CR each count once."""
    return (data.count(b"\n", start, end) + data.count(b"\r", start, end)
            - data.count(b"\r\n", start, end))


def _text(word: bytes) -> str:
    return word.decode("utf-8", errors="replace")


# ---------------------------------------------------------------------------------------
# hierarchy
# ---------------------------------------------------------------------------------------
def _parse_hierarchy(tokens: _Tokens) -> list[_Joint]:
    """Joints (End Sites included) in file order, which is parents first."""
    tokens.expect(b"HIERARCHY")
    joints: list[_Joint] = []
    open_joints: list[int] = []  # stack of joints whose '}' is still to come
    n_columns = 0
    while True:
        word = tokens.peek()
        key = word.upper() if word is not None else None
        line = tokens.line()
        if key is None:
            if open_joints:
                tokens.fail(f"hierarchy ends early (file truncated?): joint "
                            f"{joints[open_joints[-1]].name!r} has no closing '}}'")
            break
        if key == b"MOTION" and not open_joints:
            break
        tokens.pos += 1
        if key == b"ROOT" and not open_joints or key == b"JOINT" and open_joints:
            parent = open_joints[-1] if open_joints else -1
            name = _text(b" ".join(tokens.rest_of_line(f"a name after {_text(word)}")))
            joint = _Joint(name, parent, line=line, first_column=n_columns)
            tokens.expect(b"{")
            _parse_joint_body(tokens, joint)
            n_columns += len(joint.channels)
            joints.append(joint)
            open_joints.append(len(joints) - 1)
        elif key == b"END" and open_joints:
            tokens.expect(b"Site")
            joint = _Joint("", open_joints[-1], is_end_site=True, line=line,
                           first_column=n_columns)
            tokens.expect(b"{")
            tokens.expect(b"OFFSET")
            joint.offset = tuple(tokens.number("End Site OFFSET") for _ in range(3))
            tokens.expect(b"}")
            joints.append(joint)
        elif key == b"}" and open_joints:
            open_joints.pop()
        elif key == b"}":
            tokens.fail("unbalanced braces: '}' without an open joint", line)
        elif key in (b"ROOT", b"JOINT", b"END"):
            where = "inside a joint" if open_joints else "outside any ROOT"
            tokens.fail(f"{excerpt(_text(word))} {where} (unbalanced braces?)", line)
        else:
            expected = "JOINT, End Site or '}'" if open_joints else "ROOT or MOTION"
            tokens.fail(f"expected {expected}, found {excerpt(_text(word))}", line)
    if not joints:
        tokens.fail("the hierarchy has no ROOT joint")
    return joints


def _parse_joint_body(tokens: _Tokens, joint: _Joint) -> None:
    """OFFSET and CHANNELS (either order; CHANNELS optional) after a joint's '{'."""
    has_channels = False
    while True:
        key = (tokens.peek() or b"").upper()
        if key == b"OFFSET" and joint.offset is None:
            tokens.pos += 1
            joint.offset = tuple(tokens.number(f"OFFSET of {joint.name!r}") for _ in range(3))
        elif key == b"CHANNELS" and not has_channels:
            tokens.pos += 1
            joint.channels = _parse_channels(tokens, joint.name)
            has_channels = True
        else:
            break
    if joint.offset is None and tokens.at_end():
        tokens.fail(f"hierarchy ends early (file truncated?): joint {joint.name!r} has no OFFSET")
    if joint.offset is None:
        tokens.fail(f"joint {joint.name!r} has no OFFSET")


def _parse_channels(tokens: _Tokens, joint_name: str) -> list[str]:
    line = tokens.line()
    word = tokens.take(f"the channel count of {joint_name!r}")
    try:
        count = int(word)
    except ValueError:
        tokens.fail(f"CHANNELS of {joint_name!r}: count {excerpt(_text(word))} is not an integer", line)
    if count < 0 or count > len(tokens.words) - tokens.pos:
        tokens.fail(f"CHANNELS of {joint_name!r}: count {count} is impossible here", line)
    names = [_text(tokens.take("a channel name")) for _ in range(count)]
    for name in names:
        if name.upper() in ("JOINT", "END", "}", "{", "OFFSET", "CHANNELS", "MOTION"):
            tokens.fail(f"CHANNELS of {joint_name!r} declares {count} channels but lists "
                        f"fewer", line)
    positions = [n.upper() for n in names if n.upper() in _POSITION_CHANNELS]
    if len(set(positions)) != len(positions):
        tokens.fail(f"CHANNELS of {joint_name!r} repeats a position channel", line)
    return names


def _unique_names(joints: list[_Joint], notes: list[str]) -> list[str]:
    """Joint names, End Sites as ``<parent>_End``; duplicates get ``_2``, ``_3``..."""
    names: list[str] = []
    taken: set[str] = set()
    renamed = []
    for joint in joints:
        wanted = f"{names[joint.parent]}_End" if joint.is_end_site else joint.name
        name, n = wanted, 1
        while name in taken:
            n += 1
            name = f"{wanted}{n}" if joint.is_end_site else f"{wanted}_{n}"
        if name != wanted and not joint.is_end_site:
            renamed.append(f"{wanted!r} (line {joint.line}) -> {name!r}")
        taken.add(name)
        names.append(name)
    if renamed:
        notes.append("duplicate joint names made unique: " + ", ".join(renamed))
    return names


def _build_rig(joints: list[_Joint], names: list[str], n_channels: int) -> tuple[Rig, list[str]]:
    """The kinematic rig and the list of channel types nobody can use (carried through)."""
    rot_axes, rot_columns, trans_columns, unknown = [], [], [], []
    for joint in joints:
        axes, rot_cols, trans = "", [], [-1, -1, -1]
        for k, channel in enumerate(joint.channels):
            column, key = joint.first_column + k, channel.upper()
            if key in _ROTATION_CHANNELS:
                axes += _ROTATION_CHANNELS[key]
                rot_cols.append(column)
            elif key in _POSITION_CHANNELS:
                trans[_POSITION_CHANNELS[key]] = column
            else:
                unknown.append(f"{joint.name}.{channel}")
        rot_axes.append(axes)
        rot_columns.append(rot_cols)
        trans_columns.append(trans)
    rig = Rig(
        names=list(names),
        parents=np.array([j.parent for j in joints], dtype=np.intp),
        offsets=np.array([j.offset for j in joints], dtype=np.float64),
        rot_axes=rot_axes,
        rot_columns=rot_columns,
        trans_columns=np.array(trans_columns, dtype=np.intp),
        trans_adds_offset=np.zeros(len(joints), dtype=bool),
        degrees=True,
        n_channels=n_channels,
    )
    return rig, unknown


# ---------------------------------------------------------------------------------------
# motion block
# ---------------------------------------------------------------------------------------
#: bytes that ``bytes.split()`` and ``bytes.strip()`` take for whitespace
_BLANK = np.zeros(256, bool)
_BLANK[list(b" \t\n\r\x0b\x0c")] = True
#: bytes of the file scanned at a time (line ends, blank lines, token counts)
BLOCK = 1 << 22
#: frame lines converted at a time
CHUNK = 4096
#: bytes of a large file held while it is read (its hierarchy and MOTION line: :func:`_large`)
HEAD = 1 << 20


class _Lines:
    """The lines of ``data[start:]`` as ``bytes.splitlines(keepends=True)`` cuts them (LF,
    CRLF and a lone CR end a line), as offsets: ``ends[k]`` is past line k's ending; with
    per line the count of non-blank bytes (0: a blank line) and of whitespace-separated
    tokens, and its ending (``endings``: 1 LF, 2 CRLF, 0 a lone CR or none). Scanned BLOCK
    bytes at a time (``data`` bytes or a large file's
    :class:`~mocapfix.formats.filebytes.FileView`, read a block at a time), without a
    Python object per line."""

    def __init__(self, data, start: int):
        self.data, self.start = data, start
        size = len(data)
        ends, solid, tokens, endings = [], [], [], []
        solid_before = tokens_before = 0
        previous_blank, previous_cr = True, False
        for a in range(start, size, BLOCK):
            b = min(a + BLOCK, size)
            # one byte past the block: whether a CR at its end is followed by a LF
            more = np.frombuffer(data[a:min(b + 1, size)], np.uint8)
            blk = more[:b - a]
            end = line_end_bytes(more, b - a) + 1
            after_cr = np.concatenate([[previous_cr], blk[:-1] == 13])
            ending = np.zeros(len(end), np.int8)
            is_lf = blk[end - 1] == 10
            ending[is_lf] = 1 + after_cr[end[is_lf] - 1]
            blank = _BLANK[blk]
            hard = np.flatnonzero(~blank)
            first = np.flatnonzero(~blank & np.concatenate([[previous_blank], blank[:-1]]))
            solid.append(solid_before + np.searchsorted(hard, end))
            tokens.append(tokens_before + np.searchsorted(first, end))
            ends.append(a + end)
            endings.append(ending)
            solid_before += len(hard)
            tokens_before += len(first)
            previous_blank, previous_cr = bool(blank[-1]), bool(blk[-1] == 13)
        last = [e[-1] for e in ends if e.size]
        if size > start and (not last or last[-1] != size):   # no line end at the end
            ends.append(np.array([size]))
            solid.append(np.array([solid_before]))
            tokens.append(np.array([tokens_before]))
            endings.append(np.zeros(1, np.int8))
        self.ends = np.concatenate([[0], *ends])[1:].astype(np.int64)
        self.solid = np.diff(np.concatenate([[0], *solid]))
        self.tokens = np.diff(np.concatenate([[0], *tokens]))
        self.endings = np.concatenate([np.zeros(0, np.int8), *endings])

    def __len__(self) -> int:
        return len(self.ends)

    def begin(self, k: int) -> int:
        return int(self.ends[k - 1]) if k else self.start

    def __getitem__(self, k: int) -> bytes:
        return self.data[self.begin(k):int(self.ends[k])]


def _header_line(path, lines: _Lines, index: int, pattern, what: str, first_line: int):
    """Skip blank lines; the next line must match ``pattern``. Returns (match, next index)."""
    while index < len(lines) and not lines.solid[index]:
        index += 1
    if index >= len(lines):
        raise UnreadableFileError(path, f"file ends before the {what} line (truncated?)",
                                  line=first_line + index)
    match = pattern.match(lines[index])
    if match is None:
        raise UnreadableFileError(
            path, f"expected a {what} line, found {_text(lines[index].strip()[:60])!r}",
            line=first_line + index)
    return match, index + 1


def _parse_motion(path, data, motion_start: int, n_channels: int,
                  allow_truncated: bool, notes: list[str]):
    """Parse ``MOTION`` .. end of file (``data``: bytes, or a large file's FileView).
    Returns (values (T, C), frame_time, source parts)."""
    first_line = 1 + _count_lines(data[:motion_start], 0, motion_start)
    lines = _Lines(data, motion_start)  # lines[0] is the MOTION line
    frames_match, index = _header_line(path, lines, 1, _FRAMES_LINE, "'Frames: N'", first_line)
    frames_at = index - 1
    time_match, index = _header_line(path, lines, index, _FRAME_TIME_LINE,
                                     "'Frame Time: seconds'", first_line)
    frame_time_at = index - 1
    declared = _declared_frames(path, frames_match.group(2), first_line + frames_at)
    frame_time = _frame_time(path, time_match.group(2), first_line + frame_time_at)

    # each non-blank line with the blank lines before it is a frame
    at = index + np.flatnonzero(lines.solid[index:])     # the frame lines
    frames_start = lines.begin(index)
    ends = lines.ends[at]
    counts = lines.tokens[at]
    numbers = first_line + at                             # their line numbers
    tail_start = int(ends[-1]) if len(at) else frames_start
    ignored = False
    if len(at) > declared:
        if (counts[declared:] == n_channels).all() and _finite(data, lines, at[declared:],
                                                              n_channels):
            # an exporter that under-counts: the frames are in the file, so none is dropped
            notes.append(f"'Frames: {declared}' but the file holds {len(at)} frame "
                         f"lines: all {len(at)} read (the cleaned file declares "
                         f"{len(at)})")
        else:
            notes.append(f"{len(at) - declared} line(s) after the {declared} declared frames "
                         f"(from line {numbers[declared]}) are not frames of this hierarchy "
                         f"({n_channels} numbers): ignored, and not written back")
            at, ends, counts, numbers = at[:declared], ends[:declared], counts[:declared], \
                numbers[:declared]
            tail_start = len(data)
            ignored = True

    wrong = np.flatnonzero(counts != n_channels)
    bad = int(wrong[0]) if len(wrong) else None
    complete = len(at) if bad is None else bad
    cut_short = (bad is not None and bad == len(at) - 1 and not ignored
                 and counts[bad] < n_channels)  # the file ends inside a frame
    if bad is not None and not cut_short:
        raise UnreadableFileError(
            path, f"frame {bad + 1} has {counts[bad]} values, expected "
                  f"{n_channels} (one per channel)", line=int(numbers[bad]))
    if complete < declared:
        missing = declared - complete
        partial = (f"; the last line holds {counts[bad]} of {n_channels} values"
                   if cut_short else "")
        if not allow_truncated:
            raise UnreadableFileError(
                path, f"truncated: 'Frames: {declared}' but only {complete} complete frame "
                      f"lines{partial} (the file was cut short, or its Frames: count is wrong)",
                line=first_line + len(lines) - 1 if len(lines) else None)
        notes.append(f"file truncated: read {complete} of {declared} declared frames "
                     f"({missing} missing{partial})")
        at, ends, numbers = at[:complete], ends[:complete], numbers[:complete]
        tail_start = len(data)

    values = _to_float(path, data, lines, at, numbers, n_channels)
    source_parts = dict(
        head=data[:lines.begin(frames_at)],
        frames_line=lines[frames_at],
        frame_time_line=data[lines.begin(frames_at + 1):lines.begin(frame_time_at + 1)],
        data=data, frames_start=frames_start, frame_ends=ends,
        tail=data[tail_start:], newline=_dominant_newline(lines.endings[at]),
    )
    return values, frame_time, source_parts


def _declared_frames(path, word: bytes, line: int) -> int:
    try:
        count = int(word)
    except ValueError:
        raise UnreadableFileError(path, f"Frames: {excerpt(_text(word))} is not a whole number",
                                  line=line) from None
    if abs(count) > 10 ** 12:
        raise UnreadableFileError(path, f"Frames: {excerpt(count)} is not a frame count a file "
                                        "can hold", line=line)
    if count < 0:
        raise UnreadableFileError(path, f"Frames: {count} is negative", line=line)
    if count == 0:
        raise UnreadableFileError(path, "Frames: 0 — the file holds a skeleton but no motion "
                                        "to clean", line=line)
    return count


def _frame_time(path, word: bytes, line: int) -> float:
    try:
        value = float(word)
    except ValueError:
        raise UnreadableFileError(path, f"Frame Time: {excerpt(_text(word))} is not a number",
                                  line=line) from None
    if not (math.isfinite(value) and value > 0):
        raise UnreadableFileError(path, f"Frame Time: {excerpt(_text(word))} must be a positive "
                                        "number of seconds", line=line)
    if not 1.0 / MAX_FRAME_RATE_HZ <= value <= 1.0 / MIN_FRAME_RATE_HZ:
        raise UnreadableFileError(path, f"Frame Time: {excerpt(_text(word))} s is a rate outside "
                                        f"{MIN_FRAME_RATE_HZ:g}-{MAX_FRAME_RATE_HZ:g} Hz "
                                        "(a corrupt field?)", line=line)
    return value


def _finite(data: bytes, lines: _Lines, at: np.ndarray, n_channels: int) -> bool:
    """Whether the lines ``at`` (``n_channels`` tokens each) hold finite numbers only."""
    for a in range(0, len(at), CHUNK):
        rows = at[a:a + CHUNK]
        values = _plain_block(data, lines, rows, n_channels)
        if values is None:
            try:
                values = np.array([t for k in rows.tolist() for t in lines[k].split()],
                                  dtype=np.float64)
            except ValueError:
                return False
        if not np.isfinite(values).all():
            return False
    return True


#: the bytes of a plain block (:func:`_plain_block`)
_PLAIN_BYTES = b"0123456789.eE+- \t\r\n\x0b\x0c"


def _plain_block(data: bytes, lines: _Lines, rows: np.ndarray, n_channels: int):
    """The (rows, n_channels) values of the frame lines ``rows`` (``n_channels`` tokens
    each, blank lines between them included) when every byte between the first and the
    last is one of ``_PLAIN_BYTES`` and ``np.fromstring`` reads each token as one number
    (the count tells; it parses with Python's own ``PyOS_string_to_double``); else None."""
    block = data[lines.begin(int(rows[0])):int(lines.ends[rows[-1]])]
    if block.translate(None, _PLAIN_BYTES):
        return None
    try:
        values = np.fromstring(block, sep=" ")
    except ValueError:
        return None
    return values.reshape(len(rows), n_channels) if values.size == len(rows) * n_channels else None


def _to_float(path, data, lines: _Lines, at, line_numbers, n_channels: int) -> np.ndarray:
    """The frame lines ``at`` as a (frames, channels) array, CHUNK lines at a time; an
    UnreadableFileError at the first token that is not a finite number."""
    out = np.empty((len(at), n_channels))
    for a in range(0, len(at), CHUNK):
        rows = at[a:a + CHUNK]
        values = _plain_block(data, lines, rows, n_channels)
        if values is None:
            token_lists = [lines[k].split() for k in rows.tolist()]
            try:
                values = np.array(list(itertools.chain.from_iterable(token_lists)),
                                  dtype=np.float64).reshape(len(rows), n_channels)
            except ValueError:
                values = None
        if values is None or not np.isfinite(values).all():
            _refuse_value(path, [lines[k].split() for k in rows.tolist()],
                          line_numbers[a:a + CHUNK].tolist())
        out[a:a + len(rows)] = values
    return out


def _refuse_value(path, token_lists, line_numbers):
    """The UnreadableFileError of the first token that is not a finite number."""
    for toks, line in zip(token_lists, line_numbers):
        for column, word in enumerate(toks):
            try:
                ok = math.isfinite(float(word))
            except ValueError:
                ok = False
            if not ok:
                raise UnreadableFileError(
                    path, f"value {_text(word[:40])!r} (channel {column + 1}) is not a finite "
                          "number", line=line)
    raise UnreadableFileError(path, "motion values are not numbers")  # not reached


# ---------------------------------------------------------------------------------------
# units
# ---------------------------------------------------------------------------------------
def _skeleton_size(rest: np.ndarray, positions: np.ndarray) -> float:
    """Largest axis extent of the rest pose (offsets only, every rotation zero).

    Rest poses are usually T-poses, so this is about the body height or arm span; the
    animated extent is not used because some files (Bandai) keep a root joint at the
    origin while the body walks metres away. Falls back to the first frame's extent.
    """
    size = float((rest.max(axis=0) - rest.min(axis=0)).max()) if len(rest) else 0.0
    if size <= 0 and positions.shape[0]:
        size = float((positions[0].max(axis=0) - positions[0].min(axis=0)).max())
    return size


def _guess_units(size: float, notes: list[str]) -> tuple[str, float]:
    for unit, mpu, (low, high), looks_like in _UNIT_GUESSES:
        if low <= size <= high:
            notes.append(f"units guessed: rest skeleton size {size:.4g} looks like {looks_like} "
                         f"(metres_per_unit {mpu:.6g}); BVH files do not state their unit")
            return unit, mpu
    if size > 0:
        _, mpu, _, looks_like = min(
            _UNIT_GUESSES, key=lambda g: abs(math.log(size * g[1] / _TYPICAL_SIZE_M)))
    else:
        mpu, looks_like = 0.01, "centimetres"
    notes.append(f"units unknown: rest skeleton size {size:.4g} fits no usual unit; "
                 f"metres_per_unit {mpu:.6g} ({looks_like}) is only the closest guess")
    return "unknown", mpu


def _rest_positions(rig: Rig) -> np.ndarray:
    """Joint positions with every rotation zero and offsets as given (no channels)."""
    rest = np.zeros((rig.n_joints, 3))
    for j, p in enumerate(rig.parents):
        rest[j] = rig.offsets[j] + (rest[p] if p >= 0 else 0.0)
    return rest


# ---------------------------------------------------------------------------------------
# read
# ---------------------------------------------------------------------------------------
def read(path, fps: float | None = None, allow_truncated: bool = False, **options) -> Motion:
    """Read a BVH file; see the module docstring. ``allow_truncated`` reads the complete
    frames of a truncated file (with a note) instead of refusing it. ``share_values``
    (:func:`mocapfix.formats.read`'s): the source's values are the motion's channels,
    read-only, not a copy."""
    path = Path(path)
    data = _large(path) or read_input_bytes(path)
    head = data.head if isinstance(data, FileView) else data
    refuse_wide_text(path, head, "BVH")
    notes: list[str] = []
    start = len(_BOM) if head.startswith(_BOM) else 0
    motion_match = _MOTION_LINE.search(head, start)
    hierarchy_end = motion_match.start() if motion_match else len(data)
    tokens = _Tokens(path, data[:hierarchy_end], start)
    joints = _parse_hierarchy(tokens)
    if motion_match is None:
        raise UnreadableFileError(path, "no MOTION section after the hierarchy "
                                        "(file truncated?)", line=tokens.end_line)
    n_channels = sum(len(j.channels) for j in joints)
    values, frame_time, parts = _parse_motion(path, data, motion_match.start(), n_channels,
                                              allow_truncated, notes)
    names = _unique_names(joints, notes)
    rig, unknown = _build_rig(joints, names, n_channels)
    if unknown:
        notes.append(f"channels of unknown type kept but not used for positions: "
                     f"{', '.join(unknown[:10])}{' ...' if len(unknown) > 10 else ''}")
    positions = positions_in_chunks(rig, values)
    units, metres_per_unit = _guess_units(_skeleton_size(_rest_positions(rig), positions),
                                          notes)
    file_fps = 1.0 / frame_time
    if fps is not None:
        if not (math.isfinite(fps) and fps > 0):
            raise UnreadableFileError(path, f"fps must be positive, got {fps}")
        if abs(fps - file_fps) > 1e-6 * file_fps:
            notes.append(f"frame rate {fps:g} fps given by the user overrides the file's "
                         f"Frame Time ({file_fps:.6g} fps)")
    source = BvhSource(
        head=parts["head"],
        frames_line=parts["frames_line"],
        frame_time_line=parts["frame_time_line"],
        data=keep(path, parts["data"]),
        frames_start=parts["frames_start"],
        frame_ends=parts["frame_ends"],
        values=kept_values(values, options.get("share_values", False)),
        tail=parts["tail"],
        newline=parts["newline"],
        frame_time=frame_time,
        n_channels=n_channels,
        channel_names=[f"{j.name}.{c}" for j in joints for c in j.channels],
        end_sites=[j.is_end_site for j in joints],
    )
    return Motion(
        positions=positions,
        names=names,
        fps=float(fps) if fps is not None else file_fps,
        units=units,
        metres_per_unit=metres_per_unit,
        format=NAME,
        skeleton=Skeleton(rig.parents.copy()),
        rig=rig,
        channels=values,
        source=source,
        path=str(path),
        notes=notes,
    )


def _large(path) -> FileView | None:
    """A BVH over :data:`~mocapfix.formats.filebytes.HELD_MAX` bytes as a
    :class:`~mocapfix.formats.filebytes.FileView` holding its first :data:`HEAD` bytes,
    when its ``MOTION`` line ends within them: the frame lines are then scanned and
    converted from the file a block at a time, never held whole (a 500,000-frame take's
    470 MB). None for a smaller file, or one whose hierarchy does not end there (read
    whole: the reader then says what is wrong)."""
    view = large_view(path, HEAD)
    if view is None:
        return None
    start = len(_BOM) if view.head.startswith(_BOM) else 0
    match = _MOTION_LINE.search(view.head, start)
    # a match at the held bytes' very end may be a longer word in the file
    return view if match is not None and match.end() < len(view.head) else None


def _dominant_newline(endings: np.ndarray) -> bytes:
    """CRLF when more frame lines end with it than with a bare LF (``endings``: the
    lines' :attr:`_Lines.endings`)."""
    crlf = int(np.count_nonzero(endings == 2))
    return b"\r\n" if crlf > int(np.count_nonzero(endings == 1)) else b"\n"


# ---------------------------------------------------------------------------------------
# write
# ---------------------------------------------------------------------------------------
def _format_value(value: float) -> bytes:
    text = "%.6f" % value
    if "." in text:
        text = text.rstrip("0").rstrip(".")
    if text in ("-0", ""):
        text = "0"
    return text.encode("ascii")


def _replace_number(line: bytes, pattern, number: bytes) -> bytes:
    """``line`` with the number of its ``Frames:``/``Frame Time:`` part replaced."""
    lines = line.splitlines(keepends=True)
    for k, single in enumerate(lines):
        body = single.rstrip(b"\r\n")
        match = pattern.match(body)
        if match:
            lines[k] = match.group(1) + number + match.group(3) + single[len(body):]
            break
    return b"".join(lines)


def _rewrite_line(template: bytes, new_row: np.ndarray, old_row: np.ndarray | None) -> bytes:
    """``template``'s whitespace with the values of ``new_row``; values equal to
    ``old_row`` keep their original token."""
    pieces = _WHITESPACE_SPLIT.split(template)
    k = 0
    for i, piece in enumerate(pieces):
        if not piece or piece.isspace():
            continue
        if k < len(new_row):
            if old_row is None or new_row[k] != old_row[k]:
                pieces[i] = _format_value(new_row[k])
        k += 1
    return b"".join(pieces)


def _fresh_line(row: np.ndarray, newline: bytes) -> bytes:
    return b" ".join(_format_value(v) for v in row) + newline


def write(motion: Motion, path, **options) -> list[Path]:
    """Write ``motion.channels`` with the hierarchy of the file it was read from."""
    path = Path(path)
    source = motion.source
    if not isinstance(source, BvhSource):
        raise WriteError(path, "BVH output needs a motion read from a BVH file "
                               "(its hierarchy is written back unchanged)")
    if motion.channels is None:
        raise WriteError(path, "the motion has no BVH channels to write")
    channels = np.asarray(motion.channels, dtype=np.float64)
    if channels.ndim != 2 or channels.shape[1] != source.n_channels:
        raise WriteError(path, f"channels have shape {channels.shape}, the hierarchy needs "
                               f"(frames, {source.n_channels})")
    if not np.isfinite(channels).all():
        bad = np.argwhere(~np.isfinite(channels))[0]
        raise WriteError(path, f"channel {source.channel_names[bad[1]]!r} is not finite at "
                               f"frame {bad[0] + 1}; BVH cannot store missing values")
    out = itertools.chain(
        [source.head, _frames_line(source, len(channels)), _frame_time_line(source, motion)],
        _frame_pieces(source, channels), [source.tail])
    return [atomic_write_pieces(path, out)]


def _frames_line(source: BvhSource, n_frames: int) -> bytes:
    match = _FRAMES_LINE.match(source.frames_line)
    if match is not None and match.group(2).isdigit() and int(match.group(2)) == n_frames:
        return source.frames_line       # the count as spelt in the file
    return _replace_number(source.frames_line, _FRAMES_LINE, str(n_frames).encode())


def _frame_time_line(source: BvhSource, motion: Motion) -> bytes:
    if abs(motion.fps * source.frame_time - 1.0) <= 1e-9:
        return source.frame_time_line
    return _replace_number(source.frame_time_line, _FRAME_TIME_LINE,
                           ("%.10g" % (1.0 / motion.fps)).encode())


def _frame_pieces(source: BvhSource, channels: np.ndarray):
    """The frame lines of ``channels`` in pieces: runs of unchanged lines as one slice of
    the source, each other line rewritten (or made from the last one, for frames past
    the source's), every line but the last with a line ending."""
    n_old, T = len(source.values), len(channels)
    common = min(T, n_old)
    # a chunk of the values read at a time: on a long take they may be kept on disk
    # (mocapfix.core.diskarray), and a whole-take comparison was one more (T, C) array
    changed = [np.zeros(0, np.intp)]
    for a in range(0, common, CHUNK):
        b = min(a + CHUNK, common)
        changed.append(np.flatnonzero((channels[a:b] != source.values[a:b]).any(axis=1)) + a)
    changed = np.concatenate(changed)
    held = [-1, None]                             # the chunk of values read the rows are in

    def old(i: int) -> np.ndarray:
        a = i - i % CHUNK
        if held[0] != a:
            held[:] = [a, np.asarray(source.values[a:a + CHUNK])]
        return held[1][i - a]
    special = np.union1d(changed, np.array([k for k in (n_old - 1, T - 1) if 0 <= k < common],
                                           dtype=np.intp))
    ends_with_newline = n_old and source.frame_line(n_old - 1).endswith((b"\n", b"\r"))

    def finished(i: int, line: bytes) -> bytes:
        if i < T - 1:
            if not line.endswith((b"\n", b"\r")):
                line += source.newline
        elif T != n_old and n_old:
            if not ends_with_newline:
                line = line.rstrip(b"\r\n")
            elif not line.endswith((b"\n", b"\r")):
                line += source.newline
        return line

    done = 0                                      # frames written so far
    for i in special.tolist():
        if i > done:
            yield from runs_of(source.data, source.frame_start(done),
                               int(source.frame_ends[i - 1]))
        line = source.frame_line(i)
        if not np.array_equal(channels[i], old(i)):
            line = _rewrite_line(line, channels[i], old(i))
        yield finished(i, line)
        done = i + 1
    if done < common:
        yield from runs_of(source.data, source.frame_start(done),
                           int(source.frame_ends[common - 1]))
    for i in range(n_old, T):
        line = (_rewrite_line(source.frame_line(n_old - 1), channels[i], None) if n_old
                else _fresh_line(channels[i], source.newline))
        yield finished(i, line)
