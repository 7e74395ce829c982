"""The malformed-input corpus (tests/malformed_corpus.py, ~1,000 seeded cases over the four
formats and configs): every case either reads (and then cleans, writes and reports) or
fails with one MocapfixError naming the file; no other exception, no hang (per-case
guard), the inputs never modified, nothing left behind for a failed file."""
from __future__ import annotations

import hashlib
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from malformed_corpus import cases
from mocapfix.cleaning import clean_file
from mocapfix.core.errors import ConfigError, MocapfixError
from mocapfix.formats import read
from mocapfix.core.motion import Motion
from mocapfix.config import loads_config
from conftest import hang_guard

# slow: ~1,400 malformed inputs read, cleaned and written (~6 s)
pytestmark = pytest.mark.slow

CASES = cases()
PER_CASE_SECONDS = 10
# cheap, and exercising the three kernels that size arrays from parameters
CLEAN = loads_config("pipeline:\n  - cleaner: spikes\n  - cleaner: fill\n  - cleaner: butterworth\n")


def _digest(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def test_corpus_is_large_seeded_and_covers_every_family():
    assert len(CASES) >= 500
    assert [c.id for c in cases()] == [c.id for c in CASES]
    assert all(a.files == b.files for a, b in zip(cases(), CASES))
    formats = Counter(c.id.split("-")[0] for c in CASES)
    assert {"bvh", "amc", "asf", "c3d", "c3dgen", "kinect", "config"} <= set(formats)
    families = {c.family for c in CASES}
    for family in ("cut", "flip", "splice", "garbage", "utf16", "deep", "cols", "ts", "frames",
                   "frametime", "labels", "rate", "bomb"):
        assert family in families, family


def _tiny_motion():
    rng = np.random.default_rng(0)
    pos = np.cumsum(rng.normal(0, 1.0, (40, 4, 3)), axis=0)
    pos[10:13, 1] = np.nan
    return Motion(pos, ["a", "b", "c", "d"], 100.0, units="mm", metres_per_unit=0.001, format="c3d")


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_malformed_case(case, tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    for name, data in case.files.items():
        (src / name).write_bytes(data)
    before = _digest(src)
    target = src / case.target
    with hang_guard(PER_CASE_SECONDS):
        if case.kind == "config":
            try:
                pipeline = loads_config(target.read_bytes(), str(target))
            except ConfigError as exc:
                _names_the_file(exc, [target])
            else:
                try:
                    pipeline.run(_tiny_motion())
                except MocapfixError as exc:
                    _names_the_file(exc, [target], strict=False)
        else:
            try:
                motion = read(target)
            except MocapfixError as exc:
                _names_the_file(exc, [src / n for n in case.files])
            else:
                assert motion.n_frames > 0, "a motion without frames must be refused at read"
                assert motion.positions.shape == (motion.n_frames, len(motion.names), 3)
                out = tmp_path / "out" / case.target
                try:
                    if case.clean:
                        clean_file(target, out, CLEAN)
                except MocapfixError as exc:
                    _names_the_file(exc, [src / n for n in case.files] + [out], strict=False)
                    left = sorted(p.name for p in out.parent.glob("*")) if out.parent.exists() else []
                    assert not left, f"a failed clean left {left} behind"
    assert _digest(src) == before, "an input was modified"


def _names_the_file(exc, paths, strict=True):
    msg = str(exc)
    assert "\n" not in msg.strip(), f"not one line: {msg!r}"
    assert "Traceback" not in msg
    if strict:
        assert any(str(p) in msg for p in paths), f"message does not name the file: {msg}"
    assert len(msg) < 1500, f"a message of {len(msg):,} characters"
