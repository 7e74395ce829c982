"""BVH reader/writer: real files, hand-computed cases, round trips, malformed input.

Independent reference for forward kinematics: bvhio (float32, its own Euler code).
"""
from __future__ import annotations


import numpy as np
import pytest

from conftest import hang_guard, need, shared, shared_files
from mocapfix.core.errors import UnreadableFileError, WriteError
from mocapfix.formats import bvh

# name: (joints, End Sites, channels, frames, fps, rotation orders) — from data/SOURCES.md
EXPECTED = {
    "cmu_cgspeed_131_01.bvh": (31, 7, 96, 994, 120, {"ZXY", "ZYX"}),
    "cmu_cgspeed_131_03.bvh": (31, 7, 96, 1102, 120, {"ZXY", "ZYX"}),
    "bvhpython_test_freebvh.bvh": (55, 15, 168, 69, 30, {"ZYX"}),
    "bvhpython_test_mocapbank.bvh": (19, 5, 60, 455, 30, {"ZXY"}),
    "pymo_AV_8Walk_Meredith_HVHA_Rep1.bvh": (23, 7, 72, 1064, 120, {"XYZ"}),
    "bandai_dataset-1_walk_normal_001.bvh": (22, 5, 132, 195, 30, {"ZXY"}),
    "bandai_dataset-2_run_normal_001.bvh": (22, 5, 132, 68, 30, {"ZXY"}),
}
BVH_FILES = shared_files("bvh", "*.bvh")


def _read_refused(path, **options) -> UnreadableFileError:
    with hang_guard():
        with pytest.raises(UnreadableFileError) as info:
            bvh.read(path, **options)
    assert str(path) in str(info.value)
    return info.value


# ---------------------------------------------------------------------------------------
# real files
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("path", BVH_FILES)
def test_shared_file_counts_match_sources(path):
    path = need(path)
    n_joints, n_end, n_channels, n_frames, fps, orders = EXPECTED[path.name]
    motion = bvh.read(path)
    end_sites = np.array(motion.source.end_sites)
    assert int((~end_sites).sum()) == n_joints
    assert int(end_sites.sum()) == n_end
    assert motion.channels.shape == (n_frames, n_channels)
    assert motion.positions.shape == (n_frames, n_joints + n_end, 3)
    assert motion.positions.dtype == np.float64 and motion.channels.dtype == np.float64
    assert motion.fps == pytest.approx(fps, rel=1e-4)
    assert {a for a, e in zip(motion.rig.rot_axes, end_sites) if not e} == orders
    assert len(set(motion.names)) == len(motion.names)
    assert np.isfinite(motion.positions).all()
    assert any("guess" in note for note in motion.notes)  # units are always a guess
    assert motion.metres_per_unit > 0


def test_bandai_every_joint_has_six_channels():
    motion = bvh.read(shared("bvh/bandai_dataset-1_walk_normal_001.bvh"))
    rig = motion.rig
    for j, is_end in enumerate(motion.source.end_sites):
        if not is_end:
            assert rig.rot_axes[j] == "ZXY"
            assert (rig.trans_columns[j] >= 0).all()
    # with position channels REPLACING the offsets, bone lengths are the offsets' lengths
    # (the channels repeat them); adding would double every bone
    spine, chest = motion.index("Spine"), motion.index("Chest")
    length = np.linalg.norm(motion.positions[:, chest] - motion.positions[:, spine], axis=1)
    np.testing.assert_allclose(length, np.linalg.norm([8.98455, -0.406207, 0]), rtol=1e-4)


def test_unit_guesses_on_shared_files():
    assert bvh.read(shared("bvh/bvhpython_test_mocapbank.bvh")).units == "cm"
    assert bvh.read(shared("bvh/pymo_AV_8Walk_Meredith_HVHA_Rep1.bvh")).units == "in"
    cmu = bvh.read(shared("bvh/cmu_cgspeed_131_01.bvh"))
    assert cmu.units == "unknown"
    assert cmu.metres_per_unit == pytest.approx(0.0254 / 0.45)


