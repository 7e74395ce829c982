"""partlet_dictionary on real captures against ground truth: the shipped CMU model on CMU
dance trials it was not trained on (corrupt, clean, bound the error, compare with the best
classical filter per case), its use on other conventions (CMU BVH, Kinect), the
out-of-sample warning, and the train-dictionary command end to end."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import SAMPLE_DATA, no_traceback, shared
from mocapfix import formats
from mocapfix.bench import corrupt
from mocapfix.core import metrics, models
from mocapfix.bench import cleaner_input
from mocapfix.cleaners import build
from mocapfix.cli import main
from mocapfix.core.errors import ConfigError
from mocapfix.core.motion import Motion
from mocapfix.config import parse_config

# slow: the shipped models on real captures against ground truth (~20 s)
pytestmark = pytest.mark.slow

SEEDS = (0, 1, 2)
KIN = SAMPLE_DATA / "walk_kinect_v2.csv"


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
    coarse = models.read_header(ships["partlet-cmu"])["state"]["coarse"]
    assert coarse["sample_rate"] == 30.0 and coarse["window"] == 16
    assert sum(p.stat().st_size for p in ships.values()) < 8e6, "shipped models must stay small"


@pytest.mark.parametrize("setting,ratio", [("snr30", 0.92), ("snr20", 0.78), ("snr10", 0.72),
                                           ("out20", 0.3), ("snr20+out10", 0.6)])
def test_against_the_best_classical_filter_on_held_out_dance(setting, ratio):
    """05_02 and 05_10 are not in the training corpus. Bound: on every seed, below
    ``ratio`` × the best oracle-tuned classical filter of that very case. Measured (480
    frames, seeds 0–2, worst of 6): 30 dB 0.86, 20 dB 0.70, 10 dB 0.64, 20 % outliers 0.25,
    20 dB + 10 % 0.54 (before the local strength and the coarse scale 0.87, 0.73, 0.69,
    0.25, 0.54)."""
    cleaner = build("partlet_dictionary")
    for name in ("05_02.amc", "05_10.amc"):
        truth = _clean(name)
        for seed in SEEDS:
            noisy, _ = corrupt.apply_protocol(truth, "feng2015", setting, seed)
            noisy = cleaner_input(truth, noisy)
            out, info = cleaner.apply(noisy)
            ours, classic = _rmse_cm(out, truth), _best_classic(noisy, truth)
            assert ours < ratio * classic, (name, seed, ours, classic)


@pytest.mark.parametrize("setting,ratio", [("snr5", 0.96), ("snr10", 0.98)])
def test_coarse_scale_beats_the_fine_one_under_heavy_noise(setting, ratio):
    """Above ``coarse_noise`` the shipped model's 0.5 s windows (16 samples at 30 Hz) code
    the file instead of its 0.13 s ones. Held-out dance, whole trials, seeds 0–2, error with
    the coarse scale / without it, on every run: measured at most 0.94 (5 dB) and 0.97
    (10 dB), mean 0.93 and 0.95."""
    both, fine = build("partlet_dictionary"), build("partlet_dictionary", coarse_noise="0 mm")
    for name in ("05_02.amc", "05_10.amc"):
        truth = formats.read(shared(f"asfamc/{name}")).replace(rig=None, channels=None)
        for seed in SEEDS:
            noisy, _ = corrupt.apply_protocol(truth, "feng2015", setting, seed)
            noisy = cleaner_input(truth, noisy)
            out, info = both.apply(noisy)
            assert info["scale"] == "coarse"
            ratio_run = _rmse_cm(out, truth) / _rmse_cm(fine.apply(noisy)[0], truth)
            assert ratio_run < ratio, (name, seed, ratio_run)


@pytest.mark.parametrize("setting", ["snr30", "snr10", "out20"])
def test_local_smoothing_strength_beats_one_per_channel(setting):
    """The presmoothing with its strength chosen per sample by SURE over 0.5 s against one
    GCV strength per channel (``local_smoothing: 0 s``). Held-out dance, whole trials, seeds
    0–2, error ratio: measured on every run 0.96–0.98 (30 dB), 0.94–0.99 (10 dB), 0.94–0.97
    (20 % outliers); means 0.97, 0.97, 0.95."""
    local, one = build("partlet_dictionary"), build("partlet_dictionary", local_smoothing="0 s")
    ratios = []
    for name in ("05_02.amc", "05_10.amc"):
        truth = formats.read(shared(f"asfamc/{name}")).replace(rig=None, channels=None)
        for seed in SEEDS:
            noisy, _ = corrupt.apply_protocol(truth, "feng2015", setting, seed)
            noisy = cleaner_input(truth, noisy)
            ratios.append(_rmse_cm(local.apply(noisy)[0], truth) / _rmse_cm(one.apply(noisy)[0], truth))
    assert max(ratios) < 1.0 and np.mean(ratios) < 0.985, ratios


def test_coarse_scale_is_left_alone_under_light_noise():
    truth = _clean("05_02.amc")
    noisy, _ = corrupt.apply_protocol(truth, "feng2015", "snr20", 0)
    noisy = cleaner_input(truth, noisy)
    out, info = build("partlet_dictionary").apply(noisy)
    assert "scale" not in info
    assert np.array_equal(out.positions, build("partlet_dictionary", coarse_noise="0 mm").apply(noisy)[0].positions)


def test_coarse_scale_only_for_the_robust_coding():
    """OMP codes of 6 atoms per 0.5 s window are too coarse: the K-SVD coding keeps the
    fine scale under heavy noise too."""
    truth = _clean("05_02.amc")
    noisy, _ = corrupt.apply_protocol(truth, "feng2015", "snr10", 0)
    noisy = cleaner_input(truth, noisy)
    assert build("partlet_dictionary").apply(noisy)[1]["scale"] == "coarse"
    assert "scale" not in build("partlet_dictionary", coding="ksvd").apply(noisy)[1]


def test_coarse_scale_is_saved_loaded_and_optional(tmp_path):
    """A model trained with a coarse scale keeps it through save and load (same output when
    it codes); one trained without (``coarse_rate: 0``, or a model from before) has none and
    cleans as before."""
    train = [_clean("05_02.amc", 600)]
    fast = {"atoms": 16, "window": 6, "train_iterations": 3, "max_windows": 400}
    noisy, _ = corrupt.apply_protocol(_clean("05_10.amc"), "feng2015", "snr10", 0)
    outs = {}
    for rate in ("30 Hz", "0 Hz"):
        c = build("partlet_dictionary", coarse_rate=rate, coarse_noise="1 mm", **fast).fit(train)
        assert (c.coarse_ is not None) == (rate == "30 Hz")
        header, arrays = c.state()
        header.update(c.model_header_fields())
        path = models.save(tmp_path / f"{rate[0]}.npz", header, arrays)
        assert any(k.startswith("coarse_") for k in arrays) == (rate == "30 Hz")
        loaded = build("partlet_dictionary", model=str(path), coarse_noise="1 mm")
        loaded.resolve_models(None)
        out, info = c.apply(noisy)
        again, info2 = loaded.apply(noisy)
        assert np.array_equal(out.positions, again.positions)
        assert info.get("scale") == info2.get("scale") == ("coarse" if rate == "30 Hz" else None)
        outs[rate] = out.positions
    assert not np.allclose(outs["30 Hz"], outs["0 Hz"])


def test_suspect_samples_find_spikes_and_leave_fast_clean_motion_alone():
    """Known answer: on the clean dance takes almost no sample stands 40 mm off its running
    median (measured: 3 of 34,813 samples of 05_02, at a foot strike; none in 05_10); 30
    spikes of 30 cm are all found, and nothing else but those few."""
    from mocapfix.solvers.partlet import suspect_samples

    for name in ("05_02.amc", "05_10.amc"):
        truth = _clean(name, 100_000)
        P = truth.positions * truth.metres_per_unit
        clean_flags = suspect_samples(P, 5.0, 0.04)
        assert clean_flags.mean() < 2e-4
        rng = np.random.default_rng(0)
        t, j = rng.choice(len(P), 30, replace=False), rng.integers(0, P.shape[1], 30)
        spiked = P.copy()
        spiked[t, j] += rng.choice([-1, 1], size=(30, 3)) * 0.3 / np.sqrt(3)
        found = suspect_samples(spiked, 5.0, 0.04)
        assert found[t, j].all()
        found[t, j] = False
        assert (found & ~clean_flags).sum() == 0


def test_rigid_bone_test_tells_a_bone_from_a_pair_that_moves_apart():
    """Known answer: a 30 cm bone under 2 cm noise is rigid, two joints whose distance
    swings by ±10 cm are not, under the same noise; clean data: exact."""
    from mocapfix.solvers.partlet import rigid_bones

    def rigid_bone(a, b, sigma):
        return bool(rigid_bones(a[:, None], b[:, None], sigma)[0])

    rng = np.random.default_rng(1)
    T = 1000
    ang = np.linspace(0, 20, T)
    a = np.zeros((T, 3))
    b = 0.3 * np.stack([np.cos(ang), np.sin(ang), 0 * ang], axis=1)
    noise = lambda: rng.normal(0, 0.02, (T, 3))  # noqa: E731
    assert rigid_bone(a, b, 0.0)
    assert rigid_bone(a + noise(), b + noise(), 0.02)
    stretch = b * (1 + 0.33 * np.sin(3 * ang))[:, None]
    assert not rigid_bone(a, stretch, 0.0)
    assert not rigid_bone(a + noise(), stretch + noise(), 0.02)


def test_clean_input_stays_close():
    """No noise: the cleaner must not invent error beyond what the model cannot represent."""
    for name in ("05_02.amc", "05_10.amc"):
        truth = _clean(name)
        out, info = build("partlet_dictionary").apply(truth)
        assert _rmse_cm(out, truth) < 0.5


def test_fills_gaps_better_than_a_cubic_spline():
    truth = _clean("05_10.amc")
    pos = truth.positions.copy()
    pos[100:160, truth.index("lradius")] = np.nan
    pos[300:330, truth.index("rtibia")] = np.nan
    gapped = truth.replace(positions=pos)
    out, _ = build("partlet_dictionary").apply(gapped)
    assert not np.isnan(out.positions).any()
    spline, _ = build("fill", method="spline", max_gap=None).apply(gapped)
    gap = np.isnan(pos).any(axis=2)
    err = lambda p: np.sqrt(np.mean(np.sum((p - truth.positions) ** 2, axis=2)[gap]))  # noqa: E731
    assert err(out.positions) < 0.8 * err(spline.positions)      # measured 5.0 vs 7.3 cm


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


def test_one_cleaner_picks_the_model_for_each_file_of_a_mixed_batch():
    # the pipeline is built once per process: the cleaner kept the first file's shipped
    # model and failed every later file of another skeleton ("the model's torso joints
    # are not in walker_01.amc")
    from conftest import SAMPLE_DATA

    cleaner = build("partlet_dictionary")
    kinect = formats.read(shared("kinect/kv2_laban_Ges01_wavehand.csv"))
    amc = formats.read(SAMPLE_DATA / "walker_01.amc")
    for motion in (kinect, amc, kinect):
        out, info = cleaner.apply(motion)
        # the Kinect model's 25 joints, or the CMU model's (the sample ASF maps 22 of 31)
        assert info["model_joints"] == (25 if motion is kinect else 22)
        assert out.positions.shape == motion.positions.shape
    assert not cleaner.is_fitted                       # apply never changes the cleaner


def test_unknown_skeleton_says_a_model_must_be_trained():
    m = Motion(np.random.default_rng(0).normal(size=(200, 5, 3)), list("ABCDE"), 100.0)
    with pytest.raises(ConfigError, match="train-dictionary"):
        build("partlet_dictionary").apply(m)


def test_unexplained_energy_rises_for_motion_unlike_the_training_set():
    """The report's per-partlet figure: an arm whose elbow and fingers trade places (no
    body moves so) leaves far more energy unexplained than the clean take."""
    truth = _clean("05_10.amc")
    _, clean_info = build("partlet_dictionary").apply(truth)
    pos = truth.positions.copy()
    a, b = truth.index("lhumerus"), truth.index("lfingers")
    pos[:, [a, b]] = pos[:, [b, a]]
    _, info = build("partlet_dictionary").apply(truth.replace(positions=pos))
    assert set(info["unexplained"]) == {"torso", "left_arm", "right_arm", "left_leg", "right_leg"}
    assert info["unexplained"]["left_arm"] > 5 * clean_info["unexplained"]["left_arm"]
    assert info["unexplained"]["right_arm"] == clean_info["unexplained"]["right_arm"]


def test_out_of_sample_warning_on_a_walk_and_not_on_held_out_dance():
    """The shipped model saw no walk: the CMU BVH walk's arms are out of sample (measured
    0.4–1.2 % unexplained); the held-out dance trials are not (≤ 0.08 %)."""
    walk = formats.read(shared("bvh/cmu_cgspeed_131_03.bvh")).replace(rig=None, channels=None)
    _, info = build("partlet_dictionary").apply(walk)
    assert "warning" in info and "arm" in info["warning"], info
    for name in ("05_02.amc", "05_10.amc"):
        dance = formats.read(shared(f"asfamc/{name}")).replace(rig=None, channels=None)
        _, info = build("partlet_dictionary").apply(dance)
        assert "warning" not in info, info


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


def test_train_dictionary_with_no_readable_file_writes_no_model(tmp_path):
    bad = tmp_path / "broken.bvh"
    bad.write_text("HIERARCHY\nROOT x {\n")
    res = CliRunner().invoke(main, ["train-dictionary", str(bad), "-o", str(tmp_path / "m.npz")])
    assert res.exit_code == 3 and "broken.bvh" in res.output
    assert not (tmp_path / "m.npz").exists()


def test_one_unreadable_training_file_is_named_left_out_and_recorded(tmp_path):
    """A damaged take in a training folder costs that take, not the run: the others are
    trained on, the take is named, the model's provenance lists it, and the exit is 1."""
    import shutil

    takes = tmp_path / "takes"
    takes.mkdir()
    for name in ("05.asf", "05_01.amc", "05_02.amc"):
        shutil.copy(shared(f"asfamc/{name}"), takes / name)
    good = (takes / "05_02.amc").read_text().splitlines(keepends=True)
    (takes / "05_03.amc").write_text("".join(good[:40]) + "12\nroot 1.0 oops\n")
    out = tmp_path / "m.npz"
    res = CliRunner().invoke(main, ["train-dictionary", str(takes), "-o", str(out),
                                    "--atoms", "16", "--iterations", "2", "--max-windows", "400"])
    assert res.exit_code == 1, res.output
    assert "05_03.amc" in res.output and "left out of the training" in res.output
    assert "trained on 2 files" in res.output
    training = models.read_header(out)["training"]
    assert sorted(Path(f["path"]).name for f in training["files"]) == ["05_01.amc", "05_02.amc"]
    assert [Path(u["path"]).name for u in training["unread"]] == ["05_03.amc"]


