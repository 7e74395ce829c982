"""The cleaner registry: the name → module map agrees with what the modules register, and
building the default pipeline does not load the heavy scipy/pywt modules it does not use."""
import subprocess
import sys

from mocapfix import cleaners


def test_name_map_matches_registered_cleaners():
    reg = cleaners.registry()
    assert set(cleaners._WHERE) == set(reg)
    for name, module in cleaners._WHERE.items():
        assert reg[name].__module__ == module


def test_default_pipeline_loads_no_unused_heavy_module():
    code = ("import sys\n"
            "from mocapfix.pipeline import load_config, default_config_path\n"
            "load_config(default_config_path())\n"
            "print(' '.join(m for m in ('scipy.signal', 'scipy.interpolate', 'pywt', "
            "'scipy.ndimage', 'scipy.linalg', 'scipy.spatial', "
            "'mocapfix.cleaners.lowrank_isometry', 'mocapfix.cleaners.partlet') "
            "if m in sys.modules))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""


def test_unknown_cleaner_names_the_known_ones():
    import pytest

    from mocapfix.errors import ConfigError

    with pytest.raises(ConfigError, match="known: .*tsmc"):
        cleaners.build("no_such_cleaner")


def test_default_c3d_clean_loads_no_scipy():
    """The default C3D chain (swaps, trust, fill_ensemble, tsmc) on a capture with gaps,
    jitter and spikes runs on numpy alone (its DCT uses numpy's FFT): importing scipy.fft
    cost ~0.3 s of every clean."""
    code = ("import sys\n"
            "from mocapfix import read\n"
            "from mocapfix.corrupt import occlusion\n"
            "from mocapfix.clean import clean_motion\n"
            "from mocapfix.pipeline import load_config, default_config_path\n"
            "bad, _ = occlusion(read('sample_data/walk_markers.c3d'), 'mixed', 0)\n"
            "result = clean_motion(bad, load_config(default_config_path()))\n"
            "assert result.cleaned.missing.mean() < bad.missing.mean()\n"
            "print(' '.join(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n")
    from pathlib import Path

    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=Path(__file__).resolve().parents[1])
    assert out.stdout.strip() == ""


def test_listing_every_cleaner_loads_no_scipy():
    """`mocapfix cleaners` imports every cleaner module to list their parameters; the
    solvers import scipy only inside the routines that use it (importing scipy.sparse,
    scipy.spatial and scipy.ndimage had made the listing ~0.9 s against ~0.25 s)."""
    code = ("import sys\n"
            "from mocapfix import cleaners\n"
            "names = sorted(cleaners.registry())\n"
            "assert 'partlet_dictionary' in names and 'lowrank_isometry' in names\n"
            "print(' '.join(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == ""
