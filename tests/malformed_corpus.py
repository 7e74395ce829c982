"""A seeded corpus of malformed inputs over the formats and configs.

:func:`cases` returns at least 500 :class:`Case` objects built from the bundled
``sample_data`` files and from small independent C3D and TRC writers (:func:`c3d_bytes`,
written from the C3D manual, :func:`trc_bytes` from OpenSim's TRC layout, not from our
readers): truncations, bit flips, garbage (whole files and
spliced blocks), huge counts, deep nesting, bad encodings, wrong columns, bad timestamps,
and hostile configs. The same seed gives the same corpus byte for byte.

Each case is a set of files (name -> bytes) and the one to open; configs are run through
``loads_config`` and, when they load, on a tiny motion.
"""
from __future__ import annotations

import os
import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

SAMPLE_DATA = Path(__file__).resolve().parents[1] / "sample_data"
VENDOR_DATA = Path(__file__).resolve().parent / "data" / "vendor"
#: MOCAPFIX_CORPUS_SEED=N gives another corpus of the same kinds (a fuzzing run)
SEED = int(os.environ.get("MOCAPFIX_CORPUS_SEED", "13"))


@dataclass
class Case:
    id: str
    family: str
    target: str                       # file to read (or config to load)
    files: dict = field(default_factory=dict)
    kind: str = "data"                # "data" or "config"
    clean: bool = True                # also clean a file that reads (False: read only)


# ------------------------------------------------------------------ an independent C3D writer
def _record(name: str, group_id: int, body: bytes, last: bool = False) -> bytes:
    raw = name.encode("ascii")
    offset = 0 if last else 2 + len(body)
    return struct.pack("<bb", len(raw), group_id) + raw + struct.pack("<h", offset) + body


def _param(name, group_id, bpe, dims, data: bytes, last=False) -> bytes:
    body = struct.pack("<bB", bpe, len(dims)) + bytes(dims) + data + b"\x00"
    return _record(name, group_id, body, last)


def _group(name, group_id) -> bytes:
    return _record(name, -group_id, b"\x00")


def c3d_bytes(points: np.ndarray, labels: list[str], rate: float = 100.0, *,
              label_dims: tuple | None = None, header_frames: int | None = None,
              used: int | None = None, scale: float = -1.0, extra: bytes = b"",
              units: str = "mm") -> bytes:
    """A float (or int16, ``scale > 0``) Intel C3D file of ``points`` (T, P, 3), NaN = missing.

    Written from the C3D manual (header words, parameter records, frame records) so that
    the corpus does not depend on the reader under test. ``label_dims`` overrides the
    dimensions of POINT:LABELS (the data stay width x P characters).
    """
    T, P, _ = points.shape
    width = max([4] + [len(s) for s in labels])
    text = b"".join(s.encode("latin-1").ljust(width) for s in labels)
    dims = label_dims or (width, P)
    params = [
        _group("POINT", 1),
        _param("USED", 1, 2, (), struct.pack("<H", P if used is None else used)),
        _param("FRAMES", 1, 2, (), struct.pack("<H", min(T, 65535))),
        _param("SCALE", 1, 4, (), struct.pack("<f", scale)),
        _param("RATE", 1, 4, (), struct.pack("<f", rate)),
        _param("LABELS", 1, -1, dims, text),
        _param("UNITS", 1, -1, (len(units),), units.encode()),
        None,  # DATA_START, filled below
        _group("ANALOG", 2),
        _param("USED", 2, 2, (), struct.pack("<H", 0)),
    ]
    section_len = 4 + sum(len(p) for p in params if p) + len(_param("DATA_START", 1, 2, (), b"\0\0")) \
        + len(extra) + len(_param("RATE", 2, 4, (), b"\0\0\0\0"))
    n_blocks = (section_len + 511) // 512
    data_block = 2 + n_blocks
    params[7] = _param("DATA_START", 1, 2, (), struct.pack("<H", data_block))
    body = b"".join(p for p in params if p) + extra + _param("RATE", 2, 4, (), struct.pack("<f", rate), last=True)
    section = bytes([1, 0x50, n_blocks, 84]) + body
    section = section.ljust(n_blocks * 512, b"\0")
    header = bytearray(512)
    header[0], header[1] = 2, 0x50
    last_frame = T if header_frames is None else header_frames
    struct.pack_into("<5H", header, 2, P if used is None else used, 0, 1, min(last_frame, 65535), 0)
    struct.pack_into("<f", header, 12, scale)
    struct.pack_into("<2H", header, 16, data_block, 0)
    struct.pack_into("<f", header, 20, rate)
    missing = np.isnan(points).any(axis=2)
    if not scale < 0:  # int16 storage (a NaN or 0 scale is stored as if it were 1)
        scale_used = scale if np.isfinite(scale) and scale > 0 else 1.0
    if scale < 0:
        frames = np.zeros((T, P, 4), "<f4")
        frames[..., :3] = np.where(missing[..., None], 0.0, points)
        frames[..., 3] = np.where(missing, -1.0, 0.0)
    else:
        frames = np.zeros((T, P, 4), "<i2")
        frames[..., :3] = np.where(missing[..., None], 0, np.clip(np.round(np.nan_to_num(points) / scale_used), -32768, 32767))
        frames[..., 3] = np.where(missing, -1, 0)
    return bytes(header) + section + frames.tobytes()


