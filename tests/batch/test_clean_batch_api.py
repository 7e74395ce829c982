"""The clean command's policy is a library function: a script or notebook gets what
``mocapfix clean`` does (resume, refusals, overwrite/skip, the config record, roll-back)
without the command line."""
from __future__ import annotations

from pathlib import Path

import pytest

from mocapfix.batch.clean import clean_batch, plan_clean
from mocapfix.batch.discovery import discover_inputs
from mocapfix.config import load_config
from mocapfix.core.errors import MocapfixError
from mocapfix.core.presets import resolve_config
from conftest import SAMPLE_DATA


def test_a_batch_resumes_refuses_and_overwrites_from_python(tmp_path):
    out = tmp_path / "out"
    first = clean_batch([SAMPLE_DATA], out, "default", reports=("json",))
    cleaned = [r for r in first["files"] if r["status"] != "ERROR"]
    assert cleaned and len(cleaned) == len(first["files"])
    assert (out / "mocapfix-config.yaml").read_text().startswith("# effective config of this run")
    assert all(Path(r["output"]).exists() for r in cleaned)

    again = clean_batch([SAMPLE_DATA], out, "default")
    assert again["files"] == [] and {why for _, why in again["skipped"]} == {"finished earlier"}

    # another config into the same folder: its outputs are in the way
    with pytest.raises(MocapfixError, match="exist already.*--overwrite"):
        clean_batch([SAMPLE_DATA], out, "optical-c3d")
    with pytest.raises(MocapfixError, match="another config"):
        clean_batch([SAMPLE_DATA], out, "optical-c3d", policy="skip")
    redone = clean_batch([SAMPLE_DATA], out, "optical-c3d", policy="overwrite")
    assert len(redone["files"]) == len(first["files"])
    assert "optical-c3d" in (out / "mocapfix-config.yaml").read_text().splitlines()[0]


def test_a_dry_plan_makes_no_folder_and_refuses_like_the_run(tmp_path):
    pipeline = load_config(resolve_config("default"))
    found = discover_inputs([str(SAMPLE_DATA)])
    out = tmp_path / "new" / "out"
    plan = plan_clean(found.files, out, pipeline, inputs=[str(SAMPLE_DATA)], dry_run=True)
    assert plan.todo and not plan.skipped and not (tmp_path / "new").exists()
    assert plan.made == [out, tmp_path / "new"]
    with pytest.raises(ValueError, match="policy"):
        plan_clean(found.files, out, pipeline, policy="replace")


@pytest.mark.parametrize("kind", [str, Path, lambda p: str(p).encode()], ids=["str", "Path", "bytes"])
def test_one_path_is_one_input_not_a_list_of_its_characters(tmp_path, monkeypatch, kind):
    # clean_batch("takes", out) iterated the string: the inputs "t", "a", "k", ... ("t: no
    # such file or folder"), and an absolute path's first input "/" walked the whole file
    # system first; a Path was "'PosixPath' object is not iterable"
    import shutil

    monkeypatch.chdir(tmp_path)
    (tmp_path / "a").mkdir()               # a folder named like one of the characters
    shutil.copy(SAMPLE_DATA / "walk.bvh", tmp_path / "a" / "stray.bvh")
    take = tmp_path / "in" / "walk.bvh"
    take.parent.mkdir()
    shutil.copy(SAMPLE_DATA / "walk.bvh", take)
    result = clean_batch(kind(take), tmp_path / "out", "default")
    assert [Path(r["input"]) for r in result["files"]] == [take]
    assert result["files"][0]["status"] != "ERROR"
    assert sorted(p.name for p in (tmp_path / "out").iterdir() if p.suffix == ".bvh") == ["walk.bvh"]
