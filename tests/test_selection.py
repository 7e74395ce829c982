"""Only markers are cleaned: C3D model outputs (POINT:ANGLES, FORCES, MOMENTS, POWERS, ...)
pass through `mocapfix clean` bit-identical, and `markers:`/`exclude:` in a config keep the
named markers as they were, for one step or the whole pipeline."""
import subprocess
import sys

import numpy as np
import pytest

from mocapfix import read
from mocapfix.errors import ConfigError
from mocapfix.motion import Motion
from mocapfix.pipeline import loads_config

from conftest import shared

PIG = ["c3d/c3dorg_s09_PlugInC3D.c3d", "c3d/btk_PiG_Motion-FlatFoot-Hole.c3d"]


@pytest.mark.parametrize("rel", PIG)
def test_model_outputs_are_bit_identical_after_clean(rel, tmp_path):
    path = shared(rel)
    before = read(path)
    assert before.kinds is not None
    model = np.array([k != "marker" for k in before.kinds])
    assert {"angle", "force", "moment", "power"} <= set(before.kinds)
    subprocess.run([sys.executable, "-m", "mocapfix.cli", "clean", str(path), "-o", str(tmp_path)],
                   check=True, capture_output=True)
    after = read(next(tmp_path.glob("*.c3d")))
    assert after.names == before.names
    # the stored point records (x, y, z, residual word) of every model output are unchanged
    assert np.array_equal(after.source.points[:, model].view(np.uint8),
                          before.source.points[:, model].view(np.uint8))
    # their gaps (which the marker fillers used to fill) are still gaps
    assert before.missing[:, model].any()
    assert np.array_equal(after.missing[:, model], before.missing[:, model])
    # while marker gaps, where the file has some, were filled
    if before.missing[:, ~model].any():
        assert (before.missing[:, ~model] & ~after.missing[:, ~model]).any()


def test_model_outputs_do_not_feed_the_marker_models():
    """A cleaner sees only the markers: its result on the markers is the same whether the
    file's model outputs hold their values or garbage."""
    m = read(shared(PIG[0]))
    model = np.array([k != "marker" for k in m.kinds])
    pipe = loads_config("pipeline:\n  - {cleaner: fill_pca, fill_ends: true}\n")
    out1, _ = pipe.run(m)
    noisy = m.positions.copy()
    noisy[:, model] = np.random.default_rng(0).normal(0, 1e4, noisy[:, model].shape)
    out2, _ = pipe.run(m.replace(positions=noisy))
    assert np.array_equal(out1.positions[:, ~model], out2.positions[:, ~model], equal_nan=True)
    assert np.array_equal(out2.positions[:, model], noisy[:, model])


def _gapped(T=120, J=6):
    t = np.linspace(0, 4 * np.pi, T)[:, None]
    pos = np.stack([100 * np.sin(t + np.arange(J)), 100 * np.cos(t + np.arange(J)),
                    np.tile(np.arange(J) * 50.0, (T, 1))], axis=2)
    pos[40:60, :] = np.nan
    names = ["LASI", "RASI", "Probe1", "Probe2", "LKNE", "RKNE"][:J]
    return Motion(pos, names, fps=100.0, format="c3d")


@pytest.mark.parametrize("where", ["pipeline", "step"])
def test_exclude_by_glob_keeps_markers_as_they_were(where):
    m = _gapped()
    step = "  - {cleaner: fill, method: linear, max_gap: 1 s"
    if where == "pipeline":
        text = f"exclude: ['Probe*']\npipeline:\n{step}}}\n"
    else:
        text = f"pipeline:\n{step}, exclude: ['Probe*']}}\n"
    out, records = loads_config(text).run(m)
    probes = [2, 3]
    assert np.isnan(out.positions[40:60, probes]).all()
    others = [0, 1, 4, 5]
    assert not np.isnan(out.positions[:, others]).any()
    assert records[0].info["points_not_cleaned"] == 2


def test_markers_list_selects_names_and_patterns():
    m = _gapped()
    out, _ = loads_config("markers: [LASI, '*KNE']\npipeline:\n"
                          "  - {cleaner: fill, method: linear, max_gap: 1 s}\n").run(m)
    filled = ~np.isnan(out.positions[50]).any(axis=1)
    assert filled.tolist() == [True, False, False, False, True, True]
    assert loads_config("markers: [LASI]\npipeline:\n  - {cleaner: fill}\n").config()["markers"] == ["LASI"]


def test_bad_selection_is_a_config_error():
    with pytest.raises(ConfigError, match="'exclude' must be"):
        loads_config("pipeline:\n  - {cleaner: fill, exclude: 3}\n")
