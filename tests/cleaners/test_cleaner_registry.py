"""The cleaner registry: a cleaner is listed in one place (its module's ``@register``), a
new module in the package is found without being named anywhere else, and building the
default pipeline does not load the heavy scipy/pywt modules it does not use."""
import subprocess
import sys

import pytest

from mocapfix import cleaners

from conftest import REPO


def _modules_loaded_by(code: str) -> set[str]:
    """The modules a fresh interpreter has loaded after running ``code`` (in the repo, so
    ``sample_data/`` resolves); ``code`` fails the test by raising."""
    script = code + "import sys\nprint('\\n'.join(sys.modules))\n"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, cwd=REPO)
    return set(out.stdout.split())


def _scipy_modules(loaded: set[str]) -> list[str]:
    return sorted(m for m in loaded if m.split(".")[0] == "scipy")


def test_every_cleaner_module_registers_what_it_defines():
    reg = cleaners.registry()
    assert {"tsmc", "fill_ensemble", "rotation_outliers", "kinect_skeleton"} <= set(reg)
    for name, cls in reg.items():
        assert cls.name == name and cls.__module__.startswith("mocapfix.cleaners.")


def test_a_new_cleaner_module_is_found_by_the_registry_alone(tmp_path, monkeypatch):
    """Adding a cleaner is writing one module: dropped into the package's folder (here a
    second folder of the package), it is built by name with nothing else edited."""
    (tmp_path / "clamp_demo.py").write_text(
        "from mocapfix.cleaners import register\n"
        "from mocapfix.cleaners.base import Cleaner, Param\n\n"
        "@register\n"
        "class ClampDemo(Cleaner):\n"
        "    name = 'clamp_demo'\n"
        "    summary = 'a test cleaner'\n"
        "    params = (Param('limit', 'length', '1 m', 'largest coordinate', unit='m', low=0.0),)\n\n"
        "    def _apply(self, motion):\n"
        "        lim = self.length('limit', motion)\n"
        "        return motion.replace(positions=motion.positions.clip(-lim, lim)), {}\n")
    monkeypatch.setattr(cleaners, "__path__", [*cleaners.__path__, str(tmp_path)])
    monkeypatch.setattr(cleaners, "_loaded", False)
    monkeypatch.setattr(cleaners, "_REGISTRY", dict(cleaners._REGISTRY))
    import numpy as np

    from mocapfix.config import parse_config
    from mocapfix.core.motion import Motion

    pipe = parse_config({"pipeline": [{"cleaner": "clamp_demo", "limit": "500 mm"}]})
    m = Motion(np.full((4, 1, 3), 900.0), ["M"], 100.0)
    out, _ = pipe.run(m)
    assert np.all(out.positions == 500.0)


def test_default_pipeline_loads_no_unused_heavy_module():
    loaded = _modules_loaded_by("from mocapfix.config import load_config, default_config_path\n"
                                "load_config(default_config_path())\n")
    heavy = {"scipy.signal", "scipy.interpolate", "pywt", "scipy.ndimage", "scipy.linalg",
             "scipy.spatial"}
    assert not heavy & loaded


def test_unknown_cleaner_names_the_known_ones():
    import pytest

    from mocapfix.core.errors import ConfigError

    with pytest.raises(ConfigError, match="known: .*tsmc"):
        cleaners.build("no_such_cleaner")


@pytest.mark.slow
def test_default_c3d_clean_loads_no_scipy():
    """The default C3D chain (swaps, trust, fill_ensemble, tsmc) on a capture with gaps,
    jitter and spikes runs on numpy alone (its DCT uses numpy's FFT): importing scipy.fft
    cost ~0.3 s of every clean."""
    loaded = _modules_loaded_by(
        "from mocapfix import read\n"
        "from mocapfix.bench.corrupt import occlusion\n"
        "from mocapfix.cleaning import clean_motion\n"
        "from mocapfix.config import load_config, default_config_path\n"
        "bad, _ = occlusion(read('sample_data/walk_markers.c3d'), 'mixed', 0)\n"
        "result = clean_motion(bad, load_config(default_config_path()))\n"
        "assert result.cleaned.missing.mean() < bad.missing.mean()\n")
    assert _scipy_modules(loaded) == []


def test_listing_every_cleaner_loads_no_scipy():
    """`mocapfix cleaners` imports every cleaner module to list their parameters; the
    solvers import scipy only inside the routines that use it (importing scipy.sparse,
    scipy.spatial and scipy.ndimage had made the listing ~0.9 s against ~0.25 s)."""
    loaded = _modules_loaded_by(
        "from mocapfix import cleaners\n"
        "names = sorted(cleaners.registry())\n"
        "assert 'partlet_dictionary' in names and 'lowrank_isometry' in names\n")
    assert _scipy_modules(loaded) == []


def test_a_new_format_module_is_found_by_the_format_table_alone(tmp_path, monkeypatch):
    """Adding a format is writing one module: its NAME and SUFFIXES declarations put it in
    the format table, and files of it are read, cleaned and written with nothing else
    edited (the module here: one point per line, "x y z" in mm at 100 Hz)."""
    import numpy as np

    from mocapfix import formats
    from mocapfix.cleaning import clean_motion
    from mocapfix.config import load_config
    from mocapfix.core.presets import resolve_config

    (tmp_path / "xyz_demo.py").write_text(
        '"""A demo format: a line of x y z (mm) per frame of one point, 100 Hz."""\n'
        "from pathlib import Path\n\n"
        "import numpy as np\n\n"
        "from mocapfix.core.motion import Motion\n\n"
        'NAME = "xyz_demo"\n'
        'SUFFIXES = (".xyz",)\n\n\n'
        "def sniff(head):\n"
        "    return head.split(b'\\n', 1)[0].count(b' ') == 2\n\n\n"
        "def read(path, **options):\n"
        "    pos = np.loadtxt(path, ndmin=2)[:, None, :]\n"
        "    return Motion(pos, ['P'], 100.0)\n\n\n"
        "def write(motion, path, **options):\n"
        "    np.savetxt(path, motion.positions[:, 0, :])\n"
        "    return [Path(path)]\n")
    paths = [*formats.__path__, str(tmp_path)]
    table = formats._declared_formats(paths)
    assert list(table)[-1] == "xyz_demo" and table["xyz_demo"][1] == (".xyz",)
    monkeypatch.setattr(formats, "__path__", paths)
    monkeypatch.setattr(formats, "FORMATS", table)
    monkeypatch.setattr(formats, "_SUFFIXES", {s: n for n, (_, ss) in table.items() for s in ss})
    t = np.arange(50) / 100.0
    path = tmp_path / "take.xyz"
    np.savetxt(path, np.stack([100 * np.sin(t), 50 * t, np.zeros_like(t)], axis=1))
    motion = formats.read(path)
    assert motion.format == "xyz_demo" and motion.n_frames == 50
    cleaned = clean_motion(motion, load_config(resolve_config("default"))).cleaned
    written = formats.write(cleaned, tmp_path / "out.xyz")
    assert np.allclose(formats.read(written[0]).positions, motion.positions)
