"""Vicon Nexus CSV, Qualisys QTM TSV and OptiTrack Motive CSV: the fixtures in
tests/data/vendor/ (provenance in SOURCES.md there) read with the right rate, names, units
and missing counts -- checked against values read off the files with the plain ``csv``
module, not our reader -- write back byte-identical, edit only the changed fields, are
detected as their format, and convert to C3D and back."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import SAMPLE_DATA, need, shared_files

from mocapfix import formats
from mocapfix.cli import main
from mocapfix.core.errors import UnreadableFileError
from mocapfix.core.motion import Motion

VENDOR = Path(__file__).resolve().parents[1] / "data" / "vendor"


def _rows(name: str, delimiter: str) -> list[list[str]]:
    with open(VENDOR / name, newline="", encoding="utf-8") as fh:
        return list(csv.reader(fh, delimiter=delimiter))


def _expected_nexus(name):
    """(rate, names, units, (T, J) missing) of the Trajectories section, by plain csv."""
    rows = _rows(name, ",")
    at = next(i for i, r in enumerate(rows) if r and r[0] == "Trajectories")
    names = [n for n in rows[at + 2][2::3] if n]
    data = []
    for r in rows[at + 5:]:
        if not any(r):
            break
        data.append(r)
    missing = np.array([[r[2 + 3 * j] == "" for j in range(len(names))] for r in data])
    return float(rows[at + 1][0]), names, rows[at + 4][2], missing


def _expected_qtm(name):
    rows = _rows(name, "\t")
    keys = {r[0]: r[1:] for r in rows if r and r[0].isupper()}
    names = keys["MARKER_NAMES"]
    data = [r for r in rows if r and not r[0].isupper() and r[0] != "Frame"]
    lead = 2 if rows[len(keys)][0] == "Frame" else 0
    headed = lead == 2
    missing = np.array([[r[lead + 3 * j:lead + 3 * j + 3] == ["0.000"] * 3 and not headed
                         or r[lead + 3 * j] in ("", "NaN") for j in range(len(names))] for r in data])
    return float(keys["FREQUENCY"][0]), names, "mm", missing


def _expected_motive(name):
    rows = _rows(name, ",")
    settings = dict(zip(rows[0][::2], rows[0][1::2]))
    head = {r[1]: r for r in rows[2:6]}
    cols = [c for c in range(2, len(head["Type"])) if head["Type"][c] == "Marker" and rows[6][c] == "X"]
    data = rows[7:]
    missing = np.array([[r[c] == "" for c in cols] for r in data])
    units = {"Millimeters": "mm", "Meters": "m", "Centimeters": "cm"}[settings["Length Units"]]
    return float(settings["Export Frame Rate"]), [head["Name"][c] for c in cols], units, missing


FIXTURES = [
    ("nexus_pyomeca_markers.csv", "nexus_csv", _expected_nexus),
    ("nexus_sections_doc.csv", "nexus_csv", _expected_nexus),
    ("qtm_hand_embodiment_recording.tsv", "qtm_tsv", _expected_qtm),
    ("qtm_old_doc.tsv", "qtm_tsv", _expected_qtm),
    ("motive_doc.csv", "motive_csv", _expected_motive),
]
IDS = [f[0] for f in FIXTURES]


@pytest.mark.parametrize("name,fmt,expected", FIXTURES, ids=IDS)
def test_reads_rate_names_units_missing(name, fmt, expected):
    rate, names, units, missing = expected(name)
    motion = formats.read(VENDOR / name)
    assert formats.detect(VENDOR / name) == fmt and motion.format == fmt
    assert motion.fps == rate and motion.names == names and motion.units == units
    assert motion.missing.shape == missing.shape
    assert np.array_equal(motion.missing, missing)
    assert motion.times[0] == 0 and np.all(np.diff(motion.times) > 0)


def test_known_values_and_missing_counts():
    nexus = formats.read(VENDOR / "nexus_pyomeca_markers.csv")
    assert nexus.positions.shape == (5, 51, 3) and nexus.missing.sum() == 0
    assert nexus.positions[0, 0].tolist() == [44.1628, -276.862, 675.697]
    sections = formats.read(VENDOR / "nexus_sections_doc.csv")
    assert sections.names[-1] == "*12" and sections.missing.sum() == 2
    assert any("Devices, Model Outputs" in n for n in sections.notes)
    qtm = formats.read(VENDOR / "qtm_hand_embodiment_recording.tsv")
    assert qtm.positions[9, 20].tolist() == [371.962, 289.892, 223.306]
    assert any("NO_OF_FRAMES says 6000" in n for n in qtm.notes)
    old = formats.read(VENDOR / "qtm_old_doc.tsv")
    assert old.missing.sum() == 3 and old.fps == 240
    motive = formats.read(VENDOR / "motive_doc.csv")
    assert motive.missing.sum() == 3 and motive.names[2] == "Unlabeled 1000"
    assert motive.times[1] == pytest.approx(0.008333)


@pytest.mark.parametrize("name,fmt,expected", FIXTURES, ids=IDS)
def test_read_write_is_byte_identical(name, fmt, expected, tmp_path):
    out = tmp_path / ("out" + Path(name).suffix)
    assert formats.write(formats.read(VENDOR / name), out) == [out]
    assert out.read_bytes() == (VENDOR / name).read_bytes()


@pytest.mark.parametrize("name,fmt,expected", FIXTURES, ids=IDS)
def test_a_large_file_is_read_a_block_at_a_time(name, fmt, expected, tmp_path, monkeypatch):
    # over HELD_MAX (0 here) the file is never read whole: scanned, checked and parsed from
    # the file 97 bytes and 7 rows at a time, and written back from it; the same motion,
    # and the same bytes written unchanged and with a sample moved, as read whole
    from mocapfix.formats import filebytes, textlines, texttable

    held = formats.read(VENDOR / name)
    moved = held.copy()
    t, j = np.argwhere(~held.missing)[len(held.positions) // 2]
    moved.positions[t, j] += 1.5
    monkeypatch.setattr(textlines, "read_input_bytes",       # TextLines.read's whole read
                        lambda path: pytest.fail(f"{path} read whole"))
    monkeypatch.setattr(filebytes, "HELD_MAX", 0)
    monkeypatch.setattr(textlines, "BLOCK", 97)
    monkeypatch.setattr(texttable, "CHUNK", 7)
    again = formats.read(VENDOR / name)
    assert isinstance(again.source.text.raw, filebytes.FileBytes)
    np.testing.assert_array_equal(again.positions, held.positions)
    assert (again.names, again.notes, again.fps) == (held.names, held.notes, held.fps)
    suffix = Path(name).suffix
    for k, (a, b) in enumerate(((held, again), (moved, moved.replace(source=again.source)))):
        out_a, out_b = tmp_path / f"a{k}{suffix}", tmp_path / f"b{k}{suffix}"
        formats.write(a, out_a)
        formats.write(b, out_b)
        assert out_a.read_bytes() == out_b.read_bytes()


def _field_diff(a: Path, b: Path, sep: str) -> list[tuple[int, int, str, str]]:
    la, lb = a.read_text().splitlines(), b.read_text().splitlines()
    assert len(la) == len(lb)
    out = []
    for i, (x, y) in enumerate(zip(la, lb)):
        fx, fy = x.split(sep), y.split(sep)
        assert len(fx) == len(fy)
        out += [(i, k, p, q) for k, (p, q) in enumerate(zip(fx, fy)) if p != q]
    return out


@pytest.mark.parametrize("name,fmt,expected", FIXTURES, ids=IDS)
def test_one_changed_deleted_filled_sample_changes_only_its_fields(name, fmt, expected, tmp_path):
    src = VENDOR / name
    sep = "\t" if name.endswith(".tsv") else ","
    motion = formats.read(src)
    present = np.argwhere(~motion.missing)
    (t1, j1), (t2, j2) = present[0], present[-1]
    edited = motion.copy()
    edited.positions[t1, j1] = motion.positions[t1, j1] + [1.25, -2.5, 0.125]
    edited.positions[t2, j2] = np.nan
    gaps = np.argwhere(motion.missing)
    if len(gaps):
        edited.positions[tuple(gaps[0])] = [7.5, 8.25, 9.125]
    out = tmp_path / ("e" + src.suffix)
    formats.write(edited, out)
    diff = _field_diff(src, out, sep)
    assert len(diff) == 9 if len(gaps) else len(diff) == 6
    again = formats.read(out)
    np.testing.assert_allclose(again.positions, edited.positions, atol=1e-9, equal_nan=True)
    moved = [d for d in diff if d[3] and d[2] and d[3] != "0.000"]
    for _, _, old, new in moved:      # same decimals as the token replaced
        assert len(new.split(".")[1]) == len(old.split(".")[1]) if "." in old else True


def test_motion_from_elsewhere_writes_fresh_layouts(tmp_path):
    rng = np.random.default_rng(1)
    pos = rng.normal(500, 100, (20, 3, 3))
    pos[4:7, 1] = np.nan
    motion = Motion(pos, ["S:A", "S:B", "S:C"], 120.0, units="mm", metres_per_unit=0.001)
    for fmt, suffix in (("nexus_csv", ".csv"), ("qtm_tsv", ".tsv"), ("motive_csv", ".csv")):
        out = tmp_path / f"{fmt}{suffix}"
        formats.write(motion, out, format=fmt)
        back = formats.read(out)
        assert back.format == fmt and back.names == motion.names and back.fps == 120
        np.testing.assert_allclose(back.positions, pos, atol=1e-3, equal_nan=True)


def test_shared_suffix_write_defaults(tmp_path):
    motive = formats.read(VENDOR / "motive_doc.csv")
    assert formats.write_format(motive, tmp_path / "x.csv") == "motive_csv"
    assert formats.write_format(motive, tmp_path / "x.tsv") == "kinect"
    assert formats.write_format(motive, tmp_path / "x.c3d") == "c3d"
    built = Motion(np.zeros((2, 1, 3)), ["a"], 30.0)
    assert formats.write_format(built, tmp_path / "x.csv") == "kinect"


@pytest.mark.parametrize("name,fmt,expected", FIXTURES, ids=IDS)
def test_cross_format_through_c3d(name, fmt, expected, tmp_path):
    motion = formats.read(VENDOR / name)
    out = tmp_path / "x.c3d"
    formats.write(motion, out)
    back = formats.read(out)
    assert back.names == motion.names and back.fps == pytest.approx(motion.fps)
    scale = motion.metres_per_unit / back.metres_per_unit
    np.testing.assert_allclose(back.positions, motion.positions * scale, rtol=1e-6, atol=1e-4,
                               equal_nan=True)


def test_losses_name_what_a_conversion_drops():
    motive = formats.read(VENDOR / "motive_doc.csv")
    assert formats.losses(motive, "motive_csv") == []            # written back: nothing lost
    assert any("Rigid Body" in n for n in formats.losses(motive, "trc"))
    nexus = formats.read(VENDOR / "nexus_sections_doc.csv")
    assert formats.losses(nexus, "c3d") == [
        "the Devices, Model Outputs sections are not carried (only a nexus_csv holds them)"]
    timed = Motion(np.zeros((3, 2, 3)), ["a", "b"], 30.0, times=np.array([0.0, 0.03, 0.1]))
    for fmt in ("nexus_csv", "qtm_tsv", "motive_csv"):
        assert any("evenly spaced" in n for n in formats.losses(timed, fmt))
    kinect = formats.read(SAMPLE_DATA / "walk_kinect_v2.csv")
    for fmt in ("nexus_csv", "qtm_tsv", "motive_csv"):
        notes = formats.losses(kinect, fmt)
        assert any("tracking state" in n for n in notes) and any("skeleton" in n for n in notes)


@pytest.mark.parametrize("path", shared_files("kinect"))
def test_kinect_files_still_detect_as_kinect(path):
    assert formats.detect(need(path)) == "kinect"


@pytest.mark.parametrize("name,text", [
    ("notes.txt", "Session notes\nsubject walked twice\n"),
    ("numbers.csv", "12,7,3\n4,5,6\n"),
    ("numbers.tsv", "a\tb\n1\t2\n"),
])
def test_unknown_text_layout_is_named(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(UnreadableFileError) as info:
        formats.read(path)
    first = text.splitlines()[0]
    assert info.value.reason == f"not a known layout (first line: {first!r})"


@pytest.mark.parametrize("name,edit,expect", [
    ("nexus_sections_doc.csv", lambda s: s.replace("Trajectories\r\n100", "Trajectories\r\nnan"),
     "not a usable frame rate"),
    ("nexus_sections_doc.csv", lambda s: s.replace("3,0,121.5,512.125", "3,0,121.5,5x2.125"),
     "'5x2.125' is not a number"),
    ("nexus_sections_doc.csv", lambda s: s.replace("3,0,121.5,512.125,", "3,0,"), "fields where 14"),
    ("qtm_old_doc.tsv", lambda s: s.replace("NO_OF_MARKERS\t3", "NO_OF_MARKERS\t99999999999"),
     "NO_OF_MARKERS says 99999999999"),
    ("qtm_old_doc.tsv", lambda s: s.replace("FREQUENCY\t240", "FREQUENCY\t0"), "not a usable"),
    ("qtm_old_doc.tsv", lambda s: s[:-40], "looks truncated"),
    ("motive_doc.csv", lambda s: s.replace("Export Frame Rate,120.000000", "Export Frame Rate,-1"),
     "not a usable frame rate"),
    ("motive_doc.csv", lambda s: s.replace("301.500000", "9" * 5_000_000 + "x"),
     "a field longer than 1,000 characters"),
    ("motive_doc.csv", lambda s: s.replace("301.500000", "30x.5"), "'30x.5' is not a number"),
    ("qtm_hand_embodiment_recording.tsv", lambda s: s.replace("hand_top X", "hand_top Q"),
     "expected 'hand_top X'"),
])
def test_malformed_vendor_files_name_the_line(tmp_path, name, edit, expect):
    path = tmp_path / name
    path.write_bytes(edit((VENDOR / name).read_bytes().decode()).encode())
    with pytest.raises(UnreadableFileError) as info:
        formats.read(path)
    message = str(info.value)
    assert expect in message and "\n" not in message and len(message) < 400
    assert info.value.line is not None or "rate" in message


def test_qtm_headed_missing_is_empty_or_nan_and_zeros_are_kept(tmp_path):
    """The documented decision: in the headed layout empty/NaN fields are missing and an
    exact 0,0,0 triple is a position (noted) unless zero_missing=True."""
    lines = (VENDOR / "qtm_hand_embodiment_recording.tsv").read_text().split("\n")
    row = lines[13].split("\t")            # frame 2
    row[2:5] = ["", "", ""]                # hand_top empty
    row[5:8] = ["NaN", "NaN", "NaN"]       # hand_left NaN
    row[8:11] = ["0.000", "0.000", "0.000"]  # hand_right exact zeros
    lines[13] = "\t".join(row)
    path = tmp_path / "gaps.tsv"
    path.write_text("\n".join(lines))
    motion = formats.read(path)
    assert motion.missing[1, :3].tolist() == [True, True, False]
    assert motion.positions[1, 2].tolist() == [0.0, 0.0, 0.0]
    assert any("exactly (0, 0, 0): kept as positions" in n for n in motion.notes)
    assert formats.read(path, zero_missing=True).missing[1, 2]
    out = tmp_path / "out.tsv"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()
    motion.positions[1, 0] = [1.0, 2.0, 3.0]
    motion.positions[2, 0] = np.nan
    formats.write(motion, out)
    assert out.read_text().split("\n")[13].split("\t")[2:5] == ["1.000", "2.000", "3.000"]
    assert out.read_text().split("\n")[14].split("\t")[2:5] == ["NaN", "NaN", "NaN"]


@pytest.mark.parametrize("fmt,suffix", [("nexus_csv", ".csv"), ("qtm_tsv", ".tsv"),
                                        ("motive_csv", ".csv")])
def test_a_fresh_file_holds_the_same_positions_in_metres_whatever_the_unit(tmp_path, fmt, suffix):
    """An AMC's unit (1/0.45 inch) has no name in these layouts: the writer converts, and
    the positions read back are the same in metres (a Nexus CSV once wrote the numbers
    unconverted under 'mm')."""
    amc = formats.read(SAMPLE_DATA / "walker_01.amc")
    path = tmp_path / f"x{suffix}"
    formats.write(amc, path, format=fmt)
    back = formats.read(path)
    metres = back.positions * back.metres_per_unit - amc.positions * amc.metres_per_unit
    assert np.nanmax(np.abs(metres)) < 1e-6
    assert any("are converted" in n for n in formats.losses(amc, fmt))


@pytest.mark.parametrize("extra_head,extra_cell", [
    (["Extra 1"], lambda t: [f"{t * 0.5:.3f}"]),                         # 1 numeric column
    (["Extra 1", "Extra 2"], lambda t: [f"{t:.3f}", "0.000"]),           # 2 (not 3J wide)
    (["P X", "P Y", "P Z"], lambda t: ["1.000", "2.000", f"{t:.3f}"]),   # 3: a marker's width
    (["Type"], lambda t: ["Measured" if t % 2 else "Gap-filled"]),       # words
], ids=["one", "two", "three", "words"])
def test_qtm_columns_after_the_markers_are_kept_not_read(tmp_path, extra_head, extra_cell):
    """A headed QTM TSV whose column header names columns after the markers' X, Y, Z
    (rows holding them): the markers are read as without them, the extra columns noted,
    kept and written back unchanged. They used to reach the marker array: a reshape
    ValueError ("cannot reshape array of size 21"), or, three of them, a 22nd marker
    without a name ("21 names for 22 joints")."""
    source = VENDOR / "qtm_hand_embodiment_recording.tsv"
    lines = source.read_bytes().decode().split("\n")
    at = next(i for i, line in enumerate(lines) if line.startswith("Frame\t"))
    assert lines[at].endswith("Z\t")                     # the real export's trailing tab
    lines[at] += "\t".join(extra_head)
    for t in range(at + 1, len(lines)):
        if lines[t]:
            lines[t] += "\t" + "\t".join(extra_cell(t))
    path = tmp_path / "extra.tsv"
    path.write_bytes("\n".join(lines).encode())
    plain = formats.read(source)
    motion = formats.read(path)
    assert motion.names == plain.names and len(motion.names) == 21
    np.testing.assert_array_equal(motion.positions, plain.positions)
    np.testing.assert_array_equal(motion.times, plain.times)
    n = len(extra_head)
    assert any(f"{n} column{'s' if n > 1 else ''} after the markers ({extra_head[0]!r}" in note
               for note in motion.notes)
    out = tmp_path / "out.tsv"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()
    motion.positions[0, 20] = [1.0, 2.0, 3.0]
    formats.write(motion, out)
    row = out.read_bytes().decode().split("\n")[at + 1].split("\t")
    assert row[2 + 3 * 20:2 + 3 * 21] == ["1.000", "2.000", "3.000"]
    assert row[2 + 3 * 21:] == extra_cell(at + 1)


def test_qtm_header_columns_after_the_markers_that_no_row_holds(tmp_path):
    """The column header names a column after the markers that the rows do not hold: the
    rows are read with the frame, time and marker fields they have."""
    source = VENDOR / "qtm_hand_embodiment_recording.tsv"
    text = source.read_bytes().decode()
    path = tmp_path / "named.tsv"
    path.write_bytes(text.replace("pillow_right Z\t", "pillow_right Z\tExtra\t", 1).encode())
    motion = formats.read(path)
    np.testing.assert_array_equal(motion.positions, formats.read(source).positions)


def test_qtm_rows_holding_columns_after_the_markers_on_some_rows_only(tmp_path):
    """Rows of two widths (the header naming the extra column): refused naming the first
    row without it, not a traceback."""
    source = VENDOR / "qtm_hand_embodiment_recording.tsv"
    lines = source.read_bytes().decode().split("\n")
    at = next(i for i, line in enumerate(lines) if line.startswith("Frame\t"))
    lines[at] += "Extra"
    lines[at + 1] += "\t7.0"                     # frame 1 holds it, frame 2 does not
    path = tmp_path / "ragged.tsv"
    path.write_bytes("\n".join(lines).encode())
    with pytest.raises(UnreadableFileError) as info:
        formats.read(path)
    assert info.value.line == at + 3
    assert "65 fields where 66 were expected" in str(info.value)


def test_qtm_external_timebase_frequency_ext_takes_the_rate_from_frame_and_time(tmp_path):
    """QTM writes ``FREQUENCY<TAB>EXT`` for an external timebase in edge triggered mode (QTM
    manual, "Motion data (.tsv)"). Such a file was refused ("FREQUENCY 'EXT' is not a
    number") even when the caller gave fps; now the rate is the frames per second between
    its first and last rows' Frame and Time, noted, and the file writes back unchanged."""
    source = VENDOR / "qtm_hand_embodiment_recording.tsv"
    text = source.read_bytes().decode()
    assert "\nFREQUENCY\t100\n" in text
    path = tmp_path / "ext.tsv"
    path.write_bytes(text.replace("\nFREQUENCY\t100\n", "\nFREQUENCY\tEXT\n").encode())
    plain = formats.read(source)
    motion = formats.read(path)
    rows = [r for r in _rows("qtm_hand_embodiment_recording.tsv", "\t") if r and r[0].isdigit()]
    frames, times = float(rows[-1][0]) - float(rows[0][0]), float(rows[-1][1]) - float(rows[0][1])
    assert motion.fps == pytest.approx(frames / times) and motion.fps == pytest.approx(100.0)
    assert any("FREQUENCY is EXT" in n and "Frame and Time" in n for n in motion.notes)
    np.testing.assert_array_equal(motion.positions, plain.positions)
    np.testing.assert_array_equal(motion.times, plain.times)
    assert formats.read(path, fps=50).fps == 50.0
    out = tmp_path / "out.tsv"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()


def test_qtm_frequency_ext_without_frame_and_time_is_named(tmp_path):
    """The older layout (no Frame/Time columns) with FREQUENCY EXT holds no rate: one
    message naming the FREQUENCY line, or the rate the caller gives."""
    text = (VENDOR / "qtm_old_doc.tsv").read_bytes().decode()
    path = tmp_path / "ext_old.tsv"
    path.write_bytes(text.replace("FREQUENCY\t240", "FREQUENCY\tEXT").encode())
    with pytest.raises(UnreadableFileError) as info:
        formats.read(path)
    assert info.value.line == 4
    assert "FREQUENCY is EXT (external timebase) and the file has no Frame and Time columns" \
        in str(info.value)
    assert formats.read(path, fps=240).fps == 240.0
    assert "(give it with --fps)" in str(info.value)
    # the command line's --fps is the rate of a file that stores none: this one
    given = formats.read(path, default_fps=240)
    assert given.fps == 240.0 and any("240 Hz (--fps) used" in n for n in given.notes)
    assert not any("not used" in n for n in given.notes)
    r = CliRunner().invoke(main, ["info", str(path), "--fps", "240"])
    assert r.exit_code == 0 and "240 fps" in r.output, r.output
    # ... and leaves a stored rate alone, saying so
    kept = formats.read(VENDOR / "qtm_old_doc.tsv", default_fps=100)
    assert kept.fps == 240.0 and any("--fps 100 not used" in n for n in kept.notes)
