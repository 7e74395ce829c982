"""Acclaim ASF (skeleton) + AMC (motion) files, as distributed by the CMU mocap database.

Reading
    ``read("05_01.amc")`` parses the AMC and its ASF. The ASF is ``asf=`` when given,
    else ``<stem>.asf`` or ``<prefix>.asf`` beside the AMC (prefix = the stem before the
    first ``_``: CMU ``05_01.amc`` → ``05.asf``), else the only ``.asf`` in that folder.
    ``read("05.asf")`` gives a one-frame rest pose (every channel 0) with a note.

    Joints are ``root`` followed by one joint per bone — the bone's END point — in
    ``:bonedata`` order, re-ordered only where needed so that parents come first.
    ``positions`` are the forward kinematics of a :class:`~mocapfix.core.kinematics.Rig`
    built as that module's docstring describes (``pre_j = C_p⁻¹ C_j``, offset
    ``length · C_j⁻¹ · direction`` in the bone's own frame, root ``pre = C_root`` from
    ``orientation`` in the root ``axis`` order, root translation added to ``position``),
    in ASF length units: ``:units length 0.45`` (CMU) means one unit is 1/0.45 inch, so
    ``units = "in/0.45"`` and ``metres_per_unit = 0.0254 / 0.45``.
    ``channels`` (T, C) are all AMC values in file order: each frame's bone lines in the
    order of the first frame, each line's values in its ``order``/``dof`` order.

Quirks handled
    CRLF or LF (kept on writing); ``#`` comments; ``:version``/``:name``/free-text
    ``:documentation``; ``:root`` keys in any order; ``axis ax ay az XYZ`` and dof orders
    are extrinsic, so they are reversed into the Rig's matrix-product order
    (``rx ry rz`` → ``M = Rz·Ry·Rx``); ``limits`` spread over several lines with ``inf``;
    ``angle rad`` in the ASF and ``:RADIANS`` in the AMC; bones without DOFs absent from
    the AMC; ``tx ty tz`` DOFs on bones (translation added to the bone vector in the
    bone's axis frame). The ``l`` (length) DOF is refused (UnsupportedFeatureError).
    AMC files store no frame rate: 120 Hz (CMU) is assumed with a note; ``fps`` overrides.

Malformed input
    Every failure is one :class:`UnreadableFileError` naming the file, with the line
    number where known. A truncated AMC (last frame incomplete, or a frame missing bone
    lines) is REFUSED with an error naming the frame: a cleaned copy silently shorter
    than its source would be worse than no copy. Every frame must hold the bone lines of
    the first frame in the same order (true of all CMU files); a frame that differs is
    refused with its line number.

Speed
    Frame blocks are parsed in one pass: the content lines are joined and split into
    tokens once, reshaped to (frames, tokens per frame), the bone-name columns are checked
    against the first frame's layout with one array comparison, and the value columns
    are converted to float64 in one call. Only when that check fails does a line-by-line
    walk run, to name the offending line.

Writing
    ``write(motion, "x.amc")`` writes the AMC and, beside it, the ASF under its original
    name, byte-for-byte as read. The AMC keeps the source's header, bone lines, DOF order,
    frame numbers, comments and line endings; every value whose channel is unchanged
    (within 1e-10, absolute and relative) is written as its ORIGINAL token, so an
    unchanged motion is written byte-identical. Changed values are written with ``%.6f`` with trailing zeros
    trimmed. ``motion.channels`` is what is written (positions are derived data).

Why hand-written
    No maintained Python ASF/AMC library exists; the PyPI ones fail on CMU files (CRLF,
    multi-line limits, bones without DOFs) and none keeps the original tokens, which
    byte-identical round trips need. An AMC is held as its bytes with the offsets of its
    lines; its frames are tokenised and converted _CHUNK at a time, and written back as
    slices of the source between the rewritten bone lines, so that a long take costs its
    arrays, not a Python object per line or value, nor the file's bytes when it is large
    (read a block at a time from the file: :func:`~mocapfix.formats.filebytes.large_view`).
"""
from __future__ import annotations

import heapq
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapfix.core.errors import MAX_FIELD, UnreadableFileError, UnsupportedFeatureError, WriteError
from mocapfix.core.fileio import (atomic_write_bytes, atomic_write_pieces, read_input_bytes,
                                  refuse_stream, regular_file_problem)
from mocapfix.formats.filebytes import keep, kept_values, large_view, runs_of
from mocapfix.formats.textenc import UTF8_BOM, refuse_long_fields, refuse_wide_text
from mocapfix.core.kinematics import Rig, euler_to_matrix, positions_in_chunks
from mocapfix.core.motion import Motion, Skeleton
from mocapfix.core.units import asf_length_unit

NAME = "asfamc"
SUFFIXES = (".amc", ".asf")
#: what its points are (configs and rule files may name the family: ``formats: [rotations]``)
FAMILY = "rotations"
#: where its sniffer runs when the suffix does not tell (lower first: the stricter tests)
SNIFF_ORDER = 2
DEFAULT_FPS = 120.0

_AXES = "XYZ"
_ROOT_CHANNELS = ("TX", "TY", "TZ", "RX", "RY", "RZ")
_BONE_DOFS = ("rx", "ry", "rz", "tx", "ty", "tz")
_INT_RE = re.compile(r"^\d{1,18}$")
#: bytes scanned at a time for line ends; frames converted at a time
_BLOCK = 1 << 22
_CHUNK = 4096
#: a blank or comment line inside an AMC body (then the body is not one run of frame lines):
#: after a line end, or (``_GAP_FIRST``) as the file's first line; blank as ``str.strip``
#: has it (a line of a vertical tab or a no-break space alone is one)
_BLANKS = rb"[ \t\r\x0b\x0c\x1c-\x1f\x85\xa0]*"
_GAP = re.compile(rb"\n" + _BLANKS + rb"(#|\n)")
_GAP_FIRST = re.compile(_BLANKS + rb"(#|\n)")
#: bytes ``str.isspace`` takes for whitespace, one character per byte (latin-1)
_SPACE = np.array([chr(i).isspace() for i in range(256)])
#: bytes of a large AMC held while it is read (its header lines; :func:`read`)
_HEAD = 1 << 20


# --------------------------------------------------------------------------- data
@dataclass
class AsfBone:
    name: str
    direction: np.ndarray
    length: float
    axis_angles: np.ndarray          # x, y, z angles in the ASF angle unit
    axis_order: str                  # extrinsic order, e.g. "XYZ"
    dofs: list[str]                  # lower case, file order: rx ry rz tx ty tz
    limits: list[tuple[float, float]]
    id: int | None = None
    line: int = 0


