"""A take over the memory budget cleaned with its input kept on disk
(``clean_motion(..., keep_input_on_disk=folder)``, what ``clean_file`` does): the output
arrays are the input's own, cleaned in place, while the report and the writer read the
input's values back from an unlinked file. On real files of every format, cleaned in
windows with the default config: the written file and the report are those of the same
clean with the input held in memory, the values read back are the input's, and nothing is
left in the folder."""
from __future__ import annotations

import os

import numpy as np
import pytest

from mocapfix import formats
from mocapfix.cleaning import clean_file, clean_motion
from mocapfix.config import load_config
from mocapfix.core.diskarray import FramesOnDisk
from mocapfix.core.presets import resolve_config
from mocapfix.pipeline.windows import Windows
from mocapfix.quality.report import build_report, to_html, to_json
from tests.conftest import FORMATS_DATA, need, output_tree, shared

FILES = ["c3d/cmu_85_02.c3d", "bvh/cmu_cgspeed_131_01.bvh", "asfamc/05_01.amc",
         "kinect/kv2_laban_Ges01_wavehand.csv", "kinect/kv1_utkinect_joints_s02_e01.txt"]


def _path(name: str):
    return need(FORMATS_DATA / name[len("formats/"):]) if name.startswith("formats/") \
        else shared(name)


def _corrupted(path, folder):
    """A copy of the file at ``path`` in ``folder`` with work for the default: the
    occlusion protocol's mixed corruption (marker and Kinect files), or 40° spikes on
    three rotation channels (BVH, AMC); written by its own writer, so that the copy is
    read as a file of the format is (a BVH's or AMC's values read shared with the
    motion, as ``clean_file`` reads them)."""
    from mocapfix.bench.corrupt import occlusion

    motion = formats.read(path)
    if motion.channels is None:
        motion = occlusion(motion, "mixed", 0)[0]
    else:
        channels = motion.channels.copy()
        cols = [c[0] for c in motion.rig.rot_columns if len(c) and c[0] >= 0][3:6]
        for k, c in enumerate(cols):
            channels[[60 + 97 * k, 300 + 41 * k], c] += 40.0
        motion = motion.replace(channels=channels, positions=motion.rig.positions(channels))
    folder.mkdir()
    for extra in path.parent.glob("*.asf"):             # an AMC's skeleton beside it
        (folder / extra.name).write_bytes(extra.read_bytes())
    formats.write(motion, folder / path.name)
    return folder / path.name


def _clean(path, folder, disk):
    """Read as ``clean_file`` reads, clean in three windows, report, write."""
    motion = formats.read(path)
    formats.share_values_read(motion)
    overlap = max(16, motion.n_frames // 10)
    windows = Windows(max(motion.n_frames // 3, 2 * overlap), overlap)
    pipeline = load_config(resolve_config("default"))
    result = clean_motion(motion, pipeline, windows=windows, keep_input_on_disk=disk)
    report = build_report(result, pipeline.report)
    folder.mkdir()
    formats.write(result.cleaned, folder / path.name)
    (folder / f"{path.name}.report.json").write_text(to_json(report))
    return result, output_tree(folder), to_html(report, result)


@pytest.mark.parametrize("name", FILES + ["formats/trc/btk_Gait.trc", "formats/trc/btk_Knee.trc"])
def test_the_same_output_and_report_as_with_the_input_held(tmp_path, name):
    path = _corrupted(_path(name), tmp_path / "input")
    read_whole = formats.read(path)
    held, files_held, html_held = _clean(path, tmp_path / "held", None)
    disk = tmp_path / "disk"
    disk.mkdir()
    kept, files_kept, html_kept = _clean(path, tmp_path / "kept", disk)
    assert isinstance(kept.original.positions, FramesOnDisk)
    assert isinstance(held.original.positions, np.ndarray)
    assert os.listdir(disk) == []                 # the file is unlinked from the start
    np.testing.assert_array_equal(np.asarray(kept.original.positions), read_whole.positions)
    np.testing.assert_array_equal(kept.original.missing, read_whole.missing)
    # what the writer compares with (shared with the motion read) is read back too
    shared_values = "values" if read_whole.channels is not None else "original"
    if hasattr(kept.original.source, shared_values):
        assert isinstance(getattr(kept.original.source, shared_values), FramesOnDisk)
    if read_whole.channels is not None:
        assert isinstance(kept.original.channels, FramesOnDisk)
        np.testing.assert_array_equal(np.asarray(kept.original.channels), read_whole.channels)
    np.testing.assert_array_equal(kept.cleaned.positions, held.cleaned.positions)
    assert files_kept == files_held               # the output and the report
    report = files_kept[f"{path.name}.report.json"]
    assert report["file"]["samples_filled"] + report["file"]["samples_flagged"] > 0 \
        or any(j["correction_mm"]["max"] for j in report["joints"])   # work was done
    # the HTML differs only in the steps' seconds
    strip = (lambda h: __import__("re").sub(r"<td>[0-9.]+</td></tr>", "", h))
    assert strip(html_kept) == strip(html_held)


def test_a_folder_that_cannot_take_the_input_keeps_it_in_memory(tmp_path):
    path = shared("c3d/cmu_85_02.c3d")
    held, files_held, _ = _clean(path, tmp_path / "held", None)
    kept, files_kept, _ = _clean(path, tmp_path / "kept", tmp_path / "not-there")
    assert isinstance(kept.original.positions, np.ndarray)
    report = files_kept.pop(f"{path.name}.report.json")
    note = (f"the input could not be kept on disk in {tmp_path / 'not-there'} while it was "
            "cleaned (No such file or directory): it was held in memory beside the output")
    assert note in report["file"]["notes"]
    report["file"]["notes"].remove(note)
    assert report == files_held.pop(f"{path.name}.report.json")
    assert files_kept == files_held


def test_clean_file_keeps_a_long_take_on_disk_in_the_output_folder(tmp_path, monkeypatch):
    """``clean_file`` of a take over the memory budget (64 MB here, windows asked of
    the budget) keeps its input beside the output: the disk arrays are made in the
    output's folder (the nearest that exists) and the output is as without."""
    import mocapfix.core.diskarray as diskarray

    folders = []
    real = diskarray.FramesOnDisk.__init__

    def spy(self, array, folder=None):
        folders.append(folder)
        real(self, array, folder)
    pipeline = load_config(resolve_config("default"))
    monkeypatch.setattr("mocapfix.cleaning.window_for",
                        lambda budget, T, J, fps: Windows(300, 60))
    path = shared("c3d/cmu_85_02.c3d")
    clean_file(path, tmp_path / "held" / path.name, pipeline, reports=("json",))
    monkeypatch.setattr(diskarray.FramesOnDisk, "__init__", spy)
    clean_file(path, tmp_path / "kept" / "deeper" / path.name, pipeline, reports=("json",))
    assert folders == [tmp_path, tmp_path]       # positions, confidence; 'kept' not yet made
    assert output_tree(tmp_path / "held") == output_tree(tmp_path / "kept" / "deeper")
