"""A hostile model archive (issue 40, item 5): its zip directory's sizes are checked
against the documented caps before any member is decompressed."""
from __future__ import annotations

import io
import json
import time
import zipfile

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import SAMPLE_DATA, no_traceback

from mocapfix.cli import main
from mocapfix.core import models
from mocapfix.core.errors import ConfigError


def _bomb(path, zeros: int, level: int = 9):
    """A real zip bomb: a valid model header and one array of ``zeros`` zero bytes,
    deflated to a few KB per MB."""
    header = json.dumps({"schema": models.SCHEMA, "cleaner": "partlet_dictionary"}).encode()
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=level) as zf:
        buf = io.BytesIO()
        np.save(buf, np.frombuffer(header, np.uint8))
        zf.writestr(models.HEADER_KEY + ".npy", buf.getvalue())
        with zf.open("D.npy", "w", force_zip64=True) as fh:
            head = io.BytesIO()
            np.lib.format.write_array_header_1_0(
                head, {"descr": "<f8", "fortran_order": False, "shape": (zeros // 8,)})
            fh.write(head.getvalue())
            for _ in range(zeros >> 20):
                fh.write(bytes(1 << 20))
    return path


def test_a_zip_bomb_model_is_refused_from_its_directory_before_anything_is_loaded(
        tmp_path, monkeypatch):
    # the cap lowered so that a 64 MiB bomb (not a 4 GB one) is over it
    monkeypatch.setattr(models, "MAX_MODEL_BYTES", 8 << 20)
    bomb = _bomb(tmp_path / "bomb.npz", 64 << 20)
    assert bomb.stat().st_size < 1 << 20

    def no_load(*args, **kwargs):
        raise AssertionError("an array was loaded")

    monkeypatch.setattr(models.np, "load", no_load)
    monkeypatch.setattr(zipfile.ZipFile, "read", no_load)
    models._load_cached.cache_clear()
    started = time.perf_counter()
    with pytest.raises(ConfigError, match=r"bomb\.npz: .*67,10\d,\d+ bytes uncompressed "
                                          r"\(at most 8,388,608\)"):
        models.load(bomb)
    assert time.perf_counter() - started < 1.0


@pytest.mark.slow       # deflating the 1 GiB bomb takes a few seconds
def test_a_zip_bomb_over_the_real_cap_named_as_model_stops_the_run_with_one_line(tmp_path):
    bomb = _bomb(tmp_path / "bomb.npz", models.MAX_MODEL_BYTES + (1 << 20), level=1)
    config = tmp_path / "cfg.yaml"
    config.write_text("version: 1\npipeline:\n  - cleaner: partlet_dictionary\n    model: bomb.npz\n")
    started = time.perf_counter()
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA / "walk.bvh"), "-o", str(tmp_path / "o"),
                                  "-c", str(config)])
    no_traceback(r)
    assert r.exit_code == 2, r.output
    assert f"{bomb}: " in r.output and "bytes uncompressed (at most 1,073,741,824)" in r.output
    assert time.perf_counter() - started < 5


def test_the_shipped_models_are_well_within_the_cap():
    for path in models.shipped().values():
        with zipfile.ZipFile(path) as zf:
            assert sum(i.file_size for i in zf.infolist()) < models.MAX_MODEL_BYTES / 100