def small_c3d_points(T=60, P=5, seed=0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.arange(T)[:, None, None] / 100.0
    pts = 500 + 300 * np.sin(2 * np.pi * 0.8 * t + rng.uniform(0, 6, (1, P, 3)))
    pts[10:14, 1] = np.nan
    return pts


# ------------------------------------------------------------------ an independent TRC writer
def trc_bytes(points: np.ndarray, labels: list[str], rate: float = 100.0, *, units: str = "mm",
              frames: str | None = None, markers: str | None = None) -> bytes:
    """An OpenSim-4 TRC file of ``points`` (T, P, 3), NaN = missing as empty fields, written
    from OpenSim's documented layout (not from our writer). ``frames``/``markers`` override
    the NumFrames/NumMarkers header values."""
    T, P, _ = points.shape
    nf, nm = frames or str(T), markers or str(P)
    lines = ["PathFileType\t4\t(X/Y/Z)\tgen.trc",
             "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
             f"{rate}\t{rate}\t{nf}\t{nm}\t{units}\t{rate}\t1\t{nf}",
             "Frame#\tTime\t" + "\t\t\t".join(labels) + "\t\t\t",
             "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, P + 1)), ""]
    for t in range(T):
        cells = ["" if np.isnan(v) else f"{v:.5f}" for v in points[t].ravel()]
        lines.append("\t".join([str(t + 1), f"{t / 100:.3f}"] + cells))
    return ("\n".join(lines) + "\n").encode()


# ------------------------------------------------------------------------ mutations
def family(tag: str) -> str:
    """The kind of damage a case tag names: its leading word ("cut123" -> "cut")."""
    return re.match(r"[a-z]+(?:16|32)?", tag).group()


def _truncate(data, rng, n):
    cuts = sorted(set(rng.integers(1, len(data) - 1, n).tolist()))
    return [(f"cut{c}", data[:c]) for c in cuts]


def _bitflips(data, rng, n):
    out = []
    for k in range(n):
        b = bytearray(data)
        for at in rng.integers(0, len(b), int(rng.integers(1, 9))):
            b[at] ^= 1 << int(rng.integers(0, 8))
        out.append((f"flip{k}", bytes(b)))
    return out


def _splices(data, rng, n):
    out = []
    for k in range(n):
        size = int(rng.integers(1, 257))
        at = int(rng.integers(0, max(1, len(data) - size)))
        b = bytearray(data)
        b[at:at + size] = rng.integers(0, 256, size, dtype=np.uint8).tobytes()
        out.append((f"splice{k}", bytes(b)))
    return out


def _garbage(rng, n):
    out = []
    for k in range(n):
        size = int(rng.integers(1, 6000))
        if k % 3 == 0:  # printable garbage that looks like text
            raw = rng.choice(list(b"0123456789 .-+eE,:\t\nabcXYZ{}"), size).astype(np.uint8).tobytes()
        else:
            raw = rng.integers(0, 256, size, dtype=np.uint8).tobytes()
        out.append((f"garbage{k}", raw))
    return out


def _lines_edit(text: bytes, rng, n, sep):
    """Wrong columns: a value dropped, duplicated or replaced by a word on a random line."""
    lines = text.split(b"\n")
    body = [i for i, line in enumerate(lines) if len(line.split(sep)) > 3]
    out = []
    for k in range(n):
        i = int(rng.choice(body))
        parts = lines[i].rstrip(b"\r").split(sep)
        j = int(rng.integers(1, len(parts)))
        how = k % 4
        if how == 0:
            parts = parts[:j] + parts[j + 1:]
        elif how == 1:
            parts = parts[:j] + [parts[j]] + parts[j:]
        elif how == 2:
            parts[j] = [b"nan", b"inf", b"1e999", b"--", b"0x1F", b"1,5"][k % 6]
        else:
            parts = parts + parts
        new = list(lines)
        new[i] = sep.join(parts)
        out.append((f"cols{k}", b"\n".join(new)))
    return out


def _encodings(data: bytes):
    text = data.decode("latin-1")
    return [
        ("utf8bom", b"\xef\xbb\xbf" + data),
        ("utf16", text.encode("utf-16")),
        ("utf16le", text.encode("utf-16-le")),
        ("utf16be", text.encode("utf-16-be")),
        ("utf32", text.encode("utf-32")),
        ("nul", data[:200] + b"\x00" * 50 + data[200:]),
        ("badutf8", data[:300] + b"\xff\xfe\xc3" + data[300:]),
        ("crlf", data.replace(b"\n", b"\r\n")),
        ("cr", data.replace(b"\n", b"\r")),
    ]


def _generic(name: str, data: bytes, rng, companions: dict, text: bool, prefix: str) -> list[Case]:
    variants = (_truncate(data, rng, 30) + _bitflips(data, rng, 25) + _splices(data, rng, 20)
                + _garbage(rng, 10))
    encodings = _encodings(data) if text else []
    # every third generic case that reads is also cleaned (the rest only read: cleaning,
    # write-back and writing cost ~0.3 s a file and near-identical mutants add little)
    return [Case(f"{prefix}-{tag}", family(tag), name, {name: raw, **companions},
                 clean=k % 3 == 0 or k >= len(variants))
            for k, (tag, raw) in enumerate(variants + encodings)]


# ------------------------------------------------------------------- per-format specials
def _bvh_specials(data: bytes) -> list[tuple[str, bytes]]:
    head, _, motion = data.partition(b"MOTION")
    frames_re = re.compile(rb"Frames:\s*\d+")
    time_re = re.compile(rb"Frame Time:\s*\S+")
    out = [
        ("frames0", frames_re.sub(b"Frames: 0", head + b"MOTION" + motion.split(b"Frame Time")[0])
         + b"Frame Time: 0.0083333\n"),
        ("frames0-withlines", frames_re.sub(b"Frames: 0", data)),
        ("frames-huge", frames_re.sub(b"Frames: 99999999999999999999", data)),
        ("frames-neg", frames_re.sub(b"Frames: -5", data)),
        ("frames-float", frames_re.sub(b"Frames: 3.5", data)),
        ("channels-huge", data.replace(b"CHANNELS 3", b"CHANNELS 1000000000", 1)),
        ("channels-neg", data.replace(b"CHANNELS 3", b"CHANNELS -3", 1)),
        ("no-motion", head),
        ("no-hierarchy", b"MOTION" + motion),
        ("unbalanced-open", head.replace(b"}", b"", 3) + b"MOTION" + motion),
        ("unbalanced-close", head + b"}\n}\n" + b"MOTION" + motion),
    ]
    for value in (b"0", b"-0.01", b"nan", b"inf", b"1e308", b"1e-320", b"abc", b""):
        out.append((f"frametime-{value.decode() or 'empty'}", time_re.sub(b"Frame Time: " + value, data)))
    # deep nesting: a chain of 5,000 joints (5x Python's recursion limit) (explicit stack in the parser, O(n) FK)
    depth = 5_000
    chain = [b"HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition "
             b"Zrotation Xrotation Yrotation\n"]
    chain += [b"JOINT j%d\n{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n" % i
              for i in range(depth)]
    chain += [b"}\n" * (depth + 1)]
    chain += [b"MOTION\nFrames: 1\nFrame Time: 0.01\n" + b"0 " * (6 + 3 * depth) + b"\n"]
    out.append(("deep-chain", b"".join(chain)))
    out.append(("deep-braces", b"HIERARCHY\nROOT a\n" + b"{\n" * 20000 + b"}\n" * 20000 + b"MOTION\n"))
    return out


def _amc_specials(amc: bytes, asf: bytes) -> list[tuple[str, dict]]:
    out = []
    lines = amc.split(b"\n")
    first = next(i for i, line in enumerate(lines) if line.strip().isdigit())
    for tag, number in (("framenum-huge", b"99999999999999999999999"), ("framenum-neg", b"-1"),
                        ("framenum-word", b"one")):
        new = list(lines)
        new[first] = number
        out.append((tag, {"walker_01.amc": b"\n".join(new), "walker.asf": asf}))
    new = [line for line in lines[first + 1:]]
    out.append(("header-only", {"walker_01.amc": b"\n".join(lines[:first]) + b"\n", "walker.asf": asf}))
    out.append(("no-header", {"walker_01.amc": b"\n".join(lines[first:]), "walker.asf": asf}))
    out.append(("bom-both", {"walker_01.amc": b"\xef\xbb\xbf" + amc, "walker.asf": b"\xef\xbb\xbf" + asf}))
    out.append(("bom-asf", {"walker_01.amc": amc, "walker.asf": b"\xef\xbb\xbf" + asf}))
    out.append(("asf-utf16", {"walker_01.amc": amc, "walker.asf": asf.decode("latin-1").encode("utf-16")}))
    out.append(("no-asf", {"walker_01.amc": amc}))
    out.append(("asf-empty", {"walker_01.amc": amc, "walker.asf": b""}))
    # a deep ASF hierarchy: 5,000 bones in a chain
    n = 5_000
    bones = b"".join(b"begin\n id %d\n name b%d\n direction 0 1 0\n length 1\n axis 0 0 0 XYZ\n"
                     b" dof rx ry rz\nend\n" % (i + 1, i) for i in range(n))
    hierarchy = b"root b0\n" + b"".join(b"b%d b%d\n" % (i, i + 1) for i in range(n - 1))
    deep = (b":version 1.10\n:name deep\n:units\n mass 1.0\n length 1.0\n angle deg\n"
            b":root\n order TX TY TZ RX RY RZ\n axis XYZ\n position 0 0 0\n orientation 0 0 0\n"
            b":bonedata\n" + bones + b":hierarchy\nbegin\n" + hierarchy + b"end\n")
    frame = b"1\nroot 0 0 0 0 0 0\n" + b"".join(b"b%d 0 0 0\n" % i for i in range(n))
    out.append(("deep-asf", {"deep_01.amc": b":FULLY-SPECIFIED\n:DEGREES\n" + frame, "deep.asf": deep}))
    cyc = asf.replace(b":hierarchy\n  begin\n", b":hierarchy\n  begin\n    lfemur root\n")
    out.append(("asf-cycle", {"walker_01.amc": amc, "walker.asf": cyc}))
    return out


def _kinect_specials(data: bytes) -> list[tuple[str, bytes]]:
    lines = data.split(b"\n")
    head, rows = lines[:1], [line for line in lines[1:] if line.strip()]
    out = []

    def with_first_column(values):
        new = [b",".join([v] + r.split(b",")[1:]) for v, r in zip(values, rows)]
        return b"\n".join(head + new) + b"\n"

    stamps = [r.split(b",")[0] for r in rows]
    out.append(("ts-reversed", with_first_column(stamps[::-1])))
    out.append(("ts-duplicated", with_first_column([stamps[0]] * len(stamps))))
    out.append(("ts-nan", with_first_column([b"nan"] * len(stamps))))
    out.append(("ts-huge", with_first_column([b"9" * 40] * len(stamps))))
    out.append(("ts-negative", with_first_column([b"-%d" % i for i in range(len(stamps))])))
    out.append(("ts-words", with_first_column([b"noon"] * len(stamps))))
    out.append(("ts-one-jump", with_first_column(stamps[:5] + [stamps[5] + b"000000"] + stamps[6:])))
    out.append(("header-only", b"\n".join(head) + b"\n"))
    out.append(("one-row", b"\n".join(head + rows[:1]) + b"\n"))
    out.append(("wide-row", b"\n".join(head + [rows[0] + b",1" * 100000]) + b"\n"))
    out.append(("semicolons", data.replace(b",", b";")))
    out.append(("tabs", data.replace(b",", b"\t")))
    out.append(("many-columns", b"\n".join([b",".join([b"c%d" % i for i in range(3000)])]
                                          + [b",".join([b"1"] * 3000)] * 3) + b"\n"))
    return out


def _c3d_specials(rng) -> list[tuple[str, bytes]]:
    pts = small_c3d_points()
    labels = [f"M{j}" for j in range(pts.shape[1])]
    width = 4
    out = [
        ("valid", c3d_bytes(pts, labels)),
        ("valid-int16", c3d_bytes(pts, labels, scale=0.1)),
        ("labels-8dims", c3d_bytes(pts, labels, label_dims=(width, 5, 1, 1, 1, 1, 1, 1))),
        ("labels-8dims-big", c3d_bytes(pts, labels, label_dims=(width, 5, 7, 9, 200, 255, 255, 255))),
        ("labels-3dims", c3d_bytes(pts, labels, label_dims=(width, 5, 2))),
        ("labels-1dim", c3d_bytes(pts, labels, label_dims=(width * 5,))),
        ("labels-0dims", c3d_bytes(pts, labels, label_dims=())),
        ("labels-width0", c3d_bytes(pts, labels, label_dims=(0, 5))),
        ("labels-too-few", c3d_bytes(pts, labels, label_dims=(width, 2))),
        ("used-huge", c3d_bytes(pts, labels, used=65535)),
        ("used-zero", c3d_bytes(pts, labels, used=0)),
        ("frames-huge", c3d_bytes(pts, labels, header_frames=65535)),
        ("frames-zero", c3d_bytes(pts[:0], labels)),
        ("scale-zero", c3d_bytes(pts, labels, scale=0.0)),
        ("scale-nan", c3d_bytes(pts, labels, scale=float("nan"))),
        ("scale-huge-int16", c3d_bytes(pts, labels, scale=1e30)),
        ("units-odd", c3d_bytes(pts, labels, units="furlongs")),
        ("all-missing", c3d_bytes(np.full_like(pts, np.nan), labels)),
        ("nan-coordinates", c3d_bytes(np.where(rng.random(pts.shape) < 0.1, np.nan, pts), labels)),
    ]
    for rate in (0.0, -100.0, float("nan"), float("inf"), 1e-30, 1e30):
        out.append((f"rate-{rate:g}", c3d_bytes(pts, labels, rate=rate)))
    # a parameter with every dimension 255 (declares 16 GB of data in a tiny record)
    out.append(("param-dims-255", c3d_bytes(pts, labels, extra=_param("HUGE", 1, 4, (255,) * 7, b"\0" * 8))))
    out.append(("param-neg-offset", c3d_bytes(pts, labels, extra=_record("ODD", 1, b"\x02\x00", last=False)
                                              .replace(b"\x04\x00\x02\x00", b"\x00\x80\x02\x00"))))
    valid = c3d_bytes(pts, labels)
    for at, value in ((0, 0), (0, 255), (512 + 2, 255), (512 + 3, 99), (16, 0), (16, 255), (17, 255)):
        b = bytearray(valid)
        b[at] = value
        out.append((f"byte{at}={value}", bytes(b)))
    return out


def _trc_specials(valid: bytes) -> list[tuple[str, bytes]]:
    pts = small_c3d_points()
    labels = [f"M{j}" for j in range(pts.shape[1])]
    lines = valid.split(b"\n")
    out = [(f"cut-line{k}", b"\n".join(lines[:k]) + b"\n") for k in range(1, 6)]
    out += [
        ("cols-short-row", b"\n".join(lines[:8] + [lines[8].rsplit(b"\t", 4)[0]] + lines[9:])),
        ("cols-long-row", b"\n".join(lines[:8] + [lines[8] + b"\t1.5" * 7] + lines[9:])),
        ("cols-no-labels", b"\n".join(lines[:3] + [b"Frame#\tTime"] + lines[4:])),
        ("cols-bad-number", valid.replace(lines[9].split(b"\t")[3], b"1.2.3", 1)),
        ("cols-word", valid.replace(lines[9].split(b"\t")[3], b"abc", 1)),
        ("cols-no-time", b"\n".join(lines[:9] + [b"3\t\t1\t2\t3"] + lines[10:])),
        ("frames-huge", trc_bytes(pts, labels, frames=str(10 ** 12))),
        ("frames-neg", trc_bytes(pts, labels, frames="-5")),
        ("frames-word", trc_bytes(pts, labels, frames="many")),
        ("labels-huge", trc_bytes(pts, labels, markers=str(10 ** 12))),
        ("labels-zero", trc_bytes(pts, labels, markers="0")),
        ("units-odd", trc_bytes(pts, labels, units="furlongs")),
        ("units-none", valid.replace(b"\tmm\t", b"\t\t", 1)),
        ("all-missing", trc_bytes(np.full_like(pts, np.nan), labels)),
        ("header-only", b"\n".join(lines[:6]) + b"\n"),
        ("bomb-field", valid.replace(lines[9].split(b"\t")[3], b"7" * 5_000_000, 1)),
        ("bomb-field-beyond", b"\n".join(lines[:9] + [lines[9] + b"\t" + b"7" * 5_000_000] + lines[10:])),
        ("cols-inf", valid.replace(lines[9].split(b"\t")[3], b"1e999", 1)),
        ("bomb-label", b"\n".join(lines[:3] + [lines[3] + b"x" * 5_000_000] + lines[4:])),
        ("garbage-binary", lines[0] + b"\n" + bytes(range(256)) * 40),
    ]
    for rate in ("0", "-100", "nan", "inf", "1e-30", "1e30", "abc", ""):
        out.append((f"rate-{rate or 'empty'}", trc_bytes(pts, labels, rate=rate)))
    return out


# ------------------------------------------------------------------------ configs
def config_cases(rng) -> list[tuple[str, bytes]]:
    """Hostile configs; each either loads or is one ConfigError."""
    from mocapfix.cleaners import registry

    out = []
    bad_values = ["1e300", "-1e300", ".nan", ".inf", "-.inf", "0", "-1", "1e-300", "abc", "[]", "{}",
                  "null", "true", "'1e9 frames'", "'5 furlongs'", "[1, [2, [3]]]", "'" + "9" * 400 + "'",
                  "0x7fffffffffffffff", "2e9", "1e6 s", "1e9 Hz", "1 mm", "'-0 s'"]
    for name, cls in sorted(registry().items()):
        if name.startswith("test_"):
            continue
        for p in cls.params:
            for k, value in enumerate(bad_values):
                if zlib.crc32(f"{SEED}{name}{p.name}{k}".encode()) % 10 and k > 1:  # a seeded tenth
                    continue
                out.append((f"param-{name}-{p.name}-{k}",
                            f"pipeline:\n  - cleaner: {name}\n    {p.name}: {value}\n".encode()))
    bomb = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"] + [
        f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 10) + "]" for i in range(1, 9)]
    out += [
        ("formats-int", b"pipeline: [{cleaner: butterworth, formats: 5}]"),
        ("formats-alias-list", b"pipeline:\n- {cleaner: butterworth, formats: &f [c3d]}\n"
                               b"- {cleaner: gaussian, formats: [*f]}\n"),
        ("formats-map", b"pipeline: [{cleaner: butterworth, formats: {c3d: 1}}]"),
        ("bomb-step", ("pipeline:\n  - cleaner: butterworth\n    x:\n"
                       + "".join(f"      {line}\n" for line in bomb)).encode()),
        ("bomb-report", ("pipeline: [{cleaner: butterworth}]\nreport:\n"
                         + "".join(f"  {line}\n" for line in bomb)).encode()),
        ("deep-list", b"pipeline: [{cleaner: butterworth, x: " + b"[" * 20000 + b"]" * 20000 + b"}]"),
        ("deep-map", b"pipeline: [{cleaner: butterworth}]\nreport: " + b"{a: " * 5000 + b"1" + b"}" * 5000),
        ("latin1", b"pipeline: [{cleaner: butterworth}]\n# caf\xe9\n"),
        ("utf16", "pipeline: [{cleaner: butterworth}]\n".encode("utf-16")),
        ("nul", b"pipeline: [{cleaner: butterworth}]\x00\n"),
        ("recursive", b"pipeline: &p [{cleaner: butterworth, x: *p}]"),
        ("python-tag", b"pipeline: !!python/object/apply:os.system ['true']"),
        ("int-keys", b"1: 2\npipeline: [{cleaner: butterworth, 3: 4}]"),
        ("list-keys", b"pipeline: [{cleaner: butterworth, ? [a] : 1}]"),
        ("cleaner-list", b"pipeline: [{cleaner: [butterworth]}]"),
        ("version-list", b"version: [1]\npipeline: [{cleaner: butterworth}]"),
        ("pipeline-string", b"pipeline: butterworth"),
        ("pipeline-map", b"pipeline: {cleaner: butterworth}"),
        ("report-list", b"pipeline: [{cleaner: butterworth}]\nreport: [1, 2]"),
        ("empty", b""),
        ("only-comment", b"# nothing\n"),
        ("two-docs", b"pipeline: [{cleaner: butterworth}]\n---\npipeline: []\n"),
        ("tabs", b"pipeline:\n\t- cleaner: butterworth\n"),
        ("dup-keys", b"pipeline: [{cleaner: butterworth, cutoff: 5 Hz, cutoff: 7 Hz}]"),
        ("huge-int", b"pipeline: [{cleaner: butterworth, order: " + b"9" * 5000 + b"}]"),
        ("bones-odd", b"pipeline: [{cleaner: lowrank_isometry, bones: [[a], [1, 2, 3], x]}]"),
        ("bones-nested", b"pipeline: [{cleaner: lowrank_isometry, bones: [[[a, b]], [{a: b}, c]]}]"),
    ]
    # random mutations of the shipped configs
    shipped = sorted((Path(__file__).resolve().parents[1] / "configs").glob("*.yaml"))
    for path in shipped:
        data = path.read_bytes()
        for tag, raw in _truncate(data, rng, 5) + _bitflips(data, rng, 5) + _splices(data, rng, 3):
            out.append((f"{path.stem}-{tag}", raw))
    return out


