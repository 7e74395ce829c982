"""Kinect skeleton text layouts: real files from ../shared/data/kinect and hand-written cases.

Expected counts on the real files are the ones SOURCES.md states (frames, timestamp gaps,
index jumps, confidence shares), not values taken from the reader.
"""
from __future__ import annotations

import re

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import hang_guard, need, no_traceback, shared, shared_files
from mocapfix.cli import main
from mocapfix import formats
from mocapfix.core.errors import UnreadableFileError
from mocapfix.formats import kinect
from mocapfix.core import kinect_joints as kl
from mocapfix.core.motion import Motion

KINECT_FILES = shared_files("kinect")

# file -> (layout, frames, joints) from SOURCES.md
EXPECTED = {
    "kv2_laban_Ges01_wavehand.csv": ("kinect_v2_csv", 154, 25),
    "kv2_laban_Ges02_balancinghands.csv": ("kinect_v2_csv", 161, 25),
    "kv2_laban_Ges03_drawlines.csv": ("kinect_v2_csv", 213, 25),
    "kv2_laban_Ges04_comehere.csv": ("kinect_v2_csv", 172, 25),
    "kv2_laban_KinectReader_joints.csv": ("kinect_v2_csv", 371, 25),
    "kv1_utkinect_joints_s01_e01.txt": ("utkinect", 560, 20),
    "kv1_utkinect_joints_s02_e01.txt": ("utkinect", 597, 20),
    "kv1_utkinect_joints_s05_e02.txt": ("utkinect", 534, 20),
    "kv1_msr3d_a01_s01_e01_skeleton3D.txt": ("msr_action3d", 54, 20),
    "kv1_msr3d_a06_s03_e02_skeleton3D.txt": ("msr_action3d", 37, 20),
    "kv1_msr3d_a10_s06_e02_skeleton3D.txt": ("msr_action3d", 49, 20),
    "kv1_msr3d_a16_s08_e02_skeleton3D.txt": ("msr_action3d", 57, 20),
}
# Kinect v2 CSV: (timestamp gaps, longest interval ms, inferred share) from SOURCES.md
V2_TIMING = {
    "kv2_laban_Ges01_wavehand.csv": (2, 67.0, 0.003),
    "kv2_laban_Ges02_balancinghands.csv": (2, 67.1, 0.001),
    "kv2_laban_Ges03_drawlines.csv": (5, 67.1, 0.003),
    "kv2_laban_Ges04_comehere.csv": (5, 67.1, 0.002),
    "kv2_laban_KinectReader_joints.csv": (2, 65.9, 0.318),
}
# UTKinect: (first index, last index, jumps > 1, largest jump, repeated indices)
UT_INDEX = {
    "kv1_utkinect_joints_s01_e01.txt": (190, 2290, 544, 10, 15),
    "kv1_utkinect_joints_s02_e01.txt": (174, 3490, 586, 12, 10),
    "kv1_utkinect_joints_s05_e02.txt": (114, 3038, 525, 16, 8),
}
# MSR Action3D: share of rows with c = 0
MSR_ZERO_C = {
    "kv1_msr3d_a01_s01_e01_skeleton3D.txt": 0.25,
    "kv1_msr3d_a06_s03_e02_skeleton3D.txt": 0.32,
    "kv1_msr3d_a10_s06_e02_skeleton3D.txt": 0.20,
    "kv1_msr3d_a16_s08_e02_skeleton3D.txt": 0.24,
}

V2_ROW_NAMES = kl.KINECT_V2


def _write(tmp_path, name, text, mode="w"):
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, newline="")
    return path


def _v2_row(ticks, joints):
    """A Kinect v2 CSV line: joints = list of 25 (x, y, z, state)."""
    cells = [str(ticks)]
    for x, y, z, s in joints:
        cells += [repr(x), repr(y), repr(z), str(s)]
    return ",".join(cells) + ",\n"


def _v2_file(tmp_path, n_frames=4, special=None, name="hand.csv"):
    """Small Kinect v2 CSV with known values: joint j of frame t at (j/10, t/100, 2.0)."""
    special = special or {}
    lines = []
    for t in range(n_frames):
        joints = [(j / 10, t / 100, 2.0, 2) for j in range(25)]
        for (ft, fj), value in special.items():
            if ft == t:
                joints[fj] = value
        lines.append(_v2_row(1_000_000_000 + 333_333 * t, joints))
    return _write(tmp_path, name, "".join(lines))


def _bone_length(motion, parent, child):
    a, b = motion.index(parent), motion.index(child)
    return float(np.nanmedian(np.linalg.norm(motion.positions[:, a] - motion.positions[:, b],
                                             axis=1)))


# ---------------------------------------------------------------------------------------
# real files
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("path", KINECT_FILES)
def test_real_file_layout_frames_joints(path):
    path = need(path)
    layout, frames, joints = EXPECTED[path.name]
    assert formats.detect(path) == "kinect"
    motion = formats.read(path)
    assert motion.source.layout == layout
    assert motion.positions.shape == (frames, joints, 3)
    assert motion.units == "m" and motion.metres_per_unit == 1.0
    assert motion.skeleton is not None
    assert len(motion.skeleton.parents) == joints
    assert np.sum(motion.skeleton.parents < 0) == 1


@pytest.mark.parametrize("path", KINECT_FILES)
def test_real_file_bone_lengths_are_human(path):
    """Wrong joint order or topology gives absurd lengths; these ranges are anatomy."""
    motion = formats.read(need(path))
    v1_names = motion.source.layout != "kinect_v2_csv"
    hip = "HipCenter" if v1_names else "SpineBase"
    for side in ("Left", "Right"):
        upper_arm = _bone_length(motion, f"Shoulder{side}", f"Elbow{side}")
        forearm = _bone_length(motion, f"Elbow{side}", f"Wrist{side}")
        thigh = _bone_length(motion, f"Hip{side}", f"Knee{side}")
        shin = _bone_length(motion, f"Knee{side}", f"Ankle{side}")
        assert 0.2 <= upper_arm <= 0.4, upper_arm
        assert 0.15 <= forearm <= 0.35, forearm
        # MSR Action3D puts its hip points at hip-centre height (the shared files show
        # HipLeft/HipRight level with HipCenter), so its "thighs" run from the waist;
        # Kinect v2 hip joints sit a little low, giving thighs just under 0.3 m
        assert 0.27 <= thigh <= (0.65 if motion.source.layout == "msr_action3d" else 0.55), thigh
        assert 0.25 <= shin <= 0.5, shin
        assert _bone_length(motion, hip, f"Hip{side}") < 0.25
    for a, b in (("Shoulder", "Elbow"), ("Elbow", "Wrist"), ("Hip", "Knee"), ("Knee", "Ankle")):
        left = _bone_length(motion, a + "Left", b + "Left")
        right = _bone_length(motion, a + "Right", b + "Right")
        assert abs(left - right) < 0.04, (a, b, left, right)
    # the head is above the hips (camera y up) in the median frame
    head_y = np.nanmedian(motion.positions[:, motion.index("Head"), 1])
    assert head_y > np.nanmedian(motion.positions[:, motion.index(hip), 1]) + 0.4
    # every bone of the topology has a plausible median length
    bones = motion.skeleton.bone_array
    lengths = np.nanmedian(np.linalg.norm(motion.positions[:, bones[:, 0]]
                                          - motion.positions[:, bones[:, 1]], axis=2), axis=0)
    assert np.all(lengths > 0.02) and np.all(lengths < 0.65), lengths


