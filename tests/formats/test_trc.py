"""TRC reader and writer: the real files of ../shared/formats/trc (BTKData's TRC samples),
hand-written cases, and OpenSim's own TRC reader as the independent check of what we write.

Expected values come from the files themselves, read here with plain string splitting, and
from BTK's reader tests (Testing/Code/TRCFileReaderTest.h: hand-checked numbers), never
from the reader under test.
"""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import (
    FORMATS_DATA,
    REQUIRE_DATA,
    config_file,
    need,
    no_traceback,
    shared,
    shared_files,
)

from mocapfix import formats
from mocapfix.cli import main
from mocapfix.core.errors import UnreadableFileError, WriteError
from mocapfix.core.motion import Motion
from mocapfix.formats import filebytes, textlines, trc

TRC_DIR = FORMATS_DATA / "trc"
READABLE = ("btk_10002-20130626160334-Unnamed.trc", "btk_Anto.trc", "btk_Gait.trc",
            "btk_Knee.trc", "btk_Res16bits.trc", "btk_UpperLimbStatic.trc", "btk_motek_T.trc",
            "btk_motek_ballet_reduced.trc")
#: the files OpenSim 4.6's TRCFileAdapter reads: it refuses rows with values beyond the
#: labelled columns (btk_Gait.trc, btk_UpperLimbStatic.trc, the Unnamed file)
OPENSIM_READS = ("btk_Anto.trc", "btk_Knee.trc", "btk_Res16bits.trc", "btk_motek_T.trc",
                 "btk_motek_ballet_reduced.trc")
C3D_FILES = shared_files("c3d")
#: |printed - true| of a %.5f value, plus float noise
PRINTED = 0.5e-5 * (1 + 1e-9)


def trc_file(name: str):
    return need(TRC_DIR / name)


def _plain(path):
    """The file read with plain string splitting: header dict, labels, data rows' fields."""
    lines = path.read_text(encoding="latin-1").splitlines()
    header = dict(zip(lines[1].split("\t"), lines[2].split("\t")))
    labels = [f.strip() for f in lines[3].split("\t")[2:] if f.strip()]
    rows = [ln.split("\t") for ln in lines[5:] if ln.strip()]
    return header, labels, rows


def _plain_missing(rows, n_markers) -> np.ndarray:
    """(T, J): True where one of a marker's three fields is empty, blank or absent."""
    out = np.zeros((len(rows), n_markers), bool)
    for t, f in enumerate(rows):
        for j in range(n_markers):
            cells = f[2 + 3 * j: 5 + 3 * j]
            out[t, j] = len(cells) < 3 or any(not c.strip() or c.strip().lower() == "nan"
                                              for c in cells)
    return out


