"""Tests of mocapfix.formats.c3d on the shared real captures and on hand-built files.

Expected frame/marker/rate/unit/missing values are typed from ../shared/data/SOURCES.md;
py-c3d (the ``c3d`` package) serves as an independent reader of inputs and outputs.
"""
from __future__ import annotations

import struct
import warnings

import numpy as np
import pytest

from mocapfix.core.errors import UnreadableFileError
from mocapfix.formats import c3d as C
from mocapfix.core.motion import Motion
from conftest import hang_guard, need, shared, shared_files

ALL_FILES = shared_files("c3d", "*.[cC]3[dD]")

# name: (frames, markers, rate, units or None, missing % or None)  -- from SOURCES.md
SOURCES = {
    "btk_ADemo1_pc_integer.c3d": (512, 24, 200, "mm", 0.7),
    "btk_Gait.c3d": (487, 33, 100, "mm", 60.2),
    "btk_PiG_Motion-FlatFoot-Hole.c3d": (320, 193, 100, "mm", 10.5),
    "btk_mocap36_optitrack.c3d": (1380, 36, 100, None, 16.6),
    "c3dorg_s01_Eb015pi.c3d": (450, 26, 50, "mm", 1.9),
    "c3dorg_s01_Eb015vr.c3d": (450, 26, 50, "mm", 1.9),
    "c3dorg_s01_Eb015sr.c3d": (450, 26, 50, "mm", 1.9),
    "c3dorg_s02_DEC_INT.C3D": (89, 36, 50, "mm", 7.1),
    "c3dorg_s02_pc_real.c3d": (89, 36, 50, "mm", 7.1),
    # s04 and s09: SOURCES counts every (0,0,0) as missing (54.8 / 43.2 %); model outputs
    # (POINT:ANGLES, FORCES, ...) of exactly (0,0,0) are values, not gaps, so fewer here
    "c3dorg_s04_sub_labels.c3d": (333, 114, 60, "mm", 52.03),
    "c3dorg_s06_MACsample.c3d": (180, 33, 60, None, 60.0),
    "c3dorg_s08_TESTBPI.c3d": (450, 26, 50, "mm", 1.9),
    "c3dorg_s09_PlugInC3D.c3d": (281, 86, 60, "mm", 38.02),
    "c3dorg_s13_Dance.c3d": (499, 40, 65.05, None, 0.0),
    "c3dorg_s20_phasespace_sample.c3d": (701, 40, 30, None, 4.6),
    "c3dorg_s22_BKINtechnologies.c3d": (5065, 2, 1000, None, 0.0),
    # SOURCES says 19.7 % missing; the file flags 35.5 % of samples with residual -1
    # (py-c3d agrees, checked in test_missing_matches_py_c3d), so no % is asserted here.
    "c3dorg_s28_dynamic.C3D": (296, 34, 100, "mm", None),
    "cmu_85_02.c3d": (810, 41, 120, "mm", 0.0),
    "ezc3d_BTS.c3d": (675, 22, 100, "mm", 51.6),
    "ezc3d_Optotrak.c3d": (29, 54, 30, "mm", 3.8),
    "ezc3d_Qualisys.c3d": (340, 55, 200, "mm", 0.0),
    "hdm05_HDM_mm_01-02_03_120.c3d": (3990, 44, 120, "mm", 0.0),
    "ktk_tennis_serve_nan.c3d": (1092, 39, 50, "m", 0.3),
    "ktk_racing_full.c3d": (700, 46, 69.9926, "m", 19.8),
    "numediart_03_rolling.c3d": (2305, 68, 175, "mm", 22.9),
}


#: shared files py-c3d cannot read, with the exception it raises (py-c3d's own limits:
#: label record without description byte, header/parameter scale mismatch, scalar SCALE)
PY_C3D_CANNOT_READ = {
    "btk_mocap36_optitrack.c3d": (struct.error, "unpack requires a buffer"),
    "c3dorg_s06_MACsample.c3d": (AssertionError, "inconsistent scale factor"),
    "ktk_racing_full.c3d": (AssertionError, "SCALE: cannot get value"),
}


