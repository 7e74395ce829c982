"""The cleaner registry: the name → module map agrees with what the modules register, and
building the default pipeline does not load the heavy scipy/pywt modules it does not use."""
import subprocess
import sys
from pathlib import Path

from mocapfix import cleaners

REPO = Path(__file__).resolve().parents[1]


def _modules_loaded_by(code: str) -> set[str]:
    """The modules a fresh interpreter has loaded after running ``code`` (in the repo, so
    ``sample_data/`` resolves); ``code`` fails the test by raising."""
    script = code + "import sys\nprint('\\n'.join(sys.modules))\n"
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         check=True, cwd=REPO)
    return set(out.stdout.split())


def _scipy_modules(loaded: set[str]) -> list[str]:
    return sorted(m for m in loaded if m.split(".")[0] == "scipy")


def test_name_map_matches_registered_cleaners():
    reg = cleaners.registry()
    assert set(cleaners._WHERE) == set(reg)
    for name, module in cleaners._WHERE.items():
        assert reg[name].__module__ == module


def test_default_pipeline_loads_no_unused_heavy_module():
    loaded = _modules_loaded_by("from mocapfix.config import load_config, default_config_path\n"
                                "load_config(default_config_path())\n")
    heavy = {"scipy.signal", "scipy.interpolate", "pywt", "scipy.ndimage", "scipy.linalg",
             "scipy.spatial", "mocapfix.cleaners.lowrank_isometry", "mocapfix.cleaners.partlet"}
    assert not heavy & loaded


def test_unknown_cleaner_names_the_known_ones():
    import pytest

    from mocapfix.core.errors import ConfigError

    with pytest.raises(ConfigError, match="known: .*tsmc"):
        cleaners.build("no_such_cleaner")


def test_default_c3d_clean_loads_no_scipy():
    """The default C3D chain (swaps, trust, fill_ensemble, tsmc) on a capture with gaps,
    jitter and spikes runs on numpy alone (its DCT uses numpy's FFT): importing scipy.fft
    cost ~0.3 s of every clean."""
    loaded = _modules_loaded_by(
        "from mocapfix import read\n"
        "from mocapfix.bench.corrupt import occlusion\n"
        "from mocapfix.clean import clean_motion\n"
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
