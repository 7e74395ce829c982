"""Reader messages that name the cause (issue 13, item 9): C3D label records with too
many dimensions, byte-order marks and UTF-16 text, BVH files without frames, absurd rates."""
from __future__ import annotations

import re

import numpy as np
import pytest
from click.testing import CliRunner

from mocapfix.cli import main
from mocapfix.core.errors import UnreadableFileError
from mocapfix.formats import read, write

from conftest import SAMPLE_DATA, hang_guard, no_traceback
from malformed_corpus import c3d_bytes, small_c3d_points

LABELS = ["LASI", "RASI", "LKNE", "RKNE", "C7"]


def _read(path):
    with hang_guard(10):
        return read(path)


def test_c3d_labels_with_eight_unit_dimensions_are_read(tmp_path):
    path = tmp_path / "eight.c3d"
    pts = small_c3d_points()
    path.write_bytes(c3d_bytes(pts, LABELS, label_dims=(4, 5, 1, 1, 1, 1, 1, 1)))
    motion = _read(path)
    assert motion.names == LABELS
    assert np.allclose(motion.positions, pts, equal_nan=True, atol=1e-3)


def test_c3d_labels_with_eight_real_dimensions_are_named(tmp_path):
    path = tmp_path / "eight.c3d"
    path.write_bytes(c3d_bytes(small_c3d_points(), LABELS, label_dims=(4, 5, 7, 9, 200, 255, 255, 255)))
    motion = _read(path)  # used to hang decoding 4e12 declared labels
    assert motion.names == [f"marker{i}" for i in range(1, 6)]
    assert any("POINT:LABELS has 8 dimensions (4, 5, 7, 9, 200, 255, 255, 255)" in n for n in motion.notes)


def test_c3d_labels_dimension_count_byte_damaged_in_a_real_file(tmp_path):
    data = bytearray((SAMPLE_DATA / "walk_markers.c3d").read_bytes())
    at = data.find(b"LABELS") + len(b"LABELS") + 2 + 1   # offset word, type byte, then ndims
    assert data[at] == 2
    data[at] = 8
    path = tmp_path / "damaged.c3d"
    path.write_bytes(bytes(data))
    motion = _read(path)
    assert motion.names[0] == "marker1"
    assert any("POINT:LABELS has 8 dimensions" in n for n in motion.notes)


def test_c3d_label_record_shorter_than_declared_is_named(tmp_path):
    path = tmp_path / "short.c3d"
    path.write_bytes(c3d_bytes(small_c3d_points(), LABELS, label_dims=(4, 9)))
    motion = _read(path)
    assert any("declares 36 characters but its record holds 21" in n for n in motion.notes)


@pytest.mark.parametrize("rate", [1e30, 2e5, 1e-30, 5e-4])
def test_c3d_absurd_rate_is_refused_with_the_cause(tmp_path, rate):
    path = tmp_path / "fast.c3d"
    path.write_bytes(c3d_bytes(small_c3d_points(), LABELS, rate=rate))
    with pytest.raises(UnreadableFileError, match=r"frame rate .* Hz is outside 0.001-100000 Hz") as err:
        _read(path)
    assert str(path) in str(err.value)


def test_bvh_with_utf8_bom_reads_like_without(tmp_path):
    data = (SAMPLE_DATA / "walk.bvh").read_bytes()
    path = tmp_path / "bom.bvh"
    path.write_bytes(b"\xef\xbb\xbf" + data)
    assert np.array_equal(_read(path).positions, _read(SAMPLE_DATA / "walk.bvh").positions)


@pytest.mark.parametrize("encoding, name", [("utf-16", "UTF-16 (little-endian)"),
                                            ("utf-16-le", "UTF-16 (little-endian, no byte-order mark)"),
                                            ("utf-16-be", "UTF-16 (big-endian, no byte-order mark)"),
                                            ("utf-32", "UTF-32 (little-endian)")])
def test_utf16_bvh_is_named(tmp_path, encoding, name):
    text = (SAMPLE_DATA / "walk.bvh").read_text()
    path = tmp_path / "wide.bvh"
    path.write_bytes(text.encode(encoding))
    with pytest.raises(UnreadableFileError) as err:
        _read(path)
    assert f"BVH file is {name} text" in str(err.value) and str(path) in str(err.value)


