"""A large input file is not held after it is read: its writer reads the unchanged lines
(a C3D: the records) again from the file (issue 39; :mod:`mocapfix.formats.filebytes`).

The real files are small, so the threshold is set to 0 here: every BVH, AMC, Kinect and
C3D file of the shared data is then kept on disk, and what is written from it (the
motion as read, and the take cleaned with the default config) must be byte for byte
what is written from the bytes held in memory. A file changed, truncated, replaced or removed
after the read is an error naming it at the write, and nothing is left behind."""
from __future__ import annotations

import os
import pickle
import shutil

import numpy as np
import pytest
from conftest import FORMATS_DATA, need, shared, shared_files

import mocapfix
from mocapfix import formats
from mocapfix.core.errors import MocapfixError, UnreadableFileError
from mocapfix.core.fileio import read_input_bytes
from mocapfix.formats import asfamc, bvh, c3d, filebytes, kinect, textlines, trc
from mocapfix.formats.c3d import C3DSource, _StoredRecords
from mocapfix.formats.filebytes import FileBytes
from mocapfix.quality.info import summarise

#: the TRC files of ../shared/formats that read (tests/formats/test_trc.py's READABLE)
TRC_FILES = [pytest.param(FORMATS_DATA / "trc" / name, id=name) for name in (
    "btk_10002-20130626160334-Unnamed.trc", "btk_Anto.trc", "btk_Gait.trc", "btk_Knee.trc",
    "btk_Res16bits.trc", "btk_UpperLimbStatic.trc", "btk_motek_T.trc",
    "btk_motek_ballet_reduced.trc")]
FILES = (shared_files("bvh") + shared_files("asfamc", "*.amc") + shared_files("kinect")
         + shared_files("c3d") + TRC_FILES)


def _held(motion):
    """What the motion's source keeps of the file's bytes."""
    src = motion.source
    if isinstance(src, C3DSource):
        return src.points
    for holder, name in ((src, "data"), (getattr(src, "body", None), "data"),
                         (getattr(src, "text", None), "raw")):
        if holder is not None and hasattr(holder, name):
            return getattr(holder, name)
    raise AssertionError(f"no bytes kept by {type(src).__name__}")


def _write(motion, folder, name):
    out = folder / name
    formats.write(motion, out)
    return out.read_bytes()


@pytest.mark.parametrize("path", FILES)
def test_a_file_read_again_is_written_as_the_file_held(path, tmp_path, monkeypatch):
    path = need(path)
    held = formats.read(path)
    held_clean, _ = mocapfix.clean(held)
    monkeypatch.setattr(filebytes, "HELD_MAX", 0)
    monkeypatch.setattr(c3d, "CHUNK", 7)    # a large C3D's records decoded in many chunks
    # a large BVH's frame lines scanned in blocks of 97 bytes (a CRLF cut between blocks:
    # the mocapbank file) and converted 7 lines at a time
    monkeypatch.setattr(bvh, "BLOCK", 97)
    monkeypatch.setattr(bvh, "CHUNK", 7)
    monkeypatch.setattr(asfamc, "_BLOCK", 97)      # an AMC's likewise
    monkeypatch.setattr(asfamc, "_CHUNK", 7)
    monkeypatch.setattr(textlines, "BLOCK", 97)    # a Kinect or TRC file's lines likewise
    monkeypatch.setattr(trc, "CHUNK", 7)
    again = formats.read(path)
    assert isinstance(_held(again), (FileBytes, _StoredRecords))
    assert isinstance(_held(held), (bytes, np.ndarray))
    np.testing.assert_array_equal(again.positions, held.positions)
    assert again.notes == held.notes
    assert summarise(again) == summarise(held)          # what `mocapfix info` prints
    if held.confidence is not None:
        np.testing.assert_array_equal(again.confidence, held.confidence)
    if isinstance(again.source, C3DSource):
        for name in ("points", "analog", "residual", "camera_mask", "analog_frames"):
            a, b = getattr(held.source, name), np.asarray(getattr(again.source, name))
            assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), name
    # the cleaned take written over the file kept on disk: the writer's edit paths
    again_clean = held_clean.replace(source=again.source)
    for k, (a, b) in enumerate(((held, again), (held_clean, again_clean))):
        assert _write(a, tmp_path / f"held{k}", path.name) == \
            _write(b, tmp_path / f"again{k}", path.name)
    if path.suffix in (".bvh", ".csv", ".txt", ".trc"):    # an AMC's header line, a C3D's
        # parameter section (Intel-encoded, its fills listed) are written by the writer
        assert (tmp_path / "again0" / path.name).read_bytes() == path.read_bytes()