@pytest.mark.parametrize("name", sorted(V2_TIMING))
def test_kinect_v2_timing_and_dropped_frames(name):
    motion = formats.read(shared(f"kinect/{name}"))
    gaps, longest_ms, inferred = V2_TIMING[name]
    assert motion.fps == pytest.approx(30.3, abs=0.1)
    assert motion.times[0] == 0.0
    assert np.all(np.diff(motion.times) > 0)
    note = next(n for n in motion.notes if "dropped-frame gaps" in n)
    count, ms = re.search(r"(\d+) dropped-frame gaps, longest (\d+) ms", note).groups()
    assert int(count) == gaps
    assert abs(int(ms) - longest_ms) <= 1
    assert np.max(np.diff(motion.times)) * 1000 == pytest.approx(longest_ms, abs=0.1)
    # tracking states: the shared files have no NotTracked joints
    assert np.mean(motion.confidence == 0.5) == pytest.approx(inferred, abs=0.0015)
    assert set(np.unique(motion.confidence)) <= {0.5, 1.0}
    assert not motion.missing.any()


@pytest.mark.parametrize("name", sorted(UT_INDEX))
def test_utkinect_frame_indices(name):
    path = shared(f"kinect/{name}")
    motion = formats.read(path)
    first, last, jumps, largest, repeated = UT_INDEX[name]
    assert motion.times[0] == 0.0
    assert motion.times[-1] == pytest.approx((last - first) / 30.0)
    dt = np.diff(motion.times)
    assert np.sum(dt == 0) == repeated
    assert any(f"{repeated} repeated frames" in n for n in motion.notes)
    assert any(f"{jumps} jumps > 1 (largest {largest})" in n for n in motion.notes)
    # fps is the median row rate (rows are every few 30 Hz indices), not 30
    assert motion.fps == pytest.approx(1.0 / np.median(dt[dt > 0]))
    assert motion.fps < 30
    assert motion.confidence is None
    # first value of the file: HipCenter x of row 1 (whitespace layout, index first)
    first_line = path.read_text().split("\n")[0].split()
    assert int(first_line[0]) == first
    assert motion.positions[0, 0, 0] == float(first_line[1])
    head = motion.positions[0, motion.index("Head")]
    assert head.tolist() == [float(v) for v in first_line[10:13]]


@pytest.mark.parametrize("name", sorted(MSR_ZERO_C))
def test_msr_confidence_is_the_fourth_column(name):
    path = shared(f"kinect/{name}")
    motion = formats.read(path)
    table = np.loadtxt(path)
    assert motion.fps == 15.0
    np.testing.assert_array_equal(motion.confidence.ravel(), table[:, 3])
    np.testing.assert_array_equal(motion.positions.reshape(-1, 3), table[:, :3])
    assert np.mean(table[:, 3] == 0) == pytest.approx(MSR_ZERO_C[name], abs=0.006)
    assert not motion.missing.any()  # c = 0 is low confidence, not missing
    # MSR row order: row 20 is the head, row 7 the hip centre
    assert motion.names[19] == "Head" and motion.names[6] == "HipCenter"


@pytest.mark.parametrize("path", KINECT_FILES)
def test_real_file_unchanged_round_trip_is_byte_identical(path, tmp_path):
    path = need(path)
    motion = formats.read(path)
    out = tmp_path / path.name
    assert formats.write(motion.copy(), out) == [out]
    assert out.read_bytes() == path.read_bytes()


@pytest.mark.slow
@pytest.mark.parametrize("path", KINECT_FILES)
def test_real_file_changed_values_round_trip(path, tmp_path):
    path = need(path)
    motion = formats.read(path)
    changed = motion.copy()
    rng = np.random.default_rng(3)
    changed.positions[1::3, 2:5] += rng.normal(0, 0.01, changed.positions[1::3, 2:5].shape)
    out = tmp_path / path.name
    formats.write(changed, out)
    again = formats.read(out)
    assert again.source.layout == motion.source.layout
    np.testing.assert_allclose(again.positions, changed.positions, atol=1e-6)
    if motion.confidence is not None:
        np.testing.assert_array_equal(again.confidence, motion.confidence)
    # rows with no change are the original lines
    old_lines = path.read_text().splitlines()
    new_lines = out.read_text().splitlines()
    assert len(old_lines) == len(new_lines)
    touched = {int(i) for i in np.unique(motion.source.line_of[1::3, 2:5])}
    for i, (a, b) in enumerate(zip(old_lines, new_lines)):
        if i not in touched:
            assert a == b


def test_largest_files_read_without_hanging():
    """A hang guard only; the read time is measured by benchmarks/formats_io.py."""
    for name in ("kv1_utkinect_joints_s02_e01.txt", "kv2_laban_KinectReader_joints.csv"):
        path = shared(f"kinect/{name}")
        with hang_guard(60):
            motion = formats.read(path)
        assert motion.n_frames == EXPECTED[name][1]


def test_crlf_file_round_trips(tmp_path):
    text = shared("kinect/kv2_laban_Ges01_wavehand.csv").read_text()
    path = _write(tmp_path, "crlf.csv", text.replace("\n", "\r\n"))
    motion = formats.read(path)
    assert motion.n_frames == 154
    out = tmp_path / "out.csv"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()
    motion.positions[5, 3] += 0.5
    formats.write(motion, out)
    data = out.read_bytes()
    assert data.count(b"\r\n") == 154 and data.count(b"\n") == 154


# ---------------------------------------------------------------------------------------
# Kinect v2 CSV: tracking states, fill / remove write-back (hand-made)
# ---------------------------------------------------------------------------------------
def test_v2_tracking_states_to_confidence_and_missing(tmp_path):
    path = _v2_file(tmp_path, special={(1, 7): (0.5, 0.25, 1.5, 0), (2, 7): (0.5, 0.25, 1.5, 1)})
    motion = formats.read(path)
    assert motion.positions.shape == (4, 25, 3)
    assert motion.names == V2_ROW_NAMES
    assert motion.positions[3, 4].tolist() == [0.4, 0.03, 2.0]
    assert np.isnan(motion.positions[1, 7]).all()          # NotTracked -> missing
    assert motion.confidence[1, 7] == 0.0
    assert motion.positions[2, 7].tolist() == [0.5, 0.25, 1.5]
    assert motion.confidence[2, 7] == 0.5                  # Inferred
    assert motion.confidence[0, 0] == 1.0                  # Tracked
    assert motion.source.original[1, 7].tolist() == [0.5, 0.25, 1.5]
    assert motion.fps == pytest.approx(30.00003, rel=1e-4)
    assert np.allclose(np.diff(motion.times), 0.0333333)