@dataclass
class AsfSkeleton:
    """Everything an ASF file declares (angles kept in the file's angle unit)."""

    version: str | None = None
    name: str | None = None
    mass: float | None = None
    length_scale: float = 1.0
    length_declared: bool = False
    angle_unit: str = "deg"
    documentation: list[str] = field(default_factory=list)
    root_order: list[str] = field(default_factory=list)
    root_axis: str = "XYZ"
    root_position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    root_orientation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    bones: dict[str, AsfBone] = field(default_factory=dict)
    parent: dict[str, str] = field(default_factory=dict)
    order: list[str] = field(default_factory=list)        # bones, parents first
    notes: list[str] = field(default_factory=list)

    def dof_count(self, name: str) -> int:
        return len(self.root_order) if name == "root" else len(self.bones[name].dofs)


@dataclass
class AsfAmcSource:
    """What the writer needs to reproduce the files."""

    asf_path: str
    asf_bytes: bytes
    asf: AsfSkeleton
    layout: list[tuple[str, int]]          # bone lines of one frame: (name, value count)
    degrees: bool
    eol: str
    header_lines: list[str]                # raw AMC lines before the first frame ('\r' kept)
    body: _AmcLines | None = None        # the AMC lines from the first frame on
    # body line of each frame/bone line (T*lpf,): a range when they are simply the body's
    # lines (the usual case; an array of them was 8 bytes a line, 16 a joint-frame)
    content_index: np.ndarray | range | None = None
    frame_numbers: np.ndarray | None = None
    values: np.ndarray | None = None         # (T, C) the values as read
    flags: dict = field(default_factory=dict)  # AMC header: degrees, fully_specified, unknown
    notes: list[str] = field(default_factory=list)  # what the AMC parser noticed

    @property
    def asf_name(self) -> str:
        return Path(self.asf_path).name

    @property
    def body_lines(self) -> list[str] | None:
        """Every body line as a str (for tests and small files: one object per line)."""
        return None if self.body is None else [self.body[i] for i in range(len(self.body))]


class _AmcLines:
    """The lines of an AMC file from line ``first`` on, as ``text.split("\\n")`` gives them
    ('\\r' kept), held as the file's bytes and the offset of each line (latin-1: one
    character per byte), decoded one at a time: no Python object per line. A large
    file's bytes are read again from it when written (:mod:`mocapfix.formats.filebytes`)."""

    def __init__(self, data: bytes, starts: np.ndarray, first: int = 0):
        self.data, self.starts, self.first = data, starts, first

    @classmethod
    def of(cls, data) -> _AmcLines:
        """The lines of ``data`` (bytes, or a large file's FileView: read _BLOCK bytes at a
        time, never whole)."""
        newlines = [a + np.flatnonzero(np.frombuffer(data[a:a + _BLOCK], np.uint8) == 10)
                    for a in range(0, len(data), _BLOCK)]
        return cls(data, np.concatenate([[0], *[n + 1 for n in newlines]]).astype(np.int64))

    def longer_than(self, n: int) -> np.ndarray:
        """Indices of the lines (from line 0 of the file) longer than ``n`` bytes, their
        line end left out."""
        ends = np.append(self.starts[1:] - 1, len(self.data))
        return np.flatnonzero(ends - self.starts > n)

    def __len__(self) -> int:
        return len(self.starts) - self.first

    def span(self, i: int) -> tuple[int, int]:
        """Offsets of line ``i``'s text (without its newline)."""
        k = self.first + i
        end = int(self.starts[k + 1]) - 1 if k + 1 < len(self.starts) else len(self.data)
        return int(self.starts[k]), end

    def __getitem__(self, i: int) -> str:
        if i < 0:
            i += len(self)
        if not 0 <= i < len(self):
            raise IndexError(i)
        a, b = self.span(i)
        return self.data[a:b].decode("latin-1")

    def tail(self, first: int) -> _AmcLines:
        return _AmcLines(self.data, self.starts, self.first + first)


# --------------------------------------------------------------------------- sniff
def sniff(head: bytes) -> bool:
    text = head.lstrip().lower()
    if text.startswith(b"#!oml:asf") or b":fully-specified" in text:
        return True
    if re.search(rb"^\s*:(degrees|radians)\s*$", text, re.M) and re.search(rb"^\s*\d+\s*$", text, re.M):
        return True
    return b":bonedata" in text or (b":root" in text and b":units" in text)


# --------------------------------------------------------------------------- helpers
def _decode(path: Path, data: bytes) -> str:
    _check_text(path, data)
    return data.decode("latin-1")    # byte-exact round trip, never fails


def _check_text(path: Path, data, lines: _AmcLines | None = None) -> None:
    """Refuse an empty, UTF-16/32, binary file or one with a field over MAX_FIELD
    characters (latin-1: one per byte; only the lines longer than that are split).
    ``data``: bytes, or a large AMC's FileView; ``lines``: its lines, when found."""
    if _blank(data):
        raise UnreadableFileError(path, "file is empty")
    head = data[:4096]
    refuse_wide_text(path, head, Path(path).suffix.lstrip(".").upper() or "ASF/AMC")
    if b"\x00" in head:
        raise UnreadableFileError(path, "binary data where ASF/AMC text was expected")
    lines = _AmcLines.of(data) if lines is None else lines
    for k in lines.longer_than(MAX_FIELD).tolist():
        a, b = lines.span(k)
        refuse_long_fields(path, [data[a:b].decode("latin-1")], first_line=k)


def _blank(data) -> bool:
    """Whether ``data`` (bytes or a FileView) holds only whitespace, _BLOCK bytes at a time."""
    return not any(data[a:a + _BLOCK].strip() for a in range(0, len(data), _BLOCK))


def _floats(path, tokens: list[str], count: int, what: str, line: int) -> np.ndarray:
    if len(tokens) != count:
        raise UnreadableFileError(path, f"{what} needs {count} numbers, found {len(tokens)}", line)
    try:
        values = np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError:
        raise UnreadableFileError(path, f"{what}: non-numeric value in {' '.join(tokens)!r}", line) from None
    if not np.all(np.isfinite(values)):
        raise UnreadableFileError(path, f"{what}: non-finite value in {' '.join(tokens)!r}", line)
    return values


def _axis_order(path, token: str, line: int) -> str:
    order = token.upper()
    if len(order) != 3 or sorted(order) != ["X", "Y", "Z"]:
        raise UnreadableFileError(path, f"axis order {token!r} is not a permutation of XYZ", line)
    return order


def axis_matrix(angles_xyz: np.ndarray, order: str, degrees: bool) -> np.ndarray:
    """Matrix of an ASF ``axis``/``orientation``: x, y, z angles applied in the extrinsic
    ``order`` (``"XYZ"`` → ``Rz·Ry·Rx``)."""
    angles = np.asarray(angles_xyz, dtype=np.float64)
    if degrees:
        angles = np.deg2rad(angles)
    product_order = order[::-1]
    return euler_to_matrix(product_order, np.array([angles[_AXES.index(a)] for a in product_order]))


