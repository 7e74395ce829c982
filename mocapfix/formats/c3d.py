"""C3D (biomechanics / optical motion capture) reader and writer.

What is handled
---------------
* All three processor types: Intel (little-endian IEEE), DEC (little-endian words, VAX
  F-floats) and SGI/MIPS (big-endian IEEE); int16 (POINT:SCALE > 0) and float32
  (POINT:SCALE < 0) storage. DEC and MIPS files are converted to Intel on read and are
  always *written* as Intel (a note on the motion says so).
* Missing samples: residual word < 0 (the C3D flag), NaN coordinates (kineticstoolkit)
  and exact (0, 0, 0) (Qualisys/numediart, some Vicon/BTS exports). ``Motion.confidence``
  is 1.0 for a valid sample and 0.0 for a missing one (residual magnitudes are vendor
  specific and often all 0, so they are not turned into a finer confidence).
* Labels from POINT:LABELS, LABELS2, LABELS3, ... (more than 255 markers); whitespace and
  NULs stripped; subject-prefixed labels ("Matt:C7") are kept whole (unique across
  subjects); empty labels become ``marker<N>``; duplicates get ``_2``, ``_3`` suffixes.
  Every such change is listed in ``Motion.notes``.
* POINT:UNITS as one entry or one per marker ("mm  mm  mm"); unset or unknown -> mm, noted.
* POINT:RATE (header rate as fallback), POINT:SCALE (header scale as fallback; a
  disagreement is noted and the parameter wins, as in the C3D manual).
* Quirky real files: no parameter section at all (header-only PhaseSpace export: points
  are read from the header counts, labels are placeholders); POINT:DATA_START = 0 or
  absent (header pointer used); a parameter whose record lacks the description-length
  byte (OptiTrack POINT:LABELS); header/parameter frame counts that disagree or exceed
  what the file holds (PhoeniX Dance.c3d, NDI Optotrak): when the data section ends
  exactly on a frame boundary the complete frames are read and a note says so; when it
  ends inside a frame the file is truncated and refused (UnreadableFileError).

Why hand-written instead of py-c3d (``c3d`` package)
-----------------------------------------------------
py-c3d fails on several shared files and cannot write back changed samples only
(measured: docs/formats.md, "Why the readers are hand-written"); the C3D layout is small,
so this module parses it directly with bounded loops and reads the data block with one
``numpy.frombuffer`` per file. py-c3d is still used by the tests as an independent reader
of the files written here.

Writing
-------
When the motion still has this reader's :class:`C3DSource` and the same frames and
markers, the output is the input file (converted to Intel if needed) with only the point
records of changed samples re-encoded: header, every parameter byte (but the fill list
below), analog data, events and trailing bytes are copied. Unchanged motion from an Intel file gives a byte-identical
file (unless ``mark_missing`` has to flag vendor-style (0,0,0)/NaN gaps, see ``write``).
Sample rules: unchanged samples keep their record bytes (residual and camera mask);
samples filled by a cleaner get residual 0 and camera mask 0 (c3d.org: modelled, valid);
samples still missing get residual -1 with the source coordinates; samples a cleaner
modified keep their residual and camera mask; samples a cleaner deleted get (0,0,0) and
residual -1. When samples were filled, a ``MOCAPFIX`` parameter group lists every run of
them (label, first/last frame, mean confidence, long or not; :func:`_fill_params`) — the
only parameter bytes that change, besides POINT:DATA_START and the header's data pointer
when the section has to grow by whole blocks to hold it (:mod:`.c3d_params`). Int16 files
are rounded to the POINT:SCALE grid. The file's POINT:RATE is
kept even when the user overrode the rate on reading (the data were not resampled). Any other motion (no C3D
source, or a different number of frames/markers) is written as a fresh float file with
only the POINT/ANALOG/TRIAL parameters (logged).
"""
from __future__ import annotations

import logging
import struct
from dataclasses import dataclass, field
from itertools import chain
from pathlib import Path

import numpy as np

from mocapfix.core.errors import UnreadableFileError, WriteError
from mocapfix.core.fileio import atomic_open, read_input_bytes
from mocapfix.formats.filebytes import FileBytes, FileView, keep, large_file
from mocapfix.formats.c3d_params import (MAX_DIM, group_record as _group_record, param_data_offset,
                                         param_record as _param_record, string_param as _string_param,
                                         string_value, with_group)
from mocapfix.core.motion import Motion, all_xyz, any_xyz
from mocapfix.core.quantity import MAX_FRAME_RATE_HZ, MIN_FRAME_RATE_HZ
from mocapfix.core.units import METRES_PER_UNIT, normalise_unit_name

NAME = "c3d"
SUFFIXES = (".c3d",)
#: what its points are (configs and rule files may name the family: ``formats: [markers]``)
FAMILY = "markers"
#: where its sniffer runs when the suffix does not tell (lower first: the stricter tests)
SNIFF_ORDER = 0

PROCESSOR_INTEL, PROCESSOR_DEC, PROCESSOR_MIPS = 84, 85, 86
PROCESSOR_NAMES = {PROCESSOR_INTEL: "Intel", PROCESSOR_DEC: "DEC", PROCESSOR_MIPS: "SGI/MIPS"}
BLOCK = 512
MAX_EVENTS = 18

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------------------------
# number conversion between processor types (all vectorised)
# ---------------------------------------------------------------------------------------
def dec_to_float(raw: bytes) -> np.ndarray:
    """VAX/DEC F-floats (as stored in C3D files) to float64, exactly.

    A DEC float is two little-endian 16-bit words, the high word first; value =
    (-1)^s * 0.1fff... * 2^(e-128); e = 0 means zero.
    """
    words = np.frombuffer(raw, dtype="<u4").astype(np.uint64)
    bits = ((words & 0xFFFF) << 16) | (words >> 16)
    sign = np.where(bits >> 31, -1.0, 1.0)
    exponent = ((bits >> 23) & 0xFF).astype(np.int64)
    mantissa = ((bits & 0x7FFFFF) | 0x800000).astype(np.float64)
    value = sign * np.ldexp(mantissa, exponent - 128 - 24)
    return np.where(exponent == 0, 0.0, value)


def floats_to_intel(raw: bytes, processor: int) -> bytes:
    """32-bit floats of ``processor`` re-encoded as little-endian IEEE float32."""
    if processor == PROCESSOR_DEC:
        return dec_to_float(raw).astype("<f4").tobytes()
    if processor == PROCESSOR_MIPS:
        return np.frombuffer(raw, dtype=">f4").astype("<f4").tobytes()
    return bytes(raw)


def words_to_intel(raw: bytes, processor: int, itemsize: int = 2) -> bytes:
    """Integers of ``processor`` as little-endian (only MIPS needs a byte swap)."""
    if processor == PROCESSOR_MIPS and itemsize > 1:
        return np.frombuffer(raw, dtype=f">u{itemsize}").astype(f"<u{itemsize}").tobytes()
    return bytes(raw)


def header_to_intel(raw: bytes, processor: int) -> bytes:
    """The 512-byte header of ``processor`` re-encoded for an Intel file."""
    if processor == PROCESSOR_INTEL:
        return bytes(raw)
    out = bytearray(raw)
    if processor == PROCESSOR_MIPS:
        for start, stop in ((2, 12), (16, 20), (24, 304), (394, 396), (468, 512)):
            out[start:stop] = words_to_intel(raw[start:stop], processor)
    for start in (12, 20):
        out[start:start + 4] = floats_to_intel(raw[start:start + 4], processor)
    out[304:376] = floats_to_intel(raw[304:376], processor)  # 18 event times
    return bytes(out)