def test_v2_fill_gets_inferred_state_and_missing_keeps_original(tmp_path):
    path = _v2_file(tmp_path, special={(1, 7): (0.5, 0.25, 1.5, 0), (3, 9): (0.1, 0.2, 0.3, 0)})
    motion = formats.read(path)
    out = tmp_path / "out.csv"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()      # NotTracked coordinates reproduced
    motion.positions[1, 7] = [0.123456789, -0.5, 2.25]   # a cleaner filled it
    formats.write(motion, out)
    rows = out.read_text().splitlines()
    cells = rows[1].split(",")
    assert cells[1 + 4 * 7: 1 + 4 * 7 + 4] == ["0.123457", "-0.500000", "2.250000", "1"]
    assert rows[3] == path.read_text().splitlines()[3]   # still missing: original tokens
    again = formats.read(out)
    assert again.confidence[1, 7] == 0.5 and again.confidence[3, 9] == 0.0
    assert np.isnan(again.positions[3, 9]).all()
    np.testing.assert_allclose(again.positions[1, 7], [0.123457, -0.5, 2.25])


def test_v2_removed_sample_written_as_not_tracked(tmp_path):
    path = _v2_file(tmp_path)
    motion = formats.read(path)
    motion.positions[2, 5] = np.nan
    out = tmp_path / "out.csv"
    formats.write(motion, out)
    cells = out.read_text().splitlines()[2].split(",")
    assert cells[1 + 4 * 5: 1 + 4 * 5 + 4] == ["0.5", "0.02", "2.0", "0"]
    again = formats.read(out)
    assert np.isnan(again.positions[2, 5]).all() and again.confidence[2, 5] == 0.0


def test_headerless_csv_with_20_joints_is_kinect_v1(tmp_path):
    rows = [",".join([str(1000 + 333_333 * t)] + [f"{j / 10},{t / 10},2.5,2" for j in range(20)])
            for t in range(3)]
    motion = formats.read(_write(tmp_path, "v1.csv", "\n".join(rows) + "\n"))
    assert motion.source.layout == "kinect_v1_csv"
    assert motion.names == kl.KINECT_V1
    assert motion.positions[2, 19].tolist() == [1.9, 0.2, 2.5]
    assert motion.skeleton.parents[kl.KINECT_V1.index("Head")] == kl.KINECT_V1.index(
        "ShoulderCenter")


def test_changed_value_keeps_original_precision(tmp_path):
    row = _v2_row(5, [(0.000256572, 1.5, 2.0, 2)] * 25)
    path = _write(tmp_path, "p.csv", row + row.replace("5,", "333338,", 1))
    motion = formats.read(path)
    motion.positions[0, 0, 0] = 0.000123456789
    out = tmp_path / "o.csv"
    formats.write(motion, out)
    assert out.read_text().split(",")[1] == "0.000123457"  # 9 decimals like the original


def test_nan_text_in_coordinate_is_missing(tmp_path):
    path = _v2_file(tmp_path)
    lines = path.read_text().splitlines(keepends=True)
    cells = lines[2].split(",")
    cells[1 + 4 * 3] = "nan"
    lines[2] = ",".join(cells)
    path.write_text("".join(lines))
    motion = formats.read(path)
    assert np.isnan(motion.positions[2, 3]).all()
    assert motion.confidence[2, 3] == 0.0
    assert any("nan/inf" in n for n in motion.notes)
    out = tmp_path / "o.csv"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()


def test_fps_option_overrides_with_note(tmp_path):
    motion = formats.read(_v2_file(tmp_path), fps=25)
    assert motion.fps == 25
    assert any("overrides" in n for n in motion.notes)
    same = formats.read(_v2_file(tmp_path), fps=30)
    assert not any("overrides" in n for n in same.notes)


def test_repeated_timestamp_reported(tmp_path):
    lines = _v2_file(tmp_path, n_frames=6).read_text().splitlines(keepends=True)
    lines[3] = lines[2].replace("\n", "") + "\n"        # frame 3 = copy of frame 2's line
    path = _write(tmp_path, "rep.csv", "".join(lines))
    motion = formats.read(path)
    assert motion.n_frames == 6                             # rows are kept
    assert any("1 repeated frames" in n for n in motion.notes)
    assert any("1 dropped-frame gaps, longest 67 ms" in n for n in motion.notes)


# ---------------------------------------------------------------------------------------
# headed wide CSV and long layout (hand-made, known values)
# ---------------------------------------------------------------------------------------
def test_wide_csv_known_values_states_and_topology(tmp_path):
    text = ("time,SpineBase_X,SpineBase_Y,SpineBase_Z,SpineBase_State,"
            "SpineMid_X,SpineMid_Y,SpineMid_Z,SpineMid_State,note\n"
            "0.0,0.1,-0.3,2.5,2,0.1,0.0,2.5,2,a\n"
            "0.1,0.1,-0.3,2.5,1,0.9,0.9,0.9,0,b\n"
            "0.2,0.1,-0.3,2.5,2,,,,1,c\n")
    path = _write(tmp_path, "wide.csv", text)
    motion = formats.read(path)
    assert motion.source.layout == "wide_csv"
    assert motion.names == ["SpineBase", "SpineMid"]
    assert motion.positions[0].tolist() == [[0.1, -0.3, 2.5], [0.1, 0.0, 2.5]]
    assert np.isnan(motion.positions[1, 1]).all() and np.isnan(motion.positions[2, 1]).all()
    np.testing.assert_array_equal(motion.confidence, [[1, 1], [0.5, 0], [1, 0]])
    assert motion.skeleton.parents.tolist() == [-1, 0]
    np.testing.assert_allclose(motion.times, [0, 0.1, 0.2])
    assert motion.fps == pytest.approx(10)
    assert motion.units == "m"
    out = tmp_path / "out.csv"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()
    motion.positions[1, 1] = [0.2, 0.3, 0.4]
    formats.write(motion, out)
    assert out.read_text().splitlines()[2] == \
        "0.1,0.1,-0.3,2.5,1,0.200000,0.300000,0.400000,1,b"


