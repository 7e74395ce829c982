"""The Python API a notebook uses (issue "docs": `mocapfix.clean`, `check`, `load_config`
accepting preset names, `Motion.from_arrays`, the unit rule and the warning for a motion
no step applies to), through public names only, and the docstrings' examples run."""
from __future__ import annotations

import doctest
import os
import warnings

import numpy as np
import pytest

import mocapfix
from conftest import REPO, hang_guard, shared


def test_a_notebook_cleans_a_shared_c3d_with_the_default_and_a_preset_with_overrides():
    motion = mocapfix.read(shared("c3d/c3dorg_s28_dynamic.C3D"))
    cleaned, report = mocapfix.clean(motion)
    assert report["schema"] == "mocapfix.report/1" and report["file"]["samples_filled"] > 0
    assert cleaned.missing.sum() < motion.missing.sum()
    assert np.array_equal(cleaned.positions[~motion.missing], motion.positions[~motion.missing]) \
        or report["file"]["samples_flagged"] > 0          # measured samples kept but judged ones
    _, strict_report = mocapfix.clean(motion, "optical-c3d", max_fill_error="5 mm")
    preset, preset_report = mocapfix.clean(motion, "optical-c3d")
    assert strict_report["file"]["samples_filled"] < preset_report["file"]["samples_filled"]
    slower, _ = mocapfix.clean(motion, "optical-c3d", butterworth={"cutoff": "4 Hz"})

    def jitter(m):
        return np.nanmean(np.abs(np.diff(m.positions, n=2, axis=0)))
    assert jitter(slower) < 0.95 * jitter(preset)           # 4 Hz smooths more than 6 Hz
    # the preset as a pipeline, and the same call from a path
    pipeline = mocapfix.load_config("optical-c3d")
    again, _ = mocapfix.clean(shared("c3d/c3dorg_s28_dynamic.C3D"), pipeline)
    assert np.array_equal(again.positions, preset.positions, equal_nan=True)


def test_an_override_that_names_nothing_is_refused():
    with pytest.raises(mocapfix.MocapfixError, match="neither a config key"):
        mocapfix.clean(REPO / "sample_data" / "walk.bvh", cutoff="6 Hz")


def test_check_judges_a_file_and_a_motion_alike():
    path = REPO / "sample_data" / "walk_markers.c3d"
    by_path, by_motion = mocapfix.check(path), mocapfix.check(mocapfix.read(path))
    assert by_path["status"] == by_motion["status"] and by_path["findings"] == by_motion["findings"]
    assert mocapfix.check(path, would_clean="default")["would_clean"]["samples_filled"] >= 0


def test_a_motion_from_arrays_is_cleaned_as_its_kind_and_one_without_a_kind_is_said():
    src = mocapfix.read(REPO / "sample_data" / "walk_markers.c3d")
    bare = mocapfix.Motion(src.positions, src.names, src.fps)
    with pytest.warns(UserWarning, match="steps .limited to formats. do not run"):
        _, report = mocapfix.clean(bare)
    assert any("Motion.format is 'unknown'" in n for n in report["file"]["notes"])
    built = mocapfix.Motion.from_arrays(src.positions, src.names, src.fps, units=src.units)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _, report = mocapfix.clean(built)
    _, as_file = mocapfix.clean(src)
    assert report["file"]["samples_filled"] == as_file["file"]["samples_filled"] > 0
    with pytest.raises(ValueError, match="kind must be one of"):
        mocapfix.Motion.from_arrays(src.positions, src.names, src.fps, kind="bones")


def test_a_bare_number_from_python_gets_the_yaml_rule_and_says_so():
    from mocapfix.cleaners import build

    with pytest.warns(UserWarning, match="cutoff: 6 has no unit; read as '6 Hz'"):
        bare = build("butterworth", cutoff=6)
    assert bare["cutoff"] == build("butterworth", cutoff="6 Hz")["cutoff"]


@pytest.mark.parametrize("module", ["mocapfix.api", "mocapfix.core.motion"])
def test_the_docstring_examples_run(module, monkeypatch):
    import importlib

    monkeypatch.chdir(REPO)            # the examples name sample_data/ as the README does
    failed, tried = doctest.testmod(importlib.import_module(module), verbose=False)[:2]
    assert tried > 0 and failed == 0


@pytest.mark.parametrize("call", [mocapfix.clean, mocapfix.check])
def test_a_fifo_given_to_clean_or_check_is_refused_not_waited_on(tmp_path, call):
    # the batch commands refuse a FIFO before reading; mocapfix.clean(path) and
    # mocapfix.check(path) opened it and waited for a writer forever
    fifo = tmp_path / "take.bvh"
    os.mkfifo(fifo)
    with hang_guard(20), pytest.raises(mocapfix.core.errors.UnreadableFileError,
                                       match="take.bvh: cannot read: a FIFO"):
        call(fifo)


SAMPLE_BVH = REPO / "sample_data" / "walk.bvh"


@pytest.mark.parametrize("call", [
    lambda: mocapfix.load_config(""),
    lambda: mocapfix.clean(SAMPLE_BVH, " "),
    lambda: mocapfix.check(SAMPLE_BVH, ""),
    lambda: mocapfix.check(SAMPLE_BVH, would_clean=""),
], ids=["load_config", "clean", "check", "would_clean"])
def test_an_empty_config_or_rules_name_is_refused_as_empty(call):
    # "" is the current folder as a path: the error was ": is a folder, not a config file"
    with pytest.raises(mocapfix.core.errors.ConfigError, match="is an empty name"):
        call()


@pytest.mark.parametrize("fps", ["abc", float("nan"), 0, -30, 1e9])
def test_a_frame_rate_that_is_none_is_refused_as_the_callers(fps):
    # fps="abc" was the file's fault: "malformed asfamc file (ValueError ...)"; nan named
    # the ASF file
    amc = shared("asfamc/05_01.amc")
    with pytest.raises(mocapfix.core.errors.ConfigError, match=r"^fps: .*(not a number|not a frame rate)"):
        mocapfix.clean(amc, fps=fps)
    with pytest.raises(mocapfix.core.errors.ConfigError, match=r"^fps: "):
        mocapfix.check(amc, fps=fps)
