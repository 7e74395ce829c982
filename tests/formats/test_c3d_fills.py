"""The MOCAPFIX parameter group a cleaned C3D carries: every run of filled samples with its
frames, confidence and whether it is long; read back with py-c3d (an independent reader),
on a shared capture whose parameter section has to grow, and on hand-built sections."""
from __future__ import annotations

import struct
import warnings

import c3d
import numpy as np
import pytest

from mocapfix import formats
from mocapfix.formats import c3d_params as P
from mocapfix.config import default_config_path, load_config
from conftest import shared


def _reader_frames(path):
    """(T, P, 3) positions and (T, P) residuals as py-c3d reads them."""
    with open(path, "rb") as handle, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = c3d.Reader(handle)
        frames = [points for _, points, _ in reader.read_frames()]
    pts = np.stack(frames)
    return pts[..., :3], pts[..., 3]


def _group(path):
    with open(path, "rb") as handle, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = c3d.Reader(handle)
        get = r.get
        return {
            "points": [s.strip() for s in get("MOCAPFIX:FILL_POINTS").string_array],
            "first": get("MOCAPFIX:FILL_FIRST").float_array.astype(int),
            "last": get("MOCAPFIX:FILL_LAST").float_array.astype(int),
            "confidence": get("MOCAPFIX:FILL_CONFIDENCE").float_array,
            "long": get("MOCAPFIX:FILL_LONG").int8_array,
            "count": get("MOCAPFIX:FILL_COUNT").float_value,
            "long_s": get("MOCAPFIX:LONG_FILL_S").float_value,
            "data_start": get("POINT:DATA_START").uint16_value,
            "header_start": r.header.data_block,
            "labels": [s.strip() for s in get("POINT:LABELS").string_array],
            "first_frame": r.header.first_frame,
            "rate": r.header.frame_rate,
            "params": {f"{g}:{n}": p.bytes for g, grp in r.group_items() if isinstance(g, str)
                       for n, p in grp.param_items()},
        }


@pytest.mark.slow
def test_cleaned_c3d_lists_every_filled_run(tmp_path):
    """c3d.org s01 (Eb015pi): 12 gaps, two of them 0.94 s (PV2/PV3, one at the start);
    the parameter section must grow by a block to hold the list."""
    src = shared("c3d/c3dorg_s01_Eb015pi.c3d")
    out, _ = load_config(default_config_path()).run(formats.read(src))
    dst = tmp_path / "out.c3d"
    formats.write(out, dst)

    g = _group(dst)
    assert g["data_start"] == g["header_start"] > _group_or_none_start(src)
    _, res_in = _reader_frames(src)
    pos_out, res_out = _reader_frames(dst)
    ours = formats.read(dst).positions
    valid = res_out >= 0
    assert np.array_equal(valid, ~np.isnan(ours).any(axis=2))
    np.testing.assert_allclose(pos_out[valid], ours[valid], atol=1e-3)   # data found where it moved
    # the written values are the cleaned ones, to the file's int16 grid (POINT:SCALE 0.083 mm)
    np.testing.assert_allclose(ours[valid], out.positions[valid], atol=0.05)
    filled = (res_in < 0) & (res_out >= 0)
    listed = np.zeros_like(filled)
    for name, a, b in zip(g["points"], g["first"], g["last"]):
        col = g["labels"].index(name)
        rows = slice(a - g["first_frame"], b - g["first_frame"] + 1)
        assert not listed[rows, col].any()
        listed[rows, col] = True
    assert np.array_equal(listed, filled)
    length_s = (g["last"] - g["first"] + 1) / g["rate"]
    assert np.array_equal(g["long"] == 1, length_s > g["long_s"]) and g["long_s"] == 0.5
    assert g["long"].sum() >= 2 and g["count"] == len(g["points"]) == 12
    assert ((g["confidence"] >= 0) & (g["confidence"] <= 1)).all()
    # the long fills are the least trusted ones
    assert g["confidence"][g["long"] == 1].max() < g["confidence"][g["long"] == 0].max()
    # every other parameter is kept as it was
    before, after = _group_params(src), g["params"]
    moved = {k for k in after if k.startswith("MOCAPFIX:")} | {"POINT:DATA_START"}
    assert {k: v for k, v in after.items() if k not in moved} == {k: v for k, v in before.items() if k not in moved}