@pytest.mark.parametrize("header", [
    "Frame;Head.X;Head.Y;Head.Z;Neck.X;Neck.Y;Neck.Z",
    "frame;head x;head y;head z;neck x;neck y;neck z",
    "frame;HEAD_X;HEAD_Y;HEAD_Z;NECK_X;NECK_Y;NECK_Z",
])
def test_wide_csv_column_spellings(tmp_path, header):
    path = _write(tmp_path, "w.csv", header + "\n1;0;0.5;2;0;0.3;2\n2;0;0.6;2;0;0.4;2\n")
    motion = formats.read(path)
    assert [n.lower() for n in motion.names] == ["head", "neck"]
    assert motion.positions[1, 0].tolist() == [0.0, 0.6, 2.0]
    assert motion.skeleton.parents.tolist() == [1, -1]  # Head hangs off Neck (Kinect v2)
    assert motion.fps == 30 and any("30 fps assumed" in n for n in motion.notes)


def test_wide_csv_millimetres_guessed_and_tagged(tmp_path):
    guessed = _write(tmp_path, "mm.csv", "PELVIS_X,PELVIS_Y,PELVIS_Z,SPINE_NAVEL_X,SPINE_NAVEL_Y,"
                                         "SPINE_NAVEL_Z\n10,-300,2500,12,-100,2510\n")
    motion = formats.read(guessed)
    assert motion.units == "mm" and motion.metres_per_unit == 0.001
    assert any("mm guessed" in n for n in motion.notes)
    tagged = _write(tmp_path, "tag.csv", "t (s),Foo_X (mm),Foo_Y (mm),Foo_Z (mm)\n"
                                         "0,1,2,3\n0.5,1,2,3\n")
    motion = formats.read(tagged)
    assert motion.units == "mm" and not any("guessed" in n for n in motion.notes)
    assert motion.skeleton is None                          # unknown joint name
    assert motion.fps == pytest.approx(2.0)
    assert formats.read(guessed, units="cm").units == "cm"


def test_wide_csv_quoted_cells_and_bom(tmp_path):
    text = ('\ufeff"frame","Hand_X","Hand_Y","Hand_Z"\r\n'
            '"0","0.5","1.0","2.0"\r\n"1","0.5","1.1","2.0"\r\n')
    path = _write(tmp_path, "q.csv", text)
    assert kinect.sniff(path.read_bytes())
    motion = formats.read(path)
    assert motion.positions[:, 0, 1].tolist() == [1.0, 1.1]
    out = tmp_path / "o.csv"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()


def test_wide_csv_time_in_ms_and_ticks(tmp_path):
    ms = formats.read(_write(tmp_path, "ms.csv", "time_ms,A_X,A_Y,A_Z\n0,1,2,3\n40,1,2,3\n"
                                                 "80,1,2,3\n200,1,2,3\n"))
    np.testing.assert_allclose(ms.times, [0, 0.04, 0.08, 0.2])
    assert ms.fps == pytest.approx(25)
    assert any("1 dropped-frame gaps, longest 120 ms" in n for n in ms.notes)
    ticks = formats.read(_write(tmp_path, "ticks.csv", "timestamp,A_X,A_Y,A_Z\n"
                                                       "90000000000,1,2,3\n90000333333,1,2,3\n"))
    assert ticks.times[1] == pytest.approx(0.0333333)


def test_azure_kinect_names_get_documented_parents(tmp_path):
    names = kl.AZURE_KINECT
    header = ",".join(f"{n}_{a}" for n in names for a in "XYZ")
    rng = np.random.default_rng(0)
    row = ",".join(f"{v:.1f}" for v in rng.uniform(-500, 500, 3 * len(names)) + 2000)
    motion = formats.read(_write(tmp_path, "azure.csv", header + "\n" + row + "\n"))
    assert motion.n_joints == 32
    parent = {n: (names[p] if p >= 0 else None) for n, p in zip(names, motion.skeleton.parents)}
    # Microsoft "Azure Kinect body tracking joints" table
    assert parent["PELVIS"] is None
    assert parent["SPINE_NAVEL"] == "PELVIS" and parent["SPINE_CHEST"] == "SPINE_NAVEL"
    assert parent["CLAVICLE_LEFT"] == "SPINE_CHEST" and parent["SHOULDER_LEFT"] == "CLAVICLE_LEFT"
    assert parent["HANDTIP_LEFT"] == "HAND_LEFT" and parent["THUMB_LEFT"] == "WRIST_LEFT"
    assert parent["THUMB_RIGHT"] == "WRIST_RIGHT" and parent["HIP_RIGHT"] == "PELVIS"
    assert parent["HEAD"] == "NECK" and parent["EAR_RIGHT"] == "HEAD" and parent["NOSE"] == "HEAD"
    assert parent["FOOT_LEFT"] == "ANKLE_LEFT"


def test_builtin_topologies():
    v2 = dict(zip(kl.KINECT_V2, kl.skeleton_for("kinect_v2").parents))
    name = kl.KINECT_V2.__getitem__
    assert name(v2["Neck"]) == "SpineShoulder" and name(v2["ThumbLeft"]) == "WristLeft"
    assert name(v2["HandTipRight"]) == "HandRight" and name(v2["HipLeft"]) == "SpineBase"
    msr = kl.skeleton_for("msr_action3d")
    # the bone list of the MSR Action3D viewer (1-based pairs)
    viewer = {(20, 3), (1, 3), (2, 3), (1, 8), (8, 10), (2, 9), (10, 12), (9, 11), (11, 13),
              (3, 4), (4, 7), (7, 5), (7, 6), (5, 14), (6, 15), (14, 16), (15, 17), (16, 18),
              (17, 19)}
    ours = {tuple(sorted((a + 1, b + 1))) for a, b in msr.bones}
    assert ours == {tuple(sorted(p)) for p in viewer}


def test_subset_of_names_connects_to_nearest_ancestor():
    set_name, skeleton = kl.match_joint_set(["SpineBase", "ShoulderLeft", "ElbowLeft"])
    assert set_name == "kinect_v2"
    assert skeleton.parents.tolist() == [-1, 0, 1]
    assert kl.match_joint_set(["Head", "Tail"]) is None
    assert kl.match_joint_set(["LShoulder", "LElbow"])[1].parents.tolist() == [-1, 0]


def test_long_layout_absent_joints_and_fill(tmp_path):
    text = ("frame,joint,x,y,z,state\n"
            "0,ShoulderLeft,-0.2,0.4,2.0,2\n"
            "0,ElbowLeft,-0.25,0.1,2.0,2\n"
            "1,ShoulderLeft,-0.2,0.41,2.0,1\n"
            "2,ShoulderLeft,-0.2,0.42,2.0,2\n"
            "2,ElbowLeft,-0.25,0.12,2.0,0\n")
    path = _write(tmp_path, "long.csv", text)
    motion = formats.read(path)
    assert motion.source.layout == "long_csv"
    assert motion.names == ["ShoulderLeft", "ElbowLeft"]
    assert motion.positions[:, 0, 1].tolist() == [0.4, 0.41, 0.42]
    assert np.isnan(motion.positions[1, 1]).all()        # no row in frame 1
    assert np.isnan(motion.positions[2, 1]).all()        # NotTracked
    np.testing.assert_array_equal(motion.confidence, [[1, 1], [0.5, 0], [1, 0]])
    assert motion.skeleton.parents.tolist() == [-1, 0]
    out = tmp_path / "out.csv"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()
    motion.positions[1, 1] = [-0.3, 0.11, 2.0]
    motion.positions[0, 0] = np.nan
    formats.write(motion, out)
    lines = out.read_text().splitlines()
    assert lines[1] == "0,ShoulderLeft,-0.2,0.4,2.0,0"
    assert lines[4] == "1,ElbowLeft,-0.300000,0.110000,2.000000,1"   # inserted row
    again = formats.read(out)
    np.testing.assert_allclose(again.positions[1, 1], [-0.3, 0.11, 2.0])
    assert np.isnan(again.positions[0, 0]).all()