# --------------------------------------------------------------------------- ASF
class _AsfParser:
    def __init__(self, path: Path, text: str):
        self.path = path
        bom = UTF8_BOM.decode("latin-1")  # read and written back as the file's bytes
        self.lines = (text[len(bom):] if text.startswith(bom) else text).split("\n")
        self.asf = AsfSkeleton()
        self.bone: dict | None = None
        self.in_limits = False
        self.seen_sections: set[str] = set()
        self.hierarchy_lines: list[tuple[int, list[str]]] = []

    def error(self, reason: str, line: int | None = None):
        return UnreadableFileError(self.path, reason, line)

    def parse(self) -> AsfSkeleton:
        section = None
        for number, raw in enumerate(self.lines, start=1):
            raw = raw.rstrip("\r")
            if section == "documentation" and not raw.lstrip().startswith(":"):
                self.asf.documentation.append(raw)
                continue
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            if line.startswith(":"):
                section = self.start_section(line, number)
                continue
            if section is None:
                raise self.error(f"unexpected text before the first section: {line[:40]!r}", number)
            getattr(self, f"in_{section}")(line.split(), number)
        return self.finish()

    def start_section(self, line: str, number: int) -> str:
        if self.bone is not None:
            raise self.error(f"bone block opened at line {self.bone['line']} has no 'end'", number)
        keyword, _, rest = line.partition(" ")
        keyword = keyword[1:].lower()
        self.seen_sections.add(keyword)
        if keyword in ("version", "name"):
            setattr(self.asf, keyword, rest.strip())
            return "ignored"
        if keyword in ("units", "documentation", "root", "bonedata", "hierarchy"):
            return keyword
        self.asf.notes.append(f"ASF section ':{keyword}' ignored (line {number})")
        return "ignored"

    def in_ignored(self, tokens, number):
        pass

    def in_units(self, tokens, number):
        key = tokens[0].lower()
        if len(tokens) != 2:
            raise self.error(f":units line needs 'key value', got {' '.join(tokens)!r}", number)
        if key == "angle":
            unit = tokens[1].lower()
            if unit not in ("deg", "rad"):
                raise self.error(f"angle unit must be deg or rad, got {tokens[1]!r}", number)
            self.asf.angle_unit = unit
        elif key in ("mass", "length"):
            value = _floats(self.path, tokens[1:], 1, f"units {key}", number)[0]
            if key == "mass":               # no kinematics depends on it: kept, never refused
                self.asf.mass = value
                if not value > 0:
                    self.asf.notes.append(f"ASF units mass {tokens[1]} is not positive "
                                          f"(unused; line {number})")
            elif value <= 0:
                raise self.error(f"units {key} must be positive, got {tokens[1]}", number)
            else:
                self.asf.length_scale = value
                self.asf.length_declared = True
        else:
            self.asf.notes.append(f"ASF unit '{tokens[0]}' ignored (line {number})")

    def in_root(self, tokens, number):
        key, values = tokens[0].lower(), tokens[1:]
        if key == "order":
            order = [v.upper() for v in values]
            bad = [v for v in order if v not in _ROOT_CHANNELS]
            if bad or len(set(order)) != len(order):
                raise self.error(f"root order {' '.join(values)!r}: channels must be distinct "
                                 f"among {' '.join(_ROOT_CHANNELS)}", number)
            self.asf.root_order = order
        elif key == "axis":
            if len(values) != 1:
                raise self.error("root axis needs one order such as XYZ", number)
            self.asf.root_axis = _axis_order(self.path, values[0], number)
        elif key == "position":
            self.asf.root_position = _floats(self.path, values, 3, "root position", number)
        elif key == "orientation":
            self.asf.root_orientation = _floats(self.path, values, 3, "root orientation", number)
        else:
            self.asf.notes.append(f"ASF root key '{tokens[0]}' ignored (line {number})")

    def in_bonedata(self, tokens, number):
        key = tokens[0].lower()
        if key == "begin":
            if self.bone is not None:
                raise self.error("'begin' inside an open bone block", number)
            self.bone = {"line": number, "limits": []}
            self.in_limits = False
            return
        if self.bone is None:
            raise self.error(f"bone data {' '.join(tokens)[:40]!r} outside begin/end", number)
        if key == "end":
            self.finish_bone(number)
            return
        if tokens[0].startswith("(") and self.in_limits:
            self.add_limits(tokens, number)
            return
        self.in_limits = False
        bone, values = self.bone, tokens[1:]
        if key == "id":
            bone["id"] = int(_floats(self.path, values, 1, "bone id", number)[0])
        elif key == "name":
            if len(values) != 1:
                raise self.error("bone name must be one word", number)
            bone["name"] = values[0]
        elif key == "direction":
            bone["direction"] = _floats(self.path, values, 3, "bone direction", number)
        elif key == "length":
            bone["length"] = _floats(self.path, values, 1, "bone length", number)[0]
        elif key == "axis":
            if len(values) != 4:
                raise self.error("bone axis needs 'ax ay az ORDER'", number)
            bone["axis_angles"] = _floats(self.path, values[:3], 3, "bone axis", number)
            bone["axis_order"] = _axis_order(self.path, values[3], number)
        elif key == "dof":
            bone["dofs"] = self.parse_dofs(values, number)
        elif key == "limits":
            self.in_limits = True
            self.add_limits(values, number)
        # bodymass, cofmass and other per-bone keys do not change the kinematics

    def parse_dofs(self, values, number) -> list[str]:
        dofs = [v.lower() for v in values]
        if "l" in dofs:
            raise UnsupportedFeatureError(self.path, "the 'l' (bone length) DOF is not supported", number)
        bad = [v for v in dofs if v not in _BONE_DOFS]
        if bad or len(set(dofs)) != len(dofs):
            raise self.error(f"dof {' '.join(values)!r}: DOFs must be distinct among "
                             f"{' '.join(_BONE_DOFS)}", number)
        return dofs

    def add_limits(self, tokens, number):
        text = " ".join(tokens).replace("(", " ").replace(")", " ").split()
        if len(text) % 2:
            raise self.error(f"limits need (min max) pairs, got {' '.join(tokens)!r}", number)
        try:
            values = [float(t) for t in text]
        except ValueError:
            raise self.error(f"non-numeric limit in {' '.join(tokens)!r}", number) from None
        self.bone["limits"].extend(zip(values[0::2], values[1::2]))

    def finish_bone(self, number):
        bone, self.bone = self.bone, None
        for key in ("name", "direction", "length"):
            if key not in bone:
                raise self.error(f"bone block opened at line {bone['line']} has no '{key}'", number)
        name = bone["name"]
        if name in self.asf.bones or name == "root":
            raise self.error(f"bone {name!r} defined twice", bone["line"])
        dofs = bone.get("dofs", [])
        limits = bone["limits"]
        if limits and len(limits) != len(dofs):
            self.asf.notes.append(f"bone {name!r}: {len(limits)} limits for {len(dofs)} DOFs")
        self.asf.bones[name] = AsfBone(
            name=name, direction=bone["direction"], length=float(bone["length"]),
            axis_angles=bone.get("axis_angles", np.zeros(3)),
            axis_order=bone.get("axis_order", "XYZ"), dofs=dofs, limits=limits,
            id=bone.get("id"), line=bone["line"])

    def in_hierarchy(self, tokens, number):
        key = tokens[0].lower()
        if key in ("begin", "end") and len(tokens) == 1:
            return
        if len(tokens) < 2:
            raise self.error(f"hierarchy line needs 'parent child ...', got {tokens[0]!r}", number)
        self.hierarchy_lines.append((number, tokens))

    def finish(self) -> AsfSkeleton:
        asf = self.asf
        if self.bone is not None:
            raise self.error(f"bone block opened at line {self.bone['line']} has no 'end'")
        for needed in ("root", "bonedata", "hierarchy"):
            if needed not in self.seen_sections:
                raise self.error(f"no :{needed} section (is this an ASF file?)")
        if not asf.root_order:
            asf.notes.append("ASF root has no 'order': the AMC root line must be empty")
        if not asf.length_declared:
            asf.notes.append("ASF declares no ':units length'; assumed 1.0 (inches), a guess")
        self.link_hierarchy()
        return asf

    def link_hierarchy(self):
        asf = self.asf
        for number, tokens in self.hierarchy_lines:
            parent, children = tokens[0], tokens[1:]
            if parent != "root" and parent not in asf.bones:
                raise self.error(f"hierarchy parent {parent!r} is not defined in :bonedata", number)
            for child in children:
                if child not in asf.bones:
                    raise self.error(f"bone {child!r} in :hierarchy is not defined in :bonedata", number)
                if child in asf.parent:
                    raise self.error(f"bone {child!r} has two parents in :hierarchy", number)
                asf.parent[child] = parent
        orphans = [b for b in asf.bones if b not in asf.parent]
        if orphans:
            raise self.error(f"bones defined but not in :hierarchy: {', '.join(orphans[:5])}")
        asf.order = _parents_first(asf.bones, asf.parent)
        if len(asf.order) != len(asf.bones):
            stuck = [b for b in asf.bones if b not in set(asf.order)]
            raise self.error(f"bones not connected to root (cycle in :hierarchy?): {', '.join(stuck[:5])}")