# ------------------------------------------------------------------ reading the real files
@pytest.mark.parametrize("name", READABLE)
def test_real_file_reads_as_its_header_and_rows_say(name):
    path = trc_file(name)
    header, labels, rows = _plain(path)
    m = formats.read(path)
    assert m.format == "trc"
    assert m.fps == float(header["DataRate"])
    assert m.names == labels
    assert m.n_joints == len(labels)
    assert m.n_frames == len(rows)
    assert m.units == header["Units"].strip() == "mm" and m.metres_per_unit == 0.001
    assert np.array_equal(m.times, [float(f[1]) for f in rows])
    assert np.array_equal(m.missing, _plain_missing(rows, len(labels)))
    # every present value is the number in its field
    for t in (0, len(rows) // 2, len(rows) - 1):
        for j in range(len(labels)):
            if not m.missing[t, j]:
                assert m.positions[t, j].tolist() == [float(x) for x in rows[t][2 + 3 * j:5 + 3 * j]]


def test_btk_reader_test_values():
    """The hand-checked numbers of BTK's TRCFileReaderTest.h."""
    t_pose = formats.read(trc_file("btk_motek_T.trc"))
    assert (t_pose.fps, t_pose.n_joints, t_pose.n_frames) == (30, 41, 89)
    assert t_pose.names[1] == "LBHD"
    assert t_pose.positions[3, 1, 0] == pytest.approx(-171.03949, abs=1e-6)
    ballet = formats.read(trc_file("btk_motek_ballet_reduced.trc"))
    assert (ballet.fps, ballet.n_joints, ballet.n_frames) == (30, 41, 100)
    assert ballet.positions[82, 40, 2] == pytest.approx(-112.24601, abs=1e-6)
    knee = formats.read(trc_file("btk_Knee.trc"))
    assert (knee.fps, knee.n_joints, knee.n_frames) == (200, 71, 200)
    assert knee.positions[83, 1, 0] == pytest.approx(301.65476, abs=1e-6)
    assert knee.missing[82, 70]                       # BTK: residual -1 (occluded)


def test_names_with_spaces_are_stripped_at_the_ends_only():
    knee = formats.read(trc_file("btk_Knee.trc"))
    assert knee.names[0] == "genou1_ NewMarker"        # inner space kept
    assert knee.names[3] == "genou1_NewMarker3"        # " genou1_NewMarker3 " in the file
    assert knee.names[-1] == "*Unnamed_71"


def test_gait_gaps_unlabelled_columns_and_header_disagreement():
    m = formats.read(trc_file("btk_Gait.trc"))
    assert m.n_joints == 33                            # labels, not NumMarkers 66
    # the subject walks in at frame 160: before it every labelled marker is missing
    assert m.missing[:159].all()
    assert not m.missing[159].any()
    assert (~m.missing.any(axis=1)).sum() == 144       # rows with all 99 labelled values
    assert any("NumMarkers says 66" in n for n in m.notes)
    assert any("beyond the 33 labelled markers" in n for n in m.notes)


def test_gait_trc_agrees_with_the_gait_c3d_of_the_same_trial():
    """BTKData's Gait.c3d is the same Motion Analysis trial: its 33 markers, in the same
    order, are within a few mm of the TRC's where both have a sample (filtered apart)."""
    c3d = formats.read(shared("c3d/btk_Gait.c3d"))
    t = formats.read(trc_file("btk_Gait.trc"))
    assert c3d.positions.shape == t.positions.shape
    both = ~c3d.missing & ~t.missing
    d = np.linalg.norm(c3d.positions - t.positions, axis=2)[both]
    assert both.sum() > 5000 and np.median(d) < 1.0 and d.max() < 15.0


def test_no_markers_file_reads_with_frames_and_a_note():
    m = formats.read(trc_file("btk_10002-20130626160334-Unnamed.trc"))
    assert (m.n_frames, m.n_joints, m.fps) == (882, 0, 400.0)
    assert m.times[1] == pytest.approx(0.002)
    assert any("beyond the 0 labelled markers" in n for n in m.notes)


@pytest.mark.parametrize("name, cause", [("btk_Empty.trc", "file is empty"),
                                         ("btk_Truncated.trc", "file ends after line 2")])
def test_malformed_real_files_give_one_clear_error(name, cause):
    path = trc_file(name)
    with pytest.raises(UnreadableFileError) as info:
        formats.read(path)
    message = str(info.value)
    assert cause in message and str(path) in message and "\n" not in message


# ------------------------------------------------------------------ writing back
@pytest.mark.parametrize("name", READABLE)
def test_unchanged_round_trip_is_byte_identical(name, tmp_path):
    path = trc_file(name)
    out = tmp_path / name
    assert formats.write(formats.read(path), out) == [out]
    assert out.read_bytes() == path.read_bytes()


def _field_diff(a: bytes, b: bytes) -> list[tuple[int, int, str, str]]:
    """(line, field, old, new) of every field that differs, lines matched one to one."""
    la, lb = a.decode().split("\n"), b.decode().split("\n")
    assert len(la) == len(lb)
    out = []
    for i, (x, y) in enumerate(zip(la, lb)):
        if x != y:
            fx, fy = x.rstrip("\r").split("\t"), y.rstrip("\r").split("\t")
            fx += [""] * (len(fy) - len(fx))
            fy += [""] * (len(fx) - len(fy))
            out += [(i, k, u, v) for k, (u, v) in enumerate(zip(fx, fy)) if u != v]
    return out


def _line_of_frame(path, frame: int) -> int:
    lines = path.read_bytes().decode().split("\n")
    return next(i for i, ln in enumerate(lines) if ln.split("\t")[0] == str(frame + 1))


def test_one_moved_sample_changes_only_its_three_fields(tmp_path):
    path = trc_file("btk_Anto.trc")
    m = formats.read(path)
    m.positions[40, 7] += [1.234567, -2.0, 0.5]
    out = tmp_path / "moved.trc"
    formats.write(m, out)
    diff = _field_diff(path.read_bytes(), out.read_bytes())
    line = _line_of_frame(path, 40)
    assert [(i, k) for i, k, _, _ in diff] == [(line, 2 + 21), (line, 2 + 22), (line, 2 + 23)]
    for _, _, old, new in diff:                        # the decimals of the token replaced
        assert len(new.split(".")[1]) == len(old.split(".")[1]) == 5
    assert [float(v) for *_, v in diff] == pytest.approx(m.positions[40, 7].tolist(), abs=PRINTED)


def test_one_deleted_sample_becomes_three_empty_fields(tmp_path):
    path = trc_file("btk_Anto.trc")
    m = formats.read(path)
    m.positions[5, 0] = np.nan
    out = tmp_path / "deleted.trc"
    formats.write(m, out)
    diff = _field_diff(path.read_bytes(), out.read_bytes())
    line = _line_of_frame(path, 5)
    assert [(i, k, v) for i, k, _, v in diff] == [(line, 2, ""), (line, 3, ""), (line, 4, "")]
    assert formats.read(out).missing.sum() == 1


def test_one_filled_sample_in_a_trimmed_row_gets_numbers(tmp_path):
    """btk_Gait.trc's early rows are empty in the labelled columns; fill one sample there."""
    path = trc_file("btk_Gait.trc")
    m = formats.read(path)
    assert m.missing[10, 32]
    m.positions[10, 32] = [1000.5, -20.25, 3.125]
    out = tmp_path / "filled.trc"
    formats.write(m, out)
    diff = _field_diff(path.read_bytes(), out.read_bytes())
    line = _line_of_frame(path, 10)
    assert [(i, k, v) for i, k, _, v in diff] == [
        (line, 98, "1000.50000"), (line, 99, "-20.25000"), (line, 100, "3.12500")]
    back = formats.read(out)
    assert back.missing.sum() == m.missing.sum()
    assert back.positions[10, 32].tolist() == [1000.5, -20.25, 3.125]


def test_trailing_blank_of_a_row_is_kept_when_its_sample_moves(tmp_path):
    path = trc_file("btk_motek_T.trc")                 # rows end in "<Z of marker 41> \r"
    m = formats.read(path)
    m.positions[0, 40, 2] = 1.0
    out = tmp_path / "t.trc"
    formats.write(m, out)
    (_, _, old, new), = _field_diff(path.read_bytes(), out.read_bytes())
    assert old.endswith(" ") and new == "1.00000 "


# ------------------------------------------------------------------ hand-written cases
def _text_file(tmp_path, text, name="x.trc"):
    p = tmp_path / name
    p.write_bytes(text.encode())
    return p


HEAD = ("PathFileType\t4\t(X/Y/Z)\tx.trc\n"
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames\n"
        "{rate}\t{rate}\t{frames}\t2\t{units}\t{rate}\t1\t{frames}\n"
        "Frame#\tTime\tA\t\t\tB\t\t\t\n\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n\n")


def _small(rate="50", frames=3, units="mm", rows=None):
    rows = rows or ["1\t0.00\t1.0\t2.0\t3.0\t4.0\t5.0\t6.0",
                    "2\t0.02\t1.1\tNaN\t3.1\t\t\t",
                    "3\t0.04\tnan\tnan\tnan\t4.2"]
    return HEAD.format(rate=rate, frames=frames, units=units) + "\n".join(rows) + "\n"


def test_nan_tokens_short_rows_and_units(tmp_path):
    m = formats.read(_text_file(tmp_path, _small(units="Millimeters")))
    assert m.units == "mm" and m.fps == 50
    assert m.missing.tolist() == [[False, False], [True, True], [True, True]]
    for units, scale in (("m", 1.0), ("CM", 0.01), ("mm", 0.001)):
        m = formats.read(_text_file(tmp_path, _small(units=units)))
        assert m.metres_per_unit == scale


@pytest.mark.parametrize("large", [False, True])
@pytest.mark.parametrize("variant", ["crlf", "cr", "mixed", "bom", "no-final-newline",
                                     "blank-fields"])
def test_odd_texts_write_back_byte_identical_and_edit_cleanly(variant, large, tmp_path,
                                                              monkeypatch):
    if large:       # read as a file over the threshold: a block of 13 bytes at a time
        monkeypatch.setattr(filebytes, "HELD_MAX", 0)
        monkeypatch.setattr(textlines, "BLOCK", 13)
        monkeypatch.setattr(trc, "CHUNK", 2)
    text = _small()
    text = {"crlf": text.replace("\n", "\r\n"), "cr": text.replace("\n", "\r"),
            "mixed": text.replace("\n", "\r\n", 4), "bom": "\ufeff" + text,
            "no-final-newline": text.replace("\t4.2\n", "\t4.2\tnan\tnan"),
            "blank-fields": text.replace("\t\t\t\n", "\t \t \t \n")}[variant]
    path = _text_file(tmp_path, text)
    m = formats.read(path)
    assert m.missing.tolist() == [[False, False], [True, True], [True, True]]
    out = tmp_path / "out.trc"
    formats.write(m, out)
    assert out.read_bytes() == path.read_bytes()
    m.positions[0, 1] = [7.0, 8.0, 9.0]
    m.positions[2, 0] = [1.0, 2.0, 3.0]
    formats.write(m, out)
    back = formats.read(out)
    assert back.positions[0, 1].tolist() == [7.0, 8.0, 9.0]
    assert back.positions[2, 0].tolist() == [1.0, 2.0, 3.0]
    assert back.missing.tolist() == [[False, False], [True, True], [False, True]]
    kept = out.read_bytes().decode().replace("7.0\t8.0\t9.0", "4.0\t5.0\t6.0")
    assert kept.replace("3\t0.04\t1.0\t2.0\t3.0", "3\t0.04\tnan\tnan\tnan") == path.read_bytes().decode()


@pytest.mark.parametrize("large", [False, True])
def test_a_latin1_file_writes_back_in_latin1(large, tmp_path, monkeypatch):
    # a file that is not UTF-8 is read as latin-1 (a lab's marker named "Épaule"); its
    # unchanged lines are copied as they are, an edited row in latin-1 too, never re-encoded
    if large:
        monkeypatch.setattr(filebytes, "HELD_MAX", 0)
        monkeypatch.setattr(textlines, "BLOCK", 13)
    path = tmp_path / "x.trc"
    path.write_bytes(_small().replace("\tA\t", "\t\u00c9paule\t").encode("latin-1"))
    m = formats.read(path)
    assert m.names == ["\u00c9paule", "B"]
    formats.write(m, tmp_path / "same.trc")
    assert (tmp_path / "same.trc").read_bytes() == path.read_bytes()
    m.positions[2, 0] = [1.0, 2.0, 3.0]
    formats.write(m, tmp_path / "edit.trc")
    edited = (tmp_path / "edit.trc").read_bytes()
    assert edited == path.read_bytes().replace(b"3\t0.04\tnan\tnan\tnan", b"3\t0.04\t1.0\t2.0\t3.0")
    assert formats.read(tmp_path / "edit.trc").names == ["\u00c9paule", "B"]


def test_values_read_shared_with_the_motion_write_the_same_bytes(tmp_path):
    """``formats.share_values_read`` (what ``clean`` does after reading): the source's
    values as read become the motion's positions, read-only, and the motion and its
    cleaned take write the same bytes as without the sharing."""
    import mocapfix

    path = trc_file("btk_Gait.trc")
    shared_motion, own = formats.read(path), formats.read(path)
    formats.share_values_read(shared_motion)
    assert shared_motion.source.original is shared_motion.positions
    with pytest.raises(ValueError):
        shared_motion.positions[0, 0, 0] = 1.0
    assert own.source.original is not own.positions
    for k, (a, b) in enumerate([(shared_motion, own),
                                (mocapfix.clean(shared_motion)[0], mocapfix.clean(own)[0])]):
        written = [formats.write(m, tmp_path / f"{k}{side}" / "g.trc")[0].read_bytes()
                   for m, side in ((a, "shared"), (b, "own"))]
        assert written[0] == written[1]
        assert k == 1 or written[0] == path.read_bytes()


def test_short_last_row_without_line_break_is_a_truncation(tmp_path):
    m = formats.read(_text_file(tmp_path, _small().rstrip("\n")))
    assert m.n_frames == 2
    assert any("line 9) is shorter than the one before" in n for n in m.notes)


def test_header_frames_disagreeing_with_rows_is_a_note(tmp_path):
    m = formats.read(_text_file(tmp_path, _small(frames=10 ** 12)))
    assert m.n_frames == 3
    assert any("NumFrames says 1000000000000" in n for n in m.notes)


@pytest.mark.parametrize("text, cause", [
    (_small(rate="0"), "DataRate 0 is not a frame rate"),
    (_small(rate="-100"), "not a frame rate"),
    (_small(rate="nan"), "not a frame rate"),
    (_small(units="furlongs"), "unknown Units 'furlongs'"),
    (_small(rows=["1\t0.00\t1.2.3\t2\t3\t4\t5\t6"]), "x.trc:7: '1.2.3' is not a number"),
    (HEAD.format(rate=50, frames=0, units="mm"), "no data rows"),
    ("PathFileType\t4\t(X/Y/Z)\tx.trc\nDataRate\tNumMarkers\n50\t2\nFrame#\tTime\tA\t\t\n",
     "file ends after line 4; expected the coordinate labels"),
    (_small(rows=["1\t\t1\t2\t3\t4\t5\t6"]), "empty or non-finite Time"),
])
def test_malformed_cases_name_the_cause(tmp_path, text, cause):
    with pytest.raises(UnreadableFileError) as info:
        formats.read(_text_file(tmp_path, text))
    assert cause in str(info.value)


def test_sniffed_without_the_suffix(tmp_path):
    p = _text_file(tmp_path, _small(), "markers.dat")
    assert formats.detect(p) == "trc"


# ------------------------------------------------------------------ fresh files
def _motion(names=("a", "b"), T=4, kinds=None, **kw):
    pos = np.arange(T * len(names) * 3, dtype=float).reshape(T, len(names), 3) * 1.5
    return Motion(pos, list(names), 100.0, kinds=kinds, **kw)


def test_fresh_file_layout(tmp_path):
    m = _motion()
    m.positions[1, 1] = np.nan
    out = tmp_path / "fresh.trc"
    formats.write(m, out)
    lines = out.read_text().split("\n")
    assert lines[0] == "PathFileType\t4\t(X/Y/Z)\tfresh.trc"
    assert lines[2].split("\t") == ["100.00", "100.00", "4", "2", "mm", "100.00", "1", "4"]
    assert lines[3].split("\t")[:6] == ["Frame#", "Time", "a", "", "", "b"]
    assert lines[6].split("\t")[:3] == ["1", "0.000000", "0.00000"]
    assert lines[7].split("\t")[5:8] == ["", "", ""]   # the missing sample: empty, not carried
    back = formats.read(out)
    assert back.missing.tolist() == m.missing.tolist()


def test_non_markers_are_left_out_and_listed(tmp_path):
    m = _motion(names=("a", "LHipAngles", "b", "LGRF"), kinds=["marker", "angle", "marker", "force"])
    out = tmp_path / "k.trc"
    formats.write(m, out)
    assert formats.read(out).names == ["a", "b"]
    assert any("2 points that are not markers (1 angle, 1 force)" in n for n in trc.losses(m))


def test_names_with_tabs_are_sanitised_and_listed(tmp_path):
    m = _motion(names=("le\tft", "ok"))
    out = tmp_path / "n.trc"
    formats.write(m, out)
    assert formats.read(out).names == ["le ft", "ok"]
    assert any("'le\\tft'" in n for n in trc.losses(m))


def test_no_markers_is_a_write_error(tmp_path):
    m = _motion(names=("ang",), kinds=["angle"])
    with pytest.raises(WriteError):
        formats.write(m, tmp_path / "none.trc")


def test_what_a_c3d_to_trc_conversion_leaves_out_is_named(tmp_path):
    gait = formats.read(shared("c3d/btk_Gait.c3d"))    # SOURCES.md: 28 analog channels
    assert any(n.startswith("28 analog channel") for n in formats.losses(gait, "trc"))
    pig = formats.read(shared("c3d/btk_PiG_Motion-FlatFoot-Hole.c3d"))   # angles, forces ...
    notes = formats.losses(pig, "trc")
    assert sum("not markers" in n or "model outputs" in n for n in notes) == 1   # said once
    r = CliRunner().invoke(main, ["convert", str(shared("c3d/btk_Gait.c3d")), "-o",
                                  str(tmp_path / "o"), "--to", "trc"])
    assert r.exit_code == 0, r.output
    assert "not carried into trc: 28 analog channel" in r.output
    got = formats.read(tmp_path / "o" / "btk_Gait.trc")
    assert got.names == gait.names and np.array_equal(got.missing, gait.missing)


def test_what_a_trc_source_alone_holds_is_named():
    gait = formats.read(trc_file("btk_Gait.trc"))
    assert formats.losses(gait, "c3d") == [
        "10065 value(s) in unlabelled columns of the TRC file are not carried"]


def test_clean_command_writes_a_trc(tmp_path):
    src = trc_file("btk_Res16bits.trc")                # 3 short gaps
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(tmp_path / "out"),
                                  "-c", config_file(tmp_path)])
    no_traceback(r)
    out = tmp_path / "out" / src.name
    cleaned, before = formats.read(out), formats.read(src)
    assert cleaned.names == before.names
    assert cleaned.missing.sum() < before.missing.sum()
    assert not (cleaned.missing & ~before.missing).any()     # nothing removed by a fill
    seen = ~before.missing
    assert np.array_equal(cleaned.positions[seen], before.positions[seen])