def test_motion_built_in_python_writes_wide_csv(tmp_path):
    positions = np.arange(2 * 3 * 3, dtype=float).reshape(2, 3, 3) / 10
    positions[1, 2] = np.nan
    motion = Motion(positions=positions, names=["Head", "Neck", "SpineShoulder"], fps=30.0,
                    units="m", metres_per_unit=1.0)
    out = tmp_path / "built.csv"
    assert formats.write(motion, out) == [out]
    lines = out.read_text().splitlines()
    assert lines[0] == "time,Head_X,Head_Y,Head_Z,Neck_X,Neck_Y,Neck_Z,SpineShoulder_X," \
                       "SpineShoulder_Y,SpineShoulder_Z"
    again = formats.read(out)
    np.testing.assert_allclose(again.positions, positions, atol=1e-6)
    assert again.names == motion.names and again.fps == pytest.approx(30)
    assert again.skeleton.parents.tolist() == [1, 2, -1]


# ---------------------------------------------------------------------------------------
# sniffing and malformed input
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("head, expected", [
    (b"1,2,3\n4,5,6\n", False),
    (b"hello world\n", False),
    (b"a,b,c\n1,2,3\n", False),
    (b"x,y,z\n1,2,3\n", False),
    (b"HIERARCHY\nROOT Hips\n{\n", False),
    (b"1 2 3 0.5\n1 2 3 1.0\n", True),
    (b"frame,joint,x,y,z\n0,Head,1,2,3\n", True),
    (b"Head.X;Head.Y;Head.Z\n1;2;3\n", True),
])
def test_sniff_hand_made(head, expected):
    assert kinect.sniff(head) is expected


@pytest.mark.parametrize("path", KINECT_FILES)
def test_sniff_real_files(path):
    assert kinect.sniff(need(path).read_bytes()[:4096])


def test_sniff_refuses_other_formats():
    for rel in ("bvh/pymo_AV_8Walk_Meredith_HVHA_Rep1.bvh", "asfamc/05_01.amc", "asfamc/05.asf",
                "c3d/c3dorg_s01_Eb015pi.c3d"):
        assert not kinect.sniff(shared(rel).read_bytes()[:4096]), rel


def _error(path) -> UnreadableFileError:
    with pytest.raises(UnreadableFileError) as info:
        formats.read(path)
    assert str(path) in str(info.value)
    return info.value


def test_row_with_fewer_values_names_the_line(tmp_path):
    lines = _v2_file(tmp_path, n_frames=5).read_text().splitlines(keepends=True)
    lines[2] = lines[2].rsplit(",", 6)[0] + ",\n"
    err = _error(_write(tmp_path, "short.csv", "".join(lines)))
    assert err.line == 3 and "values" in err.reason


def test_non_numeric_text_names_the_line(tmp_path):
    lines = _v2_file(tmp_path, n_frames=5).read_text().splitlines(keepends=True)
    lines[3] = lines[3].replace("2.0", "two", 1)
    err = _error(_write(tmp_path, "text.csv", "".join(lines)))
    assert err.line == 4 and "'two'" in err.reason


def test_empty_and_blank_files(tmp_path):
    assert "empty" in _error(_write(tmp_path, "empty.csv", "")).reason
    assert "empty" in _error(_write(tmp_path, "blank.txt", "\n \n")).reason
    assert "no data rows" in _error(_write(tmp_path, "hdr.csv", "frame,A_X,A_Y,A_Z\n")).reason


def test_bad_tracking_state_is_refused(tmp_path):
    err = _error(_v2_file(tmp_path, special={(1, 3): (0.1, 0.2, 0.3, 7)}))
    assert err.line == 2 and "tracking state" in err.reason


def test_truncated_last_line_is_dropped_with_note(tmp_path):
    full = _v2_file(tmp_path, n_frames=5).read_text()
    path = _write(tmp_path, "trunc.csv", full[: full.rindex("\n", 0, len(full) - 1) + 200])
    motion = formats.read(path)
    assert motion.n_frames == 4
    assert any("truncated" in n and "line 5" in n for n in motion.notes)
    out = tmp_path / "out.csv"
    formats.write(motion, out)   # the fragment is not written back
    assert out.read_text() == full[: full.rindex("\n", 0, len(full) - 1) + 1]


def test_truncated_utkinect_and_msr(tmp_path):
    ut = shared("kinect/kv1_utkinect_joints_s01_e01.txt").read_text().split("\n")
    motion = formats.read(_write(tmp_path, "ut.txt", "\n".join(ut[:10]) + "\n" + ut[10][:150]))
    assert motion.n_frames == 10 and any("truncated" in n for n in motion.notes)
    msr = shared("kinect/kv1_msr3d_a01_s01_e01_skeleton3D.txt").read_text().split("\n")
    motion = formats.read(_write(tmp_path, "msr.txt", "\n".join(msr[:47]) + "\n"))
    assert motion.n_frames == 2
    assert any("7 of 20 rows" in n for n in motion.notes)


def test_msr_all_zero_row_is_missing(tmp_path):
    msr = shared("kinect/kv1_msr3d_a01_s01_e01_skeleton3D.txt").read_text().split("\n")
    msr[24] = "0.000000 0.000000 0.000000 0.000000"
    path = _write(tmp_path, "zero.txt", "\n".join(msr[:40]) + "\n")
    motion = formats.read(path)
    assert motion.missing.sum() == 1 and motion.missing[1, 4]
    out = tmp_path / "out.txt"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()


def test_unknown_numeric_table_is_refused(tmp_path):
    err = _error(_write(tmp_path, "x.txt", "1 2 3\n4 5 6\n"))
    assert "not a known layout" in err.reason


def test_undecodable_bytes_refused(tmp_path):
    err = _error(_write(tmp_path, "bin.csv", b"\x00\x01\xff\xfe\x00"))
    assert "not a text file" in err.reason


# ---------------------------------------------------------------------------------------
# The bulk writer of headerless Kinect CSVs gives the bytes of the sample-by-sample one