def _parents_first(bones: dict, parent: dict) -> list[str]:
    """:bonedata order, with a bone moved after its parent only where needed.

    Kahn's algorithm with a heap keyed on the :bonedata position: O(n log n). Bones on a
    cycle never become ready and are left out (the caller reports them)."""
    position = {name: k for k, name in enumerate(bones)}
    children: dict[str, list[str]] = {}
    for child, par in parent.items():
        children.setdefault(par, []).append(child)
    ready = [(position[c], c) for c in children.get("root", [])]
    heapq.heapify(ready)
    order: list[str] = []
    while ready:
        _, name = heapq.heappop(ready)
        order.append(name)
        for child in children.get(name, []):
            heapq.heappush(ready, (position[child], child))
    return order


def parse_asf(path, data: bytes) -> AsfSkeleton:
    path = Path(path)
    return _AsfParser(path, _decode(path, data)).parse()


# --------------------------------------------------------------------------- rig
def build_rig(asf: AsfSkeleton, layout: list[tuple[str, int]], degrees: bool) -> tuple[Rig, list[str]]:
    """The Rig of ``asf`` whose channels are the AMC values laid out as ``layout``."""
    names = ["root"] + asf.order
    index = {n: i for i, n in enumerate(names)}
    J = len(names)
    asf_deg = asf.angle_unit == "deg"
    axis = np.empty((J, 3, 3))
    axis[0] = axis_matrix(asf.root_orientation, asf.root_axis, asf_deg)
    offsets = np.zeros((J, 3))
    offsets[0] = asf.root_position
    parents = np.full(J, -1, dtype=np.intp)
    for j, name in enumerate(names[1:], start=1):
        bone = asf.bones[name]
        axis[j] = axis_matrix(bone.axis_angles, bone.axis_order, asf_deg)
        parents[j] = index[asf.parent[name]]
        offsets[j] = bone.length * axis[j].T @ bone.direction
    pre = axis.copy()
    pre[1:] = np.swapaxes(axis[parents[1:]], -1, -2) @ axis[1:]

    first_column = {}
    column = 0
    for name, count in layout:
        first_column[name] = column
        column += count
    rot_axes, rot_columns = [], []
    trans = np.full((J, 3), -1, dtype=np.intp)
    notes = []
    for j, name in enumerate(names):
        dofs = [d.lower() for d in asf.root_order] if j == 0 else asf.bones[name].dofs
        if dofs and name not in first_column:
            notes.append(f"bone {name!r} has DOFs in the ASF but no line in the AMC; held at rest")
            dofs = []
        start = first_column.get(name, 0)
        rotations = [(d[1].upper(), start + k) for k, d in enumerate(dofs) if d[0] == "r"]
        for k, d in enumerate(dofs):
            if d[0] == "t":
                trans[j, _AXES.index(d[1].upper())] = start + k
        rotations.reverse()          # extrinsic file order -> matrix-product order
        rot_axes.append("".join(a for a, _ in rotations))
        rot_columns.append([c for _, c in rotations])
    rig = Rig(names=names, parents=parents, offsets=offsets, rot_axes=rot_axes,
              rot_columns=rot_columns, trans_columns=trans,
              offset_in_own_frame=np.arange(J) > 0, pre_rotation=pre,
              trans_adds_offset=np.ones(J, dtype=bool), degrees=degrees, n_channels=column)
    return rig, notes


# --------------------------------------------------------------------------- AMC
def _amc_header(path, lines: list[str]) -> tuple[int, dict]:
    """Index of the first frame line and the header flags."""
    flags = {"degrees": None, "fully_specified": False, "unknown": []}
    bom = UTF8_BOM.decode("latin-1")  # a UTF-8 byte-order mark: kept in the header line
    for i, raw in enumerate(lines):
        line = raw.strip()
        if i == 0 and line.startswith(bom):
            line = line[len(bom):].strip()
            if _INT_RE.match(line):
                raise UnreadableFileError(path, "a UTF-8 byte-order mark before the first frame "
                                                "number and no header: remove the mark", 1)
        if not line or line.startswith("#"):
            continue
        if line.startswith(":"):
            key = line[1:].split()[0].upper() if len(line) > 1 else ""
            if key == "FULLY-SPECIFIED":
                flags["fully_specified"] = True
            elif key in ("DEGREES", "RADIANS"):
                flags["degrees"] = key == "DEGREES"
            else:
                flags["unknown"].append(line)
            continue
        if not _INT_RE.match(line):
            raise UnreadableFileError(path, f"expected a frame number, found {line[:40]!r}", i + 1)
        return i, flags
    raise UnreadableFileError(path, "no frames (header only)")


