"""partlet_dictionary on real captures against ground truth: the shipped CMU model on CMU
dance trials it was not trained on (corrupt, clean, bound the error, compare with the best
classical filter per case), its use on other conventions (CMU BVH, Kinect), the
out-of-sample warning, and the train-dictionary command end to end."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import shared
from mocapfix import corrupt, formats, metrics, models
from mocapfix.bench import cleaner_input
from mocapfix.cleaners import build
from mocapfix.cli import main
from mocapfix.errors import ConfigError
from mocapfix.motion import Motion
from mocapfix.pipeline import parse_config

SEEDS = (0, 1, 2)


def _clean(name: str, frames: int = 480) -> Motion:
    return formats.read(shared(f"asfamc/{name}")).slice_frames(0, frames).replace(rig=None, channels=None)


def _rmse_cm(motion, truth):
    return 100 * truth.metres_per_unit * metrics.rmse(motion.positions, truth.positions)


def _best_classic(noisy, truth):
    """The best of Gaussian (σ over a grid), Kalman and wavelet for this very case: an
    oracle choice, as the paper tuned its baselines."""
    best = np.inf
    for cfg in ([{"cleaner": "gaussian", "sigma": f"{s} s"}] for s in (0.01, 0.02, 0.04, 0.08)):
        out, _ = parse_config({"version": 1, "pipeline": cfg}).run(noisy)
        best = min(best, _rmse_cm(out, truth))
    for name in ("kalman", "wavelet"):
        out, _ = build(name).apply(noisy)
        best = min(best, _rmse_cm(out, truth))
    return best


def test_shipped_models_exist_and_load():
    ships = models.shipped()
    for name in ("partlet-cmu", "partlet-kinect"):
        header, arrays = models.load(ships[name], cleaner="partlet_dictionary")
        assert header["training"]["frames"] > 50_000 and len(header["training"]["files"]) == 47
        assert all(len(f["sha256"]) == 64 for f in header["training"]["files"])
        assert header["units"] == "m" and header["schema"] == models.SCHEMA
    assert sum(p.stat().st_size for p in ships.values()) < 8e6, "shipped models must stay small"


@pytest.mark.parametrize("setting,ratio", [("snr20", 0.8), ("out20", 0.5), ("snr20+out10", 0.6)])
def test_beats_the_best_classical_filter_on_held_out_dance(setting, ratio):
    """05_02 and 05_10 are not in the training corpus. Bounds: the worst seed must be below
    ``ratio`` × the best oracle-tuned classical filter of that very case."""
    cleaner = build("partlet_dictionary")
    for name in ("05_02.amc", "05_10.amc"):
        truth = _clean(name)
        for seed in SEEDS:
            noisy, _ = corrupt.apply_protocol(truth, "feng2015", setting, seed)
            noisy = cleaner_input(truth, noisy)
            out, info = cleaner.apply(noisy)
            ours, classic = _rmse_cm(out, truth), _best_classic(noisy, truth)
            assert ours < ratio * classic, (name, seed, ours, classic)


def test_clean_input_stays_close():
    """No noise: the cleaner must not invent error beyond what the model cannot represent."""
    truth = _clean("05_02.amc")
    out, info = build("partlet_dictionary").apply(truth)
    assert _rmse_cm(out, truth) < 1.0
    assert "warning" not in info


def test_fills_gaps():
    truth = _clean("05_10.amc")
    pos = truth.positions.copy()
    pos[100:160, truth.index("lradius")] = np.nan
    pos[300:330, truth.index("rtibia")] = np.nan
    out, _ = build("partlet_dictionary").apply(truth.replace(positions=pos))
    assert not np.isnan(out.positions).any()
    gap = np.isnan(pos).any(axis=2)
    err = np.linalg.norm(out.positions - truth.positions, axis=2)[gap] * truth.metres_per_unit * 100
    assert np.sqrt(np.mean(err ** 2)) < 5.0


def test_cmu_bvh_uses_the_shipped_model_through_name_mapping():
    walk = formats.read(shared("bvh/cmu_cgspeed_131_01.bvh")).slice_frames(0, 480)
    walk = walk.replace(rig=None, channels=None)
    out, info = build("partlet_dictionary").apply(walk)
    assert info["model_joints"] >= 28
    assert _rmse_cm(out, walk) < 1.5


def test_kinect_skeleton_uses_the_kinect_model():
    k = formats.read(shared("kinect/kv2_laban_Ges01_wavehand.csv"))
    out, info = build("partlet_dictionary").apply(k)
    assert info["model_joints"] == 25 and out.positions.shape == k.positions.shape


def test_unknown_skeleton_says_a_model_must_be_trained():
    m = Motion(np.random.default_rng(0).normal(size=(200, 5, 3)), list("ABCDE"), 100.0)
    with pytest.raises(ConfigError, match="train-dictionary"):
        build("partlet_dictionary").apply(m)


def test_motion_unlike_the_training_set_is_reported():
    truth = _clean("05_02.amc")
    pos = truth.positions.copy()
    # the arms spin about the body in a way no dancer's do: out of sample for the arm partlets
    t = np.arange(len(pos))[:, None]
    for name in ("lradius", "lwrist", "lhand", "lfingers", "lthumb"):
        j = truth.index(name)
        pos[:, j, 0] += 12 * np.sin(t[:, 0] / 3.0)
        pos[:, j, 1] += 12 * np.cos(t[:, 0] / 2.0)
    _, info = build("partlet_dictionary").apply(truth.replace(positions=pos))
    assert "warning" in info and "left_arm" in info["warning"]


def test_train_dictionary_command_and_a_config_that_uses_the_model(tmp_path):
    src = shared("asfamc/05_02.amc")
    out = tmp_path / "m.npz"
    res = CliRunner().invoke(main, ["train-dictionary", str(src), str(shared("asfamc/05_10.amc")),
                                    "-o", str(out), "--atoms", "24", "--iterations", "3",
                                    "--max-windows", "800"])
    assert res.exit_code == 0, res.output
    assert "trained on 2 files" in res.output
    header = models.read_header(out)
    assert header["cleaner"] == "partlet_dictionary" and header["state"]["method"] == "partlet"
    assert header["parameters"]["atoms"] == 24
    cfg = tmp_path / "c.yaml"
    cfg.write_text(f"version: 1\npipeline:\n  - cleaner: partlet_dictionary\n    model: {out.name}\n")
    res = CliRunner().invoke(main, ["clean", str(shared("asfamc/05_01.amc")), "-o",
                                    str(tmp_path / "o"), "-c", str(cfg)])
    assert res.exit_code == 0, res.output


def test_train_dictionary_refuses_unreadable_training_files(tmp_path):
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT x {\n")
    res = CliRunner().invoke(main, ["train-dictionary", str(bad), "-o", str(tmp_path / "m.npz")])
    assert res.exit_code == 2 and "broken.bvh" in res.output
    assert not (tmp_path / "m.npz").exists()