def py_c3d_points(path):
    """(T, P, 5) points and the reader from py-c3d (the ``c3d`` package, a dependency of
    mocapfix, imported here only: our reader does not use it). Raises what py-c3d raises."""
    import c3d as c3d_lib

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with open(path, "rb") as handle:
            reader = c3d_lib.Reader(handle)
            frames = [p for _, p, _ in reader.read_frames()]
            return np.array(frames), reader


# ---------------------------------------------------------------------------------------
# real files: reading
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("path", ALL_FILES)
def test_every_shared_file_reads_and_matches_sources(path):
    path = need(path)
    with hang_guard(60):                 # read time: benchmarks/formats_io.py
        motion = C.read(path)
    frames, markers, rate, units, missing_pct = SOURCES[path.name]
    assert motion.positions.shape == (frames, markers, 3)
    assert motion.fps == pytest.approx(rate, rel=1e-3)
    if units is not None:
        assert motion.units == units
    assert motion.metres_per_unit == {"mm": 0.001, "m": 1.0}[motion.units]
    if missing_pct is not None:
        assert 100 * motion.missing.mean() == pytest.approx(missing_pct, abs=0.15)
    assert len(set(motion.names)) == markers and all(n.strip() == n and n for n in motion.names)
    np.testing.assert_array_equal(motion.confidence, (~motion.missing).astype(float))


@pytest.mark.slow
@pytest.mark.parametrize("path", ALL_FILES)
def test_missing_and_positions_match_py_c3d(path):
    path = need(path)
    motion = C.read(path)
    if path.name in PY_C3D_CANNOT_READ:
        kind, text = PY_C3D_CANNOT_READ[path.name]
        with pytest.raises(kind, match=text):
            py_c3d_points(path)
        return
    points, _ = py_c3d_points(path)
    points = points[:motion.n_frames]
    # py-c3d flags residual < 0 and NaN; vendor (0,0,0) gaps are ours on top
    # (markers only: a model output of (0,0,0) is a value)
    markers = np.ones(motion.n_joints, bool) if motion.kinds is None else \
        np.array([k == "marker" for k in motion.kinds])
    theirs = (points[..., 3] < 0) | ((points[..., :3] == 0).all(axis=2) & markers)
    np.testing.assert_array_equal(motion.missing, theirs)
    valid = ~motion.missing
    tolerance = 1e-4 * max(1.0, float(np.nanmax(np.abs(motion.positions))))
    np.testing.assert_allclose(motion.positions[valid], points[..., :3][valid], atol=tolerance)