@pytest.mark.parametrize("name", READABLE)
def test_every_real_file_cleans_with_the_default_and_every_report(name, tmp_path):
    # the file with no labelled markers (values beyond the header's 0 columns) failed with
    # "internal error ValueError" in the HTML report's viewer (the up axis of no points)
    # and printed numpy's "Mean of empty slice" from the cut detection
    import warnings

    src = trc_file(name)
    out = tmp_path / "out"
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        r = CliRunner().invoke(main, ["clean", str(src), "-o", str(out), "--report", "json,md,html"])
    no_traceback(r)
    assert r.exit_code in (0, 1) and "internal error" not in r.output and "ERROR" not in r.output, r.output
    for suffix in ("", ".report.json", ".report.md", ".report.html"):
        assert (out / (src.name + suffix)).is_file()
    before, after = formats.read(src), formats.read(out / src.name)
    seen = ~before.missing
    assert after.names == before.names and not (after.missing & seen).all(axis=0).any()


def test_losses_of_a_kinect_file_and_nothing_for_a_trc_written_back():
    kinect = formats.read(shared("kinect/kv2_laban_Ges01_wavehand.csv"))
    assert any("tracking state" in n for n in formats.losses(kinect, "trc"))
    unchanged = formats.read(trc_file("btk_Anto.trc"))
    assert trc.losses(unchanged) == [] and formats.losses(unchanged, "trc") == []