def _frame_layout(path, body, content, first_line: int, asf: AsfSkeleton) -> list[tuple[str, int]]:
    """Bone lines of the first frame: [(name, value count), ...], checked against the ASF."""
    layout, seen = [], set()
    for i in content[1:]:
        tokens = body[i].split()
        if _INT_RE.match(tokens[0]):
            break
        name = tokens[0]
        number = first_line + i + 1
        if name != "root" and name not in asf.bones:
            raise UnreadableFileError(path, f"bone {name!r} is not defined in the ASF", number)
        if name in seen:
            raise UnreadableFileError(
                path, f"bone {name!r} appears twice in frame {body[content[0]].strip()}", number)
        seen.add(name)
        expected = asf.dof_count(name)
        if len(tokens) - 1 != expected:
            raise UnreadableFileError(
                path, f"bone {name!r} has {len(tokens) - 1} values, the ASF declares {expected} DOFs", number)
        layout.append((name, expected))
    return layout


def _locate_error(path, body, content, layout, first_line: int) -> UnreadableFileError:
    """Walk the frame blocks line by line to name what breaks the common layout."""
    return _as_truncation(_first_layout_break(path, body, content, layout, first_line),
                          path, body, content, first_line)


def _as_truncation(error: UnreadableFileError, path, body, content, first_line: int) -> UnreadableFileError:
    """Say "truncated" when the broken line is the last one and the file ends inside it."""
    ends_mid_line = body[-1].strip() != ""
    if ends_mid_line and error.line == first_line + content[-1] + 1 and "truncated" not in error.reason:
        return UnreadableFileError(path, f"truncated: the file ends mid-line ({error.reason})", error.line)
    return error


def _first_layout_break(path, body, content, layout, first_line: int) -> UnreadableFileError:
    per_frame = 1 + len(layout)
    frame = None
    for n, i in enumerate(content):
        tokens = body[i].split()
        number = first_line + i + 1
        slot = n % per_frame
        if slot == 0:
            if len(tokens) != 1 or not _INT_RE.match(tokens[0]):
                return UnreadableFileError(
                    path, f"after frame {frame}: expected a frame number, found {body[i].strip()[:40]!r} "
                          f"(every frame must hold the bone lines of the first frame, in the same order)",
                    number)
            frame = tokens[0]
            continue
        name, count = layout[slot - 1]
        if _INT_RE.match(tokens[0]) and len(tokens) == 1:
            return UnreadableFileError(
                path, f"frame {frame} is incomplete: it lacks bone line {name!r} "
                      f"and {per_frame - 1 - slot} more", number)
        if tokens[0] != name:
            return UnreadableFileError(
                path, f"frame {frame}: expected bone line {name!r}, found {tokens[0][:40]!r} "
                      f"(every frame must hold the bone lines of the first frame, in the same order)", number)
        if len(tokens) - 1 != count:
            return UnreadableFileError(
                path, f"frame {frame}: bone {name!r} has {len(tokens) - 1} values, expected {count}", number)
        for token in tokens[1:]:
            try:
                value = float(token)
            except ValueError:
                return UnreadableFileError(path, f"frame {frame}: {token[:40]!r} is not a number", number)
            if not np.isfinite(value):
                return UnreadableFileError(path, f"frame {frame}: non-finite value {token!r}", number)
    slot = len(content) % per_frame
    if slot:
        missing = layout[slot - 1][0]
        return UnreadableFileError(
            path, f"truncated: last frame {frame} is incomplete ({slot - 1} of {per_frame - 1} bone lines, "
                  f"missing {missing!r} onwards)", first_line + content[-1] + 1)
    return UnreadableFileError(path, "frame blocks do not share one layout")


def parse_amc(path, data, asf: AsfSkeleton, lines: _AmcLines | None = None) -> AsfAmcSource:
    """The AMC ``data`` (checked by :func:`_check_text`; bytes, or a large file's
    FileView) read against ``asf``: the frames converted _CHUNK at a time into one array,
    the file kept as its bytes. ``lines``: ``data``'s, when already found."""
    path = Path(path)
    lines = _AmcLines.of(data) if lines is None else lines
    first, flags = _amc_header(path, lines)
    header, body = [lines[i] for i in range(first)], lines.tail(first)
    content, contiguous = _content_lines(data, body)
    try:
        layout = _frame_layout(path, body, content, first, asf)
    except UnreadableFileError as error:
        raise _as_truncation(error, path, body, content, first) from None
    per_frame = 1 + len(layout)
    tokens_per_frame = 1 + sum(1 + count for _, count in layout)
    n_frames = len(content) // per_frame
    if len(content) % per_frame:
        raise _locate_error(path, body, content, layout, first)
    columns = _token_columns(layout)
    values = np.empty((n_frames, len(columns[2])))
    frame_numbers = np.empty(n_frames, np.int64)
    for a in range(0, n_frames, _CHUNK):
        n = min(n_frames - a, _CHUNK)
        tokens = _frame_tokens(data, body, content[a * per_frame:(a + n) * per_frame], contiguous)
        if len(tokens) != n * tokens_per_frame:
            # frames whose tokens are not on their own lines: the whole file decides
            values, frame_numbers = _whole_table(path, data, body, content, contiguous, layout,
                                                 first, n_frames, tokens_per_frame)
            break
        values[a:a + n], frame_numbers[a:a + n] = _frames_table(
            tokens, n, tokens_per_frame, columns,
            lambda: _locate_error(path, body, content, layout, first))
    degrees = flags["degrees"]
    source = AsfAmcSource(
        asf_path="", asf_bytes=b"", asf=asf, layout=layout,
        degrees=(asf.angle_unit == "deg") if degrees is None else degrees,
        eol="\r\n" if lines[0].endswith("\r") else "\n", header_lines=header, body=body,
        content_index=content if contiguous else np.asarray(content, dtype=np.intp),
        frame_numbers=frame_numbers, values=values,
        flags=flags)
    if body[-1].strip():
        source.notes.append("AMC does not end with a line break: if the file was cut, the last "
                            f"value ({body[-1].split()[-1]!r}) may be incomplete")
    return source


def _frame_tokens(data: bytes, body: _AmcLines, rows, contiguous: bool) -> list[str]:
    """The whitespace-separated tokens of the body lines ``rows``, trailing NUL characters
    dropped (as the numpy string table these were once read through did)."""
    if not len(rows):
        return []
    if contiguous:                               # consecutive lines: one slice of the file
        text = data[body.span(rows[0])[0]:body.span(rows[-1])[1]].decode("latin-1")
    else:
        text = " ".join([body[i] for i in rows])
    tokens = text.split()
    return [t.rstrip("\x00") for t in tokens] if "\x00" in text else tokens