def _bvhio_world_positions(path, frames):
    """World positions from bvhio for every joint and End Site, keyed by joint name.

    Joints come from bvhio's hierarchy API (``loadPose`` + ``PositionWorld``). bvhio's
    hierarchy has no End Sites; they are placed by composing bvhio's own per-joint
    keyframe poses (its Euler conversion and its offset/channel rule), and that
    composition is itself checked against the hierarchy API for the joints.
    """
    import bvhio

    root = bvhio.readAsHierarchy(str(path))
    container = bvhio.readAsBvh(str(path))
    out = {}
    for f in frames:
        root.loadPose(f)
        joints = {j.Name: np.array(tuple(j.PositionWorld)) for j, _, _ in root.layout()}
        composed, ends = {}, {}
        stack = [(container.Root, None, None)]
        while stack:
            node, parent_pos, parent_rot = stack.pop()
            key = node.Keyframes[f]
            if parent_pos is None:
                pos, rot = key.Position, key.Rotation
            else:
                pos, rot = parent_pos + parent_rot * key.Position, parent_rot * key.Rotation
            composed[node.Name] = np.array(tuple(pos))
            if not node.Children:
                ends[node.Name] = np.array(tuple(pos + rot * node.EndSite))
            stack.extend((child, pos, rot) for child in node.Children)
        out[f] = joints, composed, ends
    return out


