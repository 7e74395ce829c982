"""Seeded fuzzing of huge fields and hostile names (issue 40): a random token of a text
capture replaced by a long one (500 to 200,000 characters of digits, letters, markup and
control characters), or C3D labels made of such characters; each case must read or fail
with one short line naming the file, and a case that reads is cleaned into Markdown and
HTML reports that carry no raw tag and no control character.
``MOCAPFIX_FIELD_FUZZ=N`` (default 120) cases, ``MOCAPFIX_FIELD_FUZZ_SEED`` (default 40)."""
from __future__ import annotations

import os
import re

import numpy as np
import pytest
from conftest import SAMPLE_DATA, hang_guard
from malformed_corpus import c3d_bytes, small_c3d_points

from mocapfix.cleaning import clean_file
from mocapfix.config import loads_config
from mocapfix.core.errors import MocapfixError
from mocapfix.formats import read

pytestmark = pytest.mark.slow

N = int(os.environ.get("MOCAPFIX_FIELD_FUZZ", "120"))
SEED = int(os.environ.get("MOCAPFIX_FIELD_FUZZ_SEED", "40"))
TEXT = {"walk.bvh": (SAMPLE_DATA / "walk.bvh").read_bytes(),
        "walk_kinect_v2.csv": (SAMPLE_DATA / "walk_kinect_v2.csv").read_bytes(),
        "walker_01.amc": (SAMPLE_DATA / "walker_01.amc").read_bytes()}
ASF = (SAMPLE_DATA / "walker.asf").read_bytes()
PIECES = ["7", "0.5", "x", "<script>", "<img src=x onerror=alert(1)>", "&amp;", "\x1b[31m", "\x07",
          "\r", "|", "é", "\\", "`", "**", "-1e308"]
FILL = loads_config("pipeline:\n  - cleaner: fill\n")
_RAW_TAG = re.compile(r"(?<!\\)<(script|img)")
_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f]")


def _token(rng, length: int) -> str:
    out, n = [], 0
    while n < length:
        piece = PIECES[rng.integers(len(PIECES))] * int(rng.integers(1, 50))
        out.append(piece)
        n += len(piece)
    return "".join(out)[:length]


def _case(k: int):
    rng = np.random.default_rng([SEED, k])
    if k % 5 == 4:                      # C3D labels of the same pieces
        P = int(rng.integers(2, 6))
        labels = [_token(rng, int(rng.integers(1, 30))) for _ in range(P)]
        return "gen.c3d", {"gen.c3d": c3d_bytes(small_c3d_points(T=120, P=P, seed=k), labels)}
    name = list(TEXT)[k % 3]
    lines = TEXT[name].split(b"\n")
    row = int(rng.integers(len(lines)))
    words = lines[row].split(b"," if name.endswith(".csv") else b" ")
    at = int(rng.integers(len(words)))
    length = int(rng.choice([500, 999, 1001, 5_000, 40_000, 200_000]))
    words[at] = _token(rng, length).encode("utf-8", "surrogateescape")
    lines[row] = (b"," if name.endswith(".csv") else b" ").join(words)
    files = {name: b"\n".join(lines)}
    if name.endswith(".amc"):
        files["walker.asf"] = ASF
    return name, files


@pytest.mark.parametrize("k", range(N))
def test_field_fuzz_case(k, tmp_path):
    target, files = _case(k)
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    with hang_guard(30):
        try:
            motion = read(tmp_path / target)
        except MocapfixError as exc:
            msg = str(exc)
            assert str(tmp_path / target) in msg and "\n" not in msg and len(msg) < 1500, msg[:300]
            return
        assert motion.n_frames > 0
        out = tmp_path / "out" / target
        try:
            clean_file(tmp_path / target, out, FILL, reports=("md", "html"))
        except MocapfixError as exc:
            assert "\n" not in str(exc) and len(str(exc)) < 1500
            return
    md = (out.parent / f"{target}.report.md").read_text()
    page = (out.parent / f"{target}.report.html").read_text()
    # the page's one script is the report's own (the viewer's time cursor), once
    from mocapfix.quality.render import _CURSOR_SCRIPT

    assert page.count(_CURSOR_SCRIPT) <= 1
    page = page.replace(_CURSOR_SCRIPT, "")
    assert not _RAW_TAG.search(md) and "<script" not in page and "<img" not in page
    assert not _CONTROL.search(md) and not _CONTROL.search(page)