@pytest.mark.parametrize("path", ALL_FILES)
def test_source_decodes_the_positions_read_and_holds_no_copy(path):
    """The writer compares against the positions as read, decoded again from the records
    (bit for bit, model outputs' (0, 0, 0) included); the source holds no second
    whole-take float array beside the motion's (33 bytes a sample on a long take)."""
    motion = C.read(need(path))
    source = motion.source
    assert source.positions_of().tobytes() == motion.positions.tobytes()
    T = motion.n_frames
    assert source.positions_of(slice(T // 3, T // 2)).tobytes() == \
        motion.positions[T // 3:T // 2].tobytes()
    held = [k for k, v in vars(source).items() if isinstance(v, np.ndarray)
            and v.dtype.kind == "f" and v.dtype.itemsize == 8 and v.shape[:2] == (T, motion.n_joints)]
    assert held == []


def test_labels_units_and_quirks_of_real_files():
    sub = C.read(shared("c3d/c3dorg_s04_sub_labels.c3d"))
    assert sub.names[0] == "Matt:C7"
    dyn = C.read(shared("c3d/c3dorg_s28_dynamic.C3D"))
    assert "r should_2" in dyn.names and any("duplicate" in n for n in dyn.notes)
    assert any("POINT:UNITS unset" in n for n in dyn.notes)
    opto = C.read(shared("c3d/ezc3d_Optotrak.c3d"))  # "mm  mm  mm ..." units
    assert opto.units == "mm"
    assert any("holds 29 complete frames" in n for n in opto.notes)
    optitrack = C.read(shared("c3d/btk_mocap36_optitrack.c3d"))
    assert optitrack.names[:2] == ["Skeleton_Hip2", "Skeleton_Hip1"]
    assert any("description-length" in n for n in optitrack.notes)
    phasespace = C.read(shared("c3d/c3dorg_s20_phasespace_sample.c3d"))
    assert phasespace.names[0] == "marker1" and any("no parameter section" in n for n in phasespace.notes)
    dance = C.read(shared("c3d/c3dorg_s13_Dance.c3d"))
    assert any("DATA_START is 0" in n for n in dance.notes)
    assert any("POINT:FRAMES 500" in n for n in dance.notes)
    mac = C.read(shared("c3d/c3dorg_s06_MACsample.c3d"))
    assert any("disagrees with the header scale" in n for n in mac.notes)
    hdm = C.read(shared("c3d/hdm05_HDM_mm_01-02_03_120.c3d"))
    assert "*0" in hdm.names


def test_events_from_header_and_event_group():
    intel = C.read(shared("c3d/c3dorg_s01_Eb015pi.c3d")).source.events
    assert [e["label"] for e in intel] == ["RIC", "RHS", "RTO"]
    for twin in ("c3dorg_s01_Eb015vr.c3d", "c3dorg_s01_Eb015sr.c3d"):  # DEC / MIPS header floats
        events = C.read(shared(f"c3d/{twin}")).source.events
        assert [e["label"] for e in events] == ["RIC", "RHS", "RTO"]
        np.testing.assert_allclose([e["time"] for e in events], [e["time"] for e in intel], rtol=1e-6)
    qualisys = C.read(shared("c3d/ezc3d_Qualisys.c3d")).source.parameter_events
    assert len(qualisys) == 7 and [e["label"] for e in qualisys[:3]] == ["LHS", "RTO", "RHS"]
    sub = C.read(shared("c3d/c3dorg_s04_sub_labels.c3d")).source.parameter_events
    assert len(sub) == 8 and sub[0]["label"] == "Foot Strike"
    assert all(0 <= e["time"] < 333 / 60 + 1 for e in sub)


@pytest.mark.parametrize("path", ALL_FILES)
def test_sniff_recognises_shared_files(path):
    with open(need(path), "rb") as handle:
        assert C.sniff(handle.read(4096))


def test_fps_override_is_noted():
    motion = C.read(shared("c3d/c3dorg_s01_Eb015pi.c3d"), fps=100.0)
    assert motion.fps == 100.0 and any("overrides the file's 50 Hz" in n for n in motion.notes)


@pytest.mark.parametrize("twin", ["c3dorg_s01_Eb015vr.c3d", "c3dorg_s01_Eb015sr.c3d"])
def test_dec_and_sgi_files_equal_their_intel_twin(twin):
    intel = C.read(shared("c3d/c3dorg_s01_Eb015pi.c3d"))  # int16, scale 1/12 mm
    other = C.read(shared(f"c3d/{twin}"))
    np.testing.assert_array_equal(other.missing, intel.missing)
    valid = ~intel.missing
    step = intel.source.scale
    assert np.abs(other.positions[valid] - intel.positions[valid]).max() <= step / 2 + 1e-6
    assert other.names == intel.names
    assert any("will be written as Intel" in n for n in other.notes)


def test_dec_float_conversion_known_values():
    # DEC F-float bit patterns (high word first, little-endian words): 1.0 = 0x4080_0000,
    # -2.5 = 0xC120_0000, 0.0 = 0
    raw = struct.pack("<4H", 0x4080, 0x0000, 0xC120, 0x0000) + b"\0\0\0\0"
    np.testing.assert_array_equal(C.dec_to_float(raw), [1.0, -2.5, 0.0])


# ---------------------------------------------------------------------------------------
# real files: writing
# ---------------------------------------------------------------------------------------
def _params_equal(a, b):
    assert list(a.groups) == list(b.groups)
    for name, group in a.groups.items():
        other = b.groups[name]
        assert group.desc == other.desc and list(group.params) == list(other.params)
        for key, param in group.params.items():
            q = other.params[key]
            assert (param.bytes_per_element, param.dims, param.data, param.desc) == \
                   (q.bytes_per_element, q.dims, q.data, q.desc), f"{name}:{key}"


@pytest.mark.slow
@pytest.mark.parametrize("path", ALL_FILES)
def test_round_trip_keeps_everything(path, tmp_path):
    path = need(path)
    motion = C.read(path)
    out = tmp_path / path.name
    with hang_guard(60):                 # write time: benchmarks/formats_io.py
        assert C.write(motion, out) == [out]
    again = C.read(out)
    src, src2 = motion.source, again.source
    np.testing.assert_array_equal(again.positions, motion.positions)  # exact, NaN in place
    assert again.names == motion.names and again.fps == motion.fps and again.units == motion.units
    flagged = (src.residual >= 0) & ~motion.missing  # valid samples keep their words
    np.testing.assert_array_equal(src2.residual[flagged], src.residual[flagged])
    np.testing.assert_array_equal(src2.camera_mask[flagged], src.camera_mask[flagged])
    assert (src2.residual[motion.missing] == -1).all()  # every gap flagged on output
    np.testing.assert_array_equal(src2.analog, src.analog)
    assert src2.events == src.events
    if src.parameters is not None:
        _params_equal(src.parameters, src2.parameters)
    assert src2.processor == C.PROCESSOR_INTEL
    data = out.read_bytes()
    assert data[(data[0] - 1) * 512 + 3] == C.PROCESSOR_INTEL
    original = path.read_bytes()
    vendor_gaps = (motion.missing & (src.points[..., 3] >= 0)).any()
    if src.processor == C.PROCESSOR_INTEL and not vendor_gaps:
        assert data == original
    # independent reader on our output: it must read it, except where our output keeps
    # the input's parameter quirk that py-c3d refuses (PY_C3D_CANNOT_READ, same exception)
    if path.name in PY_C3D_CANNOT_READ:
        kind, text = PY_C3D_CANNOT_READ[path.name]
        with pytest.raises(kind, match=text):
            py_c3d_points(out)
    else:
        points, reader = py_c3d_points(out)
        assert reader.proc_type == "INTEL"
        valid = ~again.missing
        np.testing.assert_array_equal(points[..., 3] < 0, again.missing & (src2.residual < 0))
        np.testing.assert_allclose(points[..., :3][valid], again.positions[valid],
                                   atol=1e-4 * max(1.0, float(np.nanmax(np.abs(again.positions)))))
    if src.processor == C.PROCESSOR_INTEL:
        C.write(motion, out, mark_missing=False)
        assert out.read_bytes() == original


def test_round_trip_readable_by_py_c3d_for_dec_and_sgi(tmp_path):
    for name in ("c3dorg_s01_Eb015vr.c3d", "c3dorg_s01_Eb015sr.c3d", "btk_Gait.c3d"):
        motion = C.read(shared(f"c3d/{name}"))
        out = tmp_path / name
        C.write(motion, out)
        points, reader = py_c3d_points(out)
        assert reader is not None and reader.proc_type == "INTEL"
        assert points.shape[:2] == motion.positions.shape[:2]


def _edit_and_write(name, tmp_path, edit):
    motion = C.read(shared(f"c3d/{name}"))
    cleaned = motion.copy()
    edit(cleaned)
    out = tmp_path / name
    C.write(cleaned, out)
    return motion, cleaned, C.read(out), py_c3d_points(out)[0]


@pytest.mark.parametrize("name", ["c3dorg_s01_Eb015pi.c3d", "c3dorg_s02_pc_real.c3d",
                                  "c3dorg_s01_Eb015vr.c3d", "numediart_03_rolling.c3d"])
def test_filled_modified_deleted_and_still_missing_samples(name, tmp_path):
    motion = C.read(shared(f"c3d/{name}"))
    gaps = np.argwhere(motion.missing)
    (t_fill, j_fill), (t_keep, j_keep) = gaps[0], gaps[-1]
    valid = np.argwhere(~motion.missing)
    (t_mod, j_mod), (t_del, j_del) = valid[0], valid[-1]

    def edit(m):
        m.positions[t_fill, j_fill] = [100.123, -200.456, 300.789]
        m.positions[t_mod, j_mod] += 1.2345
        m.positions[t_del, j_del] = np.nan

    original, cleaned, again, theirs = _edit_and_write(name, tmp_path, edit)
    src, out = original.source, again.source
    int_grid = src.storage == "int16"
    tol = src.scale / 2 + 1e-9 if int_grid else 1e-4
    # filled: written on the grid, residual 0, camera mask 0
    np.testing.assert_allclose(again.positions[t_fill, j_fill], cleaned.positions[t_fill, j_fill], atol=tol)
    if int_grid:
        grid = again.positions[t_fill, j_fill] / src.scale
        np.testing.assert_allclose(grid, np.rint(grid), atol=1e-6)
    assert out.residual[t_fill, j_fill] == 0 and out.camera_mask[t_fill, j_fill] == 0
    # modified valid sample: new coordinates, original residual and camera mask
    np.testing.assert_allclose(again.positions[t_mod, j_mod], cleaned.positions[t_mod, j_mod], atol=tol)
    assert out.residual[t_mod, j_mod] == src.residual[t_mod, j_mod]
    assert out.camera_mask[t_mod, j_mod] == src.camera_mask[t_mod, j_mod]
    # deleted and still-missing samples: residual -1
    assert again.missing[t_del, j_del] and out.residual[t_del, j_del] == -1
    assert again.missing[t_keep, j_keep] and out.residual[t_keep, j_keep] == -1
    # unchanged samples: identical records
    untouched = np.ones(original.missing.shape, bool)
    for t, j in ((t_fill, j_fill), (t_mod, j_mod), (t_del, j_del)):
        untouched[t, j] = False
    untouched &= ~original.missing
    np.testing.assert_array_equal(out.points[untouched], src.points[untouched])  # both Intel-encoded
    np.testing.assert_array_equal(again.positions[untouched], original.positions[untouched])
    # py-c3d sees the same flags: filled valid (residual 0), deleted invalid
    if theirs is not None:
        assert theirs[t_fill, j_fill, 3] == 0 and theirs[t_fill, j_fill, 4] == 0
        assert theirs[t_del, j_del, 3] == -1 and theirs[t_keep, j_keep, 3] == -1


def test_int16_overflow_is_a_write_error(tmp_path):
    from mocapfix.core.errors import WriteError
    motion = C.read(shared("c3d/c3dorg_s01_Eb015pi.c3d"))
    motion.positions[0, 0] = [1e7, 0, 0]
    with pytest.raises(WriteError):
        C.write(motion, tmp_path / "x.c3d")
    assert not (tmp_path / "x.c3d").exists()


# ---------------------------------------------------------------------------------------
# malformed input
# ---------------------------------------------------------------------------------------
def _assert_refused(path):
    with hang_guard(30), pytest.raises(UnreadableFileError) as info:
        C.read(path)
    assert str(path) in str(info.value)
    return str(info.value)


def test_truncated_files_are_refused(tmp_path):
    original = shared("c3d/c3dorg_s01_Eb015pi.c3d").read_bytes()
    # header, parameter section, data pointer block, mid-frame in the data
    frame_bytes = (26 * 4 + 64) * 2
    data_start = 10 * 512
    for cut in (0, 100, 511, 600, 2000, data_start - 1, data_start + 7,
                data_start + 100 * frame_bytes + 3, data_start + 449 * frame_bytes + 5):
        bad = tmp_path / f"cut{cut}.c3d"
        bad.write_bytes(original[:cut])
        message = _assert_refused(bad)
        assert message


def test_truncated_on_a_frame_boundary_reads_whole_frames_with_a_note(tmp_path):
    original = shared("c3d/c3dorg_s01_Eb015pi.c3d").read_bytes()
    frame_bytes = (26 * 4 + 64) * 2
    short = tmp_path / "short.c3d"
    short.write_bytes(original[:10 * 512 + 300 * frame_bytes])
    motion = C.read(short)
    assert motion.n_frames == 300 and any("holds 300 complete frames" in n for n in motion.notes)


def test_garbage_empty_and_text_files_are_refused(tmp_path):
    rng = np.random.default_rng(0)
    cases = {
        "empty.c3d": b"",
        "text.c3d": b"this is a text file, not a capture\n" * 40,
        "garbage.c3d": rng.integers(0, 256, 5000, dtype=np.uint8).tobytes(),
        "keyonly.c3d": bytes([2, 0x50]) + rng.integers(0, 256, 3000, dtype=np.uint8).tobytes(),
    }
    for name, payload in cases.items():
        path = tmp_path / name
        path.write_bytes(payload)
        _assert_refused(path)
    corrupt = bytearray(shared("c3d/c3dorg_s02_pc_real.c3d").read_bytes())
    corrupt[512 + 4:512 + 400] = rng.integers(0, 256, 396, dtype=np.uint8).tobytes()
    path = tmp_path / "corrupt_params.c3d"
    path.write_bytes(bytes(corrupt))
    try:  # corrupt parameters: either read with notes or refused, never a crash or hang
        motion = C.read(path)
        assert motion.notes
    except UnreadableFileError as exc:
        assert str(path) in str(exc)
    assert C.sniff(shared("c3d/c3dorg_s01_Eb015sr.c3d").read_bytes()[:4096])
    assert not C.sniff(b"this is a text file")


# ---------------------------------------------------------------------------------------
# hand-built files with known answers (independent encoder below)
# ---------------------------------------------------------------------------------------
def _param(name, gid, bpe, dims, data, desc=b""):
    body = struct.pack("<bB", bpe, len(dims)) + bytes(dims) + data + bytes([len(desc)]) + desc
    return struct.pack("<bb", len(name), gid) + name + struct.pack("<h", 2 + len(body)) + body


def _group(name, gid):
    return struct.pack("<bb", len(name), -gid) + name + struct.pack("<h", 3) + b"\0"


def _strings(name, gid, values):
    width = max(len(v) for v in values)
    return _param(name, gid, -1, (width, len(values)), b"".join(v.ljust(width) for v in values))


def build_c3d(records, storage, scale, rate, labels, units=b"mm", data_start=None):
    """An Intel C3D from raw (T, P, 4) records; ``labels`` is a list of label chunks
    (LABELS, LABELS2, ...); ``data_start=0`` writes POINT:DATA_START = 0."""
    n_frames, n_points = records.shape[:2]
    params = [_group(b"POINT", 1),
              _param(b"USED", 1, 2, (), struct.pack("<H", n_points)),
              _param(b"SCALE", 1, 4, (), struct.pack("<f", scale)),
              _param(b"RATE", 1, 4, (), struct.pack("<f", rate)),
              _param(b"FRAMES", 1, 2, (), struct.pack("<H", n_frames))]
    if units is not None:
        params.append(_param(b"UNITS", 1, -1, (len(units),), units))
    for i, chunk in enumerate(labels):
        params.append(_strings(b"LABELS" if i == 0 else b"LABELS%d" % (i + 1), 1, chunk))
    body = b"".join(params)
    start_record_size = len(_param(b"DATA_START", 1, 2, (), b"\0\0"))
    n_blocks = (4 + len(body) + start_record_size) // 512 + 1
    data_block = 2 + n_blocks
    start_value = data_block if data_start is None else data_start
    body += _param(b"DATA_START", 1, 2, (), struct.pack("<H", start_value))
    section = (bytes([1, 0x50, n_blocks, 84]) + body).ljust(n_blocks * 512, b"\0")
    header = bytearray(512)
    struct.pack_into("<BBHHHHHfHHf", header, 0, 2, 0x50, n_points, 0, 1, n_frames, 0, scale,
                     data_block, 0, rate)
    dtype = "<f4" if scale < 0 else "<i2"
    return bytes(header) + section + np.asarray(records, dtype=dtype).tobytes()


def test_hand_built_int16_file(tmp_path):
    # 3 frames x 4 markers on a 0.5 mm grid
    words = np.zeros((3, 4, 4), np.int16)
    words[..., 0] = np.arange(12).reshape(3, 4) * 10
    words[..., 1] = -4
    words[..., 2] = 2000
    words[..., 3] = (5 << 8) | 3            # cameras 0 and 2, residual 3 units
    words[1, 2, 3] = -1                     # flagged gap
    words[2, 3, :3] = 0                     # vendor (0,0,0) gap
    labels = [[b" C7  ", b"Matt:RASI", b"C7", b""]]
    path = tmp_path / "int.c3d"
    path.write_bytes(build_c3d(words, "int16", 0.5, 120.0, labels, units=b"mm  mm  mm  mm  "))
    motion = C.read(path)
    assert motion.names == ["C7", "Matt:RASI", "C7_2", "marker4"]
    assert motion.fps == 120.0 and motion.units == "mm"
    np.testing.assert_array_equal(motion.positions[0, 1], [5.0, -2.0, 1000.0])
    assert motion.missing.sum() == 2 and motion.missing[1, 2] and motion.missing[2, 3]
    assert motion.source.residual[0, 0] == 1.5 and motion.source.camera_mask[0, 0] == 5
    out = tmp_path / "out.c3d"
    C.write(motion, out)
    written, built = out.read_bytes(), path.read_bytes()
    assert len(written) == len(built) and written[:512] == built[:512]
    again = C.read(out)
    np.testing.assert_array_equal(again.positions, motion.positions)
    assert again.source.residual[2, 3] == -1


def test_hand_built_float_file_with_nan_and_data_start_zero(tmp_path):
    records = np.zeros((2, 2, 4), np.float32)
    records[..., :3] = [[[1.5, 2.5, 3.5], [4.0, 5.0, 6.0]], [[np.nan, np.nan, np.nan], [7.0, 8.0, 9.0]]]
    path = tmp_path / "float.c3d"
    path.write_bytes(build_c3d(records, "float", -1.0, 50.0, [[b"A", b"B"]], units=None, data_start=0))
    motion = C.read(path)
    np.testing.assert_array_equal(motion.positions[0], [[1.5, 2.5, 3.5], [4.0, 5.0, 6.0]])
    assert motion.missing.tolist() == [[False, False], [True, False]]
    assert any("DATA_START is 0" in n for n in motion.notes)
    assert motion.units == "mm" and any("assuming mm" in n for n in motion.notes)


def test_more_than_255_markers(tmp_path):
    n = 300
    records = np.zeros((2, n, 4), np.float32)
    records[..., 0] = np.arange(n) + 1.0
    names = [b"M%03d" % i for i in range(n)]
    path = tmp_path / "many.c3d"
    path.write_bytes(build_c3d(records, "float", -1.0, 100.0, [names[:255], names[255:]]))
    motion = C.read(path)
    assert motion.names == [s.decode() for s in names]
    np.testing.assert_array_equal(motion.positions[1, :, 0], np.arange(n) + 1.0)
    # py-c3d reads only POINT:LABELS (255 names) -- our fresh writer splits into LABELS2
    fresh = Motion(positions=motion.positions, names=motion.names, fps=100.0)
    out = tmp_path / "fresh.c3d"
    C.write(fresh, out)
    again = C.read(out)
    assert again.names == motion.names
    np.testing.assert_array_equal(again.positions, motion.positions)


def test_fresh_file_from_a_motion_without_source(tmp_path):
    rng = np.random.default_rng(1)
    positions = rng.normal(size=(20, 3, 3)) * 100
    positions[5, 1] = np.nan
    motion = Motion(positions=positions, names=["a", "b", "c"], fps=60.0, units="mm")
    out = tmp_path / "fresh.c3d"
    C.write(motion, out)
    again = C.read(out)
    assert again.names == ["a", "b", "c"] and again.fps == 60.0 and again.units == "mm"
    np.testing.assert_allclose(again.positions, positions.astype(np.float32), equal_nan=True)
    points, reader = py_c3d_points(out)
    assert points is not None and points[5, 1, 3] == -1
    np.testing.assert_allclose(points[0, :, :3], positions[0], rtol=1e-6)


@pytest.mark.parametrize("units", ["mm", "unknown"])
def test_a_fresh_file_written_a_chunk_of_frames_at_a_time_is_the_same(units, tmp_path, monkeypatch):
    """The records of a fresh file are written CHUNK frames a piece: chunks of 7 frames,
    a gap across a chunk's edge and a unit the file cannot name (converted to mm) give the
    bytes one chunk gives, and the file reads back as written."""
    rng = np.random.default_rng(2)
    positions = rng.normal(size=(30, 4, 3)) * 100
    positions[5:9, 1] = np.nan
    motion = Motion(positions=positions, names=["a", "b", "c", "d"], fps=60.0, units=units,
                    metres_per_unit=0.0254 / 0.45 if units == "unknown" else 0.001)
    C.write(motion, tmp_path / "one.c3d")
    monkeypatch.setattr(C, "CHUNK", 7)
    C.write(motion, tmp_path / "chunks.c3d")
    assert (tmp_path / "one.c3d").read_bytes() == (tmp_path / "chunks.c3d").read_bytes()
    again = C.read(tmp_path / "chunks.c3d")
    expected = positions * (motion.metres_per_unit / 0.001)
    np.testing.assert_allclose(again.positions, expected.astype(np.float32), rtol=1e-6, equal_nan=True)


def test_read_does_not_modify_or_hang_on_huge_declared_counts(tmp_path):
    records = np.ones((2, 2, 4), np.float32)
    data = bytearray(build_c3d(records, "float", -1.0, 50.0, [[b"A", b"B"]]))
    struct.pack_into("<H", data, 2, 65000)  # header points
    # POINT:USED patched to 65000 too: declared size far beyond the file
    index = data.find(b"USED")
    struct.pack_into("<H", data, index + 8, 65000)
    path = tmp_path / "huge.c3d"
    path.write_bytes(bytes(data))
    _assert_refused(path)
    assert path.read_bytes() == bytes(data)  # input untouched


def test_valid_point_at_the_origin_is_not_written_as_a_gap(tmp_path):
    """In an int16 file a filled point within half a scale step of (0, 0, 0) would be
    stored as the vendor gap marker (0, 0, 0); the writer keeps it valid instead."""
    motion = C.read(shared("c3d/c3dorg_s01_Eb015pi.c3d"))
    gap = np.argwhere(motion.missing)[0]
    pos = motion.positions.copy()
    pos[gap[0], gap[1]] = [0.01, -0.02, 0.0]
    out = tmp_path / "origin.c3d"
    C.write(motion.replace(positions=pos), out)
    back = C.read(out)
    assert not back.missing[gap[0], gap[1]]
    scale = abs(motion.source.scale)
    np.testing.assert_allclose(back.positions[gap[0], gap[1]], [0.0, -scale, 0.0], atol=1e-6)


def test_int16_fill_beyond_the_file_range_stays_a_gap(tmp_path):
    """A filled sample the int16 grid cannot hold is written as a gap, not a failed file;
    the other fills are written."""
    motion = C.read(shared("c3d/c3dorg_s04_sub_labels.c3d"))
    assert motion.source.storage == "int16"
    gaps = np.argwhere(motion.missing)
    pos = motion.positions.copy()
    (t0, j0), (t1, j1) = gaps[0], gaps[-1]
    pos[t0, j0] = [1e6, 0.0, 0.0]
    pos[t1, j1] = [100.0, 200.0, 300.0]
    C.write(motion.replace(positions=pos), tmp_path / "out.c3d")
    back = C.read(tmp_path / "out.c3d")
    assert back.missing[t0, j0]
    assert not back.missing[t1, j1]
    np.testing.assert_allclose(back.positions[t1, j1], [100, 200, 300], atol=motion.source.scale)