def test_no_readable_training_file_names_it_once_with_its_line_and_writes_no_model(tmp_path):
    """Every training file unreadable: exit 3 (an unreadable input), one message naming
    the file once and the line of its fault, and no model written."""
    import re
    import shutil

    takes = tmp_path / "takes"
    takes.mkdir()
    shutil.copy(shared("asfamc/05.asf"), takes / "05.asf")
    good = shared("asfamc/05_02.amc").read_text().splitlines(keepends=True)
    (takes / "05_03.amc").write_text("".join(good[:40]) + "12\nroot 1.0 oops\n")
    out = tmp_path / "m.npz"
    res = CliRunner().invoke(main, ["train-dictionary", str(takes), "-o", str(out), "--atoms", "16"])
    assert res.exit_code == 3, res.output
    amc = str(takes / "05_03.amc")
    assert res.output.count(amc) == 1, res.output
    assert re.search(re.escape(amc) + r": none of the 1 training files could be read; this one: "
                     r"line \d+: ", res.output), res.output
    assert not out.exists()


def test_kinect_v1_v2_azure_and_msr_names_map_to_the_kinect_model_joints():
    from mocapfix.core import bodyparts
    from mocapfix.core import kinect_joints as kl

    v2 = [n.lower() for n in bodyparts.KINECT_V2_NAMES]
    for layout in (names for names, _ in kl.JOINT_SETS.values()):
        canon = bodyparts.canonical_names(layout)
        hits = [c for c in canon if c in v2]
        assert len(hits) >= 20, (layout[:3], hits)
        assert len(set(hits)) == len(hits), "two joints mapped to one model joint"


