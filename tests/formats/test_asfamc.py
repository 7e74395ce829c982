"""ASF/AMC reader and writer: real CMU files, hand-made skeletons with answers worked out
on paper, an independent textbook forward-kinematics check, and malformed inputs."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import SAMPLE_DATA, hang_guard, need, shared, shared_files
from mocapfix import formats
from mocapfix.core.errors import UnreadableFileError, UnsupportedFeatureError, WriteError
from mocapfix.formats import asfamc

#: frame counts from /work/shared/data/SOURCES.md
EXPECTED_FRAMES = {
    "05_01.amc": 598, "05_02.amc": 1123, "05_10.amc": 817, "13_39.amc": 351,
    "18_15.amc": 1536, "60_10.amc": 1197, "61_10.amc": 1197, "143_35.amc": 1279,
    "90_31.amc": 979,
}
AMC_FILES = shared_files("asfamc", "*.amc")


# ----------------------------------------------------------------- independent reference
def parse_cmu_asf_for_reference(path: Path) -> dict:
    """Minimal ASF reader, written separately from mocapfix, for CMU-style files."""
    bones, hierarchy, root = {}, {}, {}
    section, bone, in_limits = None, None, False
    for raw in path.read_text().splitlines():
        tokens = raw.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        if tokens[0].startswith(":"):
            section = tokens[0]
            continue
        if section == ":root":
            root[tokens[0]] = tokens[1:]
        elif section == ":bonedata":
            if tokens[0] == "begin":
                bone = {"dof": []}
            elif tokens[0] == "end":
                bones[bone["name"]] = bone
            elif tokens[0] == "name":
                bone["name"] = tokens[1]
            elif tokens[0] == "direction":
                bone["direction"] = np.array([float(t) for t in tokens[1:4]])
            elif tokens[0] == "length":
                bone["length"] = float(tokens[1])
            elif tokens[0] == "axis":
                bone["axis"] = ([float(t) for t in tokens[1:4]], tokens[4])
            elif tokens[0] == "dof":
                bone["dof"] = tokens[1:]
        elif section == ":hierarchy" and tokens[0] not in ("begin", "end"):
            for child in tokens[1:]:
                hierarchy[child] = tokens[0]
    return {"bones": bones, "parent": hierarchy, "root": root}


def parse_amc_for_reference(path: Path, frames: list[int]) -> dict:
    """{frame number: {bone: [values]}} for the requested frame numbers."""
    out, current = {}, None
    for raw in path.read_text().splitlines():
        tokens = raw.split()
        if not tokens or tokens[0][0] in "#:":
            continue
        if len(tokens) == 1 and tokens[0].isdigit():
            current = int(tokens[0])
            if current in frames:
                out[current] = {}
            continue
        if current in out:
            out[current][tokens[0]] = [float(t) for t in tokens[1:]]
    return out


def euler_xyz(angles_xyz, order: str) -> Rotation:
    """ASF axis: x, y, z angles applied in extrinsic ``order`` (scipy lower case = extrinsic)."""
    by_axis = dict(zip("XYZ", angles_xyz))
    return Rotation.from_euler(order.lower(), [by_axis[a] for a in order], degrees=True)


def reference_fk(asf: dict, frame: dict) -> dict:
    """Textbook Acclaim FK: L = C M C^-1, G = G_parent L, end = parent end + length G d."""
    root = asf["root"]
    order = [c.upper() for c in root["order"]]
    values = dict(zip(order, frame["root"]))
    c_root = euler_xyz([float(v) for v in root["orientation"]], root["axis"][0])
    rot_channels = [c for c in order if c.startswith("R")]
    m_root = Rotation.from_euler("".join(c[1].lower() for c in rot_channels),
                                 [values[c] for c in rot_channels], degrees=True)
    position = np.array([float(v) for v in root["position"]])
    ends = {"root": position + np.array([values.get(c, 0.0) for c in ("TX", "TY", "TZ")])}
    globals_ = {"root": c_root * m_root * c_root.inv()}
    pending = list(asf["bones"])
    while pending:
        for name in list(pending):
            parent = asf["parent"][name]
            if parent not in ends:
                continue
            bone = asf["bones"][name]
            c = euler_xyz(*bone["axis"])
            if bone["dof"]:
                m = Rotation.from_euler("".join(d[1] for d in bone["dof"]), frame[name], degrees=True)
            else:
                m = Rotation.identity()
            globals_[name] = globals_[parent] * (c * m * c.inv())
            ends[name] = ends[parent] + bone["length"] * globals_[name].apply(bone["direction"])
            pending.remove(name)
    return ends


@pytest.mark.parametrize("amc_name, asf_name", [("05_01.amc", "05.asf"), ("13_39.amc", "13.asf"),
                                               ("90_31.amc", "90.asf")])
def test_fk_matches_independent_textbook_computation(amc_name, asf_name):
    amc = shared(f"asfamc/{amc_name}")
    asf = parse_cmu_asf_for_reference(shared(f"asfamc/{asf_name}"))
    motion = asfamc.read(amc)
    frame_numbers = [1, 2, 250, 351]
    reference = parse_amc_for_reference(amc, frame_numbers)
    assert set(reference) == set(frame_numbers)
    for number in frame_numbers:
        ends = reference_fk(asf, reference[number])
        t = number - 1                      # CMU frames are numbered from 1
        for j, name in enumerate(motion.names):
            np.testing.assert_allclose(motion.positions[t, j], ends[name], atol=1e-9, rtol=0,
                                       err_msg=f"{amc_name} frame {number} joint {name}")


# ----------------------------------------------------------------- real files
@pytest.mark.slow
@pytest.mark.parametrize("amc", AMC_FILES)
def test_every_cmu_file_reads_with_its_asf(amc):
    amc = need(amc)
    with hang_guard(60):                 # read time: benchmarks/formats_io.py
        motion = formats.read(amc)
    assert motion.format == "asfamc"
    assert motion.n_frames == EXPECTED_FRAMES[amc.name]
    assert motion.n_joints == 31 and motion.names[0] == "root"
    assert motion.fps == 120.0
    assert any("120 Hz" in note for note in motion.notes)
    assert motion.units == "in/0.45"
    assert motion.metres_per_unit == pytest.approx(0.0254 / 0.45)
    parents = motion.skeleton.parents
    assert parents[0] == -1 and all(0 <= parents[j] < j for j in range(1, motion.n_joints))
    assert motion.names[parents[motion.index("ltibia")]] == "lfemur"
    assert motion.names[parents[motion.index("thorax")]] == "upperback"
    # CMU: root has 6 values, 29 bone lines; DOF counts as declared in the ASF
    assert motion.channels.shape == (motion.n_frames, 62)
    assert np.all(np.isfinite(motion.positions))
    # root columns are the first 6 values of each "root" line: first frame of the file
    first_root = amc.read_text().split("root ", 1)[1].split()[:6]
    np.testing.assert_array_equal(motion.channels[0, :6], [float(v) for v in first_root])
    np.testing.assert_allclose(motion.positions[0, 0], motion.channels[0, :3], atol=1e-12)


@pytest.mark.slow
@pytest.mark.parametrize("amc", AMC_FILES)
def test_unchanged_motion_writes_byte_identical_files(amc, tmp_path):
    amc = need(amc)
    motion = asfamc.read(amc)
    with hang_guard(60):                 # write time: benchmarks/formats_io.py
        written = formats.write(motion, tmp_path / amc.name)
    asf_source = Path(motion.source.asf_path)
    assert written == [tmp_path / amc.name, tmp_path / asf_source.name]
    assert written[0].read_bytes() == amc.read_bytes()
    assert written[1].read_bytes() == asf_source.read_bytes()
    again = asfamc.read(written[0])
    np.testing.assert_array_equal(again.channels, motion.channels)
    np.testing.assert_array_equal(again.positions, motion.positions)
    assert again.names == motion.names


def test_changed_values_round_trip_and_other_lines_stay_identical(tmp_path):
    amc = shared("asfamc/05_01.amc")
    motion = asfamc.read(amc)
    changed = motion.copy()
    layout_names = [name for name, _ in motion.source.layout]
    col = sum(n for name, n in motion.source.layout[:layout_names.index("lfemur")])
    changed.channels[9, col] = 12.3456789012          # lfemur rx, frame 10
    changed.channels[20, 0] += 1.0 / 3.0
    out = asfamc.write(changed, tmp_path / "05_01.amc")[0]
    back = asfamc.read(out)
    np.testing.assert_allclose(back.channels, changed.channels, atol=1e-6, rtol=0)
    assert back.channels[9, col] != motion.channels[9, col]
    original_lines = amc.read_bytes().split(b"\n")
    new_lines = out.read_bytes().split(b"\n")
    assert len(new_lines) == len(original_lines)
    differing = [i for i, (a, b) in enumerate(zip(original_lines, new_lines)) if a != b]
    assert len(differing) == 2
    lfemur_line, root_line = new_lines[differing[0]], new_lines[differing[1]]
    assert lfemur_line.endswith(b"\r") and root_line.endswith(b"\r")   # CRLF kept
    assert lfemur_line.startswith(b"lfemur 12.345679 ")
    # the untouched values of a rewritten line keep their original text
    assert lfemur_line.split()[2:] == original_lines[differing[0]].split()[2:]
    assert root_line.split()[0] == b"root"
    assert root_line.split()[2:] == original_lines[differing[1]].split()[2:]


def test_lf_and_crlf_files_both_read_and_keep_their_line_endings(tmp_path):
    crlf = asfamc.read(shared("asfamc/05_01.amc"))
    lf = asfamc.read(shared("asfamc/13_39.amc"))
    assert crlf.source.eol == "\r\n" and lf.source.eol == "\n"
    assert b"\r\n" in Path(crlf.source.asf_path).read_bytes()
    assert b"\r" not in Path(lf.source.asf_path).read_bytes()
    changed = lf.copy()
    changed.channels[:, 3:6] += 0.5
    out = asfamc.write(changed, tmp_path / "13_39.amc")[0]
    assert b"\r" not in out.read_bytes()


@pytest.mark.parametrize("asf_name", ["05.asf", "13.asf", "18.asf", "60.asf", "61.asf", "90.asf", "143.asf"])
def test_cmu_subjects_have_human_height(asf_name):
    """Head end above the mean foot end in the rest pose, in metres. The head bone ends
    mid-skull and the foot bones end above the sole, so this runs ~10 cm under stature;
    CMU subjects include small adults, hence 1.3–2.0 m rather than 1.5–1.9 m."""
    motion = asfamc.read(shared(f"asfamc/{asf_name}"))
    assert motion.n_frames == 1 and np.all(motion.channels == 0)
    assert any("rest pose" in note for note in motion.notes)
    metres = motion.positions[0] * motion.metres_per_unit
    feet = (metres[motion.index("lfoot"), 1] + metres[motion.index("rfoot"), 1]) / 2
    height = metres[motion.index("head"), 1] - feet
    assert 1.3 < height < 2.0
    # in the rest pose the skeleton is symmetric enough: hands at similar heights
    assert abs(metres[motion.index("lhand"), 1] - metres[motion.index("rhand"), 1]) < 0.05


def test_fps_option_overrides_default():
    motion = asfamc.read(shared("asfamc/13_39.amc"), fps=60.0)
    assert motion.fps == 60.0
    assert not any("120 Hz" in note for note in motion.notes)


# ----------------------------------------------------------------- hand-made skeleton
TINY_ASF = """# tiny skeleton: a bone up from the root, a bone sideways from its end
:version 1.10
:name tiny
:units
  mass 1.0
  length {length}
  angle {angle}