@pytest.mark.slow
@pytest.mark.parametrize("path", BVH_FILES)
def test_forward_kinematics_matches_bvhio(path):
    path = need(path)
    motion = bvh.read(path)
    frames = sorted({0, 1, motion.n_frames // 2, motion.n_frames - 1})
    reference = _bvhio_world_positions(path, frames)
    size = np.ptp(motion.positions[0], axis=0).max()
    tolerance = 1e-4 * size  # bvhio works in float32
    parents = motion.rig.parents
    end_sites = motion.source.end_sites
    for f in frames:
        joints, composed, ends = reference[f]
        checked = 0
        for j, name in enumerate(motion.names):
            if end_sites[j]:
                expected = ends[motion.names[parents[j]]]
            else:
                expected = joints[name]
                np.testing.assert_allclose(composed[name], expected, atol=tolerance)
            np.testing.assert_allclose(motion.positions[f, j], expected, atol=tolerance,
                                       err_msg=f"{name} frame {f}")
            checked += 1
        assert checked == motion.n_joints


# ---------------------------------------------------------------------------------------
# hand-made files with answers computed on paper
# ---------------------------------------------------------------------------------------
TINY = """HIERARCHY
ROOT Hips
{
  OFFSET 1 2 3
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Chest
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 5 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.04
0 0 0 0 0 0 0 0 0
10 0 0 90 0 0 0 0 0
0 0 0 0 0 0 90 90 0
"""
# Rz(90): (x, y, z) -> (-y, x, z);  Rx(90): (x, y, z) -> (x, -z, y)
TINY_POSITIONS = np.array([
    # frame 0: channels replace the root OFFSET (1, 2, 3) -> root at the origin
    [[0, 0, 0], [0, 10, 0], [0, 15, 0]],
    # frame 1: root at (10, 0, 0) turned 90° about Z: chest offset (0,10,0) -> (-10,0,0)
    [[10, 0, 0], [0, 0, 0], [-5, 0, 0]],
    # frame 2: chest Z=90 then X=90 (intrinsic, Rz·Rx): (0,5,0) -Rx-> (0,0,5) -Rz-> (0,0,5)
    # (the extrinsic reading Rx·Rz would give (-5, 0, 0))
    [[0, 0, 0], [0, 10, 0], [0, 10, 5]],
], dtype=float)


def _write(tmp_path, text: str | bytes, name: str = "t.bvh"):
    path = tmp_path / name
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def test_tiny_file_positions_computed_on_paper(tmp_path):
    motion = bvh.read(_write(tmp_path, TINY))
    assert motion.names == ["Hips", "Chest", "Chest_End"]
    assert list(motion.rig.parents) == [-1, 0, 1]
    assert motion.rig.rot_axes == ["ZXY", "ZXY", ""]
    assert motion.rig.rot_columns[1] == [6, 7, 8]
    assert motion.rig.trans_columns[0].tolist() == [0, 1, 2]
    assert motion.fps == pytest.approx(25.0)
    np.testing.assert_allclose(motion.positions, TINY_POSITIONS, atol=1e-12)
    assert list(motion.skeleton.parents) == [-1, 0, 1]


def test_tabs_whitespace_and_mixed_line_endings(tmp_path):
    lines = TINY.splitlines()
    endings = ["\r\n", "\n", "\r\n", "\r", "\n"]
    messy = "".join(
        "\t" * (k % 3) + line.replace(" ", " \t  " if k % 2 else "\t") + "   " * (k % 2)
        + endings[k % len(endings)]
        for k, line in enumerate(lines))
    motion = bvh.read(_write(tmp_path, messy))
    np.testing.assert_allclose(motion.positions, TINY_POSITIONS, atol=1e-12)
    assert motion.names == ["Hips", "Chest", "Chest_End"]


def test_old_mac_cr_line_endings(tmp_path):
    path = _write(tmp_path, TINY.replace("\n", "\r"))
    motion = bvh.read(path)
    np.testing.assert_allclose(motion.positions, TINY_POSITIONS, atol=1e-12)
    out = tmp_path / "out.bvh"
    bvh.write(motion, out)
    assert out.read_bytes() == path.read_bytes()


def test_real_crlf_lf_mix_and_byte_order_mark(tmp_path):
    path = shared("bvh/cmu_cgspeed_131_01.bvh")
    data = path.read_bytes()
    assert b"\r\n" in data and data.count(b"\n") > data.count(b"\r\n")  # really mixed
    plain = bvh.read(path)
    with_bom = bvh.read(_write(tmp_path, b"\xef\xbb\xbf" + data))
    np.testing.assert_array_equal(with_bom.channels, plain.channels)


def test_channels_zero_six_channel_child_and_nonzero_root_offset_match_bvhio(tmp_path):
    text = """HIERARCHY
ROOT Root
{
  OFFSET 3 40 -2
  CHANNELS 6 Xposition Yposition Zposition Yrotation Xrotation Zrotation
  JOINT Fixed
  {
    OFFSET 0 5 0
    CHANNELS 0
    JOINT Loose
    {
      OFFSET 1 2 3
      CHANNELS 6 Xposition Yposition Zposition Xrotation Zrotation Yrotation
      End Site
      {
        OFFSET 0 0 7
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.5
3 40 -2 10 20 30 4 5 6 -15 25 35
1.5 41 -3 -40 5 60 0.5 2 3.5 70 -20 10
"""
    path = _write(tmp_path, text)
    motion = bvh.read(path)
    assert motion.rig.rot_axes == ["YXZ", "", "XZY", ""]
    assert motion.rig.trans_columns.tolist() == [[0, 1, 2], [-1, -1, -1], [6, 7, 8], [-1, -1, -1]]
    assert not motion.rig.trans_adds_offset.any()
    # frame 0 on paper: Loose is at Fixed + F_Fixed (4,5,6) (its channels replace (1,2,3))
    fixed = motion.positions[0, 1]
    np.testing.assert_allclose(motion.positions[0, 0], [3, 40, -2])
    frame_fixed = motion.rig.forward(motion.channels)[1][0, 1]
    np.testing.assert_allclose(motion.positions[0, 2], fixed + frame_fixed @ [4, 5, 6],
                               atol=1e-12)
    reference = _bvhio_world_positions(path, [0, 1])
    for f in (0, 1):
        joints, _, ends = reference[f]
        for j, name in enumerate(["Root", "Fixed", "Loose"]):
            np.testing.assert_allclose(motion.positions[f, j], joints[name], atol=1e-4)
        np.testing.assert_allclose(motion.positions[f, 3], ends["Loose"], atol=1e-4)


def test_joint_names_with_spaces_and_duplicates(tmp_path):
    text = TINY.replace("JOINT Chest", "JOINT Upper Chest").replace("ROOT Hips", "ROOT Upper Chest")
    motion = bvh.read(_write(tmp_path, text))
    assert motion.names == ["Upper Chest", "Upper Chest_2", "Upper Chest_2_End"]
    assert any("duplicate" in note for note in motion.notes)


def test_user_fps_overrides_with_note(tmp_path):
    motion = bvh.read(_write(tmp_path, TINY), fps=50.0)
    assert motion.fps == 50.0
    assert any("overrides" in note for note in motion.notes)
    assert not any("overrides" in n for n in bvh.read(_write(tmp_path, TINY), fps=25.0).notes)


def test_sniff():
    assert bvh.sniff(b"HIERARCHY\r\nROOT Hips")
    assert bvh.sniff(b"\xef\xbb\xbf  \nHIERARCHY\nROOT")
    assert not bvh.sniff(b"#!OML:ASF\n")
    assert not bvh.sniff(b"")


# ---------------------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("path", BVH_FILES)
def test_unchanged_round_trip_is_byte_identical(path, tmp_path):
    path = need(path)
    out = tmp_path / "out.bvh"
    written = bvh.write(bvh.read(path), out)
    assert written == [out]
    assert out.read_bytes() == path.read_bytes()


def test_changed_values_round_trip_and_untouched_bytes_stay(tmp_path):
    path = shared("bvh/cmu_cgspeed_131_01.bvh")
    original = path.read_bytes()
    motion = bvh.read(path)
    changed = motion.copy()
    changed.channels[10:20, 5] += 0.1234567891
    changed.channels[500, :] = np.linspace(-100, 100, changed.channels.shape[1])
    out = tmp_path / "changed.bvh"
    bvh.write(changed, out)
    back = bvh.read(out)
    np.testing.assert_allclose(back.channels, changed.channels, rtol=0, atol=1e-6)
    np.testing.assert_allclose(back.positions, bvh.read(path).rig.positions(changed.channels),
                               atol=1e-4)
    data = out.read_bytes()
    head = motion.source.head + motion.source.frames_line + motion.source.frame_time_line
    assert data.startswith(head) and original.startswith(head)
    original_lines = original.splitlines(keepends=True)
    new_lines = data.splitlines(keepends=True)
    assert len(new_lines) == len(original_lines)
    first_frame = len(head.splitlines())
    differing = [k - first_frame for k, (a, b) in enumerate(zip(original_lines, new_lines))
                 if a != b]
    assert differing == list(range(10, 20)) + [500]
    # a changed line keeps the unchanged tokens and the line ending
    old_line, new_line = original_lines[first_frame + 10], new_lines[first_frame + 10]
    assert old_line.split()[:5] == new_line.split()[:5]
    assert old_line.split()[6:] == new_line.split()[6:]
    assert new_line.endswith(b"\r\n") == old_line.endswith(b"\r\n")


def test_fewer_frames_and_new_rate_update_header_lines(tmp_path):
    path = _write(tmp_path, TINY.replace("\n", "\r\n"))
    motion = bvh.read(path)
    shorter = motion.replace(channels=motion.channels[:2], positions=motion.positions[:2],
                             fps=50.0)
    out = tmp_path / "short.bvh"
    bvh.write(shorter, out)
    data = out.read_bytes()
    assert b"Frames: 2\r\n" in data and b"Frame Time: 0.02\r\n" in data
    back = bvh.read(out)
    assert back.n_frames == 2 and back.fps == pytest.approx(50.0)
    np.testing.assert_allclose(back.positions, TINY_POSITIONS[:2], atol=1e-12)
    assert data.count(b"\n") == data.count(b"\r\n")  # line endings as in the source


def test_more_frames_than_source(tmp_path):
    path = _write(tmp_path, TINY.rstrip("\n"))  # the last line has no line ending
    motion = bvh.read(path)
    longer = np.vstack([motion.channels, motion.channels[1:2] + 0.5])
    out = tmp_path / "long.bvh"
    bvh.write(motion.replace(channels=longer, positions=motion.rig.positions(longer)), out)
    back = bvh.read(out)
    np.testing.assert_allclose(back.channels, longer, atol=1e-6)
    assert back.n_frames == 4


def test_write_refuses_what_it_cannot_write(tmp_path):
    motion = bvh.read(_write(tmp_path, TINY))
    with pytest.raises(WriteError):
        bvh.write(motion.replace(channels=None), tmp_path / "a.bvh")
    with pytest.raises(WriteError):
        bvh.write(motion.replace(channels=motion.channels[:, :5]), tmp_path / "b.bvh")
    nan = motion.channels.copy()
    nan[1, 3] = np.nan
    with pytest.raises(WriteError, match="Hips.Zrotation"):
        bvh.write(motion.replace(channels=nan), tmp_path / "c.bvh")
    with pytest.raises(WriteError):
        bvh.write(motion.replace(source=None), tmp_path / "d.bvh")
    assert not list(tmp_path.glob("[abcd].bvh*")) and not list(tmp_path.glob(".*part"))


# ---------------------------------------------------------------------------------------
# malformed input: one UnreadableFileError naming the file, quickly
# ---------------------------------------------------------------------------------------
def test_every_truncation_of_a_small_file_is_refused(tmp_path):
    data = TINY.encode()
    last_line_start = data.rstrip(b"\n").rfind(b"\n") + 1
    last_separator = data.rstrip(b"\n").rfind(b" ")
    for cut in range(0, last_separator + 1):
        path = _write(tmp_path, data[:cut], f"cut{cut}.bvh")
        error = _read_refused(path)
        if cut > last_line_start:
            assert "truncated" in error.reason
    # cutting only the final line ending leaves a complete file
    assert bvh.read(_write(tmp_path, data[:-1], "full.bvh")).n_frames == 3


@pytest.mark.parametrize("where", ["hierarchy", "motion header", "mid-line", "line boundary"])
def test_truncated_real_file_is_refused(where, tmp_path):
    data = shared("bvh/cmu_cgspeed_131_01.bvh").read_bytes()
    motion_at = data.index(b"MOTION")
    first_frame = data.index(b"Frame Time")
    cut = {
        "hierarchy": motion_at // 2,
        "motion header": motion_at + 12,
        "mid-line": first_frame + len(data[first_frame:]) // 2,
        "line boundary": data.index(b"\n", len(data) // 2) + 1,
    }[where]
    error = _read_refused(_write(tmp_path, data[:cut]))
    assert error.line is not None
    if where in ("mid-line", "line boundary"):
        assert "truncated" in error.reason and "994" in error.reason


def test_frames_larger_than_present_is_refused_or_read_on_request(tmp_path):
    path = _write(tmp_path, TINY.replace("Frames: 3", "Frames: 1000000000"))
    error = _read_refused(path)
    assert "truncated" in error.reason and "3 complete" in error.reason
    motion = bvh.read(path, allow_truncated=True)
    assert motion.n_frames == 3
    assert any("truncated" in note for note in motion.notes)
    np.testing.assert_allclose(motion.positions, TINY_POSITIONS, atol=1e-12)


def test_partial_last_line_read_on_request(tmp_path):
    data = TINY.encode()
    path = _write(tmp_path, data[: data.rstrip(b"\n").rfind(b" ")])
    motion = bvh.read(path, allow_truncated=True)
    assert motion.n_frames == 2
    assert any("8 of 9 values" in note for note in motion.notes)


def test_frames_beyond_an_under_counted_header_are_read_and_declared(tmp_path):
    """An exporter that writes too small a ``Frames:`` count: every frame line in the file is
    read (a cleaner must not drop 290 of 300 frames), and the written file declares them."""
    path = _write(tmp_path, TINY.replace("Frames: 3", "Frames: 2"))
    motion = bvh.read(path)
    assert motion.n_frames == 3
    np.testing.assert_allclose(motion.positions, TINY_POSITIONS, atol=1e-12)
    assert any("'Frames: 2' but the file holds 3 frame lines" in note for note in motion.notes)
    out = tmp_path / "out.bvh"
    bvh.write(motion, out)
    assert out.read_text() == TINY          # the count corrected, every other byte as read


def test_lines_after_the_frames_that_are_not_frames_are_ignored_with_a_note(tmp_path):
    for extra in ("0 0 0\n", "end of take\n", "1 2 3 4 5 6 7 8 nan\n"):
        path = _write(tmp_path, TINY.replace("Frames: 3", "Frames: 2") + extra)
        motion = bvh.read(path)
        assert motion.n_frames == 2
        assert any("2 line(s) after the 2 declared frames (from line 21) are not frames"
                   in note for note in motion.notes), extra
        out = tmp_path / "out.bvh"
        bvh.write(motion, out)
        assert out.read_text() == TINY.replace("Frames: 3", "Frames: 2").rsplit("0 0 0 0 0 0 90", 1)[0]


def test_a_truncated_file_read_on_request_is_written_with_its_real_count(tmp_path):
    path = _write(tmp_path, TINY.replace("Frames: 3", "Frames: 1000"))
    motion = bvh.read(path, allow_truncated=True)
    out = tmp_path / "out.bvh"
    bvh.write(motion, out)
    assert out.read_text() == TINY
    assert bvh.read(out).n_frames == 3


def test_frames_count_spelt_oddly_round_trips_byte_identical(tmp_path):
    path = _write(tmp_path, TINY.replace("Frames: 3", "Frames:   003  "))
    out = tmp_path / "out.bvh"
    bvh.write(bvh.read(path), out)
    assert out.read_bytes() == path.read_bytes()


@pytest.mark.parametrize("change, message", [
    (("10 0 0 90 0 0 0 0 0", "10 0 0 90 0 0 0 0"), "frame 2 has 8 values, expected 9"),
    (("0 0 0 0 0 0 90 90 0", "0 0 0 0 0 0 90 90"), "truncated"),  # short LAST line
    (("10 0 0 90 0 0 0 0 0", "10 0 0 90 0 0 0 0 0 1"), "frame 2 has 10 values"),
    (("10 0 0 90", "10 0 abc 90"), "'abc'"),
    (("10 0 0 90", "10 0 nan 90"), "'nan'"),
    (("MOTION\n", ""), "MOTION"),
    (("  }\n}\n", "  }\n}\n}\n"), "unbalanced"),
    (("    }\n  }\n}\n", "    }\n  }\n"), "closing"),
    (("OFFSET 0 10 0", "OFFSET 0 ten 0"), "not a number"),
    (("CHANNELS 3 Z", "CHANNELS 4 Z"), "declares 4"),
    (("Frames: 3", "Frames: three"), "whole number"),
    (("Frame Time: 0.04", "Frame Time: 0"), "positive"),
    (("HIERARCHY", "HIERARCHIE"), "HIERARCHY"),
])
def test_malformed_files_are_refused(change, message, tmp_path):
    old, new = change
    assert old in TINY
    error = _read_refused(_write(tmp_path, TINY.replace(old, new, 1)))
    assert message in str(error)


def test_wrong_line_is_named(tmp_path):
    error = _read_refused(_write(tmp_path, TINY.replace("10 0 0 90", "10 0 x 90")))
    assert error.line == TINY.splitlines().index("10 0 0 90 0 0 0 0 0") + 1


@pytest.mark.parametrize("content", [b"", b"   \n\r\n", b"HIERARCHY\n", b"\x00\xff" * 100])
def test_empty_and_garbage_files_are_refused(content, tmp_path):
    _read_refused(_write(tmp_path, content))


def test_registry_reads_bvh(tmp_path):
    from mocapfix import formats

    path = _write(tmp_path, TINY)
    assert formats.detect(path) == "bvh"
    np.testing.assert_allclose(formats.read(path).positions, TINY_POSITIONS, atol=1e-12)


def test_positions_in_chunks_are_bit_identical_to_one_forward_pass():
    from conftest import SAMPLE_DATA

    from mocapfix.core.kinematics import positions_in_chunks

    motion = bvh.read(SAMPLE_DATA / "walk.bvh")
    whole = motion.rig.positions(motion.channels)
    chunked = positions_in_chunks(motion.rig, motion.channels, chunk=7)
    assert chunked.tobytes() == whole.tobytes()
    assert motion.positions.tobytes() == whole.tobytes()


@pytest.mark.parametrize("name", ["bvh/cmu_cgspeed_131_01.bvh", "asfamc/05_01.amc"])
def test_a_read_that_shares_its_values_makes_no_copy(tmp_path, name):
    """``formats.read(..., share_values=True)`` (what ``clean`` reads with): the BVH and
    AMC readers keep the channels they read as the source's values themselves, read-only
    (a copy was one more whole-take array at the read's peak), the same values as a plain
    read, and the motion writes back byte for byte."""
    from mocapfix import formats

    path = shared(name)
    module = formats.module(formats.detect(path))
    plain, motion = module.read(path), module.read(path, share_values=True)
    assert plain.channels is not plain.source.values and plain.channels.flags.writeable
    assert motion.channels is motion.source.values and not motion.channels.flags.writeable
    np.testing.assert_array_equal(motion.channels, plain.channels)
    again = formats.read(path, share_values=True)
    assert again.channels is again.source.values
    out = tmp_path / path.name
    formats.write(again, out)
    assert out.read_bytes() == path.read_bytes()


def test_values_shared_with_the_motion_read_are_read_only_and_write_the_same_bytes(tmp_path):
    """``formats.share_values_read`` (what ``clean`` does after reading): the source's
    copy of the values read becomes the motion's channels, read-only, and the motion
    still writes back byte for byte; an edited copy is written with its edits."""
    from mocapfix import formats

    path = shared("bvh/cmu_cgspeed_131_01.bvh")
    motion = bvh.read(path)
    formats.share_values_read(motion)
    assert motion.channels is motion.source.values and not motion.channels.flags.writeable
    with pytest.raises(ValueError):
        motion.channels[0, 0] = 1.0
    assert bvh.write(motion, tmp_path / "same.bvh")[0].read_bytes() == path.read_bytes()
    changed = motion.copy()
    changed.channels[10, 5] += 0.25
    back = bvh.read(bvh.write(changed, tmp_path / "changed.bvh")[0])
    assert abs(back.channels[10, 5] - motion.channels[10, 5] - 0.25) < 1e-5