def _group_or_none_start(path):
    with open(path, "rb") as handle, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return c3d.Reader(handle).header.data_block


def _group_params(path):
    with open(path, "rb") as handle, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = c3d.Reader(handle)
        return {f"{g}:{n}": p.bytes for g, grp in r.group_items() if isinstance(g, str)
                for n, p in grp.param_items()}


def test_recleaning_keeps_the_fills_listed_before(tmp_path):
    src = shared("c3d/c3dorg_s01_Eb015pi.c3d")
    motion = formats.read(src)
    missing = np.isnan(motion.positions).any(axis=2)
    (t0, c0), (t1, c1) = np.argwhere(missing)[[0, -1]]
    first = motion.positions.copy()
    first[t0, c0] = [1.0, 2.0, 3.0]
    formats.write(motion.replace(positions=first), tmp_path / "a.c3d")
    again = formats.read(tmp_path / "a.c3d")
    second = again.positions.copy()
    second[t1, c1] = [4.0, 5.0, 6.0]
    formats.write(again.replace(positions=second), tmp_path / "b.c3d")
    g = _group(tmp_path / "b.c3d")
    names = motion.names
    start = g["first_frame"]
    assert list(zip(g["points"], g["first"], g["last"])) == [
        (names[c0], start + t0, start + t0), (names[c1], start + t1, start + t1)]
    assert sum(k.startswith("MOCAPFIX:FILL_POINTS") for k in g["params"]) == 1
    # nothing filled: the file is written back byte for byte, group and all
    formats.write(formats.read(tmp_path / "b.c3d"), tmp_path / "c.c3d")
    assert (tmp_path / "c.c3d").read_bytes() == (tmp_path / "b.c3d").read_bytes()


