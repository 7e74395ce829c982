"""C3D parameter records: encoding them, and adding a parameter group to a file's section.

A C3D parameter section (c3d.org, "The C3D File Format User Guide", ch. 3) is a 4-byte
header (first block, key 0x50, number of 512-byte blocks, processor) and a chain of
records, each ``int8 name length`` (negative: locked), ``int8 group id`` (negative: a
group), the name, ``int16 offset to the next record`` (0: the last one), then for a
parameter its type, dimensions, data and description, for a group its description.

:func:`with_group` rebuilds a section with one group (and its parameters) replaced or
added and every other record kept byte for byte (only the next-record offsets of the
records around the change are rewritten); the writer uses it to list mocapfix's fills in
a ``MOCAPFIX`` group. Written by hand for the same reasons as the reader
(:mod:`mocapfix.formats.c3d`: the C3D writers of py-c3d and ezc3d re-lay out the whole
parameter section).
"""
from __future__ import annotations

import struct
from dataclasses import dataclass

BLOCK = 512
#: one dimension of a C3D parameter holds at most this many elements (a byte)
MAX_DIM = 255


def param_record(name: str, group_id: int, bpe: int, dims, data: bytes, desc: str = "") -> bytes:
    name_b, desc_b = name.encode("latin-1"), desc.encode("latin-1")
    body = struct.pack("<bB", bpe, len(dims)) + bytes(dims) + data + struct.pack("<B", len(desc_b)) + desc_b
    return struct.pack("<bb", len(name_b), group_id) + name_b + struct.pack("<h", 2 + len(body)) + body


def group_record(name: str, group_id: int, desc: str) -> bytes:
    name_b, desc_b = name.encode("latin-1"), desc.encode("latin-1")
    body = struct.pack("<B", len(desc_b)) + desc_b
    return struct.pack("<bb", len(name_b), -group_id) + name_b + struct.pack("<h", 2 + len(body)) + body


def string_value(strings: list[str], errors: str = "strict") -> tuple[tuple, bytes]:
    """(dims, data) of a character parameter holding ``strings``: (width, count), each
    string padded with blanks to the longest."""
    width = max([len(s) for s in strings] + [1])
    return (width, len(strings)), "".join(s.ljust(width) for s in strings).encode("latin-1", errors)


def string_param(name, group_id, strings: list[str], desc="") -> bytes:
    dims, data = string_value(strings)
    return param_record(name, group_id, -1, dims, data, desc)


@dataclass
class Record:
    """One record of a parsed section: ``start``/``end`` byte offsets in the section (end:
    just past its content), ``link`` the offset of its next-record field, ``group_id`` as
    stored (negative for a group), ``name`` upper case."""

    start: int
    end: int
    link: int
    group_id: int
    name: str


def _content_end(section: bytes, body: int, is_group: bool) -> int:
    """End of a record's content from its body (for the last record, whose next-record
    offset is 0 and so does not give it)."""
    if is_group:
        return body + 1 + section[body] if body < len(section) else body
    bpe, ndims = struct.unpack_from("<bB", section, body)
    dims = section[body + 2:body + 2 + ndims]
    count = 1
    for d in dims:
        count *= d
    data_end = body + 2 + ndims + count * abs(bpe)
    return data_end + 1 + section[data_end] if data_end < len(section) else data_end


def records(section: bytes) -> list[Record] | None:
    """The records of an Intel-encoded section, in file order; None when the chain is
    malformed (a link pointing backwards or past the end, a record cut short), in which
    case the section is left alone."""
    out = []
    pos, size = 4, len(section)
    while pos + 2 <= size:
        name_len, group_id = struct.unpack_from("<bb", section, pos)
        name_len = abs(name_len)
        if name_len == 0 or group_id == 0:
            break
        link = pos + 2 + name_len
        if link + 2 > size:
            return None
        (to_next,) = struct.unpack_from("<h", section, link)
        name = section[pos + 2:link].decode("latin-1").strip().upper()
        try:
            end = link + to_next if to_next > 0 else _content_end(section, link + 2, group_id < 0)
        except struct.error:
            return None
        if end > size or end <= link:
            return None
        out.append(Record(pos, end, link, group_id, name))
        if to_next <= 0:
            break
        pos = end
    return out


def with_group(section: bytes, name: str, params: list[tuple], desc: str = "") -> bytes | None:
    """The section with group ``name`` holding ``params`` ((name, bpe, dims, data, desc)
    tuples) instead of whatever that group held, padded to whole blocks and the block
    count in its header updated; None when the section cannot be parsed safely or no group
    id is free. Records of other groups keep their bytes."""
    recs = records(section)
    if recs is None:
        return None
    groups = {-r.group_id: r.name for r in recs if r.group_id < 0}
    mine = next((g for g, n in groups.items() if n == name.upper()), None)
    used = {abs(r.group_id) for r in recs}
    gid = mine if mine is not None else next((g for g in range(1, 128) if g not in used), None)
    if gid is None:
        return None
    kept = [r for r in recs if abs(r.group_id) != gid]
    chain = bytearray()
    for r in kept:
        raw = bytearray(section[r.start:r.end])
        struct.pack_into("<h", raw, r.link - r.start, r.end - r.link)
        chain += raw
    new = [group_record(name.upper(), gid, desc)]
    new += [param_record(p, gid, bpe, dims, data, d) for p, bpe, dims, data, d in params]
    chain += b"".join(new)
    blocks = -(-(4 + len(chain)) // BLOCK)
    if blocks > 255:
        return None
    head = bytes([section[0], section[1], blocks, section[3]])
    return (head + bytes(chain)).ljust(blocks * BLOCK, b"\0")


def param_data_offset(section: bytes, group: str, name: str) -> int | None:
    """Byte offset in ``section`` of the data of parameter ``group:name`` (None if absent)."""
    recs = records(section) or []
    gid = next((-r.group_id for r in recs if r.group_id < 0 and r.name == group.upper()), None)
    for r in recs:
        if r.group_id == gid and r.name == name.upper():
            ndims = section[r.link + 3]
            return r.link + 4 + ndims
    return None