_CELL_STYLES = ["{:.6f}", "{:.3f}", "{:.9f}", "{:g}", " {:.6f}", "{:.6f} ", "{:.2e}",
                "{:+.6f}", "{:.4E}", "{:.0f}"]


def _odd_v2_csv(rng, frames=80, trailing=False) -> str:
    """A Kinect v2 CSV whose lines mix plain six-decimal lines (most) with lines holding
    short and long decimals, %g, exponents, blanks around cells, signs, integers, "nan"
    cells of NotTracked joints; some lines end with a comma, CRLF and LF endings mixed."""
    out = []
    for t in range(frames):
        plain = rng.random() < 0.5
        odd = _CELL_STYLES[rng.integers(len(_CELL_STYLES))]     # one oddity per line
        cells = [str(10_000_000_000 + 333_333 * t)]
        for j in range(25):
            state = int(rng.choice([0, 1, 2], p=[0.1, 0.2, 0.7]))
            xyz = rng.normal(0, 0.4, 3) + [0, 0, 2.5]
            for v in xyz:
                style = odd if not plain and rng.random() < 0.3 else "{:.6f}"
                cells.append("nan" if (state == 0 and not plain and rng.random() < 0.3)
                             else style.format(v))
            cells.append(str(state))
        line = ",".join(cells) + ("," if trailing and t % 3 == 0 else "")
        out.append(line + ("\r\n" if t % 7 == 3 else "\n"))
    return "".join(out)


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(6))
def test_bulk_csv_writer_gives_the_bytes_of_the_sample_by_sample_writer(seed, tmp_path):
    rng = np.random.default_rng(seed)
    path = _write(tmp_path, "odd.csv", _odd_v2_csv(rng, trailing=seed % 2 == 1))
    motion = kinect.read(path, layout="kinect_v2_csv")
    src = motion.source
    assert src.layout == "kinect_v2_csv" and motion.missing.any()
    new = motion.positions.copy()
    T, J = motion.missing.shape
    edit = rng.random((T, J))
    moved = (edit < 0.5) & ~motion.missing
    new[moved] += rng.normal(0, 0.01, (int(moved.sum()), 3))
    filled = (edit < 0.7) & motion.missing
    new[filled] = rng.normal(0, 0.3, (int(filled.sum()), 3)) + [0, 0, 2.5]
    removed = (edit > 0.95) & ~motion.missing
    new[removed] = np.nan
    new[5] = motion.positions[5]                    # one row left as it was
    cleaned = motion.replace(positions=new)
    bulk, reference = kinect._fast_csv_text(src, cleaned), kinect._edited_text(src, cleaned)
    assert bulk == reference
    assert bulk.splitlines()[5] == src.lines[5]
    again = kinect.read(_write(tmp_path, "again.csv", bulk), layout="kinect_v2_csv")
    np.testing.assert_array_equal(again.missing, np.isnan(new).any(axis=2))
    np.testing.assert_allclose(again.positions[~again.missing], new[~again.missing], atol=5e-3)


@pytest.mark.parametrize("name", ["kv2_laban_Ges01_wavehand.csv", "kv2_laban_KinectReader_joints.csv"])
def test_bulk_csv_writer_matches_on_real_files(name):
    """Kinect SDK exports (%g-style numbers, 3-9 decimals, a few exponents): nearly every
    line takes the bulk path, the ones with an exponent the token-by-token one."""
    motion = formats.read(shared(f"kinect/{name}"))
    lines = [motion.source.lines[i] for i in motion.source.line_of[:, 0]]
    plain = kinect._plain_lines(lines)
    assert 0.9 < plain.mean() < 1.0
    rng = np.random.default_rng(1)
    new = motion.positions + rng.normal(0, 0.005, motion.positions.shape)
    new[::11, 3] = np.nan
    cleaned = motion.replace(positions=new)
    assert kinect._fast_csv_text(motion.source, cleaned) == kinect._edited_text(motion.source, cleaned)


@pytest.mark.parametrize("name, text", [
    ("long.csv", "frame,joint,x,y,z\n0,Head,0,1,2\n0,Neck,0,0.8,2\n1,Head,0,1.01,2\n1,Neck,0,0.81,2\n"
                 "2,Head,0,1.02,2\n2,Neck,0,0.82,2\n"),
    ("wide.csv", "Head_X,Head_Y,Head_Z,Neck_X,Neck_Y,Neck_Z\n0,1,2,0,0.8,2\n0,1.01,2,0,0.81,2\n"
                 "0,1.02,2,0,0.82,2\n"),
])
def test_every_layout_without_a_rate_takes_the_given_default_and_says_so(tmp_path, monkeypatch,
                                                                         name, text):
    """A layout that stores no rate notes the one it assumed; ``default_fps`` (--fps)
    replaces it and its note, while a file with a time column keeps its own rate; either
    way the file is read once."""
    path = _write(tmp_path, name, text)
    assumed = formats.read(path)
    assert assumed.fps == pytest.approx(kinect.DEFAULT_FPS) and assumed.source.extra["rate_assumed"]
    assert any("assumed" in n for n in assumed.notes)
    reads = []
    monkeypatch.setattr(kinect, "read_input_bytes",
                        lambda p, _read=kinect.read_input_bytes: reads.append(p) or _read(p))
    given = formats.read(path, default_fps=45)
    assert reads == [path]
    assert given.fps == 45 and not any("assumed" in n for n in given.notes)
    if name == "long.csv":                          # times from the frame column, at 45 Hz
        assert np.allclose(np.diff(given.times), 1 / 45)
    assert any("fps 45 given by the user (the file stores no rate)" in n for n in given.notes)
    header, *rows = text.splitlines()
    if name == "wide.csv":                          # a time column in seconds, 50 Hz
        rows = [f"{k / 50:.2f},{row}" for k, row in enumerate(rows)]
        header = "time," + header
    else:                                           # the frame column becomes seconds
        rows = [f"{int(row.split(',')[0]) / 50:.2f},{row.split(',', 1)[1]}" for row in rows]
        header = header.replace("frame,", "time_s,")
    timed = _write(tmp_path, "timed_" + name, "\n".join([header, *rows]) + "\n")
    kept = formats.read(timed, default_fps=45)
    assert reads == [path, timed]
    assert kept.fps == pytest.approx(50) and not kept.source.extra["rate_assumed"]