@pytest.mark.parametrize("path", C3D_FILES)
def test_c3d_to_trc_to_c3d(path, tmp_path):
    """Every shared C3D: TRC keeps marker names, rate, gaps and values to the printed
    precision; that motion written as C3D again keeps them to float32 precision."""
    src = formats.read(need(path))
    marker = np.arange(src.n_joints) if src.kinds is None else \
        np.array([j for j, k in enumerate(src.kinds) if k == "marker"])
    if src.kinds is not None and len(marker) < src.n_joints:
        assert any("model outputs" in n for n in formats.losses(src, "trc"))
    out = tmp_path / "x.trc"
    formats.write(src, out)
    t = formats.read(out)
    assert t.names == [src.names[j] for j in marker]
    assert t.fps == src.fps
    assert t.units == src.units
    want = src.positions[:, marker]
    assert np.array_equal(t.missing, src.missing[:, marker])
    seen = ~t.missing
    assert np.all(np.abs(t.positions[seen] - want[seen]) <= PRINTED + 1e-12 * np.abs(want[seen]))
    back_path = tmp_path / "back.c3d"
    formats.write(t, back_path)
    back = formats.read(back_path)
    assert back.names == t.names and back.fps == pytest.approx(t.fps, rel=1e-6)
    assert np.array_equal(back.missing, t.missing)
    assert np.allclose(back.positions[seen], t.positions[seen], rtol=2e-7, atol=1e-9)


