"""One contract over every fitted cleaner (scikit-learn style): fit → save → load → apply
gives the same result; fit leaves parameters alone; apply leaves the cleaner alone; metres
and millimetres give the same result. Plus the model-file rules: versioned, no pickle,
wrong / corrupt / foreign models refused when the config is loaded, naming the line."""
from __future__ import annotations

import copy
import json
import zipfile

import numpy as np
import pytest
from click.testing import CliRunner

from mocapfix.core import models
from mocapfix.cleaners import registry
from mocapfix.cleaners.base import FittedCleaner
from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion, Skeleton
from mocapfix.config import loads_config
from mocapfix.cli import main

from conftest import SAMPLE_DATA, config_file, no_traceback

FITTED = sorted(n for n, c in registry().items() if issubclass(c, FittedCleaner))
# small, fast training settings per fitted cleaner (the contract, not the accuracy)
FAST = {"partlet_dictionary": {"atoms": 16, "window": 4, "train_iterations": 3, "max_windows": 400},
        "mssa": {"window": 8, "window_step": 2}}

_NAMES = ["root", "lhipjoint", "lfemur", "ltibia", "lfoot", "rhipjoint", "rfemur", "rtibia", "rfoot",
          "lowerback", "thorax", "upperneck", "head", "lclavicle", "lhumerus", "lradius", "lhand",
          "rclavicle", "rhumerus", "rradius", "rhand"]
_PARENTS = [-1, 0, 1, 2, 3, 0, 5, 6, 7, 0, 9, 10, 11, 10, 13, 14, 15, 10, 17, 18, 19]


