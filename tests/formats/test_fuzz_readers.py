"""Property-based fuzzing of the four readers with hypothesis (derandomised, bounded
examples, no example database: the same inputs on every run, a few seconds each).

Properties: whatever the bytes, a read returns a Motion whose arrays agree with each
other, or raises one UnreadableFileError naming the file — nothing else, never a hang;
and a well-formed C3D written by the corpus's independent writer reads back to the
points it was given."""
from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from malformed_corpus import c3d_bytes
from mocapfix.core.errors import UnreadableFileError
from mocapfix.formats import read
from mocapfix.core.motion import Motion
from conftest import SAMPLE_DATA, hang_guard

# slow: hypothesis fuzzing of the four readers (~6 s)
pytestmark = pytest.mark.slow

# MOCAPFIX_FUZZ_EXAMPLES=2000 for a longer hunt (random, not derandomised)
_LONG = int(os.environ.get("MOCAPFIX_FUZZ_EXAMPLES", "0"))
FUZZ = settings(max_examples=_LONG or 60, deadline=None, derandomize=not _LONG, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large])

SAMPLES = {"walk.bvh": None, "walker_01.amc": "walker.asf", "walk_markers.c3d": None,
           "walk_kinect_v2.csv": None}


def _read_or_refuse(path) -> Motion | None:
    with hang_guard(10):
        try:
            motion = read(path)
        except UnreadableFileError as exc:
            assert str(path) in str(exc) or ".asf" in str(exc), str(exc)
            assert "\n" not in str(exc).strip()
            return None
    T, J = motion.n_frames, len(motion.names)
    assert T > 0 and motion.positions.shape == (T, J, 3)
    assert motion.fps > 0 and np.isfinite(motion.fps)
    if motion.confidence is not None:
        assert motion.confidence.shape == (T, J)
    return motion


@st.composite
def _edits(draw, size: int):
    """A truncation point and up to 12 byte overwrites / insertions / deletions."""
    edits = draw(st.lists(st.tuples(st.sampled_from("oid"), st.integers(0, size - 1),
                                    st.binary(min_size=1, max_size=16)), max_size=12))
    cut = draw(st.one_of(st.none(), st.integers(1, size)))
    return edits, cut


def _apply(data: bytes, edits, cut) -> bytes:
    out = bytearray(data)
    for op, at, blob in edits:
        at = min(at, len(out))
        if op == "o":
            out[at:at + len(blob)] = blob
        elif op == "i":
            out[at:at] = blob
        else:
            del out[at:at + len(blob)]
    return bytes(out[:cut] if cut else out)


@pytest.mark.parametrize("name", sorted(SAMPLES))
def test_byte_edits_of_real_files(name, tmp_path):
    data = (SAMPLE_DATA / name).read_bytes()
    if SAMPLES[name]:
        (tmp_path / SAMPLES[name]).write_bytes((SAMPLE_DATA / SAMPLES[name]).read_bytes())

    @FUZZ
    @given(_edits(len(data)))
    def check(edit):
        path = tmp_path / name
        path.write_bytes(_apply(data, *edit))
        _read_or_refuse(path)

    check()


_NUMBER = st.one_of(st.floats(allow_nan=True, allow_infinity=True).map(repr),
                    st.integers(-10**6, 10**6).map(str),
                    st.sampled_from(["", "-", "1e999", "nan", "0x10", "1,5", "abc", "--1"]))
_CHANNELS = st.lists(st.sampled_from(["Xposition", "Yposition", "Zposition", "Xrotation",
                                      "Yrotation", "Zrotation", "Wrotation"]), max_size=7)


@st.composite
def _bvh(draw):
    """A BVH of random shape: random nesting, channel lists, counts and frame tokens."""
    lines = ["HIERARCHY"]
    depth, n_channels, joints = 0, 0, 0
    for step in draw(st.lists(st.sampled_from(["joint", "joint", "end", "close"]), min_size=1, max_size=30)):
        if step == "joint" or depth == 0:
            lines.append(("ROOT" if depth == 0 else "JOINT") + f" j{joints}")
            joints += 1
            lines.append("{")
            depth += 1
            lines.append("OFFSET " + " ".join(draw(st.lists(_NUMBER, min_size=3, max_size=3))))
            ch = draw(_CHANNELS)
            declared = draw(st.one_of(st.just(len(ch)), st.integers(-2, 9)))
            lines.append(f"CHANNELS {declared} " + " ".join(ch))
            n_channels += len(ch)
        elif step == "end":
            lines += ["End Site", "{", "OFFSET 0 1 0", "}"]
        else:
            lines.append("}")
            depth -= 1
    lines += ["}"] * draw(st.integers(max(depth - 1, 0), depth + 1))
    frames = draw(st.integers(0, 6))
    lines += ["MOTION", f"Frames: {draw(st.one_of(st.just(str(frames)), _NUMBER))}",
              f"Frame Time: {draw(st.one_of(st.just('0.008333'), _NUMBER))}"]
    for _ in range(frames):
        count = draw(st.one_of(st.just(n_channels), st.integers(0, n_channels + 2)))
        lines.append(" ".join(draw(st.lists(st.one_of(st.just("0.5"), _NUMBER), min_size=count, max_size=count))))
    return "\n".join(lines) + draw(st.sampled_from(["\n", "", "\r\n"]))