# ---------------------------------------------------------------------------------------
# parameter section
# ---------------------------------------------------------------------------------------
@dataclass
class C3DParam:
    """One parameter; ``data`` is Intel-encoded (converted from DEC/MIPS on read)."""

    name: str
    group_id: int
    bytes_per_element: int
    dims: tuple
    data: bytes
    desc: str = ""

    @property
    def value(self):
        """Decoded value: list of str (bpe -1, one per string), numpy array or scalar."""
        bpe, dims = self.bytes_per_element, self.dims
        if bpe == -1:
            text = self.data.decode("latin-1")
            if len(dims) <= 1:
                return [text]
            width = dims[0]
            count = int(np.prod(dims[1:], dtype=np.int64)) if width else 0
            count = min(count, -(-len(text) // width) if width else 0)  # strings held, not declared
            return [text[i * width:(i + 1) * width] for i in range(count)]
        dtype = {1: "<i1", 2: "<i2", 4: "<f4"}.get(bpe)
        if dtype is None or len(self.data) % abs(bpe):
            return self.data
        values = np.frombuffer(self.data, dtype=dtype)
        if not dims:
            return values[0].item() if values.size else None
        try:
            return values.reshape(tuple(reversed(dims)))
        except ValueError:
            return values

    def scalar(self, kind: str = "float"):
        """First element as float or as unsigned 16-bit int; None if empty."""
        if self.bytes_per_element == 4 and len(self.data) >= 4:
            number = float(np.frombuffer(self.data[:4], "<f4")[0])
        elif self.bytes_per_element == 2 and len(self.data) >= 2:
            number = float(np.frombuffer(self.data[:2], "<u2" if kind == "uint" else "<i2")[0])
        elif self.bytes_per_element == 1 and len(self.data) >= 1:
            number = float(self.data[0])
        else:
            return None
        return number


@dataclass
class C3DGroup:
    name: str
    group_id: int
    desc: str = ""
    params: dict = field(default_factory=dict)


@dataclass
class ParameterSection:
    groups: dict            # name -> C3DGroup (in file order)
    intel_bytes: bytes      # the whole section re-encoded for Intel (same layout)
    offset: int             # byte offset in the file
    problems: list          # oddities noticed while parsing

    def get(self, key: str):
        group_name, _, param_name = key.upper().partition(":")
        group = self.groups.get(group_name)
        return None if group is None else group.params.get(param_name)


def parse_parameters(path, data: bytes, start: int, stop: int, processor: int) -> ParameterSection:
    """Walk the linked parameter records in ``data[start:stop]``.

    Every iteration advances by at least one record header, so the loop is bounded by the
    section size. Malformed records end the walk with a recorded problem.
    """
    section = bytearray(data[start:stop])
    section[3] = PROCESSOR_INTEL
    groups_by_id: dict = {}
    problems: list = []
    int16 = ">h" if processor == PROCESSOR_MIPS else "<h"
    pos = start + 4
    while pos + 2 <= stop:
        name_len, group_id = struct.unpack_from("<bb", data, pos)
        name_len = abs(name_len)
        if name_len == 0 or group_id == 0:
            break
        name_end = pos + 2 + name_len
        if name_end + 2 > stop:
            problems.append(f"parameter record at byte {pos} runs past the section end")
            break
        name = data[pos + 2:name_end].decode("latin-1").strip().upper()
        offset_pos = name_end
        (to_next,) = struct.unpack_from(int16, data, offset_pos)
        section[offset_pos - start:offset_pos - start + 2] = struct.pack("<h", to_next)
        record_end = stop if to_next <= 0 else min(offset_pos + to_next, stop)
        if to_next > 0 and offset_pos + to_next > stop:
            problems.append(f"parameter {name!r} points past the parameter section")
        body = offset_pos + 2
        if group_id < 0:
            _read_group(data, body, record_end, name, -group_id, groups_by_id)
        else:
            param = _read_param(data, body, record_end, name, group_id, processor, problems)
            if param is not None:
                lo = body + 2 + len(param.dims) - start
                section[lo:lo + len(param.data)] = param.data
                group = groups_by_id.setdefault(group_id, C3DGroup(f"GROUP{group_id}", group_id))
                if name in group.params:
                    problems.append(f"duplicate parameter {group.name}:{name} (first kept)")
                else:
                    group.params[name] = param
        if to_next <= 0:
            break
        pos = offset_pos + to_next
    groups = {}
    for group in groups_by_id.values():
        name = group.name
        if name in groups:
            problems.append(f"duplicate group name {name!r}: second one renamed {name}{group.group_id}")
            name = f"{name}{group.group_id}"
        groups[name] = group
    return ParameterSection(groups, bytes(section), start, problems)


def _read_group(data, body, record_end, name, group_id, groups_by_id):
    desc = ""
    if body < record_end:
        desc_len = data[body]
        desc = data[body + 1:min(body + 1 + desc_len, record_end)].decode("latin-1")
    group = groups_by_id.setdefault(group_id, C3DGroup(name, group_id))
    group.name, group.desc = name, desc


def _read_param(data, body, record_end, name, group_id, processor, problems):
    if body + 2 > record_end:
        problems.append(f"parameter {name!r} has no type/dimension bytes")
        return None
    (bpe,) = struct.unpack_from("<b", data, body)
    ndims = data[body + 1]
    dims_end = body + 2 + ndims
    if dims_end > record_end or bpe not in (-1, 1, 2, 4):
        problems.append(f"parameter {name!r} has an invalid type ({bpe}) or dimensions")
        return None
    dims = tuple(data[body + 2:dims_end])
    size = int(np.prod(dims, dtype=np.int64)) * abs(bpe) if dims else abs(bpe)
    data_end = dims_end + size
    if data_end > record_end:
        problems.append(f"parameter {name!r} declares {size} bytes but its record holds "
                        f"{record_end - dims_end}; value cut")
        data_end = record_end - (record_end - dims_end) % abs(bpe)
    raw = data[dims_end:data_end]
    raw = floats_to_intel(raw, processor) if bpe == 4 else words_to_intel(raw, processor, abs(bpe))
    desc = ""
    if data_end < record_end:
        desc_len = data[data_end]
        desc = data[data_end + 1:min(data_end + 1 + desc_len, record_end)].decode("latin-1")
    else:
        problems.append(f"parameter {name!r} lacks its description-length byte")
    return C3DParam(name, group_id, bpe, dims, bytes(raw), desc)


# ---------------------------------------------------------------------------------------
# the source kept on the Motion for writing back
# ---------------------------------------------------------------------------------------
@dataclass
class C3DSource:
    """Everything the writer needs; arrays are Intel-encoded and never changed by cleaners.

    ``points`` (T, P, 4) float32 or int16 records as stored (x, y, z, residual word);
    ``analog`` (T, A) raw analog words per point frame (channels interleaved per sample,
    ``analog_per_frame`` samples); ``missing`` (T, P) as read. The positions as read
    (:meth:`positions_of`), ``residual`` (T, P, in length units, -1 if flagged invalid)
    and ``camera_mask`` (T, P, uint8) are decoded from ``points`` when asked for, not
    held: on a long take they were 33 bytes a sample beside the motion's own positions.
    For a large file ``points`` and ``analog`` are :class:`_StoredRecords`, read again
    from the file a chunk of frames at a time (:mod:`mocapfix.formats.filebytes`).
    """

    processor: int
    header: bytes                 # 512 bytes, Intel-encoded
    original_header: bytes
    parameters: ParameterSection | None
    data_offset: int
    storage: str                  # "float" or "int16"
    scale: float                  # |scale| used for int16 storage
    points: np.ndarray
    analog: np.ndarray
    analog_per_frame: int
    analog_dtype: str
    missing: np.ndarray
    names: list
    units: str
    metres_per_unit: float
    first_frame: int
    events: list                  # header events (time s, label, displayed)
    prefix: bytes                 # file bytes from 512 up to data_offset, Intel-encoded
    tail: bytes                   # bytes after the last frame read
    conversion_note: str | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """(frames, points) of the records."""
        return self.missing.shape

    def positions_of(self, frames: slice = slice(None)) -> np.ndarray:
        """The positions of ``frames`` as read (NaN where missing), decoded again from
        the records: the same values as the motion read had, bit for bit."""
        positions, _ = _positions(self.points[frames], self.storage, self.scale,
                                  self.missing[frames])
        return positions

    @property
    def residual(self) -> np.ndarray:
        """(T, P) residuals as read, in length units; -1 where flagged invalid."""
        return _residual_and_mask(self.points, self.storage, self.scale)[0]

    @property
    def camera_mask(self) -> np.ndarray:
        """(T, P) uint8 camera masks as read (0 where flagged invalid)."""
        return _residual_and_mask(self.points, self.storage, self.scale)[1]

    @property
    def groups(self) -> dict:
        return {} if self.parameters is None else self.parameters.groups

    def param(self, key: str):
        return None if self.parameters is None else self.parameters.get(key)

    @property
    def parameter_events(self) -> list[dict]:
        """EVENT group events (``events`` holds the header's)."""
        return parameter_events(self.parameters)

    @property
    def analog_frames(self) -> np.ndarray:
        """Analog data as (T, analog_per_frame, channels) float64 raw values (no scaling)."""
        t, words = self.analog.shape
        per = max(self.analog_per_frame, 1)
        return self.analog.astype(np.float64).reshape(t, per, words // per if words else 0)


# ---------------------------------------------------------------------------------------
# reading
# ---------------------------------------------------------------------------------------
def sniff(head: bytes) -> bool:
    if len(head) < 4 or head[1] != 0x50 or head[0] < 2:
        return False
    param_at = (head[0] - 1) * BLOCK
    if len(head) >= param_at + 4:
        return head[param_at + 3] in PROCESSOR_NAMES
    return True  # parameter section beyond the 4 KiB head: the reader will check it


def read(path, fps: float | None = None, **options) -> Motion:
    """Read a C3D file. ``fps`` overrides the file's rate (noted when they disagree)."""
    path = Path(path)
    try:
        data = _large(path) or read_input_bytes(path)
        return _read_bytes(path, data, fps)
    except UnreadableFileError:
        raise
    except (struct.error, ValueError, IndexError, UnicodeDecodeError, OverflowError) as exc:
        raise UnreadableFileError(path, f"malformed C3D file ({type(exc).__name__}: {exc})") from None


def _large(path) -> FileView | None:
    """A C3D over :data:`~mocapfix.formats.filebytes.HELD_MAX` bytes as a
    :class:`~mocapfix.formats.filebytes.FileView` holding its header and parameter section
    (up to the data section's block, or the section's declared end if later): its records
    are decoded from the file a chunk at a time and read again when written, the file is
    never held whole. None for a smaller file, or one whose first blocks do not lay out a
    C3D (read whole, the reader then says what is wrong)."""
    file = large_file(path)
    if file is None:
        return None
    first = file[0:BLOCK]
    if len(first) < BLOCK or first[0] < 2:
        return None
    param_start = (first[0] - 1) * BLOCK
    section = file[param_start:param_start + 4]
    if len(section) < 4 or section[3] not in PROCESSOR_NAMES:
        return None
    data_block = _unpack_header(header_to_intel(first, section[3]))["data_block"]
    end = max(param_start + 4, param_start + section[2] * BLOCK, (data_block - 1) * BLOCK)
    return FileView(file, min(end, len(file)))


def _read_bytes(path, data: bytes | FileView, fps):
    notes: list[str] = []
    if len(data) == 0:
        raise UnreadableFileError(path, "file is empty")
    if len(data) < BLOCK:
        raise UnreadableFileError(path, f"file is {len(data)} bytes, shorter than the 512-byte C3D header")
    if data[1] != 0x50:
        raise UnreadableFileError(path, "not a C3D file (byte 2 of the header is not the C3D key 0x50)")
    param_block = data[0]
    if param_block < 2 or (param_block - 1) * BLOCK + 4 > len(data):
        raise UnreadableFileError(path, f"parameter section pointer (block {param_block}) lies outside "
                                        f"the file ({len(data)} bytes): truncated or not a C3D file")
    param_start = (param_block - 1) * BLOCK
    n_param_blocks, processor = data[param_start + 2], data[param_start + 3]
    if processor not in PROCESSOR_NAMES:
        raise UnreadableFileError(path, f"unknown processor type {processor} in the parameter section "
                                        "(expected 84 Intel, 85 DEC, 86 SGI/MIPS)")
    header = header_to_intel(data[:BLOCK], processor)
    h = _unpack_header(header)

    parameters = None
    if n_param_blocks == 0:
        notes.append("file has no parameter section; points, rate and scale taken from the header, "
                     "labels are placeholders")
    else:
        # the data pointer bounds the section better than its declared block count, which
        # some writers get wrong (PhoeniX Dance.c3d declares too few blocks)
        stop = min(param_start + n_param_blocks * BLOCK, len(data))
        if param_start + 4 < (h["data_block"] - 1) * BLOCK <= len(data):
            stop = (h["data_block"] - 1) * BLOCK
        parameters = parse_parameters(path, data.head if isinstance(data, FileView) else data,
                                      param_start, stop, processor)
        notes += [f"parameter section: {p}" for p in parameters.problems]
    get = (lambda key: None) if parameters is None else parameters.get

    n_points = _choose_count(get("POINT:USED"), h["point_count"], "POINT:USED", "points", notes)
    if n_points == 0:
        raise UnreadableFileError(path, "file holds no 3D points (POINT:USED and header point count are 0)")
    scale = _choose_float(get("POINT:SCALE"), h["scale"], "POINT:SCALE", "scale", notes)
    if scale is None or scale == 0:
        raise UnreadableFileError(path, "no usable POINT:SCALE or header scale factor (0)")
    storage = "float" if scale < 0 else "int16"
    rate = _choose_float(get("POINT:RATE"), h["rate"], "POINT:RATE", "frame rate", notes)

    data_offset = _data_offset(path, get("POINT:DATA_START"), h["data_block"], param_start, len(data),
                               notes if parameters is not None else [])
    word = 4 if storage == "float" else 2
    analog_words = h["analog_count"]
    analog_per_frame = h["analog_per_frame"]
    analog_words = _check_analog_layout(get, analog_words, analog_per_frame, notes)
    frame_bytes = (4 * n_points + analog_words) * word
    n_frames = _frame_count(path, get, h, frame_bytes, len(data) - data_offset, notes)

    analog_fmt = get("ANALOG:FORMAT")
    unsigned = analog_fmt is not None and "UNSIGNED" in "".join(analog_fmt.value).upper()
    label_notes: list[str] = []         # after the records' notes, as they are reported
    names = _labels(get, parameters, n_points, label_notes)
    units, metres = _units(get("POINT:UNITS"), label_notes)
    kinds = point_kinds(get, names)
    # a model output of exactly (0, 0, 0) is a value (no ground reaction in swing), not a
    # gap: only the residual flag and NaN make it missing
    model = None if kinds is None else np.array([k != "marker" for k in kinds])
    record = _record_dtype(n_points, analog_words, storage, processor, unsigned)
    kept = keep(path, data)
    with np.errstate(invalid="ignore", over="ignore"):  # garbage may hold signalling NaNs
        if isinstance(kept, FileBytes):     # a large file: its records are read again when written
            positions, missing = _decode_stored(data, data_offset, record, n_frames, storage,
                                                abs(scale), processor, model, notes)
            points, analog = (_StoredRecords(kept, data_offset, record, n_frames, part, storage,
                                             processor) for part in ("p", "a"))
        else:
            points, analog = _read_data(data, data_offset, n_frames, record, storage, processor)
            positions, missing = _decode_points(points, storage, abs(scale), notes, model)
    tail = data[data_offset + n_frames * frame_bytes:]
    notes += label_notes

    if fps is not None:
        if rate is not None and not np.isclose(fps, rate):
            notes.append(f"frame rate {fps:g} Hz given by the user overrides the file's {rate:g} Hz")
        rate = float(fps)
    if rate is None or not np.isfinite(rate) or rate <= 0:
        raise UnreadableFileError(path, "no valid frame rate in POINT:RATE or the header; pass fps")
    if not MIN_FRAME_RATE_HZ <= rate <= MAX_FRAME_RATE_HZ:
        raise UnreadableFileError(path, f"frame rate {rate:g} Hz is outside {MIN_FRAME_RATE_HZ:g}"
                                        f"-{MAX_FRAME_RATE_HZ:g} Hz (a corrupt POINT:RATE?); pass fps")

    conversion_note = None
    if processor != PROCESSOR_INTEL:
        conversion_note = (f"processor {PROCESSOR_NAMES[processor]}: will be written as Intel "
                           "(little-endian IEEE floats and integers)")
        notes.append(conversion_note)
    prefix = bytearray(data[BLOCK:data_offset])
    if parameters is not None:
        lo = param_start - BLOCK
        section = parameters.intel_bytes[:max(0, min(len(parameters.intel_bytes), len(prefix) - lo))]
        prefix[lo:lo + len(section)] = section
    else:
        prefix[param_start - BLOCK + 3] = PROCESSOR_INTEL

    source = C3DSource(
        processor=processor, header=header, original_header=data[:BLOCK], parameters=parameters,
        data_offset=data_offset, storage=storage, scale=abs(scale), points=points, analog=analog,
        analog_per_frame=analog_per_frame, analog_dtype=str(analog.dtype),
        missing=missing,
        names=list(names), units=units, metres_per_unit=metres, first_frame=h["first_frame"],
        events=_events(header), prefix=bytes(prefix), tail=tail, conversion_note=conversion_note)
    if kinds is not None:
        other = [n for n, k in zip(names, kinds) if k != "marker"]
        notes.append(f"{len(other)} points are model outputs, not markers (POINT:"
                     f"{'/'.join(sorted({k.upper() + 'S' for k in kinds if k != 'marker'}))}); "
                     "cleaning passes them through unchanged")
    return Motion(positions=positions, names=names, fps=float(rate), units=units,
                  metres_per_unit=metres, format=NAME, confidence=(~missing).astype(np.float64),
                  source=source, path=str(path), notes=notes, kinds=kinds)


#: POINT parameters that list model outputs stored as points (Vicon Plug-in Gait and
#: others; POINT:TYPE_GROUPS may name more)
MODEL_OUTPUT_GROUPS = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "SCALARS", "REACTIONS")


def point_kinds(get, names: list[str]) -> list[str] | None:
    """Per point: "marker", or the kind of model output ("angle", "force", ...) when its
    label is listed in POINT:ANGLES, FORCES, MOMENTS, POWERS, SCALARS, REACTIONS or a
    group named in POINT:TYPE_GROUPS. None when the file lists no model outputs."""
    groups = list(MODEL_OUTPUT_GROUPS)
    typed = get("POINT:TYPE_GROUPS")
    if typed is not None:
        values = typed.value if isinstance(typed.value, (list, tuple)) else [typed.value]
        for name in [str(v).strip().upper() for v in values][0::2]:
            if name and name not in groups:
                groups.append(name)
    kind_of: dict[str, str] = {}
    for group in groups:
        listed = get(f"POINT:{group}")
        if listed is None or not isinstance(listed.value, (list, tuple)):
            continue
        kind = group.lower()[:-1] if group.endswith("S") else group.lower()
        for label in listed.value:
            label = str(label).strip()
            if label:
                kind_of.setdefault(label, kind)
    if not kind_of:
        return None
    kinds = [kind_of.get(n, "marker") for n in names]
    return kinds if any(k != "marker" for k in kinds) else None


def _unpack_header(header: bytes) -> dict:
    (point_count, analog_count, first, last, max_gap) = struct.unpack_from("<5H", header, 2)
    (scale,) = struct.unpack_from("<f", header, 12)
    data_block, analog_per_frame = struct.unpack_from("<2H", header, 16)
    (rate,) = struct.unpack_from("<f", header, 20)
    return dict(point_count=point_count, analog_count=analog_count, first_frame=first,
                last_frame=last, scale=float(scale), data_block=data_block,
                analog_per_frame=analog_per_frame, rate=float(rate))


def _choose_count(param, header_value, key, what, notes) -> int:
    value = None if param is None else param.scalar("uint")
    if value is None:
        return int(header_value)
    if int(value) != header_value:
        notes.append(f"{key} = {int(value)} disagrees with the header {what} count {header_value}; "
                     f"{key} used")
    return int(value)


def _choose_float(param, header_value, key, what, notes):
    """The parameter's value unless it is unreadable, non-finite or 0 (then the header's)."""
    value = None if param is None else param.scalar()
    if value is None or not np.isfinite(value) or value == 0:
        if param is not None:
            notes.append(f"{key} unusable ({value}); header {what} {header_value:g} used")
        return header_value if np.isfinite(header_value) else None
    if not np.isclose(value, header_value, rtol=1e-5, atol=0):
        notes.append(f"{key} = {value:g} disagrees with the header {what} {header_value:g}; {key} used")
    return float(value)


def _data_offset(path, data_start, header_block, param_start, size, notes) -> int:
    block = header_block
    if data_start is None:
        notes.append("POINT:DATA_START missing; header data pointer used")
    else:
        value = int(data_start.scalar("uint") or 0)
        if value == 0:
            notes.append("POINT:DATA_START is 0; header data pointer used")
        elif value != header_block:
            notes.append(f"POINT:DATA_START = {value} disagrees with the header data block "
                         f"{header_block}; header used")
    offset = (block - 1) * BLOCK
    if block < 2 or offset <= param_start or offset > size:
        raise UnreadableFileError(path, f"data section pointer (block {block}) lies outside the file "
                                        f"({size} bytes): truncated or corrupt header")
    return offset


def _check_analog_layout(get, analog_words, analog_per_frame, notes) -> int:
    used = get("ANALOG:USED")
    if used is not None:
        expected = int(used.scalar("uint") or 0) * analog_per_frame
        if expected != analog_words:
            notes.append(f"ANALOG:USED x samples per frame = {expected} disagrees with the header "
                         f"analog word count {analog_words}; header used for the data layout")
    return analog_words


def _frame_count(path, get, h, frame_bytes, available_bytes, notes) -> int:
    """Frames to read: the largest declared count the file holds completely.

    Declared counts come from the header (last - first + 1), POINT:FRAMES,
    POINT:LONG_FRAMES and TRIAL:ACTUAL_START/END_FIELD. If the file holds fewer frames than
    every declaration: complete frames followed by end-of-file are read (noted); a partial
    frame means the file was cut, and it is refused.
    """
    candidates = {}
    if h["last_frame"] >= h["first_frame"]:
        candidates["header"] = h["last_frame"] - h["first_frame"] + 1
    frames = get("POINT:FRAMES")
    if frames is not None and frames.scalar("uint"):
        candidates["POINT:FRAMES"] = int(frames.scalar("uint"))
    long_frames = get("POINT:LONG_FRAMES")
    if long_frames is not None and long_frames.bytes_per_element == 4:
        value = long_frames.scalar()
        if value and np.isfinite(value) and value > 0:
            candidates["POINT:LONG_FRAMES"] = int(value)
    start, end = get("TRIAL:ACTUAL_START_FIELD"), get("TRIAL:ACTUAL_END_FIELD")
    if start is not None and end is not None and len(start.data) >= 4 and len(end.data) >= 4:
        s = np.frombuffer(start.data[:4], "<u2").astype(np.int64)
        e = np.frombuffer(end.data[:4], "<u2").astype(np.int64)
        first, last = s[0] + s[1] * 65536, e[0] + e[1] * 65536
        if last >= first > 0:
            candidates["TRIAL:ACTUAL_END_FIELD"] = int(last - first + 1)
    if not candidates:
        raise UnreadableFileError(path, "no frame count in the header or parameters")
    if frame_bytes <= 0:
        raise UnreadableFileError(path, "frame record size is 0")
    held = available_bytes // frame_bytes
    if len(set(candidates.values())) > 1:
        notes.append("frame counts disagree: " + ", ".join(f"{k} {v}" for k, v in candidates.items()))
    fitting = [v for v in candidates.values() if v <= held]
    if fitting:
        return max(fitting)
    declared = min(candidates.values())
    if available_bytes % frame_bytes:
        raise UnreadableFileError(
            path, f"truncated: data section holds {available_bytes / frame_bytes:.2f} frames of "
                  f"{frame_bytes} bytes, {declared} declared")
    if held == 0:
        raise UnreadableFileError(path, f"data section is empty, {declared} frames declared")
    notes.append(f"file declares {declared} frames but holds {held} complete frames ending exactly "
                 f"at end of file; read {held}")
    return int(held)


def _record_dtype(n_points, analog_words, storage, processor, unsigned) -> np.dtype:
    """One frame's record as the file stores it: point words (P, 4) then analog words."""
    if storage == "float":
        base = "f4"
        analog_base = "f4"
    else:
        base = "i2"
        analog_base = "u2" if unsigned else "i2"
    order = ">" if processor == PROCESSOR_MIPS else "<"
    if processor == PROCESSOR_DEC and storage == "float":
        base = analog_base = "u4"
    return np.dtype([("p", order + base, (n_points, 4)), ("a", order + analog_base, (analog_words,))])


def _intel(words: np.ndarray, storage: str, processor: int) -> np.ndarray:
    """Words of records as stored, Intel-encoded (a contiguous copy)."""
    if processor == PROCESSOR_DEC and storage == "float":
        words = dec_to_float(words.tobytes()).astype("<f4").reshape(words.shape)
    return np.ascontiguousarray(words.astype(words.dtype.newbyteorder("<")))


def _read_data(data, offset, n_frames, record, storage, processor):
    """Point records (T, P, 4) and analog words (T, A) of ``record`` (:func:`_record_dtype`),
    Intel-encoded, one frombuffer each."""
    frames = np.frombuffer(data, dtype=record, count=n_frames, offset=offset)
    return _intel(frames["p"], storage, processor), _intel(frames["a"], storage, processor)


class _StoredRecords:
    """The point records (``part="p"``) or analog words (``"a"``) of a large file, read
    again from it when asked for (:mod:`mocapfix.formats.filebytes`): ``[frames]`` (a
    slice) gives those frames' words as :func:`_read_data` gave them, ``np.asarray`` all
    of them; ``shape``, ``ndim``, ``dtype`` and ``size`` as of that array (``info`` reads
    the analog words' shape). The writer reads CHUNK frames at a time."""

    def __init__(self, data, offset: int, record: np.dtype, n_frames: int, part: str,
                 storage: str, processor: int):
        self.data, self.offset, self.record, self.part = data, offset, record, part
        self.storage, self.processor = storage, processor
        field = record.fields[part][0]
        self.shape = (n_frames, *field.shape)
        dec_float = processor == PROCESSOR_DEC and storage == "float"
        self.dtype = np.dtype("<f4") if dec_float else field.base.newbyteorder("<")
        self.size = int(np.prod(self.shape))
        self.ndim = len(self.shape)

    def __len__(self) -> int:
        return self.shape[0]

    def __getitem__(self, frames):
        if not isinstance(frames, slice) or frames.step not in (None, 1):
            return np.asarray(self)[frames]
        a, b, _ = frames.indices(self.shape[0])
        n = max(b - a, 0)
        raw = self.data[self.offset + a * self.record.itemsize:
                        self.offset + (a + n) * self.record.itemsize]
        with np.errstate(invalid="ignore", over="ignore"):
            return _intel(np.frombuffer(raw, dtype=self.record, count=n)[self.part],
                          self.storage, self.processor)

    def __array__(self, dtype=None, copy=None):
        whole = self[0:self.shape[0]]
        return whole if dtype is None else whole.astype(dtype)

    def astype(self, dtype):
        return np.asarray(self).astype(dtype)


def _residual_words(points: np.ndarray, storage: str) -> np.ndarray:
    """The 4th word of each record as a signed integer (-1 when it is not finite)."""
    fourth = points[..., 3]
    if storage == "float":
        finite = np.isfinite(fourth)
        clipped = np.clip(np.where(finite, fourth, -1.0), -32768, 32767)
        return np.trunc(clipped).astype(np.int32)
    return fourth.astype(np.int32)


def _decode_points(points, storage, scale, notes, model=None):
    """Positions (NaN where missing) and the missing mask of the records ``points``: a
    sample is missing when its residual word is negative, a coordinate is not finite, or
    it is exactly (0, 0, 0) (a vendor's gap) — unless it is a model output (``model``:
    (P,) bool, or None), whose (0, 0, 0) with a valid residual is a value."""
    positions, missing, counts = _decoded(points, storage, scale, model)
    _decode_notes(*counts, notes)
    return positions, missing


def _decoded(points, storage, scale, model):
    """:func:`_decode_points` without the notes: positions, mask and the counts of
    non-finite and (0, 0, 0) samples that the notes report."""
    xyz = _coordinates(points, storage, scale)
    flagged = _residual_words(points, storage) < 0
    non_finite = ~all_xyz(np.isfinite(xyz))
    zeros = all_xyz(xyz == 0) & ~flagged & ~non_finite
    missing = flagged | non_finite | zeros
    positions = _positions_from(xyz, missing)
    if model is not None:
        zero = model[None, :] & all_xyz(points[..., :3] == 0) & ~flagged
        positions[zero] = 0.0
        missing &= ~zero
    return positions, missing, (int(non_finite.sum()), int(zeros.sum()))


def _decode_notes(non_finite: int, zeros: int, notes: list[str]) -> None:
    if non_finite:
        notes.append(f"{non_finite} samples with NaN/inf coordinates treated as missing")
    if zeros:
        notes.append(f"{zeros} samples at exactly (0,0,0) without the residual -1 flag "
                     "treated as missing")


def _decode_stored(data, offset, record, n_frames, storage, scale, processor, model, notes):
    """:func:`_decode_points` of the point records in ``data`` (bytes or a
    :class:`~mocapfix.formats.filebytes.FileView`) from ``offset`` (``record`` per frame),
    CHUNK frames at a time: a large file's reader holds the positions and the mask, not
    the file, an Intel copy of every record or whole-take temporaries of them (its
    records are read again when written: :class:`_StoredRecords`)."""
    n_points = record.fields["p"][0].shape[0]
    positions = np.empty((n_frames, n_points, 3))
    missing = np.empty((n_frames, n_points), dtype=bool)
    non_finite = zeros = 0
    size = record.itemsize
    for frames in _chunks(n_frames):
        n = frames.stop - frames.start
        raw = data[offset + frames.start * size:offset + frames.stop * size]
        words = _intel(np.frombuffer(raw, dtype=record, count=n)["p"], storage, processor)
        positions[frames], missing[frames], (a, b) = _decoded(words, storage, scale, model)
        non_finite, zeros = non_finite + a, zeros + b
    _decode_notes(non_finite, zeros, notes)
    return positions, missing


def _coordinates(points, storage, scale) -> np.ndarray:
    """(T, P, 3) float64 coordinates of the records, in length units."""
    xyz = points[..., :3].astype(np.float64)
    if storage == "int16":
        xyz *= scale
    return xyz


def _positions_from(xyz: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """``xyz`` with NaN where ``missing`` (in place)."""
    xyz[missing] = np.nan
    return xyz


def _positions(points, storage, scale, missing) -> tuple[np.ndarray, np.ndarray]:
    """The positions the reader gave for records ``points`` whose samples are ``missing``
    (the reader's final mask: a model output's (0, 0, 0) is a value, +0.0), and that mask."""
    xyz = _coordinates(points, storage, scale)
    # a sample seen at exactly (0, 0, 0) is a model output's zero (any other is missing)
    zero = all_xyz(xyz == 0) & ~missing
    xyz[zero] = 0.0
    return _positions_from(xyz, missing), missing


def _residual_and_mask(points, storage, scale) -> tuple[np.ndarray, np.ndarray]:
    """(T, P) residuals (length units, -1 where flagged invalid) and uint8 camera masks
    of the records ``points``."""
    word = _residual_words(points, storage)
    flagged = word < 0
    residual = np.where(flagged, -1.0, (word & 0xFF) * scale)
    camera_mask = np.where(flagged, 0, (word & 0x7F00) >> 8).astype(np.uint8)
    return residual, camera_mask


def _labels(get, parameters, n_points, notes) -> list[str]:
    raw: list[str] = []
    if parameters is not None and "POINT" in parameters.groups:
        keys = ["LABELS"] + [f"LABELS{i}" for i in range(2, 1 + len(parameters.groups["POINT"].params))]
        for key in keys:
            param = get(f"POINT:{key}")
            if param is None or param.bytes_per_element != -1:
                if key != "LABELS":
                    break
                continue
            problem = _label_problem(param)
            if problem:
                notes.append(f"POINT:{key} {problem}; its labels are not used")
                continue
            raw += param.value
            if len(raw) >= n_points:
                break
    if parameters is not None and len(raw) < n_points:
        notes.append(f"POINT:LABELS holds {len(raw)} labels for {n_points} points; placeholders added")
    raw = [s.replace("\x00", " ").strip() for s in raw[:n_points]]
    raw += [""] * (n_points - len(raw))
    empty = [i for i, s in enumerate(raw) if not s]
    taken = set(s for s in raw if s)
    for i in empty:
        candidate = f"marker{i + 1}"
        while candidate in taken:
            candidate += "_"
        raw[i] = candidate
        taken.add(candidate)
    if empty and parameters is not None:
        notes.append(f"{len(empty)} empty marker labels named marker<N>")
    seen: dict[str, int] = {}
    renamed = []
    names = []
    for label in raw:
        if label in seen:
            seen[label] += 1
            new = f"{label}_{seen[label]}"
            while new in taken:
                seen[label] += 1
                new = f"{label}_{seen[label]}"
            renamed.append(f"{label}->{new}")
            taken.add(new)
            names.append(new)
        else:
            seen[label] = 1
            names.append(label)
    if renamed:
        notes.append("duplicate marker labels made unique: " + ", ".join(renamed[:10])
                     + (" ..." if len(renamed) > 10 else ""))
    return names


def _label_problem(param: C3DParam) -> str | None:
    """Why a label parameter cannot be a list of labels (None when it can): labels are a
    (width, count) character array; more dimensions are accepted only when they are 1."""
    dims = param.dims
    declared = int(np.prod(dims, dtype=np.int64)) if dims else 1
    if len(dims) > 2 and any(d != 1 for d in dims[2:]):
        shown = ", ".join(map(str, dims[:8])) + (", ..." if len(dims) > 8 else "")
        return f"has {len(dims)} dimensions ({shown}) (a label list has 2: width and count)"
    if declared != len(param.data):
        return f"declares {declared} characters but its record holds {len(param.data)}"
    return None


def _units(param, notes) -> tuple[str, float]:
    if param is None or param.bytes_per_element != -1:
        notes.append("POINT:UNITS unset; assuming mm")
        return "mm", METRES_PER_UNIT["mm"]
    tokens = " ".join(param.value).replace("\x00", " ").split()
    units = {normalise_unit_name(t) for t in tokens}
    if not tokens:
        notes.append("POINT:UNITS empty; assuming mm")
        return "mm", METRES_PER_UNIT["mm"]
    if None in units:
        notes.append(f"POINT:UNITS {tokens[0]!r} not recognised; assuming mm")
        return "mm", METRES_PER_UNIT["mm"]
    if len(units) > 1:
        notes.append(f"POINT:UNITS lists several units {sorted(units)}; the first ({tokens[0]}) used")
    unit = normalise_unit_name(tokens[0])
    return unit, METRES_PER_UNIT[unit]


def parameter_events(parameters: ParameterSection | None) -> list[dict]:
    """Events of the EVENT group (Vicon style): context, label, time in seconds."""
    if parameters is None or parameters.get("EVENT:TIMES") is None:
        return []
    times = parameters.get("EVENT:TIMES").value
    if not isinstance(times, np.ndarray) or times.ndim != 2 or times.shape[1] != 2:
        return []
    used = parameters.get("EVENT:USED")
    declared = None if used is None else used.scalar("uint")
    count = len(times) if declared is None else min(int(declared), len(times))

    def strings(key):
        param = parameters.get(key)
        values = param.value if param is not None and param.bytes_per_element == -1 else []
        return [v.strip("\x00 ") for v in values] + [""] * max(0, count - len(values))

    labels, contexts = strings("EVENT:LABELS"), strings("EVENT:CONTEXTS")
    return [dict(context=contexts[i], label=labels[i], time=float(times[i, 0]) * 60 + float(times[i, 1]))
            for i in range(count)]


def _events(header: bytes) -> list[dict]:
    """Header events (up to 18): time (s from the first frame), label, displayed flag."""
    (count,) = struct.unpack_from("<H", header, 300)
    count = min(count, MAX_EVENTS)
    times = np.frombuffer(header[304:376], "<f4")
    events = []
    for i in range(count):
        events.append(dict(time=float(times[i]), displayed=bool(header[376 + i]),
                           label=header[396 + 4 * i:400 + 4 * i].decode("latin-1").strip("\x00 ")))
    return events


# ---------------------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------------------
def write(motion: Motion, path, mark_missing: bool = True, **options) -> list[Path]:
    """Write ``motion`` as an Intel C3D file; returns ``[path]``.

    ``mark_missing`` (default True): samples missing in the source only by a vendor
    convention ((0,0,0) or NaN with a non-negative residual) are written with residual -1,
    so every reader sees the gap; False keeps those records byte-for-byte.
    """
    path = Path(path)
    source = motion.source
    if (isinstance(source, C3DSource) and motion.positions.shape[:2] == source.shape
            and list(motion.names) == list(source.names)):
        pieces = _splice(motion, source, path, mark_missing)
    else:
        if isinstance(source, C3DSource):
            log.warning("%s: frames or markers changed since reading; writing a fresh C3D "
                        "without the original analog data and parameters", path)
        pieces = _fresh_file(motion, path)
    with atomic_open(path, "wb") as handle:
        for piece in pieces:
            handle.write(piece)
    return [path]


def _positions_in_source_units(motion: Motion, source: C3DSource,
                               frames: slice = slice(None)) -> np.ndarray:
    """The motion's positions of ``frames`` in the source file's length unit."""
    positions = np.asarray(motion.positions[frames], dtype=np.float64)
    if motion.metres_per_unit != source.metres_per_unit:
        positions = positions * (motion.metres_per_unit / source.metres_per_unit)
    return positions


def _beyond_int16(new: np.ndarray, source: C3DSource, frames: slice = slice(None),
                  moved: bool = False) -> np.ndarray:
    """(T, P) True for the fills (samples missing in the source, present in ``new``: the
    positions of ``frames``, in source units; ``moved``: the samples present in both
    instead) that an int16 file's grid cannot hold: beyond ±32767 × POINT:SCALE."""
    if source.storage != "int16":
        return np.zeros(new.shape[:2], bool)
    with np.errstate(invalid="ignore", over="ignore"):
        out = np.abs(np.rint(new / source.scale)) > 32767
    which = ~source.missing[frames] if moved else source.missing[frames]
    return which & all_xyz(np.isfinite(new)) & any_xyz(out)


def _chunks(n_frames: int):
    """Slices of CHUNK frames covering ``n_frames``: the writer compares and encodes a
    take a chunk at a time, never holding a whole-take temporary of it."""
    return [slice(a, min(a + CHUNK, n_frames)) for a in range(0, n_frames, CHUNK)]


def kept_only_here(motion: Motion) -> list[str]:
    """What of a motion read from a C3D no other format carries: analog channels,
    events, the points that are model outputs (angles, forces ...), the residuals and
    camera masks. For :func:`mocapfix.formats.losses`."""
    source = motion.source
    if not isinstance(source, C3DSource):
        return []
    notes = []
    channels = source.analog.shape[1] // max(source.analog_per_frame, 1) if source.analog.size else 0
    if channels:
        notes.append(f"{channels} analog channel(s) (force plates, EMG ...) are not carried")
    events = len(source.events) + len(source.parameter_events)
    if events:
        notes.append(f"{events} event(s) are not carried")
    if motion.kinds is not None:
        others = [n for n, k in zip(motion.names, motion.kinds) if k != "marker"]
        if others:
            notes.append(f"{len(others)} point(s) that are model outputs, not markers "
                         f"({', '.join(others[:3])}{' ...' if len(others) > 3 else ''}), are "
                         "written as positions by formats that keep every point, left out by "
                         "marker formats")
    notes.append("the residuals and camera masks of the samples are not carried")
    return notes


def storable(motion: Motion) -> Motion:
    """``motion`` as :func:`write` will store it in its source file: a fill an int16 file
    cannot hold (far outside where the markers ever were) is made a gap again, and a
    sample seen in the file but moved beyond that range (a smoother's overshoot of a
    sample at the range's edge, where the file saturated) is held at the edge, each with a
    note, so that the report describes the file written (the write failed for the whole
    file). Other motions come back as they are."""
    source = motion.source
    if (not isinstance(source, C3DSource) or motion.positions.shape[:2] != source.shape
            or source.storage != "int16"):
        return motion
    lost, held = np.zeros(source.shape, bool), np.zeros(source.shape, bool)
    for frames in _chunks(source.shape[0]):
        new = _positions_in_source_units(motion, source, frames)
        lost[frames] = _beyond_int16(new, source, frames)
        held[frames] = _beyond_int16(new, source, frames, moved=True)
    if not lost.any() and not held.any():
        return motion
    positions = motion.positions.copy()
    positions[lost] = np.nan
    notes = list(motion.notes)
    if lost.any():
        notes.append(f"{int(lost.sum())} filled samples lie beyond the int16 range of the file "
                     f"(±32767 × POINT:SCALE {source.scale:g}); left as gaps")
    if held.any():
        edge = 32767 * abs(source.scale) * source.metres_per_unit / motion.metres_per_unit
        positions[held] = np.clip(positions[held], -edge, edge)
        notes.append(f"{int(held.sum())} moved samples lie beyond the int16 range of the file "
                     f"(±32767 × POINT:SCALE {source.scale:g}); held at its edge")
    confidence = None if motion.confidence is None else np.where(lost, 0.0, motion.confidence)
    return motion.replace(positions=positions, confidence=confidence, notes=notes)


def _splice(motion: Motion, source: C3DSource, path, mark_missing: bool):
    """The file's pieces (bytes) with the changed samples re-encoded.

    The take is compared with the source and its records edited CHUNK frames at a time,
    twice: once here, for what the parameter section lists (the runs filled, the gaps
    left) and what must be warned of or refused before anything is written, and again
    as the data section is written (:func:`_edited_records`). A whole-take copy of the
    records, the positions in source units and a dozen per-sample masks were ~60 bytes
    a sample at the writer's peak; now two masks (2 bytes a sample) are held."""
    T = source.shape[0]
    filled = np.zeros(source.shape, bool)
    new_missing = np.zeros(source.shape, bool)
    unrepresentable, refused = 0, None
    for frames in _chunks(T):
        edits = _SampleEdits(motion, source, frames)
        filled[frames], new_missing[frames] = edits.filled, edits.new_missing
        if edits.unrepresentable is not None:
            unrepresentable += int(edits.unrepresentable.sum())
        if refused is None and source.storage == "int16":
            try:        # a measured sample moved beyond the int16 grid: refused up front
                _encode_xyz(edits.new[edits.filled | edits.modified], source, path)
            except WriteError as exc:
                refused = exc
    if unrepresentable:
        # a fill the file's int16 grid cannot hold stays a gap (:func:`storable`, which
        # ``clean`` applies before the report) rather than failing the file; a *measured*
        # sample moved out of range is still an error
        log.warning("%s: %d filled samples lie beyond the int16 range of the file; "
                    "written as gaps", path, unrepresentable)
    if refused is not None:
        raise refused

    header, prefix = source.header, source.prefix
    left = _left_runs(motion, new_missing)
    if filled.any() or left:
        header, prefix = _with_fill_group(source, _fill_params(motion, source, filled, left), path)
    return chain([header, prefix],
                 _frame_records(_edited_records(motion, source, path, mark_missing), source.analog),
                 [source.tail])


class _SampleEdits:
    """How the motion's samples of ``frames`` differ from the source's: the positions in
    source units (``new``) and (frames, P) masks of the samples ``filled`` (missing in
    the source, present now; less those an int16 grid cannot hold, ``unrepresentable``,
    None for a float file), ``modified`` (present in both, moved), ``deleted`` (present
    in the source, missing now), ``still_missing`` (missing in both, or unrepresentable)
    and ``new_missing``."""

    def __init__(self, motion: Motion, source: C3DSource, frames: slice):
        new = _positions_in_source_units(motion, source, frames)
        old = source.positions_of(frames)
        was_missing = source.missing[frames]
        self.new = new
        self.new_missing = ~all_xyz(np.isfinite(new))
        changed = ~all_xyz((new == old) | (np.isnan(new) & np.isnan(old)))
        self.filled = changed & ~self.new_missing & was_missing
        self.modified = changed & ~self.new_missing & ~was_missing
        self.deleted = self.new_missing & ~was_missing
        self.still_missing = self.new_missing & was_missing
        self.unrepresentable = None
        if source.storage == "int16":
            self.unrepresentable = self.filled & _beyond_int16(new, source, frames)
            self.filled = self.filled & ~self.unrepresentable
            self.still_missing = self.still_missing | self.unrepresentable


def _edited_records(motion: Motion, source: C3DSource, path, mark_missing: bool):
    """The point records of the motion, CHUNK frames a piece: the source's, with the
    samples filled or moved re-encoded (residual 0 for a fill), those deleted made (0, 0,
    0) with residual -1, and (``mark_missing``) every sample still missing flagged -1."""
    for frames in _chunks(source.shape[0]):
        edits = _SampleEdits(motion, source, frames)
        original = source.points[frames]
        points = original.copy()
        encode = edits.filled | edits.modified
        if encode.any():
            points[..., :3][encode] = _encode_xyz(edits.new[encode], source, path)
        words = _residual_words(original, source.storage)
        points[..., 3][edits.filled] = 0
        if edits.deleted.any():
            points[..., :3][edits.deleted] = 0
            points[..., 3][edits.deleted] = -1
        if mark_missing:
            unflagged = edits.still_missing & (words >= 0)
            points[..., 3][unflagged] = -1
            if source.storage == "float":
                nan_word = edits.still_missing & ~np.isfinite(original[..., 3])
                points[..., 3][nan_word] = -1
        yield points


#: frames interleaved and written at a time
CHUNK = 4096


def _frame_records(pieces, analog: np.ndarray):
    """The data section: each frame's points then its analog samples, a piece of the
    point records (T, P, 4) at a time, in frame order (never the whole section as one
    more copy)."""
    at = 0
    for points in pieces:
        record = np.dtype([("p", points.dtype, points.shape[1:]),
                           ("a", analog.dtype, analog.shape[1:])])
        frames = np.empty(len(points), dtype=record)
        frames["p"] = points
        frames["a"] = analog[at:at + len(points)]
        at += len(points)
        yield frames.tobytes()


#: the parameter group listing mocapfix's fills (see :func:`_fill_params`)
FILL_GROUP = "MOCAPFIX"


def _chunked(name: str, values: list, make) -> list[tuple]:
    """Parameters ``name``, ``name2``, ``name3``… of at most 255 values each (the C3D
    LABELS/LABELS2 convention: one dimension holds at most 255 elements)."""
    out = []
    for n, lo in enumerate(range(0, max(len(values), 1), MAX_DIM)):
        out.append(make(name if n == 0 else f"{name}{n + 1}", values[lo:lo + MAX_DIM]))
    return out


def _old_fills(source: C3DSource) -> list[tuple]:
    """The fills listed by an earlier mocapfix run in the source's MOCAPFIX group."""
    group = source.groups.get(FILL_GROUP)
    if group is None:
        return []

    def joined(key, cast):
        out, n = [], 1
        while (p := group.params.get(key if n == 1 else f"{key}{n}")) is not None:
            value = p.value
            out += [cast(v) for v in (value if isinstance(value, list) else np.ravel(value))]
            n += 1
        return out

    cols = [joined("FILL_POINTS", str.strip), joined("FILL_FIRST", float), joined("FILL_LAST", float),
            joined("FILL_CONFIDENCE", float), joined("FILL_LONG", int)]
    n = min(len(c) for c in cols)
    # FILL_ERROR / FILL_BOUND: -1 for runs listed by a mocapfix that wrote none
    for key in ("FILL_ERROR", "FILL_BOUND"):
        values = joined(key, float)
        cols.append(values[:n] + [-1.0] * (n - len(values[:n])))
    # FILL_EXTRAPOLATED: 0 for runs listed by a mocapfix that wrote none
    values = joined("FILL_EXTRAPOLATED", int)
    cols.append(values[:n] + [0] * (n - len(values[:n])))
    return [tuple(c[i] for c in cols) for i in range(n)]


def listed_fills(motion: Motion) -> list[tuple]:
    """``(label, start, length, error_mm, bound_mm)`` of every filled run a mocapfix run
    listed in the ``MOCAPFIX`` group of a C3D as read (start: index into the frames read;
    error and bound None where not estimated). Empty for a file without the group."""
    source = motion.source
    if not isinstance(source, C3DSource):
        return []
    out = []
    for label, first, last, _conf, _long, error, bound, _extra in _old_fills(source):
        start = round(first) - int(source.first_frame)
        out.append((label, start, round(last - first) + 1,
                    None if error < 0 else float(error), None if bound < 0 else float(bound)))
    return out


def _left_runs(motion: Motion, missing: np.ndarray) -> list[tuple]:
    """``(point, start, length, error_mm, bound_mm, extrapolated)`` of every gap the
    pipeline left as too uncertain to fill (``Motion.fill_errors`` entries not written)
    that is still missing in ``missing`` (-1 for an estimate it had none of)."""
    index = {name: j for j, name in enumerate(motion.names)}
    out = []
    for name, entries in (motion.fill_errors or {}).items():
        for e in entries:
            j = index.get(name)
            if len(e) >= 6 and not e[5] and j is not None and missing[e[0]:e[0] + e[1], j].all():
                out.append((j, int(e[0]), int(e[1]), -1.0 if e[2] is None else float(e[2]),
                            -1.0 if e[3] is None else float(e[3]), int(len(e) > 6 and e[6])))
    return sorted(out, key=lambda r: (r[1], r[0]))


def _fill_params(motion: Motion, source: C3DSource, filled: np.ndarray,
                 left: list[tuple] = ()) -> list[tuple]:
    """MOCAPFIX group parameters listing every run of filled samples per point: FILL_POINTS
    (label), FILL_FIRST / FILL_LAST (C3D frame numbers, first and last filled frame),
    FILL_CONFIDENCE (mean ``Motion.confidence`` over the run, 0–1), FILL_LONG (1 when the
    run spans more than LONG_FILL_S seconds: rebuilt from a model, not bridged), plus
    FILL_ERROR / FILL_BOUND (the run's estimated RMS error and its calibrated 90 % bound,
    mm, :mod:`mocapfix.solvers.fill_error`; -1: no estimate), FILL_EXTRAPOLATED (1 when
    that estimate was extrapolated from windows shorter than the run), plus FILL_COUNT and
    LONG_FILL_S. Fills listed by an earlier run are kept. The gaps left as too uncertain
    to fill (``left``, :func:`_left_runs`: residual -1 in the file) are listed as
    LEFT_POINTS, LEFT_FIRST / LEFT_LAST, LEFT_ERROR / LEFT_BOUND (what their fill's error
    was estimated to be), LEFT_EXTRAPOLATED and LEFT_COUNT."""
    from mocapfix.core.gaps import runs
    from mocapfix.core.gaps import LONG_FILL_S
    from mocapfix.solvers.fill_error import FillIndex

    col, start, length = runs(filled)
    conf = motion.confidence if motion.confidence is not None else np.zeros(filled.shape)
    first = source.first_frame
    rows = _old_fills(source)
    estimates = FillIndex(motion.fill_errors)
    for c, s, n in sorted(zip(col.tolist(), start.tolist(), length.tolist()), key=lambda r: (r[1], r[0])):
        mean = float(np.nanmean(conf[s:s + n, c])) if np.isfinite(conf[s:s + n, c]).any() else 0.0
        rows.append((source.names[c], float(first + s), float(first + s + n - 1), mean,
                     int(n / motion.fps > LONG_FILL_S),
                     *(estimates.error(motion.names[c], s, n) or (-1.0, -1.0, False))))
    f32 = lambda name, v: (name, 4, (len(v),), np.asarray(v, "<f4").tobytes(), "")  # noqa: E731
    i8 = lambda name, v: (name, 1, (len(v),), np.asarray(v, "<i1").tobytes(), "")  # noqa: E731
    params = _chunked("FILL_POINTS", [r[0] for r in rows],
                      lambda name, v: (name, -1, *string_value(v, "replace"), "label of each filled run"))
    params += _chunked("FILL_FIRST", [r[1] for r in rows], f32)
    params += _chunked("FILL_LAST", [r[2] for r in rows], f32)
    params += _chunked("FILL_CONFIDENCE", [r[3] for r in rows], f32)
    params += _chunked("FILL_LONG", [r[4] for r in rows], i8)
    params += _chunked("FILL_ERROR", [r[5] for r in rows], f32)
    params += _chunked("FILL_BOUND", [r[6] for r in rows], f32)
    params += _chunked("FILL_EXTRAPOLATED", [int(r[7]) for r in rows], i8)
    if left:
        params += _chunked("LEFT_POINTS", [source.names[r[0]] for r in left],
                           lambda name, v: (name, -1, *string_value(v, "replace"),
                                            "label of each gap left as too uncertain to fill"))
        params += _chunked("LEFT_FIRST", [float(first + r[1]) for r in left], f32)
        params += _chunked("LEFT_LAST", [float(first + r[1] + r[2] - 1) for r in left], f32)
        params += _chunked("LEFT_ERROR", [r[3] for r in left], f32)
        params += _chunked("LEFT_BOUND", [r[4] for r in left], f32)
        params += _chunked("LEFT_EXTRAPOLATED", [r[5] for r in left], i8)
        params += [("LEFT_COUNT", 4, (), struct.pack("<f", float(len(left))),
                    "gaps left as too uncertain to fill")]
    params += [("FILL_COUNT", 4, (), struct.pack("<f", float(len(rows))), "filled runs listed"),
               ("LONG_FILL_S", 4, (), struct.pack("<f", LONG_FILL_S), "a fill longer than this (s) is long")]
    return params


def _with_fill_group(source: C3DSource, params: list[tuple], path) -> tuple[bytes, bytes]:
    """(header, prefix) of the source with the MOCAPFIX group in its parameter section.
    The section grows by whole blocks when it must: the data then start that many blocks
    later (header word 9 and POINT:DATA_START moved). A section that cannot be edited
    safely is left as it was (logged): the fills are then marked only by residual 0."""
    header, prefix = source.header, source.prefix
    lo = source.parameters.offset - BLOCK if source.parameters is not None else -1
    if lo < 0 or lo + 4 > len(prefix):
        log.warning("%s: no parameter section to list the fills in", path)
        return header, prefix
    old_len = min(prefix[lo + 2] * BLOCK, len(prefix) - lo)   # some files count blocks they lack
    section = with_group(prefix[lo:lo + old_len], FILL_GROUP, params,
                         "mocapfix: runs of samples filled by cleaning (residual 0, camera mask 0)")
    if section is None:
        log.warning("%s: parameter section not editable; fills marked by residual 0 only", path)
        return header, prefix
    if len(section) <= len(prefix) - lo:
        section = section.ljust(max(old_len, len(section)), b"\0")
        blocks = len(section) // BLOCK
        section = section[:2] + bytes([blocks]) + section[3:]
        tail = prefix[lo + len(section):]
        return header, prefix[:lo] + section + tail
    extra = (len(section) - old_len) // BLOCK
    at = param_data_offset(section, "POINT", "DATA_START")
    start_block = struct.unpack_from("<H", header, 16)[0] + extra
    if start_block > 65535:
        log.warning("%s: parameter section cannot grow; fills marked by residual 0 only", path)
        return header, prefix
    section = bytearray(section)
    if at is not None:      # without POINT:DATA_START readers take the header's pointer
        struct.pack_into("<H", section, at, start_block)
    header = bytearray(header)
    struct.pack_into("<H", header, 16, start_block)
    return bytes(header), prefix[:lo] + bytes(section) + prefix[lo + old_len:]


def _encode_xyz(values: np.ndarray, source: C3DSource, path) -> np.ndarray:
    if source.storage == "float":
        return values.astype(np.float32)
    grid = np.rint(values / source.scale)
    if (np.abs(grid) > 32767).any():
        raise WriteError(path, f"coordinate beyond the int16 range of this file "
                               f"(|value| > {32767 * source.scale:g} {source.units})")
    # A valid point within half a grid step of the origin would be stored as (0, 0, 0),
    # which readers (ours included) take for a vendor-style gap: move it one step along
    # its largest coordinate instead (an error of at most one scale step).
    at_origin = ~grid.any(axis=-1)
    if at_origin.any():
        v = values[at_origin]
        axis = np.argmax(np.abs(v), axis=-1)
        step = np.where(v[np.arange(len(v)), axis] < 0, -1.0, 1.0)
        g = grid[at_origin]
        g[np.arange(len(v)), axis] = step
        grid[at_origin] = g
    return grid.astype(np.int16)


# -- fresh file (no C3D source, or frames/markers changed) -------------------------------
def _fresh_file(motion: Motion, path):
    positions = np.asarray(motion.positions, dtype=np.float64)
    n_frames, n_points = positions.shape[:2]
    if n_frames == 0 or n_points == 0:
        raise WriteError(path, "cannot write a C3D file without frames or markers")
    if n_points > 65535 or any(len(n.encode("latin-1", "replace")) > 255 for n in motion.names):
        raise WriteError(path, "too many markers (> 65535) or a label longer than 255 characters")
    unit = motion.units if motion.units in METRES_PER_UNIT else "mm"
    scale = None if unit == motion.units else motion.metres_per_unit / METRES_PER_UNIT["mm"]
    rate = float(motion.fps)
    records = [_group_record("POINT", 1, "3-D point parameters")]
    f32 = lambda v: struct.pack("<f", v)  # noqa: E731
    u16 = lambda v: struct.pack("<H", v)  # noqa: E731
    records += [
        _param_record("USED", 1, 2, (), u16(n_points)),
        _param_record("FRAMES", 1, 2, (), u16(min(n_frames, 65535))),
        _param_record("DATA_START", 1, 2, (), u16(0)),  # patched below
        _param_record("SCALE", 1, 4, (), f32(-1.0)),
        _param_record("RATE", 1, 4, (), f32(rate)),
        _param_record("UNITS", 1, -1, (len(unit),), unit.encode("latin-1")),
    ]
    if n_frames >= 65535:
        records.append(_param_record("LONG_FRAMES", 1, 4, (), f32(float(n_frames))))
    names = [n.encode("latin-1", "replace").decode("latin-1") for n in motion.names]
    for chunk, start in enumerate(range(0, n_points, 255)):
        key = "LABELS" if chunk == 0 else f"LABELS{chunk + 1}"
        records.append(_string_param(key, 1, names[start:start + 255]))
    records += [_group_record("ANALOG", 2, "Analog parameters"),
                _param_record("USED", 2, 2, (), u16(0)),
                _param_record("RATE", 2, 4, (), f32(rate))]
    body = b"".join(records)
    n_param_blocks = -(-(4 + len(body)) // BLOCK)
    data_block = 2 + n_param_blocks
    body = body.replace(_param_record("DATA_START", 1, 2, (), u16(0)),
                        _param_record("DATA_START", 1, 2, (), u16(data_block)), 1)
    section = (bytes([1, 0x50, n_param_blocks, PROCESSOR_INTEL]) + body).ljust(n_param_blocks * BLOCK, b"\0")

    header = bytearray(BLOCK)
    # one analog sample per frame with zero channels keeps ANALOG:RATE / POINT:RATE = 1
    struct.pack_into("<BBHHHHHfHHf", header, 0, 2, 0x50, n_points, 0, 1, min(n_frames, 65535),
                     0, -1.0, data_block, 1, rate)
    return chain([bytes(header), section], _fresh_records(positions, scale),
                 [b"\0" * (-(n_frames * n_points * 16) % BLOCK)])


def _fresh_records(positions: np.ndarray, scale: float | None):
    """The point records (float, residual 0; a missing sample (0, 0, 0) with residual −1)
    of a fresh file, CHUNK frames a piece (never a whole-take copy of the take)."""
    for frames in _chunks(len(positions)):
        part = positions[frames] if scale is None else positions[frames] * scale
        missing = ~all_xyz(np.isfinite(part))
        points = np.zeros((*part.shape[:2], 4), dtype="<f4")
        points[..., :3] = np.where(missing[..., None], 0.0, part)
        points[..., 3] = np.where(missing, -1.0, 0.0)
        yield points.tobytes()