def _body(seed: int, T: int = 300) -> Motion:
    """A 21-joint stick figure walking and swinging its limbs (mm, 120 Hz), CMU names."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) / 120.0
    phase = rng.uniform(0, 2 * np.pi)
    rest = np.array([[0, 0, 0], [-90, -20, 0], [-90, -450, 0], [-90, -850, 0], [-90, -900, 120],
                     [90, -20, 0], [90, -450, 0], [90, -850, 0], [90, -900, 120], [0, 150, 0],
                     [0, 400, 0], [0, 520, 0], [0, 650, 0], [-180, 420, 0], [-220, 150, 0],
                     [-230, -100, 0], [-235, -180, 0], [180, 420, 0], [220, 150, 0], [230, -100, 0],
                     [235, -180, 0]], float)
    pos = np.repeat(rest[None], T, axis=0)
    swing = np.sin(2 * np.pi * 1.2 * t + phase)[:, None]
    for j, sgn in ((2, 1), (3, 1), (4, 1), (6, -1), (7, -1), (8, -1)):
        pos[:, j, 2] += sgn * swing[:, 0] * 80 * (j % 4 + 1) / 2
    for j, sgn in ((14, -1), (15, -1), (16, -1), (18, 1), (19, 1), (20, 1)):
        pos[:, j, 2] += sgn * swing[:, 0] * 60 * ((j - 13) % 4 + 1) / 2
    heading = 0.3 * t
    c, s = np.cos(heading), np.sin(heading)
    x, z = pos[..., 0].copy(), pos[..., 2].copy()
    pos[..., 0] = c[:, None] * x + s[:, None] * z
    pos[..., 2] = -s[:, None] * x + c[:, None] * z
    pos += np.stack([800 * t, 900 + 15 * np.sin(4 * np.pi * t), 0 * t], axis=1)[:, None]
    return Motion(pos, list(_NAMES), 120.0, units="mm", metres_per_unit=0.001, format="asfamc",
                  skeleton=Skeleton(np.array(_PARENTS)))


def _noisy(motion: Motion, seed: int = 9) -> Motion:
    rng = np.random.default_rng(seed)
    pos = motion.positions + rng.normal(0, 8.0, motion.positions.shape)
    pos[40:60, 15] = np.nan
    return motion.replace(positions=pos)


@pytest.fixture(scope="module")
def training():
    return [_body(s) for s in range(3)]


def test_there_is_a_fitted_cleaner():
    assert "partlet_dictionary" in FITTED


@pytest.mark.parametrize("name", FITTED)
def test_fit_save_load_apply(name, training, tmp_path):
    cls = registry()[name]
    cleaner = cls(**FAST[name])
    params_before = copy.deepcopy(cleaner.config())
    assert not cleaner.is_fitted
    assert cleaner.fit(training) is cleaner
    assert cleaner.is_fitted
    assert cleaner.config() == params_before, "fit changed a parameter"
    for attr in cls.fitted_attributes:
        assert attr.endswith("_") and getattr(cleaner, attr) is not None
    test = _noisy(_body(7))
    snapshot = test.positions.copy()
    out, info = cleaner.apply(test)
    assert np.array_equal(test.positions, snapshot, equal_nan=True), "input was mutated"
    assert out.names == test.names and out.fps == test.fps and isinstance(info, dict)
    assert np.array_equal(cleaner.apply(test)[0].positions, out.positions, equal_nan=True), \
        "not deterministic"
    header, arrays = cleaner.state()
    header.update(cleaner.model_header_fields())
    path = models.save(tmp_path / "m.npz", header, arrays)
    # no pickle anywhere: every member loads with allow_pickle=False
    with np.load(path, allow_pickle=False) as z:
        assert "__header__" in z.files
    loaded = cls(**FAST[name]).load_state(*models.load(path, cleaner=name))
    again, _ = loaded.apply(test)
    assert np.array_equal(out.positions, again.positions, equal_nan=True)
    # apply leaves the cleaner alone
    state_before = cleaner.state()[1]
    cleaner.apply(test)
    for k, v in cleaner.state()[1].items():
        assert np.array_equal(v, state_before[k])
    # the result is a cleaning: closer to the truth than the noisy input, gap filled
    truth = _body(7).positions
    err = lambda p: np.sqrt(np.nanmean(np.sum((p - truth) ** 2, axis=2)))  # noqa: E731
    assert not np.isnan(out.positions).any()
    assert err(out.positions) < err(test.positions)


@pytest.mark.parametrize("name", FITTED)
def test_metres_and_millimetres_give_the_same_result(name, training):
    mm = registry()[name](**FAST[name]).fit(training)
    in_m = [t.replace(positions=t.positions / 1000.0, units="m", metres_per_unit=1.0) for t in training]
    m = registry()[name](**FAST[name]).fit(in_m)
    for a, b in zip(mm.state()[1].values(), m.state()[1].values()):
        assert np.allclose(a, b, rtol=1e-6, atol=1e-9)
    test = _noisy(_body(7))
    out_mm, _ = mm.apply(test)
    out_m, _ = m.apply(test.replace(positions=test.positions / 1000.0, units="m", metres_per_unit=1.0))
    assert np.allclose(out_m.positions * 1000.0, out_mm.positions, atol=1e-5)


def _model(tmp_path, training):
    c = registry()["partlet_dictionary"](**FAST["partlet_dictionary"]).fit(training)
    header, arrays = c.state()
    header.update(c.model_header_fields())
    return models.save(tmp_path / "models" / "body.npz", header, arrays)


def test_config_names_a_model_relative_to_the_config_file(tmp_path, training):
    _model(tmp_path, training)
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("version: 1\npipeline:\n  - cleaner: partlet_dictionary\n    model: models/body.npz\n")
    from mocapfix.config import load_config

    pipe = load_config(cfg)
    step = pipe.steps[0].cleaner
    assert step.is_fitted
    # the effective config carries an absolute path, so a worker in another folder finds it
    assert step.config()["model"] == str((tmp_path / "models" / "body.npz").resolve())
    again = loads_config(pipe.dump(), "<dump>")
    assert again.steps[0].cleaner.is_fitted


@pytest.mark.parametrize("damage", ["missing", "garbage", "truncated", "foreign", "schema"])
def test_bad_models_are_config_errors_naming_the_line(tmp_path, training, damage):
    path = _model(tmp_path, training)
    if damage == "missing":
        path.unlink()
    elif damage == "garbage":
        path.write_bytes(b"not a zip at all")
    elif damage == "truncated":
        path.write_bytes(path.read_bytes()[:200])
    elif damage in ("foreign", "schema"):
        with zipfile.ZipFile(path) as zf:
            raw = zf.read("__header__.npy")
        import io

        header = json.loads(np.load(io.BytesIO(raw)).tobytes())
        _, arrays = models.load(path)
        if damage == "foreign":
            header["cleaner"] = "mssa"
        else:
            header["schema"] = "mocapfix.model/999"
            header.pop("units")
        models.save(path, {k: v for k, v in header.items() if k not in ("schema", "mocapfix", "units")}
                    if damage == "foreign" else header, dict(arrays))
        if damage == "schema":   # save() stamps the current schema: write the old one back by hand
            buf = io.BytesIO()
            payload = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
            np.savez(buf, __header__=payload, **arrays)
            path.write_bytes(buf.getvalue())
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text("version: 1\npipeline:\n  - cleaner: fill\n  - cleaner: partlet_dictionary\n"
                   "    model: models/body.npz\n")
    from mocapfix.config import load_config

    with pytest.raises(ConfigError) as err:
        load_config(cfg)
    message = str(err.value)
    assert "line 4" in message and "body.npz" in message, message


def test_models_are_written_atomically_and_load_once(tmp_path, training, monkeypatch):
    path = _model(tmp_path, training)
    assert not list(path.parent.glob("*.part"))
    models._load_cached.cache_clear()
    calls = []
    real = models.read_header
    monkeypatch.setattr(models, "read_header", lambda p: calls.append(p) or real(p))
    for _ in range(3):
        models.load(path, cleaner="partlet_dictionary")
    assert len(calls) == 1


def test_a_model_whose_array_header_lies_is_a_config_error(tmp_path):
    # a model member whose .npy header declares 10^11 floats (a few bytes in the file):
    # np.load first allocates what is declared -> MemoryError (745 GiB), a traceback;
    # now a config error naming the model and the array, before any file is read
    import io
    import zipfile

    import numpy as np

    from mocapfix.core import models

    shipped = models.shipped()["mssa-cmu"]
    bomb = tmp_path / "bomb.npz"
    with zipfile.ZipFile(shipped) as zin, zipfile.ZipFile(bomb, "w") as zout:
        for name in zin.namelist():
            data = zin.read(name)
            if name == "bases.npy":
                buf = io.BytesIO()
                np.lib.format.write_array_header_1_0(
                    buf, {"descr": "<f8", "fortran_order": False, "shape": (10 ** 11,)})
                data = buf.getvalue() + bytes(64)
            zout.writestr(name, data)
    cfg = config_file(tmp_path, "version: 1\npipeline:\n  - cleaner: mssa\n    model: bomb.npz\n")
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA / "walker_01.amc"), "-o",
                                  str(tmp_path / "out"), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2, r.output
    assert "bomb.npz: corrupt model file" in r.output and "'bases' declares" in r.output
    assert not (tmp_path / "out").exists()
    models.load(shipped, "mssa")                        # a sound model still loads


def test_a_model_header_nested_too_deep_is_a_config_error(tmp_path):
    # the JSON header "[[[[...]]]]" 100,000 deep: RecursionError, an internal error
    import numpy as np

    deep = ("[" * 100_000 + "]" * 100_000).encode()
    np.savez(tmp_path / "deep.npz", __header__=np.frombuffer(deep, dtype=np.uint8))
    cfg = config_file(tmp_path, "version: 1\npipeline:\n  - cleaner: mssa\n    model: deep.npz\n")
    r = CliRunner().invoke(main, ["clean", str(SAMPLE_DATA / "walker_01.amc"), "-o",
                                  str(tmp_path / "out"), "-c", cfg])
    no_traceback(r)
    assert r.exit_code == 2 and "deep.npz: not a mocapfix model file (RecursionError" in r.output, r.output
