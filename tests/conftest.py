"""Shared test helpers.

Tests that use the real captures in ``../shared/data`` get their paths from
:func:`shared_files`. When the folder is absent they skip — unless
``MOCAPFIX_REQUIRE_DATA=1`` (CI sets it), in which case they fail.
"""
from __future__ import annotations

import contextlib
import fnmatch
import os
import re
import signal
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("MOCAPFIX_DATA", REPO.parent / "shared" / "data"))
REQUIRE_DATA = os.environ.get("MOCAPFIX_REQUIRE_DATA") == "1"
SAMPLE_DATA = REPO / "sample_data"
#: real files of formats beyond the four, ``<format>/<file>`` (../shared/formats, SOURCES.md)
FORMATS_DATA = Path(os.environ.get("MOCAPFIX_FORMATS_DATA", DATA.parent / "formats"))


def _missing(what: str):
    message = f"shared data not found: {what} (set MOCAPFIX_DATA or place ../shared/data)"
    if REQUIRE_DATA:
        pytest.fail(message)
    pytest.skip(message)


#: Every file of the shared data, by folder, as listed in ../shared/data/SOURCES.md. The
#: per-file tests are parametrised from this table, not from what happens to be on disk,
#: so a missing file fails its own test under MOCAPFIX_REQUIRE_DATA=1, and
#: tests/formats/test_shared_data.py checks that the disk holds exactly these files.
EXPECTED_FILES = {
    "c3d": (
        "btk_ADemo1_pc_integer.c3d", "btk_Gait.c3d", "btk_PiG_Motion-FlatFoot-Hole.c3d",
        "btk_mocap36_optitrack.c3d", "c3dorg_s01_Eb015pi.c3d", "c3dorg_s01_Eb015sr.c3d",
        "c3dorg_s01_Eb015vr.c3d", "c3dorg_s02_DEC_INT.C3D", "c3dorg_s02_pc_real.c3d",
        "c3dorg_s04_sub_labels.c3d", "c3dorg_s06_MACsample.c3d", "c3dorg_s08_TESTBPI.c3d",
        "c3dorg_s09_PlugInC3D.c3d", "c3dorg_s13_Dance.c3d", "c3dorg_s20_phasespace_sample.c3d",
        "c3dorg_s22_BKINtechnologies.c3d", "c3dorg_s28_dynamic.C3D", "cmu_85_02.c3d",
        "ezc3d_BTS.c3d", "ezc3d_Optotrak.c3d", "ezc3d_Qualisys.c3d",
        "hdm05_HDM_mm_01-02_03_120.c3d", "ktk_racing_full.c3d", "ktk_tennis_serve_nan.c3d",
        "numediart_03_rolling.c3d",
    ),
    "asfamc": (
        "05.asf", "05_01.amc", "05_02.amc", "05_10.amc", "13.asf", "13_39.amc", "143.asf",
        "143_35.amc", "18.asf", "18_15.amc", "60.asf", "60_10.amc", "61.asf", "61_10.amc",
        "90.asf", "90_31.amc",
    ),
    "bvh": (
        "bandai_dataset-1_walk_normal_001.bvh", "bandai_dataset-2_run_normal_001.bvh",
        "bvhpython_test_freebvh.bvh", "bvhpython_test_mocapbank.bvh", "cmu_cgspeed_131_01.bvh",
        "cmu_cgspeed_131_03.bvh", "pymo_AV_8Walk_Meredith_HVHA_Rep1.bvh",
    ),
    "kinect": (
        "kv1_msr3d_a01_s01_e01_skeleton3D.txt", "kv1_msr3d_a06_s03_e02_skeleton3D.txt",
        "kv1_msr3d_a10_s06_e02_skeleton3D.txt", "kv1_msr3d_a16_s08_e02_skeleton3D.txt",
        "kv1_utkinect_joints_s01_e01.txt", "kv1_utkinect_joints_s02_e01.txt",
        "kv1_utkinect_joints_s05_e02.txt", "kv2_laban_Ges01_wavehand.csv",
        "kv2_laban_Ges02_balancinghands.csv", "kv2_laban_Ges03_drawlines.csv",
        "kv2_laban_Ges04_comehere.csv", "kv2_laban_KinectReader_joints.csv",
    ),
}


def expected_names(subdir: str, pattern: str = "*") -> list:
    """Names of :data:`EXPECTED_FILES` ``[subdir]`` matching the glob ``pattern``."""
    return [n for n in EXPECTED_FILES[subdir] if fnmatch.fnmatchcase(n, pattern)]


