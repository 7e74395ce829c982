"""Bounded memory on one huge field (issue 39): a text reader (Kinect, BVH, TRC and the
vendor tables: Nexus CSV, Motive CSV, QTM TSV) given a file with a 5 MB field reads it or
refuses it with an UnreadableFileError, and its peak memory grows by less than 200 MB (a
5 MB number once made the Kinect reader ask numpy for 211 GiB).

Each read runs in a fresh process; its peak RSS (``ru_maxrss``) is compared with that of a
process that only imports mocapfix."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import SAMPLE_DATA

VENDOR = Path(__file__).resolve().parents[1] / "data" / "vendor"

LIMIT_MB = 200
#: the Kinect reader refuses a field over MAX_FIELD characters; BVH reads the digits as a
#: number too large for a float and refuses the value; either way one short message
FIELD = "1" * 5_000_000

_CHILD = """
import json, resource, sys
import mocapfix
from mocapfix.core.errors import UnreadableFileError
outcome = "imported"
if len(sys.argv) > 1:
    try:
        mocapfix.read(sys.argv[1])
        outcome = "read"
    except UnreadableFileError as exc:
        outcome = "refused: " + str(exc)
print(json.dumps({"kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, "outcome": outcome}))
"""


def _child(*args) -> dict:
    done = subprocess.run([sys.executable, "-c", _CHILD, *map(str, args)], check=False,
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def _with_huge_field(tmp_path, name: str, row: int, sep: str | None) -> str:
    """The sample file ``name`` with the second field of line ``row`` (0-based) made 5 MB."""
    lines = (SAMPLE_DATA / name).read_text().split("\n")
    cells = lines[row].split(sep)
    cells[1] = FIELD
    lines[row] = (sep or " ").join(cells)
    path = tmp_path / f"huge_{name}"
    path.write_text("\n".join(lines))
    return path


def _motion_row(name: str) -> int:
    lines = (SAMPLE_DATA / name).read_text().split("\n")
    return next(i for i, line in enumerate(lines) if line.startswith("Frame Time")) + 3


@pytest.mark.parametrize("name, row, sep", [
    ("walk_kinect_v2.csv", 3, ","),
    ("walk.bvh", None, None),
])
def test_a_5mb_field_is_read_or_refused_in_under_200_mb(tmp_path, name, row, sep):
    path = _with_huge_field(tmp_path, name, _motion_row(name) if row is None else row, sep)
    base = _child()
    got = _child(path)
    grew_mb = (got["kb"] - base["kb"]) / 1024
    assert got["outcome"] == "read" or got["outcome"].startswith("refused: "), got
    assert len(got["outcome"]) < 500, "the message quotes an excerpt, not the field"
    assert grew_mb < LIMIT_MB, f"{name}: peak RSS grew by {grew_mb:.0f} MB"


def test_a_5mb_field_in_a_trc_is_read_or_refused_in_under_200_mb(tmp_path):
    from mocapfix import formats

    trc = tmp_path / "walk.trc"
    formats.write(formats.read(SAMPLE_DATA / "walk_markers.c3d"), trc)
    lines = trc.read_text().split("\n")
    row = next(i for i, line in enumerate(lines) if line[:1].isdigit()) + 2
    cells = lines[row].split("\t")
    cells[3] = FIELD
    lines[row] = "\t".join(cells)
    trc.write_text("\n".join(lines))
    base = _child()
    got = _child(trc)
    assert got["outcome"] == "read" or got["outcome"].startswith("refused: "), got
    assert len(got["outcome"]) < 500
    assert (got["kb"] - base["kb"]) / 1024 < LIMIT_MB


@pytest.mark.parametrize("name, sep", [
    ("nexus_pyomeca_markers.csv", ","),
    ("motive_doc.csv", ","),
    ("qtm_hand_embodiment_recording.tsv", "\t"),
])
def test_a_5mb_field_in_a_vendor_table_is_read_or_refused_in_under_200_mb(tmp_path, name, sep):
    """An X coordinate of the last data row made 5 MB (the vendor fixtures end with one)."""
    lines = (VENDOR / name).read_text().split("\n")
    row = max(i for i, line in enumerate(lines) if line.strip(sep + " "))
    cells = lines[row].split(sep)
    cells[3] = FIELD
    lines[row] = sep.join(cells)
    path = tmp_path / f"huge_{name}"
    path.write_text("\n".join(lines))
    base = _child()
    got = _child(path)
    assert got["outcome"] == "read" or got["outcome"].startswith("refused: "), got
    assert len(got["outcome"]) < 500, "the message quotes an excerpt, not the field"
    assert (got["kb"] - base["kb"]) / 1024 < LIMIT_MB, f"{name}: peak RSS grew too much"