def _copy(tmp_path, name="131_01.bvh"):
    src = shared("bvh/cmu_cgspeed_131_01.bvh")
    path = tmp_path / name
    shutil.copyfile(src, path)
    return path


def _changed_sample(motion):
    channels = motion.channels.copy()
    channels[len(channels) // 2, 3] += 1.0
    return motion.replace(channels=channels)


@pytest.mark.parametrize("change", ["edited", "truncated", "replaced", "removed", "c3d truncated"])
def test_a_file_changed_after_the_read_is_an_error_at_the_write(change, tmp_path, monkeypatch):
    monkeypatch.setattr(filebytes, "HELD_MAX", 0)
    if change.startswith("c3d"):
        path = tmp_path / "take.c3d"
        shutil.copyfile(shared("c3d/cmu_85_02.c3d"), path)
        motion = formats.read(path)
        positions = motion.positions.copy()
        positions[10, 0] += 1.0
        motion = motion.replace(positions=positions)
    else:
        path = _copy(tmp_path)
        motion = _changed_sample(formats.read(path))
    data = path.read_bytes()
    if change == "edited":          # same size, one digit changed, a later time
        at = data.rindex(b"0")
        path.write_bytes(data[:at] + b"1" + data[at + 1:])
        os.utime(path, ns=(os.stat(path).st_atime_ns, os.stat(path).st_mtime_ns + 10**9))
    elif change.endswith("truncated"):
        path.write_bytes(data[: len(data) // 2])
    elif change == "replaced":
        other = tmp_path / "other.bvh"
        other.write_bytes(data)
        os.replace(other, path)
    else:
        path.unlink()
    out = tmp_path / "out" / f"take{path.suffix}"
    with pytest.raises(UnreadableFileError) as caught:
        formats.write(motion, out)
    assert str(path) in str(caught.value) and "changed or moved since it was read" in str(caught.value)
    assert not out.parent.exists() or not any(out.parent.iterdir())


@pytest.mark.parametrize("name", ["btk_Gait.trc", "kinect"])
def test_a_file_changed_while_it_is_read_in_blocks_is_named_so(name, tmp_path, monkeypatch):
    # a large file is read a block at a time: one that shrinks meanwhile is an error
    # naming that moment, not the writer's ("since it was read ... when the output is
    # written"), which nothing has started yet
    monkeypatch.setattr(filebytes, "HELD_MAX", 0)
    monkeypatch.setattr(textlines, "HEAD", 100)
    monkeypatch.setattr(textlines, "BLOCK", 97)
    src = (FORMATS_DATA / "trc" / name if name.endswith(".trc")
           else shared("kinect/kv2_laban_Ges01_wavehand.csv"))
    path = tmp_path / need(src).name
    shutil.copyfile(src, path)
    size = path.stat().st_size
    real = textlines._block_to_line_end

    def then_shrunk(raw, a, end, *args):
        if a > 1000 and path.stat().st_size == size:
            with open(path, "r+b") as f:
                f.truncate(size // 2)
        return real(raw, a, end, *args)

    monkeypatch.setattr(textlines, "_block_to_line_end", then_shrunk)
    with pytest.raises(UnreadableFileError) as caught:
        formats.read(path)
    message = str(caught.value)
    assert str(path) in message and "changed or moved while it was read" in message


def test_the_cli_names_the_changed_input_and_writes_nothing(tmp_path, monkeypatch):
    """Through clean_file: the failure is the input's, and no output or report is left."""
    from mocapfix.cleaning import clean_file
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config

    monkeypatch.setattr(filebytes, "HELD_MAX", 0)
    path = _copy(tmp_path)
    real_read = formats.read

    def read_then_edit(p, *args, **kwargs):
        motion = real_read(p, *args, **kwargs)
        with open(p, "ab") as fh:   # another program appends while the take is cleaned
            fh.write(b"\n")
        return motion

    monkeypatch.setattr(formats, "read", read_then_edit)
    out = tmp_path / "out" / "take.bvh"
    with pytest.raises(MocapfixError, match="changed or moved since it was read"):
        clean_file(path, out, load_config(resolve_config("default")))
    assert not out.parent.exists() or not any(out.parent.iterdir())


@pytest.mark.parametrize("pread", [True, False], ids=["pread", "seek and read"])
def test_file_bytes_slices_as_bytes_do(pread, tmp_path, monkeypatch):
    if not pread:                                 # as on Windows, which has no os.pread
        monkeypatch.delattr(os, "pread", raising=False)
    path = tmp_path / "f.txt"
    rng = np.random.default_rng(0)
    data = bytes(rng.integers(0, 256, 3 * filebytes.BLOCK + 17, dtype=np.uint8))
    path.write_bytes(data)
    kept = FileBytes(path, os.stat(path))
    assert len(kept) == len(data)
    for a, b in ((0, 10), (5, 5), (len(data) - 3, len(data) + 50), (-20, None), (None, 7),
                 (filebytes.BLOCK - 1, 2 * filebytes.BLOCK + 1)):
        assert kept[a:b] == data[a:b]
    assert b"".join(filebytes.runs_of(kept, 3, len(data) - 2)) == data[3:-2]
    assert b"".join(bytes(p) for p in filebytes.runs_of(data, 3, len(data) - 2)) == data[3:-2]
    with pytest.raises(TypeError):
        kept[3]
    copy = pickle.loads(pickle.dumps(kept))       # a batch worker's copy opens its own
    assert copy[100:200] == data[100:200]
    kept.close()
    monkeypatch.chdir(tmp_path)
    relative = FileBytes("f.txt", os.stat("f.txt"))
    monkeypatch.chdir("/")                        # a notebook that changed directory
    assert relative[5:9] == data[5:9]


def test_file_view_indexes_and_slices_as_bytes_do(tmp_path, monkeypatch):
    # a head of 1,000 bytes held, the rest read from the file: every index and slice,
    # inside the head, across its end and beyond it, as the bytes give them
    path = tmp_path / "f.bin"
    data = bytes(np.random.default_rng(1).integers(0, 256, 5000, dtype=np.uint8))
    path.write_bytes(data)
    view = filebytes.FileView(FileBytes(path, os.stat(path)), 1000)
    assert len(view) == len(data) and view.head == data[:1000]
    for i in (0, 999, 1000, 4999, -1, -4000):
        assert view[i] == data[i]
    for a, b in ((0, 10), (990, 1010), (1000, 1000), (2000, 6000), (-30, None), (None, None),
                 (-4990, 10), (-4995, -4990), (20, 5)):
        assert view[a:b] == data[a:b]
    with pytest.raises(IndexError):
        view[5000]
    assert filebytes.keep(path, view) is view.file
    monkeypatch.setattr(filebytes, "HELD_MAX", 4999)
    assert isinstance(filebytes.large_file(path), FileBytes)
    monkeypatch.setattr(filebytes, "HELD_MAX", 5000)
    assert filebytes.large_file(path) is None and filebytes.large_file(tmp_path) is None


def test_a_large_c3d_is_never_read_whole(tmp_path, monkeypatch):
    # its header and parameter section are read, its records a chunk at a time (for the
    # positions) and again when written; the same motion as a file read whole
    path = need(shared("c3d/cmu_85_02.c3d"))
    held = formats.read(path)
    whole = []
    monkeypatch.setattr(c3d, "read_input_bytes", lambda p: whole.append(p) or b"")
    monkeypatch.setattr(filebytes, "HELD_MAX", 0)
    again = formats.read(path)
    assert not whole
    np.testing.assert_array_equal(again.positions, held.positions)
    assert again.names == held.names and again.notes == held.notes


@pytest.mark.parametrize("head", ["the default", "ends in its MOTION line", "ends before it"])
def test_a_large_bvh_is_read_whole_only_when_its_hierarchy_is_not_held(head, monkeypatch):
    # its hierarchy and MOTION line are read and held, its frame lines scanned and
    # converted from the file a block at a time; a MOTION line that does not end within
    # the bytes held (a hierarchy over a megabyte, or no MOTION at all) and the file is
    # read whole, as a small one (the reader then parses it or says what is wrong)
    path = need(shared("bvh/bvhpython_test_mocapbank.bvh"))
    held = formats.read(path)
    motion_end = path.read_bytes().index(b"MOTION") + len(b"MOTION")
    if head != "the default":
        monkeypatch.setattr(bvh, "HEAD", motion_end if head == "ends in its MOTION line" else 500)
    whole = []
    real = bvh.read_input_bytes
    monkeypatch.setattr(bvh, "read_input_bytes", lambda p: whole.append(p) or real(p))
    monkeypatch.setattr(filebytes, "HELD_MAX", 0)
    again = formats.read(path)
    assert bool(whole) == (head != "the default")
    np.testing.assert_array_equal(again.channels, held.channels)
    assert again.names == held.names and again.notes == held.notes
    assert again.source.newline == held.source.newline == b"\r\n"
    assert isinstance(again.source.data, FileBytes)


def test_a_large_amc_is_never_read_whole(monkeypatch):
    # its lines are scanned, checked and converted from the file a block at a time; its
    # ASF (small) is read whole; the same motion as the file read whole
    path = need(shared("asfamc/05_02.amc"))
    held = formats.read(path)
    whole = []
    real = asfamc.read_input_bytes
    monkeypatch.setattr(asfamc, "read_input_bytes", lambda p: whole.append(p) or real(p))
    monkeypatch.setattr(filebytes, "HELD_MAX", 0)
    again = formats.read(path)
    assert [p.suffix for p in whole] == [".asf"]
    np.testing.assert_array_equal(again.channels, held.channels)
    assert again.names == held.names and again.notes == held.notes
    assert isinstance(again.source.body.data, FileBytes)


def test_a_large_kinect_file_is_never_read_whole(monkeypatch):
    # its lines are scanned, decoded and parsed from the file a block at a time; the same
    # motion as the file read whole
    path = need(shared("kinect/kv2_laban_Ges01_wavehand.csv"))
    held = formats.read(path)
    whole = []
    monkeypatch.setattr(kinect, "read_input_bytes", lambda p: whole.append(p) or b"")
    monkeypatch.setattr(filebytes, "HELD_MAX", 0)
    monkeypatch.setattr(textlines, "BLOCK", 1000)
    again = formats.read(path)
    assert not whole
    np.testing.assert_array_equal(again.positions, held.positions)
    assert again.names == held.names and again.notes == held.notes
    assert isinstance(again.source.text.raw, FileBytes)


@pytest.mark.parametrize("fmt,name", [("kinect", "take.csv"), ("nexus_csv", "take.csv"),
                                      ("qtm_tsv", "take.tsv"), ("motive_csv", "take.csv"),
                                      ("bvh", "take.bvh"), ("asfamc", "take.amc")])
@pytest.mark.parametrize("large", [False, True])
def test_a_file_of_whitespace_is_empty_read_whole_or_in_blocks(fmt, name, large, tmp_path,
                                                                monkeypatch):
    # read a block at a time (over HELD_MAX, 0 here) a file holding only blank lines is
    # refused as empty, as when read whole, not by whatever the parser checks next
    import importlib

    path = tmp_path / name
    path.write_bytes(b"  \n\n \t \r\n" * 50)
    if large:
        monkeypatch.setattr(filebytes, "HELD_MAX", 0)
    with pytest.raises(UnreadableFileError, match="file is empty"):
        importlib.import_module(f"mocapfix.formats.{fmt}").read(path)


def test_only_a_large_file_read_unchanged_is_kept_on_disk(tmp_path, monkeypatch):
    path = tmp_path / "f.txt"
    path.write_bytes(b"x" * 1000)
    data = read_input_bytes(path)
    assert filebytes.keep(path, data) is data               # under HELD_MAX: held
    monkeypatch.setattr(filebytes, "HELD_MAX", 100)
    assert isinstance(filebytes.keep(path, read_input_bytes(path)), FileBytes)
    assert filebytes.keep(path, b"x" * 1000) == b"x" * 1000  # not read by read_input_bytes
    data = read_input_bytes(path)
    path.write_bytes(b"y" * 1000)                            # changed before the reader kept it
    os.utime(path, ns=(0, os.stat(path).st_mtime_ns + 10**9))
    assert filebytes.keep(path, data) is data