@pytest.mark.parametrize("path", shared_files("bvh", "cmu_cgspeed_131_01.bvh"))
def test_bvh_joint_positions_to_trc(path, tmp_path):
    src = formats.read(need(path))
    losses = formats.losses(src, "trc")
    assert any("rotations" in n for n in losses)
    assert src.units == "unknown" and any("converted from the unit 'unknown'" in n for n in losses)
    out = tmp_path / "joints.trc"
    formats.write(src, out)
    t = formats.read(out)
    assert t.names == src.names and t.fps == pytest.approx(src.fps, rel=1e-12)
    assert t.units == "mm"
    want = src.positions * (src.metres_per_unit * 1000)
    assert np.all(np.abs(t.positions - want) <= PRINTED + 1e-12 * np.abs(want))


# ------------------------------------------------------------------ OpenSim, independent
def _opensim():
    try:
        import opensim
    except ImportError:
        message = "opensim (the dev extra's independent TRC reader) is not installed"
        if REQUIRE_DATA:
            pytest.fail(message)
        pytest.skip(message)
    return opensim


def _opensim_read(path):
    """(names, rate, units, times, positions (T, J, 3) NaN = missing) by OpenSim."""
    osim = _opensim()
    table = osim.TimeSeriesTableVec3(str(path))
    names = list(table.getColumnLabels())
    flat_table = table.flatten()   # kept in a name: the matrix view dies with its table
    flat = np.array(flat_table.getMatrix().to_numpy())  # x, y, z of each marker in turn
    positions = flat.reshape(flat.shape[0], len(names), 3)
    return (names, float(table.getTableMetaDataAsString("DataRate")),
            table.getTableMetaDataAsString("Units"), np.array(table.getIndependentColumn()),
            positions)