def shared_files(subdir: str, pattern: str = "*") -> list:
    """Parametrisation list of the expected files (:data:`EXPECTED_FILES`) of
    ``DATA/subdir`` matching ``pattern`` — one entry per listed file whether it is on disk
    or not; the test must call :func:`need` on it, which skips or (under
    MOCAPFIX_REQUIRE_DATA=1) fails for a missing file."""
    return [pytest.param(DATA / subdir / name, id=name) for name in expected_names(subdir, pattern)]


def need(path) -> Path:
    """Return ``path`` if it exists; otherwise skip or fail (see module docstring)."""
    if path is None or not Path(path).exists():
        _missing(str(path))
    return Path(path)


def shared(relpath: str) -> Path:
    """One named file of the shared data, with the skip/fail rule applied."""
    return need(DATA / relpath)


class Hang(BaseException):
    """Raised by :func:`hang_guard`. A BaseException, not TimeoutError: TimeoutError is an
    OSError, which readers turn into "malformed file" errors, hiding the hang."""


@contextlib.contextmanager
def hang_guard(seconds: int = 10):
    """Fail instead of hanging forever (a generous guard, not a timing assertion)."""
    if not hasattr(signal, "SIGALRM"):
        yield
        return

    def _timeout(signum, frame):
        raise Hang(f"no answer within {seconds} s")

    previous = signal.signal(signal.SIGALRM, _timeout)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def output_tree(folder) -> dict:
    """Every file under an output ``folder`` but the batch manifest (it holds times of
    day): motion files as bytes, reports as JSON without their timing fields (the only thing
    that differs between two runs of the same config). For comparing two batches."""
    import json

    def drop_seconds(x):
        if isinstance(x, dict):
            return {k: drop_seconds(v) for k, v in x.items() if k != "seconds"}
        if isinstance(x, list):
            return [drop_seconds(v) for v in x]
        return x

    out = {}
    for p in sorted(Path(folder).rglob("*")):
        if p.is_file() and p.name != "mocapfix-manifest.jsonl":
            rel = p.relative_to(folder).as_posix()
            out[rel] = drop_seconds(json.loads(p.read_text())) if p.name.endswith(".report.json") \
                else p.read_bytes()
    return out


#: A quick config for command-line tests that need one: one fill step.
FILL_CONFIG = "version: 1\npipeline:\n  - cleaner: fill\n    max_gap: 0.5 s\n"


def config_file(tmp_path, text: str = FILL_CONFIG, name: str = "cfg.yaml") -> str:
    """``text`` written to ``tmp_path / name``; its path, as ``-c`` takes it."""
    p = tmp_path / name
    p.write_text(text)
    return str(p)


def md5_tree(folder) -> dict:
    """Every file under ``folder`` -> its MD5: compare two of them to show that a run changed
    nothing there."""
    import hashlib

    return {p: hashlib.md5(p.read_bytes()).hexdigest() for p in sorted(Path(folder).rglob("*"))
            if p.is_file()}


def no_traceback(result) -> None:
    """A CliRunner result printed no traceback and raised nothing but its exit."""
    assert "Traceback" not in result.output
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)


def cut_amc(src: Path, dst: Path, frames: int) -> Path:
    """``src`` AMC with its first ``frames`` frames only, written to ``dst``."""
    parts = re.split(r"(?m)^(?=\d+\s*$)", src.read_text())
    dst.write_text("".join(parts[:1 + frames]))
    return dst


class _OneThread:
    """``threading`` as :mod:`mocapfix.core.forked` sees it in a process of one thread."""

    @staticmethod
    def active_count():
        return 1


@pytest.fixture
def fork_allowed(monkeypatch):
    """Let :mod:`mocapfix.core.forked` fork in a test: an earlier test of the session may
    leave a thread alive (Dask's offload thread), which rightly stops every fork
    (that policy is tested alone, tests/core/test_forked.py)."""
    from mocapfix.core import forked

    monkeypatch.setattr(forked, "threading", _OneThread)


@pytest.fixture
def fork_calls(monkeypatch, fork_allowed):
    """The calls of :func:`mocapfix.core.forked.both` during the test, each True when it
    forked a child (with :func:`fork_allowed`)."""
    from mocapfix.core import forked

    calls, both = [], forked.both

    def watched(aside, here, fork=True):
        calls.append(fork and forked.can_fork())
        return both(aside, here, fork)

    monkeypatch.setattr(forked, "both", watched)
    return calls
