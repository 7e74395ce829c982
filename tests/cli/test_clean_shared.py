"""`mocapfix clean` with the default config on every shared capture: exit 0, outputs in
the same format readable by our reader and by the reference library (py-c3d, bvhio),
reports written, inputs byte-identical afterwards."""
from __future__ import annotations

import hashlib
import json
import warnings

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import DATA, need
from mocapfix.cli import main
from mocapfix.formats import MOTION_SUFFIXES, read

# slow: `mocapfix clean` over every shared capture (~20 s)
pytestmark = pytest.mark.slow


def _digests(folder):
    return {p: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def cleaned_shared(tmp_path_factory):
    data = need(DATA if DATA.is_dir() else None)
    before = _digests(data)
    out = tmp_path_factory.mktemp("cleaned")
    result = CliRunner().invoke(main, ["clean", str(data), "-o", str(out), "-j", "2", "--json",
                                       "--report", "json,md"])
    after = _digests(data)
    return data, out, result, before, after


def test_exit_zero_and_every_file_cleaned(cleaned_shared):
    data, out, result, before, after = cleaned_shared
    assert result.exit_code == 0, result.output[-3000:]
    summary = json.loads(result.stdout)
    n_inputs = sum(1 for p in data.rglob("*") if p.suffix.lower() in MOTION_SUFFIXES)
    assert summary["failed"] == 0 and summary["cleaned"] == n_inputs
    assert before == after, "an input file was modified"


def test_outputs_readable_by_us_and_reports_written(cleaned_shared):
    data, out, result, *_ = cleaned_shared
    for f in json.loads(result.stdout)["files"]:
        cleaned, original = read(f["output"]), read(f["input"])
        assert cleaned.positions.shape == original.positions.shape, f["input"]
        # nothing observed in the input went missing, and nothing was left worse than read
        assert cleaned.missing.sum() <= original.missing.sum(), f["input"]
        report = json.loads(open(f["reports"][0]).read())
        assert report["file"]["frames"] == original.n_frames


def test_c3d_outputs_readable_by_py_c3d(cleaned_shared):
    import c3d

    data, out, *_ = cleaned_shared
    checked = 0
    for src in sorted((data / "c3d").glob("*")):
        try:  # only files py-c3d itself can read are a fair check of our output
            with open(src, "rb") as fh, warnings.catch_warnings():
                warnings.simplefilter("ignore")
                n_in = sum(1 for _ in c3d.Reader(fh).read_frames())
        except Exception:  # noqa: BLE001 — py-c3d fails on several real files
            continue
        with open(out / "c3d" / src.name, "rb") as fh, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reader = c3d.Reader(fh)
            frames = [p for _, p, _ in reader.read_frames()]
        ours = read(out / "c3d" / src.name)
        assert len(frames) == n_in == ours.n_frames
        pts = np.stack(frames)[:, :, :3]
        valid = np.stack(frames)[:, :, 3] >= 0
        np.testing.assert_allclose(pts[valid], ours.positions[valid], atol=0.01 * max(1.0, abs(reader.point_scale)))
        checked += 1
    assert checked >= 15


def test_bvh_outputs_readable_by_bvhio(cleaned_shared):
    import bvhio

    data, out, *_ = cleaned_shared
    for src in sorted((data / "bvh").glob("*.bvh")):
        ref = bvhio.readAsBvh(str(out / "bvh" / src.name))
        ours = read(out / "bvh" / src.name)
        assert ref.FrameCount == ours.n_frames
        assert len(ref.Root.layout()) == ours.n_joints - sum(ours.source.end_sites)