def _amc_pair(tmp_path, amc: bytes, asf: bytes):
    (tmp_path / "walker.asf").write_bytes(asf)
    (tmp_path / "walker_01.amc").write_bytes(amc)
    return tmp_path / "walker_01.amc"


def test_amc_and_asf_with_utf8_bom_are_read_and_written_back(tmp_path):
    amc = (SAMPLE_DATA / "walker_01.amc").read_bytes()
    asf = (SAMPLE_DATA / "walker.asf").read_bytes()
    plain = _read(SAMPLE_DATA / "walker_01.amc")
    path = _amc_pair(tmp_path, b"\xef\xbb\xbf" + amc, b"\xef\xbb\xbf" + asf)
    motion = _read(path)
    assert np.array_equal(motion.positions, plain.positions)
    written = write(motion, tmp_path / "out" / "walker_01.amc")
    assert written[0].read_bytes() == b"\xef\xbb\xbf" + amc       # unchanged motion: same bytes
    assert written[1].read_bytes() == b"\xef\xbb\xbf" + asf


def test_amc_bom_right_before_a_frame_number_is_named(tmp_path):
    amc = (SAMPLE_DATA / "walker_01.amc").read_bytes()
    first = re.search(rb"(?m)^1\s*$", amc).start()
    path = _amc_pair(tmp_path, b"\xef\xbb\xbf" + amc[first:], (SAMPLE_DATA / "walker.asf").read_bytes())
    with pytest.raises(UnreadableFileError, match="byte-order mark"):
        _read(path)


@pytest.mark.parametrize("which", ["amc", "asf"])
def test_utf16_amc_or_asf_is_named(tmp_path, which):
    amc = (SAMPLE_DATA / "walker_01.amc").read_bytes()
    asf = (SAMPLE_DATA / "walker.asf").read_bytes()
    if which == "amc":
        amc = amc.decode("latin-1").encode("utf-16")
    else:
        asf = asf.decode("latin-1").encode("utf-16")
    path = _amc_pair(tmp_path, amc, asf)
    with pytest.raises(UnreadableFileError) as err:
        _read(path)
    assert f"{which.upper()} file is UTF-16 (little-endian) text" in str(err.value)
    assert f"walker{'_01' if which == 'amc' else ''}.{which}" in str(err.value)


def test_bvh_without_frames_is_refused_at_read(tmp_path):
    data = (SAMPLE_DATA / "walk.bvh").read_bytes()
    head = data[:data.index(b"Frames:")]
    path = tmp_path / "empty.bvh"
    path.write_bytes(head + b"Frames: 0\nFrame Time: 0.008333\n")
    with pytest.raises(UnreadableFileError, match="Frames: 0 — the file holds a skeleton but no motion") as err:
        _read(path)
    assert str(path) in str(err.value)


@pytest.mark.parametrize("frame_time", [b"1e-320", b"1e-6", b"1e308", b"2000"])
def test_bvh_absurd_frame_time_is_refused(tmp_path, frame_time):
    data = (SAMPLE_DATA / "walk.bvh").read_bytes()
    path = tmp_path / "fast.bvh"
    path.write_bytes(re.sub(rb"Frame Time:\s*\S+", b"Frame Time: " + frame_time, data))
    with pytest.raises(UnreadableFileError, match="rate outside 0.001-100000 Hz"):
        _read(path)


def test_truncated_bvh_message_gives_no_python_only_advice(tmp_path):
    # the CLI said "(pass allow_truncated=True to read them)": no option of mocapfix does
    text = (SAMPLE_DATA / "walk.bvh").read_text()
    cut = tmp_path / "cut.bvh"
    cut.write_text(text[: len(text) - len(text.splitlines()[-1]) * 5 // 2])
    before = cut.read_bytes()
    r = CliRunner().invoke(main, ["info", str(cut)])
    no_traceback(r)
    assert r.exit_code == 3, r.output
    assert f"{cut}" in r.output and "truncated: 'Frames:" in r.output
    assert "allow_truncated" not in r.output and "cut short" in r.output
    assert cut.read_bytes() == before