def _section(*records):
    body = b"".join(records)
    blocks = -(-(4 + len(body)) // P.BLOCK)
    return (bytes([1, 0x50, blocks, 84]) + body).ljust(blocks * P.BLOCK, b"\0")


def test_with_group_replaces_one_group_and_keeps_the_others_bytes():
    point = [P.group_record("POINT", 1, "points"),
             P.param_record("USED", 1, 2, (), struct.pack("<H", 3)),
             P.string_param("LABELS", 1, ["A", "B", "C"])]
    old = [P.group_record("MOCAPFIX", 2, "old"), P.param_record("X", 2, 4, (), struct.pack("<f", 1.0))]
    last = P.param_record("RATE", 1, 4, (), struct.pack("<f", 100.0))
    last = last[:6] + struct.pack("<h", 0) + last[8:]        # the chain's end: offset 0
    section = _section(*point, *old, last)
    new = P.with_group(section, "MOCAPFIX", [("Y", 4, (2,), struct.pack("<2f", 2.0, 3.0), "")], "new")
    recs = P.records(new)
    assert [(r.group_id, r.name) for r in recs] == [(-1, "POINT"), (1, "USED"), (1, "LABELS"), (1, "RATE"),
                                                    (-2, "MOCAPFIX"), (2, "Y")]
    for raw, r in zip([*point, last], recs):
        # same bytes but for the next-record offset of the record that used to end the chain
        assert new[r.start:r.end][:r.link - r.start] == raw[:r.link - r.start]
        assert new[r.link + 2:r.end] == raw[r.link - r.start + 2:]
    at = P.param_data_offset(new, "MOCAPFIX", "Y")
    assert struct.unpack_from("<2f", new, at) == (2.0, 3.0)
    assert new[2] == len(new) // P.BLOCK
    # a broken chain (a link past the end) is refused, not guessed at
    broken = bytearray(section)
    struct.pack_into("<h", broken, 4 + 2 + len("POINT"), 30000)
    assert P.with_group(bytes(broken), "MOCAPFIX", []) is None


@pytest.mark.slow
def test_the_report_describes_the_fills_an_int16_file_could_not_hold(tmp_path):
    """c3d.org s09 stores int16 coordinates (POINT:SCALE 0.0966: ±3.2 m). The default's fills
    of markers leaving the volume reach beyond that; the writer leaves them as gaps, and the
    report, the summary line and the gap counts must describe the file written, not the
    fills the writer dropped (they said 2.2 % missing and 4 gaps for a file with 2.9 % and
    28)."""
    import json
    from mocapfix.cleaning import clean_file
    from mocapfix.core.gaps import runs, take_frames

    out = tmp_path / "s09.c3d"
    summary = clean_file(shared("c3d/c3dorg_s09_PlugInC3D.c3d"), out,
                         load_config(default_config_path()))
    report = json.loads((tmp_path / "s09.c3d.report.json").read_text())
    written = formats.read(out)
    markers = np.array([k == "marker" for k in written.kinds])
    missing = written.missing
    span = take_frames(missing, markers)
    assert any("beyond the int16 range" in n for n in report["file"]["notes"])
    assert report["file"]["missing_after"] == summary["missing_after"]
    assert abs(report["file"]["missing_after"] - missing[span][:, markers].mean()) < 1e-6
    assert report["file"]["gaps_after"] == len(runs(missing[span][:, markers])[0])
    before = formats.read(shared("c3d/c3dorg_s09_PlugInC3D.c3d")).missing
    filled = (before & ~missing)[:, markers]
    assert report["file"]["samples_filled"] == int(filled.sum())
    listed = sum(g["length"] for j in report["joints"] for g in j["gaps"]["filled"])
    partly = sum(g["filled_frames"] for j in report["joints"] for g in j["gaps"]["unfilled"])
    assert listed + partly == int(filled[span].sum())


def test_a_seen_sample_moved_beyond_an_int16_files_range_is_held_at_its_edge(tmp_path):
    """c3d.org s06 stores int16 coordinates (POINT:SCALE 0.0215: ±705.8 mm) and LTHI_2's x
    reaches the edge at frame 110 (the file saturated there). A smoother that moved it
    0.01 mm beyond (optical-c3d's Butterworth) failed the whole file at the write ("coordinate
    beyond the int16 range"); the sample is now held at the edge and the report says so."""
    from mocapfix.cleaning import clean_file, clean_motion
    from mocapfix.core.presets import resolve_config

    src = shared("c3d/c3dorg_s06_MACsample.c3d")
    edge = 32767 * 0.021541154012084007
    motion = formats.read(src)
    j = motion.names.index("LTHI_2")
    assert motion.positions[110, j, 0] == pytest.approx(edge, abs=1e-9)
    moved = motion.positions.copy()
    moved[110, j, 0] += 0.5                              # a smoother's overshoot
    moved[111, j] = moved[109, j]                        # a fill within the range
    held = formats.storable(motion.replace(positions=moved))
    assert held.positions[110, j, 0] == pytest.approx(edge, abs=1e-9)
    assert np.array_equal(held.positions[111, j], moved[109, j])     # left as it was
    assert any("1 moved samples lie beyond the int16 range" in n for n in held.notes)
    pipeline = load_config(resolve_config("optical-c3d"))
    out = tmp_path / "s06.c3d"
    clean_file(src, out, pipeline)                       # was a WriteError
    written = formats.read(out)
    assert np.nanmax(np.abs(written.positions)) <= edge + 1e-6
    assert written.positions[110, j, 0] == pytest.approx(edge, abs=1e-9)
