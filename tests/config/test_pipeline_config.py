"""Config parsing and validation, physical quantities, and the shipped configs."""
from __future__ import annotations

import numpy as np
import pytest

from mocapfix.cleaners import registry
from mocapfix.cleaners.base import Cleaner, Param
from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion
from mocapfix.config import load_config, loads_config
from mocapfix.core.quantity import parse_quantity

from conftest import REPO

CONFIGS = sorted((REPO / "configs").glob("*.yaml"))


def test_quantities_convert_to_si_and_frames():
    assert parse_quantity("0.5 s", "time", "s", "x").in_frames(120) == pytest.approx(60)
    assert parse_quantity("12 frames", "time", "s", "x").in_frames(50) == 12
    assert parse_quantity("250 ms", "time", "s", "x").si == pytest.approx(0.25)
    assert parse_quantity("20 mm", "length", "mm", "x").in_units(0.001) == pytest.approx(20)
    assert parse_quantity("2 cm", "length", "mm", "x").in_units(1.0) == pytest.approx(0.02)
    assert parse_quantity(6, "frequency", "Hz", "x").si == 6
    with pytest.raises(ConfigError, match="not a time unit"):
        parse_quantity("5 mm", "time", "s", "step 1 (fill): parameter 'max_gap'")
    with pytest.raises(ConfigError, match="cannot read"):
        parse_quantity("fast", "frequency", "Hz", "x")


def test_every_shipped_config_loads_and_names_real_cleaners():
    assert {c.name for c in CONFIGS} >= {"default.yaml", "optical-c3d.yaml", "kinect.yaml",
                                         "animation-bvh.yaml"}
    for path in CONFIGS:
        pipeline = load_config(path)
        assert pipeline.steps, path
        for step in pipeline.steps:
            assert step.cleaner.name in registry()
        # the effective config round-trips through YAML to the same steps
        again = loads_config(pipeline.dump(), "dumped")
        assert again.config() == pipeline.config()


def test_unknown_cleaner_is_named_with_line():
    text = "version: 1\npipeline:\n  - cleaner: butterworth\n  - cleaner: magic_wand\n"
    with pytest.raises(ConfigError) as err:
        loads_config(text, "my.yaml")
    msg = str(err.value)
    assert "magic_wand" in msg and "my.yaml" in msg and "line 4" in msg and "step 2" in msg


def test_unknown_parameter_and_bad_value_are_named():
    with pytest.raises(ConfigError, match=r"unknown parameter.*'cuttoff'"):
        loads_config("pipeline:\n  - cleaner: butterworth\n    cuttoff: 6 Hz\n")
    with pytest.raises(ConfigError, match=r"parameter 'cutoff'.*out of range"):
        loads_config("pipeline:\n  - cleaner: butterworth\n    cutoff: -3 Hz\n")
    with pytest.raises(ConfigError, match=r"'cutoff'.*not a frequency unit"):
        loads_config("pipeline:\n  - cleaner: butterworth\n    cutoff: 6 mm\n")


def test_structural_errors():
    for text, pattern in [
        ("version: 2\npipeline: [{cleaner: butterworth}]", "version"),
        ("version: 1", "list of steps"),
        ("pipeline: [butterworth]", "mapping with a 'cleaner'"),
        ("pipeline: [{cleaner: butterworth}]\nextra: 1", "unknown top-level"),
        ("pipeline: [{cleaner: butterworth, formats: [fbx]}]", "formats"),
        ("pipeline: [{cleaner: butterworth\n", "not valid YAML"),
        ("- just a list", "mapping"),
    ]:
        with pytest.raises(ConfigError, match=pattern):
            loads_config(text)


def test_yaml_is_safe_loaded():
    with pytest.raises(ConfigError):
        loads_config("pipeline: !!python/object/apply:os.system ['echo hacked']")


class _Double(Cleaner):
    name = "test_double"
    params = (Param("factor", "float", 2.0, low=0.0, low_open=True),)

    def _apply(self, motion):
        return motion.replace(positions=motion.positions * self["factor"]), {"ok": True}


def test_pipeline_records_filled_flagged_and_skips_other_formats(monkeypatch):
    from mocapfix import cleaners

    monkeypatch.setitem(cleaners._REGISTRY, "test_double", _Double)
    pos = np.ones((5, 2, 3))
    pos[1, 0] = np.nan
    m = Motion(pos, ["a", "b"], 100.0, format="c3d")
    pipe = loads_config("pipeline:\n  - cleaner: test_double\n  - cleaner: test_double\n    formats: [bvh]\n")
    out, records = pipe.run(m)
    assert np.allclose(out.positions[0], 2.0) and np.isnan(out.positions[1, 0]).all()
    assert records[0].moved[0, 0] == pytest.approx(np.sqrt(3))
    assert records[1].skipped and not records[1].filled.any()
    assert np.allclose(m.positions[0], 1.0)  # input untouched


def test_version_true_is_not_version_1():
    # YAML's true is Python's True, which equals 1: "version: true" passed as version 1
    import pytest

    from mocapfix.core.errors import ConfigError
    from mocapfix.config import loads_config
    from mocapfix.quality.rules import loads_rules

    with pytest.raises(ConfigError, match="unsupported config version True"):
        loads_config("version: true\npipeline: []\n", "c.yaml")
    with pytest.raises(ConfigError, match="unsupported rules version True"):
        loads_rules("version: true\nrules: []\n", "r.yaml")
    assert loads_config("version: 1\npipeline: []\n").steps == []