def test_generated_bvh(tmp_path):
    @FUZZ
    @given(_bvh())
    def check(text):
        path = tmp_path / "gen.bvh"
        path.write_bytes(text.encode())
        motion = _read_or_refuse(path)
        if motion is not None:
            assert np.isfinite(motion.channels).all()

    check()


def test_generated_amc(tmp_path):
    asf = (SAMPLE_DATA / "walker.asf").read_bytes()
    (tmp_path / "walker.asf").write_bytes(asf)
    bones = [line.split()[1] for line in asf.decode().splitlines() if line.strip().startswith("name ")]

    @FUZZ
    @given(st.lists(st.lists(st.tuples(st.sampled_from(["root"] + bones), st.lists(_NUMBER, max_size=7)),
                             max_size=8), max_size=5),
           st.sampled_from([":FULLY-SPECIFIED\n:DEGREES\n", "", ":RADIANS\n", "#!junk\n"]))
    def check(frames, header):
        text = header + "".join(f"{i + 1}\n" + "".join(f"{b} {' '.join(v)}\n" for b, v in frame)
                                for i, frame in enumerate(frames))
        path = tmp_path / "walker_01.amc"
        path.write_bytes(text.encode())
        _read_or_refuse(path)

    check()


def test_generated_kinect_csv(tmp_path):
    @FUZZ
    @given(st.lists(st.lists(_NUMBER, min_size=1, max_size=80), max_size=12),
           st.sampled_from([",", ";", "\t", " "]))
    def check(rows, sep):
        path = tmp_path / "gen.csv"
        path.write_bytes("\n".join(sep.join(r) for r in rows).encode() + b"\n")
        _read_or_refuse(path)

    check()


@st.composite
def _c3d_case(draw):
    T = draw(st.integers(1, 40))
    P = draw(st.integers(1, 12))
    seed = draw(st.integers(0, 2**16))
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-3000, 3000, (T, P, 3))
    pts[rng.random((T, P)) < draw(st.floats(0, 0.5))] = np.nan
    labels = [draw(st.text(st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=8))
              for _ in range(P)]
    rate = draw(st.floats(1.0, 2000.0))
    return pts, labels, rate


def test_generated_c3d_reads_back_what_was_written(tmp_path):
    """Our reader against an independent writer (the C3D manual's layout)."""
    @FUZZ
    @given(_c3d_case())
    def check(case):
        pts, labels, rate = case
        path = tmp_path / "gen.c3d"
        path.write_bytes(c3d_bytes(pts, labels, rate=rate))
        motion = _read_or_refuse(path)
        assert motion is not None
        assert motion.fps == pytest.approx(np.float32(rate))
        assert np.array_equal(np.isnan(motion.positions), np.isnan(pts))
        assert np.allclose(motion.positions, pts.astype(np.float32), equal_nan=True)
        assert len(set(motion.names)) == len(labels)   # duplicates made unique
        if len(set(labels)) == len(labels):
            assert motion.names == labels

    check()


def test_generated_c3d_with_damaged_parameters(tmp_path):
    @FUZZ
    @given(_c3d_case(), st.lists(st.integers(0, 255), min_size=0, max_size=9),
           st.one_of(st.none(), st.integers(0, 65535)),
           st.sampled_from([-1.0, 0.1, 0.0, float("nan"), float("inf"), -float("inf"), 1e30, -1e-30]),
           st.one_of(st.none(), st.integers(0, 65535)))
    def check(case, dims, used, scale, header_frames):
        pts, labels, rate = case
        path = tmp_path / "bad.c3d"
        path.write_bytes(c3d_bytes(pts, labels, rate=rate, label_dims=tuple(dims) or None,
                                   used=used, scale=scale, header_frames=header_frames))
        _read_or_refuse(path)

    check()