@pytest.mark.parametrize("name", OPENSIM_READS)
def test_opensim_reads_the_real_files_as_we_do(name):
    path = trc_file(name)
    names, rate, units, times, positions = _opensim_read(path)
    m = formats.read(path)
    assert [n.strip() for n in names] == m.names
    assert rate == m.fps and units == m.units
    assert np.allclose(times, m.times)
    assert np.array_equal(np.isnan(positions), np.isnan(m.positions))
    assert np.allclose(positions, m.positions, equal_nan=True, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name", ["btk_Gait.c3d", "btk_PiG_Motion-FlatFoot-Hole.c3d",
                                  "ktk_tennis_serve_nan.c3d", "c3dorg_s13_Dance.c3d"])
def test_opensim_reads_our_fresh_files(name, tmp_path):
    src = formats.read(shared(f"c3d/{name}"))
    out = tmp_path / "fresh.trc"
    formats.write(src, out)
    names, rate, units, times, positions = _opensim_read(out)
    ours = formats.read(out)
    assert names == ours.names and rate == pytest.approx(src.fps, rel=1e-12) and units == src.units
    assert np.allclose(times, np.arange(src.n_frames) / src.fps, atol=1e-6)
    assert np.array_equal(np.isnan(positions).any(axis=2), ours.missing)
    assert np.allclose(positions, ours.positions, equal_nan=True, rtol=0, atol=1e-12)


def test_opensim_reads_our_edited_write_back(tmp_path):
    path = trc_file("btk_Knee.trc")
    m = formats.read(path)
    m.positions[20:40, 5] = np.nan                     # removed
    m.positions[82, 70] = [1.0, 2.0, 3.0]              # filled
    m.positions[100] += 0.123456                       # moved
    out = tmp_path / "edited.trc"
    formats.write(m, out)
    names, rate, _, _, positions = _opensim_read(out)
    assert [n.strip() for n in names] == m.names and rate == 200
    assert np.array_equal(np.isnan(positions).any(axis=2), m.missing)
    assert np.allclose(positions, m.positions, equal_nan=True, rtol=0, atol=PRINTED)