@pytest.mark.parametrize("row, stamp", [(50, "1e23"), (50, "0"), (0, "1e23"), (-1, "5")])
def test_a_lone_corrupt_time_stamp_is_read_between_its_neighbours(tmp_path, row, stamp):
    """One tick field corrupted (1e23, 0) in a real v2 recording: the time axis is the
    recording's, not 3e17 dropped frames or a backward step, a note names the row, and
    the file writes back byte for byte as read."""
    src = shared("kinect/kv2_laban_Ges01_wavehand.csv")
    lines = src.read_text().splitlines(keepends=True)
    fields = lines[row].split(",")
    fields[0] = stamp
    lines[row] = ",".join(fields)
    path = tmp_path / "stamp.csv"
    path.write_text("".join(lines))
    clean, hit = formats.read(src), formats.read(path)
    assert np.allclose(hit.times, clean.times, atol=0.04)
    assert hit.fps == pytest.approx(clean.fps, rel=1e-3)
    k = row % len(lines) + 1
    assert any(f"data rows {k})" in n for n in hit.notes), hit.notes
    assert not any("backward" in n for n in hit.notes)
    formats.write(hit, tmp_path / "out.csv")
    assert (tmp_path / "out.csv").read_bytes() == path.read_bytes()


def test_a_kinect_time_column_of_absurd_steps_is_refused_by_the_reader(tmp_path):
    # a headed CSV whose time stamps are 1e300 apart read as "90 frames at 0 fps" and
    # cleaning died in the smoother: "internal error OverflowError"
    import math

    joints = ["Head", "Neck", "SpineShoulder", "SpineMid", "SpineBase", "ShoulderLeft",
              "ElbowLeft", "WristLeft", "ShoulderRight", "ElbowRight", "WristRight", "HipLeft",
              "KneeLeft", "AnkleLeft", "HipRight", "KneeRight", "AnkleRight"]
    header = "time," + ",".join(f"{j}_X,{j}_Y,{j}_Z" for j in joints)

    def take(step):
        rows = [",".join([f"{step * (t + 1):.6g}"] + [f"{v:.4f}" for k in range(len(joints))
                 for v in (0.1 * k + 0.01 * math.sin(t / 5), 1.0 - 0.05 * k, 2.5 + 0.01 * math.cos(t / 7))])
                for t in range(90)]
        return header + "\n" + "\n".join(rows) + "\n"

    src = tmp_path / "in"
    src.mkdir()
    (src / "absurd.csv").write_text(take(1e300))
    (src / "fine.csv").write_text(take(1 / 30))
    r = CliRunner().invoke(main, ["clean", str(src), "-o", str(tmp_path / "out"), "-c", "kinect"])
    no_traceback(r)
    assert r.exit_code == 1, r.output
    error = [line for line in r.output.splitlines() if line.startswith("ERROR")]
    assert len(error) == 1 and error[0].startswith(f"ERROR {src / 'absurd.csv'}: the time column gives ")
    assert error[0].endswith("frames per second, outside 0.001-100000 Hz (a corrupt time column?)")
    assert (tmp_path / "out" / "fine.csv").is_file() and not list((tmp_path / "out").glob("absurd*"))


@pytest.mark.parametrize("name", ["kv1_utkinect_joints_s01_e01.txt", "kv1_msr3d_a01_s01_e01_skeleton3D.txt"])
def test_edited_lines_a_chunk_of_frames_at_a_time_give_the_whole_take_bytes(name, tmp_path, monkeypatch):
    """The writer sorts the changed samples a chunk of frames at a time where each
    frame's lines follow the previous frame's: the same bytes as one sort of the take."""
    motion = kinect.read(need(shared(f"kinect/{name}")))
    rng = np.random.default_rng(0)
    moved = motion.positions + rng.normal(0, 0.01, motion.positions.shape)
    moved[rng.random(moved.shape[:2]) < 0.05] = np.nan
    edited = motion.replace(positions=moved)
    assert kinect._lines_follow_frames(motion.source.line_of)
    whole = kinect._edited_text(motion.source, edited)
    monkeypatch.setattr(kinect, "CHUNK", 7)
    assert kinect._edited_text(motion.source, edited) == whole


# ---------------------------------------------------------------------------------------
# variants found in the wild
# ---------------------------------------------------------------------------------------
def test_v2_csv_with_millisecond_stamps_is_read_as_milliseconds(tmp_path):
    """The LabanotationSuite's own reader (LabanEditor/src/kinect.py) takes the KinectReader
    layout with small stamps ("yamada data": 1, 34, 67, ... ms) as milliseconds; read as
    100 ns ticks they gave ~300 000 fps and the file was refused as a corrupt time column."""
    lines = [_v2_row(1 + round(1000 * t / 30), [(j / 10, t / 100, 2.0, 2) for j in range(25)])
             for t in range(6)]
    path = _write(tmp_path, "yamada.csv", "".join(lines))
    motion = formats.read(path)
    assert motion.source.layout == "kinect_v2_csv"
    assert motion.fps == pytest.approx(30, rel=0.02)
    assert motion.times[-1] == pytest.approx(0.167)
    assert any("milliseconds" in n for n in motion.notes)
    out = tmp_path / "out.csv"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()


def test_v2_csv_with_fractional_stamps_is_refused_naming_the_line(tmp_path):
    lines = [_v2_row(f"{t / 30:.4f}", [(j / 10, t / 100, 2.0, 2) for j in range(25)])
             for t in range(4)]
    path = _write(tmp_path, "seconds.csv", "".join(lines))
    with pytest.raises(UnreadableFileError, match=r"seconds\.csv:2: time stamp 0\.0333 is not "
                                                  r"a whole number"):
        formats.read(path)


def _lsl_kinect_file(tmp_path):
    """The shape of an LSL-Kinect ``Kinect_Capture_MoCap_Data <date>.csv`` (its
    MainWindow.xaml.cs: CsvHelper, CRLF): a settings line, a blank line, a header
    ``TimeSpan,<JointType>_X,_Y,_Z,_Conf`` x 25, rows stamped ``yyyy-MM-dd HH:mm:ss.fff``,
    confidence = TrackingState / 2, and a frame without the selected body written as 101
    zeros after its stamp."""
    rows = ["Software : LSL_Kinect,Version : 1.0.4.1,Stream nominal rate : 15,"
            "Sequence Name : Reaching Task", "",
            "TimeSpan," + ",".join(f"{n}{s}" for n in kl.KINECT_V2
                                   for s in ("_X", "_Y", "_Z", "_Conf"))]
    for t in range(6):
        stamp = f"2020-07-03 16:01:47.{100 + 66 * t:03d}"
        if t == 4:
            rows.append(stamp + "," + ",".join(["0"] * 100))
            continue
        cells = []
        for j in range(25):
            cells += [f"{j / 10 + t / 1000:g}", f"{0.5 - j / 20:g}", f"{2 + j / 100:g}",
                      "0.5" if j == 7 else "1"]
        rows.append(stamp + "," + ",".join(cells))
    return _write(tmp_path, "Kinect_Capture_MoCap_Data 2020.07.03 04.01 PM.csv",
                  "\r\n".join(rows) + "\r\n")