def _vendor_specials(name: str, data: bytes) -> list[tuple[str, bytes]]:
    """Vendor marker tables (Nexus CSV, QTM TSV, Motive CSV): bad rates, huge counts, a
    5 MB field, a truncated last row, a binary block in the data."""
    lines = data.split(b"\n")
    out = []
    if name.endswith(".tsv"):
        rate = next(i for i, ln in enumerate(lines) if ln.startswith(b"FREQUENCY"))
        for tag, value in (("ratenan", b"nan"), ("ratezero", b"0"), ("rateneg", b"-100"),
                           ("rateword", b"fast")):
            out.append((tag, b"\n".join(lines[:rate] + [b"FREQUENCY\t" + value] + lines[rate + 1:])))
        count = next(i for i, ln in enumerate(lines) if ln.startswith(b"NO_OF_MARKERS"))
        out.append(("bombmarkers", b"\n".join(lines[:count] + [b"NO_OF_MARKERS\t" + b"9" * 15]
                                              + lines[count + 1:])))
        out.append(("bombframes", data.replace(lines[0], b"NO_OF_FRAMES\t" + b"9" * 30, 1)))
    elif lines[0].startswith(b"Format Version"):
        for tag, value in (("ratenan", b"nan"), ("ratezero", b"0.000000"), ("rateneg", b"-120")):
            out.append((tag, data.replace(b"Export Frame Rate,120.000000",
                                          b"Export Frame Rate," + value, 1)))
        out.append(("labelsgone", data.replace(b",Name,", b",Nom,", 1)))
    else:
        at = lines.index(next(ln for ln in lines if ln.rstrip(b"\r,") == b"Trajectories"))
        for tag, value in (("ratenan", b"nan"), ("ratezero", b"0"), ("rateneg", b"-100")):
            out.append((tag, b"\n".join(lines[:at + 1] + [value] + lines[at + 2:])))
        out.append(("labelsgone", b"\n".join(lines[:at + 2] + [b""] + lines[at + 3:])))
    last = max(i for i, ln in enumerate(lines) if ln.strip())
    out.append(("cuttail", b"\n".join(lines[:last] + [lines[last][:len(lines[last]) // 2]])))
    out.append(("bombfield", b"\n".join(lines[:last] + [lines[last] + b"7" * 5_000_000])))
    out.append(("garbageblock", b"\n".join(lines[:last] + [bytes(range(256)) * 4])))
    return out


# ------------------------------------------------------------------------ the corpus
def _huge_fields(bvh: bytes, kin: bytes) -> list[tuple[str, str, bytes]]:
    """(tag, file name, bytes): a 5 MB number in a Kinect CSV (the writer once asked for a
    211 GiB array), 40,000 bytes of garbage as a BVH joint name, offset, frame count and
    channel value (a 120 KB one-line error quoted them whole), C3D labels that are HTML
    or terminal escapes."""
    rows = kin.split(b"\n")
    cells = rows[3].split(b",")
    cells[2] = b"1" * 5_000_000
    rows[3] = b",".join(cells)
    junk = b"x" * 40_000
    head, _, motion = bvh.partition(b"MOTION")
    first_frame = motion.split(b"\n")[3]
    out = [
        ("huge-number", "walk_kinect_v2.csv", b"\n".join(rows)),
        ("huge-name-line", "walk_kinect_v2.csv", kin.replace(b"\n", b"\n" + junk + b"\n", 1)),
        ("huge-joint-name", "walk.bvh", head.replace(b"ROOT ", b"ROOT " + junk, 1) + b"MOTION" + motion),
        ("huge-offset", "walk.bvh", head.replace(b"OFFSET ", b"OFFSET " + b"9" * 40_000 + b" ", 1)
         + b"MOTION" + motion),
        ("huge-frames", "walk.bvh", re.sub(rb"Frames:\s*\d+", b"Frames: " + b"7" * 4_000, bvh)),
        ("huge-value", "walk.bvh", bvh.replace(first_frame, b"1" * 40_000 + first_frame[1:], 1)),
        ("huge-garbage", "walk.bvh", b"HIERARCHY\n" + bytes(range(33, 127)) * 2_000),
    ]
    labels = ["<script>alert(1)</script>", "<img src=x onerror=alert(1)>", "\x1b[31m\x07", "a\nb"]
    out.append(("hostile-labels", "gen.c3d", c3d_bytes(small_c3d_points(P=4), labels)))
    return out


def cases(seed: int = SEED) -> list[Case]:
    rng = np.random.default_rng(seed)
    bvh = (SAMPLE_DATA / "walk.bvh").read_bytes()
    amc = (SAMPLE_DATA / "walker_01.amc").read_bytes()
    asf = (SAMPLE_DATA / "walker.asf").read_bytes()
    c3d = (SAMPLE_DATA / "walk_markers.c3d").read_bytes()
    kin = (SAMPLE_DATA / "walk_kinect_v2.csv").read_bytes()
    out: list[Case] = []
    out += _generic("walk.bvh", bvh, rng, {}, True, "bvh")
    out += _generic("walker_01.amc", amc, rng, {"walker.asf": asf}, True, "amc")
    out += [Case(f"asf-{c.id[4:]}", c.family, "walker_01.amc", {"walker_01.amc": amc, "walker.asf": c.files["walker.asf"]})
            for c in _generic("walker.asf", asf, rng, {}, True, "asf")[::3]]
    out += _generic("walk_markers.c3d", c3d, rng, {}, False, "c3d")
    out += _generic("walk_kinect_v2.csv", kin, rng, {}, True, "kinect")
    # the 5,000-joint chains are read only: cleaning them is slow (per-joint loops in the
    # rotation write-back and the report, ~18 s), not stuck
    out += [Case(f"bvh-{t}", family(t), "walk.bvh", {"walk.bvh": raw}, clean=not t.startswith("deep"))
            for t, raw in _bvh_specials(bvh)]
    out += [Case(f"bvh-{t}", "cols", "walk.bvh", {"walk.bvh": raw})
            for t, raw in _lines_edit(bvh.split(b"MOTION")[1], rng, 12, b" ")
            for raw in [bvh.split(b"MOTION")[0] + b"MOTION" + raw]]
    out += [Case(f"amc-{t}", family(t), next(n for n in files if n.endswith(".amc")), files,
                 clean=not t.startswith("deep"))
            for t, files in _amc_specials(amc, asf)]
    out += [Case(f"amc-{t}", "cols", "walker_01.amc", {"walker_01.amc": raw, "walker.asf": asf})
            for t, raw in _lines_edit(amc, rng, 12, b" ")]
    out += [Case(f"kinect-{t}", family(t), "walk_kinect_v2.csv", {"walk_kinect_v2.csv": raw})
            for t, raw in _kinect_specials(kin) + _lines_edit(kin, rng, 12, b",")]
    vrng = np.random.default_rng(seed + 1)   # its own stream: the other cases stay as they were
    for prefix, name in (("nexus", "nexus_sections_doc.csv"), ("qtm", "qtm_old_doc.tsv"),
                         ("qtmhdr", "qtm_hand_embodiment_recording.tsv"), ("motive", "motive_doc.csv")):
        raw = (VENDOR_DATA / name).read_bytes()
        out += _generic(name, raw, vrng, {}, True, prefix)[::2]
        out += [Case(f"{prefix}-{t}", family(t), name, {name: v}) for t, v in _vendor_specials(name, raw)]
        sep = b"\t" if name.endswith(".tsv") else b","
        out += [Case(f"{prefix}-{t}", "cols", name, {name: v}) for t, v in _lines_edit(raw, vrng, 8, sep)]
    out += [Case(f"c3dgen-{t}", family(t), "gen.c3d", {"gen.c3d": raw}) for t, raw in _c3d_specials(rng)]
    out += [Case(f"config-{t}", family(t), "config.yaml", {"config.yaml": raw}, kind="config")
            for t, raw in config_cases(rng)]
    # TRC last, from a generator of its own, so that the cases above keep their bytes
    trc_rng = np.random.default_rng([seed, 5])
    pts = small_c3d_points()
    trc = trc_bytes(pts, [f"M{j}" for j in range(pts.shape[1])])
    out += _generic("gen.trc", trc, trc_rng, {}, True, "trc")
    out += [Case(f"trc-{t}", family(t), "gen.trc", {"gen.trc": raw}) for t, raw in _trc_specials(trc)]
    # huge fields and hostile names (issue 40), last again: they draw nothing from rng
    prefix = {"walk_kinect_v2.csv": "kinect", "walk.bvh": "bvh", "gen.c3d": "c3dgen"}
    out += [Case(f"{prefix[name]}-{t}", "huge", name, {name: raw})
            for t, name, raw in _huge_fields(bvh, kin)]
    ids = [c.id for c in out]
    assert len(ids) == len(set(ids)), "case ids must be unique"
    return out