def _whole_table(path, data, body, content, contiguous, layout, first, n_frames,
                 tokens_per_frame):
    """(values, frame numbers) from all the tokens at once: a file whose frames do not
    each hold their own tokens (a value on the next frame's lines) is read as the
    token stream allows, or refused by :func:`_locate_error`."""
    tokens = _frame_tokens(data, body, content, contiguous)
    if len(tokens) != n_frames * tokens_per_frame:
        raise _locate_error(path, body, content, layout, first)
    return _frames_table(tokens, n_frames, tokens_per_frame, _token_columns(layout),
                         lambda: _locate_error(path, body, content, layout, first))


def _frames_table(tokens: list[str], n: int, tokens_per_frame: int, columns, error):
    """(values (n, channels), frame numbers (n,)) of ``n`` frames' ``tokens``: each frame's
    number, then per bone its name (``columns``: :func:`_token_columns`) and values; a
    name out of place, a frame number that is not one, or a value that is not a finite
    number raises ``error()``."""
    expected_names, name_columns, value_columns = columns
    table = np.array(tokens, dtype=object).reshape(n, tokens_per_frame)
    frame_tokens = table[:, 0].tolist()
    if not (np.all(table[:, name_columns] == expected_names)
            and all(t.isdigit() and len(t) < 19 for t in frame_tokens)):
        raise error()
    try:
        values = np.array(table[:, value_columns].ravel().tolist(), dtype=np.float64)
    except ValueError:
        raise error() from None
    if not np.all(np.isfinite(values)):
        raise error()
    return values.reshape(n, -1), np.array(frame_tokens).astype(np.int64)


def _content_lines(data, body: _AmcLines):
    """Indices of the body lines that are neither blank nor comments, and whether they are
    simply all lines up to trailing blank ones (the usual case, checked with one regex
    over the body's bytes, trailing whitespace left out: :func:`_gap`)."""
    start = body.span(0)[0]
    end = _end_of_text(data, start)
    if not _gap(data, body, max(start - 1, 0), end):
        last = len(body)
        while last and not body[last - 1].strip():
            last -= 1
        return range(last), True
    return [i for i in range(len(body)) if (line := body[i]).strip()
            and not line.lstrip().startswith("#")], False


def _end_of_text(data, start: int) -> int:
    """The offset past the last byte of ``data[start:]`` that is not whitespace
    (``str.isspace`` of its latin-1 character; ``start`` when there is none), read back
    from the end a block at a time."""
    end = len(data)
    while end > start:
        a = max(start, end - (1 << 16))
        solid = np.flatnonzero(~_SPACE[np.frombuffer(data[a:end], np.uint8)])
        if solid.size:
            return a + int(solid[-1]) + 1
        end = a
    return start


def _gap(data, lines: _AmcLines, lo: int, end: int) -> bool:
    """Whether a blank or comment line starts in ``data[lo:end]`` and ends before ``end``
    (``_GAP``; the file's first line too when ``lo`` is 0): searched _BLOCK bytes at a
    time, each search cut at a line end (a match never crosses one)."""
    if end <= lo:
        return False
    if lo == 0 and _GAP_FIRST.match(data[:min(end, int(lines.starts[1]) if len(lines.starts) > 1
                                               else end)]):
        return True
    newlines = lines.starts[1:] - 1
    at = np.searchsorted(newlines, np.arange(lo + _BLOCK, end, _BLOCK))
    cuts = newlines[at[at < len(newlines)]]
    bounds = [lo, *sorted({int(c) for c in cuts if lo < c < end}), end]
    return any(_GAP.search(data[a:min(b + 1, end)]) for a, b in zip(bounds, bounds[1:]))