def test_train_dictionary_passes_over_notes_in_a_training_folder(tmp_path):
    """A lab folder holds notes beside the takes: training skips them, says so, and trains."""
    import shutil

    takes = tmp_path / "takes"
    takes.mkdir()
    for name in ("05.asf", "05_01.amc", "05_02.amc"):
        shutil.copy(shared(f"asfamc/{name}"), takes / name)
    (takes / "notes.txt").write_text("session notes: subject 5, good takes\n")
    res = CliRunner().invoke(main, ["train-dictionary", str(takes), "-o", str(tmp_path / "m.npz"),
                                    "--atoms", "16", "--iterations", "2", "--max-windows", "400"])
    assert res.exit_code == 0, res.output
    assert "skipped" in res.output and "notes.txt" in res.output
    assert "trained on 2 files" in res.output


def test_partlet_training_on_unusable_takes_is_one_clear_error(tmp_path):
    # a Kinect take then an AMC (other joint names: no body frame) failed with "internal
    # error ValueError: no frame has enough torso points"; takes shorter than one window
    # (an ASF alone is a one-frame rest pose) with "need at least one array to concatenate"
    asf, amc = SAMPLE_DATA / "walker.asf", SAMPLE_DATA / "walker_01.amc"
    for files, message in (([KIN, amc], f"{amc}: lacks body-frame joints of {KIN}"),
                           ([asf], "no training motion has a complete window of 16 samples")):
        r = CliRunner().invoke(main, ["train-dictionary", *map(str, files), "--atoms", "4",
                                      "--iterations", "1", "-o", str(tmp_path / "m.npz")])
        no_traceback(r)
        assert r.exit_code == 2 and message in r.output, r.output
    assert not (tmp_path / "m.npz").exists()
