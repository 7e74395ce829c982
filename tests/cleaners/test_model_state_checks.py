"""A hand-edited or damaged model file whose arrays and header still parse but do not
make a state (a joint index past the joint list, a sample rate of 0, NaN in a dictionary,
an array of another rank) is a config error naming the model when the config is loaded.
It used to load, then fail every file with "internal error IndexError" (or
ZeroDivisionError, LinAlgError, a broadcast ValueError), or clean silently with NaN."""
from __future__ import annotations

import io
import json

import numpy as np
import pytest
from click.testing import CliRunner

from mocapfix.cleaners import registry
from mocapfix.cli import main
from mocapfix.core import models

from conftest import SAMPLE_DATA, config_file, no_traceback


def _rewrite(src, dst, edit):
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(arrays.pop(models.HEADER_KEY).tobytes())
    edit(header, arrays)
    buf = io.BytesIO()
    np.savez(buf, **{models.HEADER_KEY: np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)},
             **arrays)
    dst.write_bytes(buf.getvalue())
    return dst


def _set(key, value):
    return lambda h, a: h["state"].__setitem__(key, value)


def _array(name, f):
    return lambda h, a: a.__setitem__(name, f(a[name]))


PARTLET = {
    "joint index past the list": lambda h, a: h["state"]["partlets"]["torso"].__setitem__(0, 300),
    "negative joint index": lambda h, a: h["state"]["partlets"]["torso"].__setitem__(0, -3000),
    "frame joint past the list": lambda h, a: h["state"]["frame_joints"].__setitem__(0, 300),
    "joints cut short": lambda h, a: h["state"].__setitem__("joints", h["state"]["joints"][:3]),
    "sample rate 0": _set("sample_rate", 0),
    "sample rate negative": _set("sample_rate", -120),
    "NaN dictionary": _array("dictionary_torso", lambda d: d * np.nan),
    "NaN template": _array("template", lambda d: d * np.nan),
    "no atoms": _array("dictionary_torso", lambda d: d[:, :0]),
    "3-D dictionary": _array("dictionary_torso", lambda d: d[:, :, None]),
    "text dictionary": _array("dictionary_torso", lambda d: d.astype("U3")),
}
MSSA = {
    "fps 0": _set("fps", 0),
    "NaN bases": _array("bases", lambda b: b * np.nan),
    "NaN mean": _array("mean", lambda m: m * np.nan),
    "no bases": _array("bases", lambda b: b[:, :0]),
    "3-D bases": _array("bases", lambda b: b[:, :, None]),
    "2-D mean": _array("mean", lambda m: m[:, None]),
}


@pytest.mark.parametrize("cleaner,shipped,damage", [("partlet_dictionary", "partlet-cmu", d) for d in PARTLET]
                         + [("mssa", "mssa-cmu", d) for d in MSSA])
def test_a_model_edited_into_nonsense_is_a_config_error(tmp_path, cleaner, shipped, damage):
    edit = (PARTLET if cleaner == "partlet_dictionary" else MSSA)[damage]
    _rewrite(models.shipped()[shipped], tmp_path / "bad.npz", edit)
    cfg = config_file(tmp_path, f"version: 1\npipeline:\n  - cleaner: {cleaner}\n    model: bad.npz\n")
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA / "walker_01.amc"), "-o",
                                  str(tmp_path / "out"), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2, r.output
    assert "bad.npz: corrupt model file" in r.output and "internal error" not in r.output, r.output
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("name", sorted(models.shipped()))
def test_shipped_and_rewritten_models_still_load(tmp_path, name):
    header, _ = models.load(models.shipped()[name])
    copy = _rewrite(models.shipped()[name], tmp_path / "same.npz", lambda h, a: None)
    cleaner = registry()[header["cleaner"]](model=str(copy))
    cleaner.resolve_models()
    assert cleaner.is_fitted