def _token_columns(layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bone names a frame's tokens hold, and the columns of the names and the values."""
    names, values = [], []
    column = 1
    for _, count in layout:
        names.append(column)
        values.extend(range(column + 1, column + 1 + count))
        column += 1 + count
    return (np.array([name for name, _ in layout], dtype=object), np.array(names, dtype=np.intp),
            np.array(values, dtype=np.intp))


# --------------------------------------------------------------------------- read
def find_asf(amc_path: Path, asf_option=None) -> Path:
    if asf_option is not None:
        asf = Path(asf_option)
        if not asf.is_file():
            raise UnreadableFileError(amc_path, f"ASF skeleton {asf} (asf= option) not found")
        return asf
    folder = amc_path.parent
    stems = [amc_path.stem, amc_path.stem.split("_", 1)[0]]

    def asf_files():
        with os.scandir(folder) as entries:
            return [e.name for e in entries if e.name.lower().endswith(".asf") and e.is_file()]

    found = _asf_for(amc_path.name, lambda name: (folder / name).is_file(), asf_files)
    if found is not None:
        return folder / found
    in_folder = asf_files()
    tried = " or ".join(f"{s}.asf" for s in dict.fromkeys(stems))
    why = f"{len(in_folder)} .asf files there" if in_folder else "no .asf file there"
    # a name looked for that is there but is no file (a FIFO, a folder, a broken link)
    odd: dict = {}                  # by inode: one entry on a case-insensitive file system
    for name in _asf_names(amc_path.name):
        path = folder / name
        if os.path.lexists(path) and not path.is_file():
            kind = "a folder" if path.is_dir() else regular_file_problem(path)
            odd.setdefault(os.lstat(path).st_ino, f"{name} ({kind})")
    if odd:
        why = f"found but not a file: {', '.join(odd.values())}"
    raise UnreadableFileError(
        amc_path, f"cannot find the ASF skeleton: no {tried} in {folder} ({why}); put the "
                  f"skeleton beside the AMC as {stems[-1]}.asf (from Python: read(..., asf=PATH))")


def read(path, fps: float | None = None, **options) -> Motion:
    path = Path(path)
    if path.suffix.lower() == ".asf":
        return _read_rest_pose(path, fps)
    # a large AMC is read a block at a time from the file, never held whole
    amc = large_view(path, _HEAD) or read_input_bytes(path)
    lines = _AmcLines.of(amc)
    _check_text(path, amc, lines)
    asf_path = find_asf(path, options.get("asf"))
    asf_bytes = read_input_bytes(asf_path)
    asf = parse_asf(asf_path, asf_bytes)
    source = parse_amc(path, amc, asf, lines)
    source.asf_path, source.asf_bytes = str(asf_path), asf_bytes
    if source.body is not None:
        source.body.data = keep(path, source.body.data)
    notes = list(asf.notes) + source.notes
    if source.flags["degrees"] is None:
        notes.append(f"AMC has no :DEGREES/:RADIANS line; angles read in the ASF unit ({asf.angle_unit})")
    for line in source.flags["unknown"]:
        notes.append(f"AMC header line {line!r} kept but not interpreted")
    frames = source.frame_numbers
    if len(frames) > 1 and np.any(np.diff(frames) != 1):
        notes.append("AMC frame numbers are not consecutive; frames are taken as evenly spaced")
    return _motion(source, kept_values(source.values, options.get("share_values", False)),
                   fps, notes)


def _read_rest_pose(path: Path, fps) -> Motion:
    asf_bytes = read_input_bytes(path)
    asf = parse_asf(path, asf_bytes)
    layout = [(name, asf.dof_count(name)) for name in ["root"] + asf.order if asf.dof_count(name)]
    eol = "\r\n" if b"\r\n" in asf_bytes else "\n"
    cr = eol[:-1]
    source = AsfAmcSource(
        asf_path=str(path), asf_bytes=asf_bytes, asf=asf, layout=layout, degrees=True, eol=eol,
        header_lines=[":FULLY-SPECIFIED" + cr, ":DEGREES" + cr], frame_numbers=np.array([1]))
    n_channels = sum(count for _, count in layout)
    notes = list(asf.notes) + ["ASF skeleton read alone: one frame, rest pose (every channel 0)"]
    return _motion(source, np.zeros((1, n_channels)), fps, notes)


def _motion(source: AsfAmcSource, channels: np.ndarray, fps, notes: list[str]) -> Motion:
    asf = source.asf
    rig, rig_notes = build_rig(asf, source.layout, source.degrees)
    positions = positions_in_chunks(rig, channels)
    if fps is None:
        fps = DEFAULT_FPS
        if source.values is not None:
            notes.append("AMC files store no frame rate; assumed 120 Hz (CMU default)")
    elif not (np.isfinite(float(fps)) and float(fps) > 0):
        raise UnreadableFileError(source.asf_path, f"frame rate must be a positive number, got {fps}")
    scale = asf.length_scale
    units = "in" if scale == 1.0 else f"in/{scale:g}"
    return Motion(
        positions=positions, names=list(rig.names), fps=float(fps), units=units,
        metres_per_unit=asf_length_unit(scale), format=NAME,
        skeleton=Skeleton(rig.parents.copy()), rig=rig, channels=channels,
        source=source, notes=notes + rig_notes)


# --------------------------------------------------------------------------- write
def format_value(value: float) -> str:
    """``%.6f`` without trailing zeros (``-0`` written as ``0``)."""
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def write(motion: Motion, path, skeleton_checked: bool = False, **options) -> list[Path]:
    """Write the copy of the motion's ASF beside the AMC ``path``, then the AMC (a run
    killed in between leaves the AMC's old version beside the new skeleton, which a re-run
    rewrites, never an AMC without its skeleton). The copy is checked first
    (:func:`skeleton_conflict`) unless ``skeleton_checked``: a batch checks all its files
    together before any runs (each file alone would see its batch-mates' half-written
    state)."""
    path = Path(path)
    source = motion.source
    if not isinstance(source, AsfAmcSource):
        raise WriteError(path, "ASF/AMC can only be written from a motion read from ASF/AMC "
                               "(its skeleton and channel layout are needed)")
    if motion.channels is None:
        raise WriteError(path, "motion has no channels to write")
    channels = np.asarray(motion.channels, dtype=np.float64)
    n_channels = sum(count for _, count in source.layout)
    if channels.ndim != 2 or channels.shape[1] != n_channels:
        raise WriteError(path, f"channels must be (frames, {n_channels}), got {channels.shape}")
    if not np.all(np.isfinite(channels)):
        raise WriteError(path, "channels hold NaN or infinite values, which AMC cannot store")
    asf_target = path.with_name(source.asf_name)
    if path.suffix.lower() == ".asf":
        if channels.shape[0] > 1:
            raise WriteError(path, "an .asf file holds only the skeleton; write the motion to a .amc path")
        conflict = None if skeleton_checked else skeleton_conflict(
            None, Path(source.asf_path), source.asf_bytes, target=path)
        if conflict:
            raise WriteError(path, f"cannot be written there: {conflict}")
        return [_write_asf(path, source)]
    if asf_target.resolve() == path.resolve():
        raise WriteError(path, f"the AMC would overwrite its skeleton {source.asf_name}")
    if not skeleton_checked:
        conflict = skeleton_conflict(path, Path(source.asf_path), source.asf_bytes)
        if conflict:
            raise WriteError(path, f"its skeleton cannot be written: {conflict}")
    copy = _write_asf(asf_target, source)
    atomic_write_pieces(path, _amc_pieces(source, channels))
    return [path, copy]


def companion_files(path: Path) -> list[Path]:
    """The ASF that :func:`read` reads with the AMC ``path`` (none for an ASF, or when none
    is found: reading the AMC says so)."""
    if path.suffix.lower() == ".asf":
        return []
    try:
        return [find_asf(path)]
    except (UnreadableFileError, OSError):
        return []


def skeleton_output(amc: Path, output: Path) -> tuple[Path, Path] | None:
    """(the ASF the AMC ``amc`` is read with, the copy of it written beside ``output``), or
    None when no ASF is found (reading the AMC will say so). For batch planning: two
    AMCs whose skeletons would land on one name must share the skeleton."""
    try:
        asf = find_asf(Path(amc))
    except (UnreadableFileError, OSError):
        return None
    return Path(output).with_name(asf.name), asf


def skeleton_conflict(amc: Path | None, asf: Path, asf_bytes: bytes, *, rewriting=(),
                      planned: dict | None = None, present: set | None = None,
                      outsiders: list | None = None, target: Path | None = None) -> str | None:
    """Why the copy of the ASF ``asf`` (content ``asf_bytes``) cannot be written beside the
    AMC output ``amc`` (None: it can); with ``amc`` None, why the ASF cannot be written at
    ``target`` (an ASF cleaned as a file of its own). An AMC is paired with its skeleton by
    file name (:func:`find_asf`: the AMC's own name, its subject's, else the only ``.asf``
    there), so the copy must not leave an AMC there with the wrong skeleton or none:

    - ``amc`` itself read with another file (``05.asf`` beside a copy ``05.ASF``), or with
      none (two ``.asf`` files there, neither named after it);
    - another AMC there read with another skeleton than now, or none (it found the only
      ``.asf`` there, and the copy is a second);
    - a copy of another ASF already at the copy's name, which other AMC files there are
      read with (an earlier file of the batch from another folder, an earlier run):
      replacing it would pair them with the wrong skeleton, keeping it this one. When the
      only AMCs there read with it are being written again (``rewriting``: the names of
      the AMC outputs the caller writes there, each beside its own copy: the outputs of
      an earlier run, cleaned again after their ASF was edited), it is replaced.

    A batch checks every file before any runs (:func:`mocapfix.batch.plan.skeleton_conflicts`):
    ``planned`` maps the names of the other copies it writes in that folder to the ASF
    each copies, ``present`` holds the names of the files there (:func:`file_names`),
    ``outsiders`` the AMCs there it does not write; the writer checks a file written
    alone."""
    target = Path(target) if target is not None else Path(amc).with_name(Path(asf).name)
    folder = target.parent
    planned = planned or {}
    present = file_names(folder) if present is None else present
    after = present | {target.name} | set(planned)
    if amc is not None:
        amc = Path(amc)
        found = _asf_for(amc.name, after.__contains__, lambda: after)
        stem = amc.stem
        if found is None:
            shown = ", ".join(sorted(n for n in after if n.lower().endswith(".asf")))
            return (f"it could not be read back with it: the folder would hold several .asf "
                    f"files ({shown}) and none named {stem}.asf or {stem.split('_', 1)[0]}.asf; "
                    "clean it into a folder of its own")
        if found != target.name and not _holds(planned.get(found, folder / found), asf_bytes):
            return (f"{folder / found} would be read with it instead of its skeleton (a copy "
                    f"of {asf}); clean this file into another folder, or move {found} away")
    replaced = target.name in present and not _holds(target, asf_bytes)
    if not replaced and after == present:
        return None                 # nothing another AMC there is read with changes
    if outsiders is None:
        skip = {*([amc.name] if amc is not None else []), *rewriting}
        outsiders = sorted(n for n in present if n.lower().endswith(".amc") and n not in skip)
    users, lost = [], []
    for other in outsiders:
        now = _asf_for(other, present.__contains__, lambda: present)
        if now is None:
            continue
        if _asf_for(other, after.__contains__, lambda: after) != now:
            lost.append(f"{other} (read with {now})")
        elif now == target.name and replaced:
            users.append(other)
    if lost:
        return (f"writing {target.name} there would leave {', '.join(lost[:3])} without its "
                "skeleton; clean this file into another folder")
    if users:
        shown = ", ".join(users[:3]) + (f" and {len(users) - 3} more" if len(users) > 3 else "")
        return (f"{target} holds another ASF (not {asf}), which other AMC files there use "
                f"({shown}); clean this file into another folder, or remove that ASF")
    return None


def _asf_for(amc_name: str, has, listing) -> str | None:
    """The name of the ASF the AMC ``amc_name`` is read with (None: none): the AMC's own
    name, then its subject's (the part before the first ``_``), in three letter cases,
    else the only ``.asf`` of the folder. ``has(name)``: whether the folder holds that
    file; ``listing()``: the names there (asked only for the last rule)."""
    for name in _asf_names(amc_name):
        if has(name):
            return name
    asfs = [n for n in listing() if n.lower().endswith(".asf")]
    return asfs[0] if len(asfs) == 1 else None


def _asf_names(amc_name: str) -> list[str]:
    """The names an AMC's ASF is looked for under, in order: the AMC's own name, then its
    subject's (the part before the first ``_``), each in three letter cases."""
    stem = Path(amc_name).stem
    return list(dict.fromkeys(base + suffix for base in (stem, stem.split("_", 1)[0])
                              for suffix in (".asf", ".ASF", ".Asf")))


def file_names(folder: Path) -> set:
    """The names of the files in ``folder`` (empty when it is not there or not listable)."""
    try:
        with os.scandir(folder) as entries:
            return {e.name for e in entries if e.is_file()}
    except OSError:
        return set()


def _holds(path, content: bytes) -> bool:
    try:
        return path.read_bytes() == content
    except OSError:
        return False


def _write_asf(target: Path, source: AsfAmcSource) -> Path:
    try:
        if target.is_file() and target.read_bytes() == source.asf_bytes:
            return target           # already there, identical (e.g. a second trial of a subject)
    except OSError:
        pass
    refuse_stream(target)           # an output folder's device or FIFO would swallow it
    return atomic_write_bytes(target, source.asf_bytes)


def _amc_pieces(source: AsfAmcSource, channels: np.ndarray):
    """The AMC's bytes (latin-1) in pieces: the source with the changed bone lines
    rewritten, or frame blocks written from scratch; _CHUNK frames at a time."""
    if source.values is not None and source.values.shape == channels.shape:
        return _patched_pieces(source, channels)
    return _generated_pieces(source, channels)


def _patched_pieces(source: AsfAmcSource, channels: np.ndarray):
    """The source's bytes, with only the bone lines holding changed values re-written."""
    body = source.body
    done = 0                                       # offset of the source written so far
    for a in range(0, len(channels), _CHUNK):
        for i, line in _patched_lines(source, channels[a:a + _CHUNK], a):
            start, end = body.span(i)
            yield from runs_of(body.data, done, start)
            yield line.encode("latin-1")
            done = end
    yield from runs_of(body.data, done, len(body.data))


def _body_lines(index: np.ndarray | range, rows: np.ndarray) -> list[int]:
    """The body lines of the content lines ``rows`` (``index``: the source's
    ``content_index``)."""
    if isinstance(index, range):
        return (index.start + rows * index.step).tolist()
    return index[rows].tolist()


def _patched_lines(source: AsfAmcSource, channels: np.ndarray, first: int):
    """(body line, new text) of the bone lines of frames ``first`` on (``channels``) whose
    values changed, in line order."""
    old = source.values[first:first + len(channels)]
    changed = ~np.isclose(channels, old, rtol=1e-10, atol=1e-10)
    if not changed.any():
        return []
    text = np.empty(channels.shape, dtype=object)
    text[changed] = [format_value(v) for v in channels[changed].tolist()]
    per_frame = 1 + len(source.layout)
    starts = np.cumsum([0] + [count for _, count in source.layout])
    out = []
    for k, (name, _) in enumerate(source.layout):
        line_changed = changed[:, starts[k]:starts[k + 1]]
        frames = np.flatnonzero(line_changed.any(axis=1))
        rows = line_changed[frames].tolist()
        new_text = text[frames, starts[k]:starts[k + 1]].tolist()
        lines = _body_lines(source.content_index, (first + frames) * per_frame + 1 + k)
        for i, row, new in zip(lines, rows, new_text):
            line = source.body[i]
            tokens = [n if c else o for o, n, c in zip(line.split()[1:], new, row)]
            ending = "\r" if line.endswith("\r") else ""
            out.append((i, " ".join([name, *tokens]) + ending))
    return sorted(out)


def _generated_pieces(source: AsfAmcSource, channels: np.ndarray):
    """Frame blocks written from scratch (frame count differs from the source, or ASF
    only), after the source's header lines."""
    eol_cr = "\r" if source.eol == "\r\n" else ""
    first = int(source.frame_numbers[0]) if source.frame_numbers is not None else 1
    starts = np.cumsum([0] + [count for _, count in source.layout])
    head = "\n".join(source.header_lines)
    yield head.encode("latin-1")
    joined = bool(source.header_lines)             # a "\n" goes before the next line
    for a in range(0, channels.shape[0], _CHUNK):
        block = channels[a:a + _CHUNK]
        text = np.vectorize(format_value, otypes=[object])(block) if block.size else block
        lines = []
        for f in range(block.shape[0]):
            lines.append(f"{first + a + f}{eol_cr}")
            for k, (name, _) in enumerate(source.layout):
                lines.append(" ".join([name, *text[f, starts[k]:starts[k + 1]]]) + eol_cr)
        if lines:
            yield (("\n" if joined else "") + "\n".join(lines)).encode("latin-1")
            joined = True
    yield b"\n" if joined else b""               # the final line ending