:documentation
  Free text: two bones.
  # not a comment inside documentation
:root
   orientation 0 0 {thirty}
   position 1 0 0
   axis XYZ
   order TX TY TZ RX RY RZ
:bonedata
  begin
    id 1
    name up
    direction 0 1 0
    length 2
    axis 0 0 {fortyfive} XYZ
    dof rz
    limits (-inf inf)
  end
  begin
    id 2
    name side
    direction 1 0 0
    length 1
    axis 0 0 {ninety} XYZ   # local x is world y
    dof rx ry
    limits (-180.0 180.0)
           (-inf inf)
  end
:hierarchy
  begin
    root up
    up side
  end
"""

TINY_AMC = """#!OML:ASF tiny.asf
:FULLY-SPECIFIED
:{unit}
1
root 0 0 0 0 0 0
up 0
side 0 0
2
root 10 20 30 0 0 0
up {q}
side {q} 0
3
root 0 0 0 0 0 {q}
up 0
side 0 0
4
root 0 0 0 0 0 0
up 0
side {q} {q}
"""

# Worked on paper. Frame 1 (rest): root at position (1,0,0); up end = root + 2*(0,1,0);
# side end = up end + (1,0,0).
# Frame 2: root at (11,20,30); up: Rz(90)(0,2,0) = (-2,0,0) -> (9,20,30); side: C = Rz(90),
# rx 90 about local x = world y, so L = Ry(90); G = Rz(90) Ry(90); Ry(90)(1,0,0) = (0,0,-1),
# Rz(90)(0,0,-1) = (0,0,-1) -> (9,20,29).
# Frame 3: root RZ 90 turns the chain: up end = (1,0,0) + (-2,0,0); side end = + (0,1,0).
# Frame 4: side rx 90 then ry 90 (extrinsic, M = Ry Rx); L (1,0,0) = C M C^-1 (1,0,0):
# C^-1 -> (0,-1,0), Rx(90) -> (0,0,-1), Ry(90) -> (-1,0,0), C -> (0,-1,0): side end (1,1,0).
# (The other product order, Rx Ry, would give (0,0,-1).)
# The root orientation (about z) and the axis of "up" (about z) commute with every rotation
# they meet here, so they must not move any end point: C M C^-1 cancels them.
TINY_EXPECTED = np.array([
    [[1, 0, 0], [1, 2, 0], [2, 2, 0]],
    [[11, 20, 30], [9, 20, 30], [9, 20, 29]],
    [[1, 0, 0], [-1, 0, 0], [-1, 1, 0]],
    [[1, 0, 0], [1, 2, 0], [1, 1, 0]],
], dtype=float)


def tiny_asf_text() -> str:
    return TINY_ASF.format(length="1", angle="deg", ninety="90", thirty="0", fortyfive="0")


def write_tiny(folder: Path, *, length="1.0", angle="deg", unit="DEGREES", eol="\n",
               asf_name="tiny.asf", amc_name="tiny_01.amc") -> Path:
    def angle_text(degrees, as_degrees):
        return f"{degrees}" if as_degrees else repr(float(np.deg2rad(degrees)))
    asf = TINY_ASF.format(length=length, angle=angle, ninety=angle_text(90, angle == "deg"),
                          thirty=angle_text(30, angle == "deg"),
                          fortyfive=angle_text(45, angle == "deg"))
    q = angle_text(90, unit == "DEGREES")
    amc = TINY_AMC.format(unit=unit, q=q)
    (folder / asf_name).write_bytes(asf.replace("\n", eol).encode())
    (folder / amc_name).write_bytes(amc.replace("\n", eol).encode())
    return folder / amc_name


def test_hand_checked_two_bone_skeleton(tmp_path):
    motion = asfamc.read(write_tiny(tmp_path))
    assert motion.names == ["root", "up", "side"]
    assert list(motion.skeleton.parents) == [-1, 0, 1]
    np.testing.assert_allclose(motion.positions, TINY_EXPECTED, atol=1e-12)
    assert motion.units == "in" and motion.metres_per_unit == pytest.approx(0.0254)
    assert motion.source.asf.documentation[0].strip() == "Free text: two bones."
    assert motion.source.asf.bones["side"].limits == [(-180.0, 180.0), (-np.inf, np.inf)]
    assert motion.channels.shape == (4, 9)


@pytest.mark.parametrize("angle, unit", [("rad", "DEGREES"), ("deg", "RADIANS"), ("rad", "RADIANS")])
def test_radians_in_asf_and_amc_give_the_same_pose(tmp_path, angle, unit):
    motion = asfamc.read(write_tiny(tmp_path, angle=angle, unit=unit))
    np.testing.assert_allclose(motion.positions, TINY_EXPECTED, atol=1e-12)


def test_cmu_length_unit_and_crlf_hand_case(tmp_path):
    motion = asfamc.read(write_tiny(tmp_path, length="0.45", eol="\r\n"))
    np.testing.assert_allclose(motion.positions, TINY_EXPECTED, atol=1e-12)
    assert motion.units == "in/0.45"
    assert motion.metres_per_unit == pytest.approx(0.0254 / 0.45)
    out = tmp_path / "out"
    out.mkdir()
    written = asfamc.write(motion, out / "tiny_01.amc")
    assert written[0].read_bytes() == (tmp_path / "tiny_01.amc").read_bytes()
    assert written[1] == out / "tiny.asf"


@pytest.mark.parametrize("between", [b"\n# a comment between frames", b"\x0b", b"\xa0 \x1c",
                                     b"\xa0# a comment after a no-break space"])
def test_comments_and_blank_lines_between_frames_are_kept(tmp_path, between):
    # blank as str.strip has it (the lines are read so): a line of a vertical tab or a
    # no-break space alone is blank, a '#' after one a comment; such lines crashed the
    # reader (IndexError, an internal error) when the body was taken for one run of frames
    amc = write_tiny(tmp_path)
    data = amc.read_bytes().replace(b"\n2\n", b"\n" + between + b"\n2\n")
    amc.write_bytes(data)
    motion = asfamc.read(amc)
    np.testing.assert_allclose(motion.positions, TINY_EXPECTED, atol=1e-12)
    out = tmp_path / "out"
    out.mkdir()
    assert asfamc.write(motion, out / "a.amc")[0].read_bytes() == data
    changed = motion.copy()
    changed.channels[2, 5] = -45.0                  # frame 3, root RZ
    written = asfamc.write(changed, out / "b.amc")[0].read_bytes()
    assert written == data.replace(b"root 0 0 0 0 0 90", b"root 0 0 0 0 0 -45")


def test_trailing_blank_lines_are_kept(tmp_path):
    amc = write_tiny(tmp_path, eol="\r\n")
    data = amc.read_bytes() + b"\r\n  \r\n"
    amc.write_bytes(data)
    motion = asfamc.read(amc)
    np.testing.assert_allclose(motion.positions, TINY_EXPECTED, atol=1e-12)
    out = tmp_path / "out"
    out.mkdir()
    assert asfamc.write(motion, out / "a.amc")[0].read_bytes() == data


def test_amc_without_angle_line_uses_the_asf_angle_unit(tmp_path):
    amc = write_tiny(tmp_path, angle="rad", unit="RADIANS")
    amc.write_text(amc.read_text().replace(":RADIANS\n", ""))
    motion = asfamc.read(amc)
    np.testing.assert_allclose(motion.positions, TINY_EXPECTED, atol=1e-12)
    assert any("no :DEGREES/:RADIANS" in note for note in motion.notes)


def test_bone_translation_dofs_add_along_the_bone_axes(tmp_path):
    asf = tiny_asf_text().replace("dof rx ry", "dof tx ty")
    (tmp_path / "t.asf").write_text(asf)
    # side has axis Rz(90): local x = world y, local y = world -x
    (tmp_path / "t.amc").write_text(":DEGREES\n1\nroot 0 0 0 0 0 0\nup 0\nside 0.5 0.25\n")
    motion = asfamc.read(tmp_path / "t.amc")
    np.testing.assert_allclose(motion.positions[0, 2], [2 - 0.25, 2 + 0.5, 0], atol=1e-12)


def test_length_dof_is_refused_clearly(tmp_path):
    asf = tiny_asf_text().replace("dof rx ry", "dof rx l")
    (tmp_path / "t.asf").write_text(asf)
    (tmp_path / "t.amc").write_text(":DEGREES\n1\nroot 0 0 0 0 0 0\nup 0\nside 0 1\n")
    with pytest.raises(UnsupportedFeatureError, match=r"t\.asf:\d+: the 'l'"):
        asfamc.read(tmp_path / "t.amc")


def test_asf_is_found_by_prefix_single_file_or_option(tmp_path):
    amc = write_tiny(tmp_path, asf_name="tiny.asf", amc_name="tiny_07.amc")
    assert asfamc.read(amc).source.asf_path == str(tmp_path / "tiny.asf")
    (tmp_path / "tiny.asf").rename(tmp_path / "other.asf")
    assert asfamc.read(amc).source.asf_path == str(tmp_path / "other.asf")   # the only one
    (tmp_path / "third.asf").write_bytes((tmp_path / "other.asf").read_bytes())
    with pytest.raises(UnreadableFileError, match="tiny_07.amc.*cannot find the ASF"):
        asfamc.read(amc)
    assert asfamc.read(amc, asf=tmp_path / "third.asf").source.asf_path == str(tmp_path / "third.asf")


def test_changed_frame_count_is_numbered_from_the_first_source_frame(tmp_path):
    motion = asfamc.read(write_tiny(tmp_path))
    shorter = motion.replace(positions=motion.positions[1:], channels=motion.channels[1:])
    out = tmp_path / "out"
    out.mkdir()
    text = asfamc.write(shorter, out / "x.amc")[0].read_text()
    assert text.startswith("#!OML:ASF tiny.asf\n:FULLY-SPECIFIED\n:DEGREES\n1\nroot 10 20 30 0 0 0\n")
    back = asfamc.read(out / "x.amc")
    np.testing.assert_allclose(back.positions, TINY_EXPECTED[1:], atol=1e-12)


def test_rest_pose_from_asf_alone_writes_a_one_frame_amc(tmp_path):
    write_tiny(tmp_path)
    motion = formats.read(tmp_path / "tiny.asf")
    np.testing.assert_allclose(motion.positions, TINY_EXPECTED[:1], atol=1e-12)
    out = tmp_path / "out"
    out.mkdir()
    amc, asf = asfamc.write(motion, out / "rest.amc")
    assert amc.read_text() == ":FULLY-SPECIFIED\n:DEGREES\n1\nroot 0 0 0 0 0 0\nup 0\nside 0 0\n"
    assert asf.read_bytes() == (tmp_path / "tiny.asf").read_bytes()


def test_write_refuses_motion_without_channels_or_with_nan(tmp_path):
    motion = asfamc.read(write_tiny(tmp_path))
    with pytest.raises(WriteError, match="no channels"):
        asfamc.write(motion.replace(channels=None), tmp_path / "a.amc")
    bad = motion.copy()
    bad.channels[1, 2] = np.nan
    with pytest.raises(WriteError, match="NaN"):
        asfamc.write(bad, tmp_path / "b.amc")
    assert not (tmp_path / "b.amc").exists()


def test_sniff_recognises_amc_and_asf_but_not_bvh():
    assert asfamc.sniff(b"#!OML:ASF x.asf\r\n:FULLY-SPECIFIED\r\n:DEGREES\r\n1\r\n")
    assert asfamc.sniff(TINY_ASF.encode())
    assert not asfamc.sniff(b"HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n")


# ----------------------------------------------------------------- malformed
def cmu_copy(tmp_path: Path, amc_name="05_01.amc", asf_name="05.asf") -> tuple[Path, Path]:
    amc = shared(f"asfamc/{amc_name}")
    asf = shared(f"asfamc/{asf_name}")
    (tmp_path / asf_name).write_bytes(asf.read_bytes())
    (tmp_path / amc_name).write_bytes(amc.read_bytes())
    return tmp_path / amc_name, tmp_path / asf_name


def test_truncated_amc_is_refused_naming_the_frame(tmp_path):
    amc, _ = cmu_copy(tmp_path)
    lines = amc.read_bytes().split(b"\r\n")
    amc.write_bytes(b"\r\n".join(lines[:-6]))          # last frame loses its last bone lines
    with pytest.raises(UnreadableFileError, match=r"05_01\.amc:\d+: truncated: last frame 598"):
        asfamc.read(amc)


def test_truncated_amc_in_the_middle_of_a_number_is_refused(tmp_path):
    amc, _ = cmu_copy(tmp_path)
    data = amc.read_bytes()
    cut = data.index(b"lhumerus", len(data) // 2) + 12     # inside the first number
    amc.write_bytes(data[:cut])
    with pytest.raises(UnreadableFileError, match=r"05_01\.amc:\d+: truncated: the file ends mid-line"):
        asfamc.read(amc)


def test_file_cut_inside_its_last_number_reads_with_a_note(tmp_path):
    """The one truncation that cannot be told from a short number: say so."""
    amc, _ = cmu_copy(tmp_path)
    amc.write_bytes(amc.read_bytes()[:-4])                 # "ltoes 4.52449\r\n" -> "ltoes 4.524"
    motion = asfamc.read(amc)
    assert motion.channels[-1, -1] == 4.524
    assert any("does not end with a line break" in note for note in motion.notes)


def test_frame_missing_a_bone_line_is_refused_with_its_line(tmp_path):
    amc, _ = cmu_copy(tmp_path)
    lines = amc.read_bytes().split(b"\r\n")
    frame5 = 3 + 30 * 4                                    # 3 header lines, 30 lines a frame
    assert lines[frame5] == b"5" and lines[frame5 + 8].startswith(b"rclavicle")
    del lines[frame5 + 8]
    amc.write_bytes(b"\r\n".join(lines))
    with pytest.raises(UnreadableFileError,
                       match=r"05_01\.amc:132: frame 5: expected bone line 'rclavicle', found 'rhumerus'"):
        asfamc.read(amc)


def test_non_numeric_value_is_refused_with_its_line(tmp_path):
    amc, _ = cmu_copy(tmp_path)
    lines = amc.read_bytes().split(b"\r\n")
    lines[100] = lines[100].split(b" ")[0] + b" 1.0 abc" + b" 2" * (len(lines[100].split()) - 3)
    amc.write_bytes(b"\r\n".join(lines))
    with pytest.raises(UnreadableFileError, match=r"05_01\.amc:101: frame 4: 'abc' is not a number"):
        asfamc.read(amc)


def test_missing_asf_is_refused_naming_the_amc(tmp_path):
    amc, asf = cmu_copy(tmp_path)
    asf.unlink()
    with pytest.raises(UnreadableFileError, match=r"05_01\.amc: cannot find the ASF skeleton") as err:
        formats.read(amc)
    # what a command-line user can do (the CLI has no asf= option)
    assert "put the skeleton beside the AMC as 05.asf" in str(err.value)


@pytest.mark.parametrize("kind", ["a FIFO", "a folder", "broken symlink"])
def test_an_asf_name_that_is_no_file_is_said_to_be_so(kind, tmp_path):
    """A FIFO, a folder or a dangling link where the skeleton should be: the message says
    what is there (it said "no .asf file there"), and reading never blocks on the FIFO."""
    import os

    amc, asf = cmu_copy(tmp_path)
    asf.unlink()
    if kind == "a FIFO":
        os.mkfifo(asf)
    elif kind == "a folder":
        asf.mkdir()
    else:
        asf.symlink_to(tmp_path / "gone.asf")
    with hang_guard(), pytest.raises(UnreadableFileError) as err:
        formats.read(amc)
    assert f"found but not a file: {asf.name} ({kind})" in str(err.value)


def test_hierarchy_bone_missing_from_bonedata_is_refused(tmp_path):
    amc, asf = cmu_copy(tmp_path)
    asf.write_bytes(asf.read_bytes().replace(b"lhand lfingers", b"lhand lfingers lpinky"))
    with pytest.raises(UnreadableFileError,
                       match=r"05\.asf:\d+: bone 'lpinky' in :hierarchy is not defined in :bonedata"):
        formats.read(amc)


@pytest.mark.parametrize("which", ["amc", "asf"])
def test_empty_files_are_refused(tmp_path, which):
    amc, asf = cmu_copy(tmp_path)
    (amc if which == "amc" else asf).write_bytes(b"")
    with pytest.raises(UnreadableFileError, match=rf"05(_01)?\.{which}: file is empty"):
        asfamc.read(amc)


def test_garbage_is_refused_with_a_line_number(tmp_path):
    path = tmp_path / "junk.amc"
    path.write_bytes(b":DEGREES\nhello world\n")
    (tmp_path / "junk.asf").write_text(tiny_asf_text())
    with pytest.raises(UnreadableFileError, match=r"junk\.amc:2: expected a frame number"):
        asfamc.read(path)
    (tmp_path / "junk.asf").write_text(":bonedata\n  begin\n    name a\n  end\n:hierarchy\n")
    with pytest.raises(UnreadableFileError, match=r"junk\.asf:4: bone block opened at line 2 "
                                                  r"has no 'direction'"):
        asfamc.read(path)
    (tmp_path / "junk.asf").write_text(":bonedata\n begin\n name a\n direction 0 1 0\n length 1\n end\n")
    with pytest.raises(UnreadableFileError, match=r"junk\.asf: no :root section"):
        asfamc.read(path)
    (tmp_path / "junk.asf").write_text("just some\ntext\n")
    with pytest.raises(UnreadableFileError, match=r"junk\.asf:1: unexpected text"):
        asfamc.read(path)


def test_absurd_frame_number_is_refused(tmp_path):
    path = write_tiny(tmp_path)
    path.write_text(path.read_text().replace("\n3\n", "\n" + "9" * 30 + "\n"))
    with pytest.raises(UnreadableFileError, match=r"tiny_01\.amc:\d+: "):
        asfamc.read(path)


def test_bone_line_with_wrong_value_count_is_refused(tmp_path):
    path = write_tiny(tmp_path)
    path.write_text(path.read_text().replace("up 90", "up 90 1"))
    with pytest.raises(UnreadableFileError, match=r"tiny_01\.amc:\d+: frame 2: bone 'up' has 2 values"):
        asfamc.read(path)


def test_unknown_bone_in_amc_is_refused(tmp_path):
    path = write_tiny(tmp_path)
    path.write_text(path.read_text().replace("side 0 0\n2", "side 0 0\ntail 1\n2", 1))
    with pytest.raises(UnreadableFileError, match=r"tiny_01\.amc:8: bone 'tail' is not defined"):
        asfamc.read(path)


def test_asf_mass_that_is_not_positive_is_noted_not_refused(tmp_path):
    """':units mass 0' was refused as if the kinematics needed it; no position depends on
    the mass, so the skeleton reads (the hand-checked positions) with a note, while a
    length that is not positive is still refused naming its line."""
    amc = write_tiny(tmp_path)
    asf = tmp_path / "tiny.asf"
    asf.write_text(asf.read_text().replace("  mass 1.0", "  mass 0"))
    motion = asfamc.read(amc)
    np.testing.assert_allclose(motion.positions, TINY_EXPECTED, atol=1e-12)
    assert any("mass 0 is not positive" in n for n in motion.notes)
    text = asf.read_text()
    assert text.count("\n  length 1.0\n") == 1                 # the :units line
    asf.write_text(text.replace("\n  length 1.0\n", "\n  length 0\n"))
    with pytest.raises(UnreadableFileError, match=r"units length must be positive, got 0"):
        asfamc.read(amc)


def test_reading_an_amc_at_a_non_finite_rate_is_refused():
    import pytest

    from mocapfix import formats
    from mocapfix.core.errors import UnreadableFileError

    for fps in (float("nan"), float("inf"), 0.0):
        with pytest.raises(UnreadableFileError, match="frame rate must be a positive number"):
            formats.read(SAMPLE_DATA / "walker_01.amc", fps=fps)
