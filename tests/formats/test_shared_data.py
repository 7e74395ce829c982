"""The shared data on disk is exactly the list of SOURCES.md (conftest.EXPECTED_FILES),
and every per-file table of expected values covers the files of its folder: a missing
file fails instead of shrinking the per-file tests."""
from __future__ import annotations

import pytest

import test_asfamc
import test_bvh
import test_c3d
import test_kinect
from conftest import DATA, EXPECTED_FILES, REQUIRE_DATA, expected_names


@pytest.mark.parametrize("subdir", sorted(EXPECTED_FILES))
def test_disk_holds_exactly_the_listed_files(subdir):
    folder = DATA / subdir
    if not folder.is_dir() and not REQUIRE_DATA:
        pytest.skip(f"shared data not found: {folder}")
    on_disk = {p.name for p in folder.iterdir() if p.is_file()} if folder.is_dir() else set()
    listed = set(EXPECTED_FILES[subdir])
    assert not listed - on_disk, f"missing from {folder}: {sorted(listed - on_disk)}"
    assert not on_disk - listed, f"not in SOURCES.md / EXPECTED_FILES: {sorted(on_disk - listed)}"


def test_sources_md_lists_the_same_files():
    sources = DATA / "SOURCES.md"
    if not sources.exists() and not REQUIRE_DATA:
        pytest.skip(f"shared data not found: {sources}")
    rows = {line.split("|")[1].strip() for line in sources.read_text().splitlines()
            if line.startswith("| ") and "/" in line.split("|")[1]}
    assert rows == {f"{sub}/{name}" for sub, names in EXPECTED_FILES.items() for name in names}


@pytest.mark.parametrize("table, subdir, pattern", [
    (test_c3d.SOURCES, "c3d", "*"),
    (test_asfamc.EXPECTED_FRAMES, "asfamc", "*.amc"),
    (test_bvh.EXPECTED, "bvh", "*"),
    (test_kinect.EXPECTED, "kinect", "*"),
], ids=["c3d", "asfamc", "bvh", "kinect"])
def test_expected_value_tables_cover_every_listed_file(table, subdir, pattern):
    assert set(table) == set(expected_names(subdir, pattern))
