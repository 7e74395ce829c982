"""Malformed input, for every format: truncated at random byte offsets, garbage bytes,
empty files, NaN text, wrong column counts. Each read either returns a Motion (when the
format's users expect partial files to load, with a note) or raises one
UnreadableFileError naming the file — quickly, never a hang, never another exception.
Inputs that are certainly broken (a few bytes, random bytes, random bytes in the middle of
a text file) must be refused; a truncated file that does load holds a prefix of the
original's frames and says it may be cut."""
from __future__ import annotations

import numpy as np
import pytest

from mocapfix.core.errors import UnreadableFileError
from mocapfix.formats import read
from mocapfix.core.motion import Motion
from conftest import SAMPLE_DATA, hang_guard

SAMPLES = ["walk.bvh", "walker_01.amc", "walk_markers.c3d", "walk_kinect_v2.csv"]


def _check(path):
    with hang_guard():
        try:
            motion = read(path)
        except UnreadableFileError as exc:
            assert str(path) in str(exc), f"message does not name the file: {exc}"
            assert len(str(exc).splitlines()) == 1
            return None
    assert isinstance(motion, Motion)
    assert motion.positions.ndim == 3
    return motion


def _refused(path):
    with hang_guard(), pytest.raises(UnreadableFileError) as info:
        read(path)
    assert str(path) in str(info.value) and len(str(info.value).splitlines()) == 1


@pytest.mark.slow
@pytest.mark.parametrize("name", SAMPLES)
def test_truncated_at_random_offsets(name, tmp_path):
    data = (SAMPLE_DATA / name).read_bytes()
    rng = np.random.default_rng(7)
    offsets = sorted(set(rng.integers(1, len(data) - 1, 25).tolist()) | {1, 10, len(data) // 2})
    if name.endswith(".amc"):
        (tmp_path / "walker.asf").write_bytes((SAMPLE_DATA / "walker.asf").read_bytes())
    full = read(SAMPLE_DATA / name)
    loaded = 0
    for cut in offsets:
        path = tmp_path / name
        path.write_bytes(data[:cut])
        if cut <= 10:                           # a few bytes: certainly broken
            _refused(path)
            continue
        motion = _check(path)
        if motion is not None:
            loaded += 1
            # a prefix of the original: fewer frames, all but the last one (which may hold
            # a cut number) identical, and a note that the file may be cut
            assert 0 < motion.n_frames < full.n_frames, (cut, motion.n_frames)
            assert motion.names == full.names
            np.testing.assert_array_equal(motion.positions[:-1], full.positions[:motion.n_frames - 1])
            assert any("trunc" in n.lower() or "incomplete" in n.lower() or "cut" in n.lower()
                       for n in motion.notes), motion.notes
    # measured: the Kinect CSV loads whole rows of a cut file, BVH and C3D refuse a cut
    # anywhere but a frame boundary (random cuts: all 28), AMC loads one of 28
    assert loaded == {"walk_kinect_v2.csv": 25, "walker_01.amc": 1}.get(name, 0)


@pytest.mark.parametrize("name", SAMPLES)
def test_garbage_and_empty(name, tmp_path):
    rng = np.random.default_rng(8)
    if name.endswith(".amc"):
        (tmp_path / "walker.asf").write_bytes((SAMPLE_DATA / "walker.asf").read_bytes())
    path = tmp_path / name
    path.write_bytes(b"")
    with pytest.raises(UnreadableFileError, match="empty"):
        read(path)
    for _ in range(10):                         # random bytes: certainly broken
        path.write_bytes(rng.integers(0, 256, int(rng.integers(1, 5000)), dtype=np.uint8).tobytes())
        _refused(path)
    # garbage in the middle of a valid file: binary bytes in a text format are certainly
    # broken; in a C3D data block they are just other numbers, so the file keeps its shape
    data = bytearray((SAMPLE_DATA / name).read_bytes())
    full = read(SAMPLE_DATA / name)
    for _ in range(10):
        at = int(rng.integers(0, len(data) - 64))
        corrupt = bytearray(data)
        corrupt[at:at + 64] = rng.integers(0, 256, 64, dtype=np.uint8).tobytes()
        path.write_bytes(bytes(corrupt))
        if name.endswith(".c3d"):
            motion = _check(path)
            if motion is not None:
                assert motion.positions.shape == full.positions.shape
                assert motion.names == full.names
        else:
            _refused(path)


@pytest.mark.parametrize("name", ["walk.bvh", "walker_01.amc", "walk_kinect_v2.csv"])
def test_nan_text_and_wrong_columns(name, tmp_path):
    if name.endswith(".amc"):
        (tmp_path / "walker.asf").write_bytes((SAMPLE_DATA / "walker.asf").read_bytes())
    text = (SAMPLE_DATA / name).read_text()
    lines = text.splitlines(keepends=True)
    last = len(lines) - 3
    # a value replaced by NaN text
    bad = list(lines)
    tokens = bad[last].replace(",", " , ").split()
    bad[last] = bad[last].replace(tokens[1].strip(","), "nan", 1)
    (tmp_path / name).write_text("".join(bad))
    _check(tmp_path / name)
    # a line with one value missing
    bad = list(lines)
    sep = "," if name.endswith(".csv") else " "
    parts = bad[last].rstrip("\r\n").split(sep)
    bad[last] = sep.join(parts[:-2] + parts[-1:]) + "\n"
    (tmp_path / name).write_text("".join(bad))
    _check(tmp_path / name)


def test_unknown_and_missing_files(tmp_path):
    with pytest.raises(UnreadableFileError, match="no such file"):
        read(tmp_path / "nope.c3d")
    odd = tmp_path / "notes.xyz"
    odd.write_text("hello\n")
    with pytest.raises(UnreadableFileError, match="unknown file format"):
        read(odd)
    with pytest.raises(UnreadableFileError, match="directory"):
        read(tmp_path)