def test_lsl_kinect_csv_settings_line_date_stamps_and_bodiless_frame(tmp_path):
    """Before: refused ("first line has 4 values"): the header is on line 3; then the
    date-time stamps were "non-numeric"; and the frame without a body read as 25 joints
    at the camera's origin."""
    path = _lsl_kinect_file(tmp_path)
    assert kinect.sniff(path.read_bytes()[:4096])
    motion = formats.read(path)
    assert motion.source.layout == "wide_csv"
    assert motion.names == kl.KINECT_V2
    assert motion.positions.shape == (6, 25, 3)
    assert motion.positions[1, 2].tolist() == pytest.approx([0.201, 0.4, 2.02])
    np.testing.assert_allclose(motion.times, np.arange(6) * 0.066)
    assert motion.fps == pytest.approx(1 / 0.066)
    assert motion.confidence[0, 7] == 0.5 and motion.confidence[0, 6] == 1.0
    assert np.isnan(motion.positions[4]).all() and (motion.confidence[4] == 0).all()
    assert not np.isnan(np.delete(motion.positions, 4, axis=0)).any()
    out = tmp_path / "out.csv"
    formats.write(motion, out)
    assert out.read_bytes() == path.read_bytes()
    motion.positions[4] = motion.positions[3]            # a cleaner filled the frame
    formats.write(motion, out)
    lines = out.read_text().splitlines()
    assert lines[:3] == path.read_text().splitlines()[:3]
    assert lines[7].split(",")[1:5] == ["0.003000", "0.500000", "2.000000", "0.500000"]


def test_preamble_before_a_header_of_unknown_joints_is_still_refused(tmp_path):
    path = _write(tmp_path, "other.csv", "Software : Tool,Version : 1\n\n"
                  "time,Foo_X,Foo_Y,Foo_Z\n0,1,2,3\n")
    with pytest.raises(UnreadableFileError, match="other.csv:1: not a Kinect skeleton layout"):
        kinect.read(path)
    assert not kinect.sniff(path.read_bytes())
    with pytest.raises(UnreadableFileError, match="other.csv: not a known layout"):
        formats.read(path)


def _nuitrack_file(tmp_path, users):
    """The shape of Nuitrack's CSV recorder (its doc's sample data): ``timestamp`` in
    microseconds, the sensor's ``serial``, the user ``id``, ``JOINT_<NAME>.x/.y/.z`` and a
    ``.rot`` on some joints; one row per tracked user per frame."""
    joints = ["JOINT_WAIST", "JOINT_TORSO", "JOINT_NECK", "JOINT_HEAD"]
    header = ["timestamp", "serial", "id"]
    for j in joints:
        header += [f"{j}.x", f"{j}.y", f"{j}.z"] + ([f"{j}.rot"] if j != "JOINT_WAIST" else [])
    rows = [",".join(header)]
    for t in range(6):
        for user in users(t):
            cells = [str(1715151474879921 + 33358 * t), "AS3M323001D", str(user)]
            for k, j in enumerate(joints):
                cells += [f"{-0.23 + user + k / 100:g}", f"{0.26 + k / 5:g}", f"{3.38 + t / 100:g}"]
                cells += ["178.678"] if j != "JOINT_WAIST" else []
            rows.append(",".join(cells))
    return _write(tmp_path, "SkeletonData.csv", "\n".join(rows) + "\n")


def test_rows_of_two_bodies_at_one_time_stamp_are_refused_naming_the_column(tmp_path):
    """Before: Nuitrack rows of users 1 and 2 at the same stamps were read as one body
    jumping between them ("3 repeated frames")."""
    one = formats.read(_nuitrack_file(tmp_path, lambda t: [1]))
    assert one.names == ["JOINT_WAIST", "JOINT_TORSO", "JOINT_NECK", "JOINT_HEAD"]
    assert one.fps == pytest.approx(1e6 / 33358)
    assert one.positions[2, 1].tolist() == pytest.approx([0.78, 0.46, 3.40])
    # a user who leaves and comes back under a new id is still one body per frame
    again = formats.read(_nuitrack_file(tmp_path, lambda t: [1] if t < 3 else [4]))
    assert again.n_frames == 6
    path = _nuitrack_file(tmp_path, lambda t: [1] if t < 3 else [1, 2])
    with pytest.raises(UnreadableFileError, match=r"SkeletonData\.csv:6: more than one body per "
                                                  r"frame: column 'id' holds '1' and '2'"):
        formats.read(path)


def test_long_layout_with_two_bodies_names_the_body_column(tmp_path):
    rows = ["frame,body,joint,x,y,z"] + [f"{t},{b},{n},0.1,0.2,2.0" for t in range(2)
                                         for b in (0, 1) for n in ("Head", "Neck")]
    path = _write(tmp_path, "long.csv", "\n".join(rows) + "\n")
    with pytest.raises(UnreadableFileError, match=r"long\.csv:4: more than one body per frame: "
                                                  r"column 'body' holds '0' and '1' at frame 0"):
        formats.read(path)


def test_a_row_number_column_named_id_is_not_a_body(tmp_path):
    rows = ["id,time,Head_X,Head_Y,Head_Z,Neck_X,Neck_Y,Neck_Z"] + [
        f"{k},{[0, 0.033, 0.033, 0.067][k]},0.1,0.5,2.0,0.1,0.3,2.0" for k in range(4)]
    motion = formats.read(_write(tmp_path, "rows.csv", "\n".join(rows) + "\n"))
    assert motion.n_frames == 4
    assert any("1 repeated frames" in n for n in motion.notes)


@pytest.mark.parametrize("name", ["kv2_laban_Ges01_wavehand.csv", "kv1_utkinect_joints_s01_e01.txt",
                                  "kv2_laban_KinectReader_joints.csv"])
def test_coordinates_shared_with_the_motion_read_write_the_same_bytes(name, tmp_path):
    """``formats.share_values_read`` (what ``clean`` does after reading): the source's
    coordinates as written become the motion's positions, read-only, and the motion and
    its cleaned take write the same bytes as without the sharing; a motion whose positions
    were edited before is left unshared."""
    import mocapfix

    path = shared(f"kinect/{name}")
    shared_motion, own = formats.read(path), formats.read(path)
    formats.share_values_read(shared_motion)
    assert shared_motion.source.original is shared_motion.positions
    assert not shared_motion.positions.flags.writeable
    with pytest.raises(ValueError):
        shared_motion.positions[0, 0, 0] = 1.0
    assert own.source.original is not own.positions
    for k, (a, b) in enumerate([(shared_motion, own),
                                (mocapfix.clean(shared_motion)[0], mocapfix.clean(own)[0])]):
        written = [formats.write(m, tmp_path / f"{k}{side}" / name)[0].read_bytes()
                   for m, side in ((a, "shared"), (b, "own"))]
        assert written[0] == written[1]
    edited = formats.read(path)
    seen = np.flatnonzero(~edited.source.missing.ravel())[0]
    edited.positions.reshape(-1, 3)[seen] += 0.01
    formats.share_values_read(edited)
    assert edited.source.original is not edited.positions and edited.positions.flags.writeable
