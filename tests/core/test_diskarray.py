"""A whole-take array kept on disk (mocapfix.core.diskarray): every index gives what the
array in memory gives, the reads that return a column or a chunk of frames read only that,
and the file is never seen in its folder."""
from __future__ import annotations

import os

import numpy as np
import pytest

from mocapfix.core.diskarray import FramesOnDisk


def _positions(T=57, J=5, seed=0):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(T, J, 3))
    a[rng.random((T, J)) < 0.2, rng.integers(0, 3)] = np.nan     # some samples missing
    return a


KEYS = [0, 5, -1, -57, slice(None), slice(3, 9), slice(None, None, 4), slice(50, 200),
        slice(-10, None), slice(9, 3), slice(1, 50, 7), slice(3, 4, 9), (slice(None), 2), (slice(4, 20), -1), (7, 3),
        (slice(None), [4, 0, 2]), (slice(2, 11), np.array([1, 1, 3])), (slice(None), slice(1, 4)),
        (slice(None), 2, 1), (slice(5, 9), slice(None), 0), (3, [0, 4], slice(1, None)),
        (slice(None), np.array([], dtype=np.intp)),
        # the rest are read whole, then indexed: the same values
        slice(None, None, -2), np.array([3, 1, 3]), (Ellipsis, 0), (), (slice(None), None),
        (slice(None), np.array([True, False, True, False, True]))]


@pytest.mark.parametrize("key", KEYS, ids=[repr(k)[:40] for k in KEYS])
def test_every_index_gives_what_the_array_gives(tmp_path, key):
    a = _positions()
    d = FramesOnDisk(a, tmp_path)
    np.testing.assert_array_equal(d[key], a[key])
    assert np.asarray(d[key]).dtype == a.dtype


def test_whole_array_arithmetic_and_attributes(tmp_path):
    a = _positions()
    d = FramesOnDisk(a, tmp_path)
    assert d.shape == a.shape and d.ndim == 3 and len(d) == 57 and d.size == a.size
    assert d.nbytes == a.nbytes and d.dtype == np.float64
    np.testing.assert_array_equal(np.asarray(d), a)
    np.testing.assert_array_equal(d.copy(), a)
    np.testing.assert_array_equal(d - 1.0, a - 1.0)
    np.testing.assert_array_equal(a == d, a == a)
    assert np.nansum(d) == np.nansum(a)
    assert d.astype(np.float32).dtype == np.float32     # an ndarray method, on the whole
    np.testing.assert_array_equal(np.linalg.norm(d, axis=-1), np.linalg.norm(a, axis=-1))


def test_missing_mask_of_positions_kept_in_memory(tmp_path):
    a = _positions()
    d = FramesOnDisk(a, tmp_path)
    np.testing.assert_array_equal(d.missing, np.isnan(a).any(axis=2))
    assert not d.missing.flags.writeable
    channels = FramesOnDisk(np.arange(40.0).reshape(8, 5), tmp_path)   # not positions
    assert channels.missing is None
    np.testing.assert_array_equal(channels[:, 3], np.arange(40.0).reshape(8, 5)[:, 3])


def test_values_are_the_array_as_it_was_written(tmp_path):
    a = _positions()
    d = FramesOnDisk(a, tmp_path)
    kept = a.copy()
    a[:] = 0.0                               # the array cleaned in place afterwards
    np.testing.assert_array_equal(np.asarray(d), kept)


@pytest.mark.parametrize("step", [2, 3, 4095, 4096, 5000, 9000])
def test_every_kth_frame_of_a_long_array(tmp_path, step):
    a = np.arange(20_000 * 2 * 3, dtype=np.float64).reshape(20_000, 2, 3)
    d = FramesOnDisk(a, tmp_path)
    np.testing.assert_array_equal(d[::step], a[::step])
    np.testing.assert_array_equal(d[17:19_999:step, 1], a[17:19_999:step, 1])


def test_int_and_float32_arrays(tmp_path):
    ints = np.arange(6 * 4 * 2, dtype=np.int16).reshape(6, 4, 2)
    d = FramesOnDisk(ints, tmp_path)
    np.testing.assert_array_equal(d[2:5, [3, 0]], ints[2:5, [3, 0]])
    assert d[1:3].dtype == np.int16 and d.missing is None
    f32 = _positions().astype(np.float32)
    np.testing.assert_array_equal(FramesOnDisk(f32, tmp_path)[:, 4], f32[:, 4])


def test_out_of_range_indices_raise_as_numpy_does(tmp_path):
    a = _positions(T=10, J=3)
    d = FramesOnDisk(a, tmp_path)
    for key in (10, -11, (slice(None), 3), (slice(None), -4), (slice(None), [0, 3])):
        with pytest.raises(IndexError):
            a[key]
        with pytest.raises(IndexError):
            d[key]


def test_a_column_is_one_read_and_frames_one_read_per_column(tmp_path, monkeypatch):
    a = _positions(T=1000, J=6)
    d = FramesOnDisk(a, tmp_path)
    sizes = []
    real = os.preadv

    def counted(fd, buffers, offset):
        sizes.append(sum(len(memoryview(b).cast("B")) for b in buffers))
        return real(fd, buffers, offset)
    monkeypatch.setattr(os, "preadv", counted)
    d[:, 4]
    assert sizes == [1000 * 3 * 8]
    sizes.clear()
    d[100:150]
    assert sizes == [50 * 3 * 8] * 6


def test_read_by_seek_where_the_system_has_no_preadv(tmp_path, monkeypatch):
    a = _positions(T=300, J=4)
    d = FramesOnDisk(a, tmp_path)
    monkeypatch.delattr(os, "preadv")           # Windows
    np.testing.assert_array_equal(d[10:200:3, [3, 1]], a[10:200:3, [3, 1]])
    np.testing.assert_array_equal(np.asarray(d), a)


def test_the_file_is_never_seen_and_goes_with_the_array(tmp_path):
    d = FramesOnDisk(_positions(), tmp_path)
    assert list(tmp_path.iterdir()) == []        # unlinked as it was made
    fd = d._file.fileno()
    os.fstat(fd)
    d.close()
    with pytest.raises(OSError):
        os.fstat(fd)


def test_a_folder_that_cannot_take_it_raises_oserror(tmp_path):
    with pytest.raises(OSError):
        FramesOnDisk(_positions(), tmp_path / "not-there")


def test_refuses_an_array_without_columns(tmp_path):
    with pytest.raises(ValueError, match="frames × columns"):
        FramesOnDisk(np.zeros(5), tmp_path)
