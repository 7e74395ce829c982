"""M-SSA filter bases (Lou 2012 ch. 2), continuous rotation features, rotation-space
glitch removal and SURE denoising, and the ``rotations`` bench protocol: known-answer
cases on synthetic signals, and corrupt → clean → bound on real BVH/AMC files."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from mocapfix.bench import rotations as br
from mocapfix import formats
from mocapfix.core import models
from mocapfix.cleaners import build
from mocapfix.core.errors import ConfigError
from mocapfix.cli import main
from mocapfix.solvers import glitches, rotchannels, ssa, sure
from conftest import SAMPLE_DATA, no_traceback, shared

BVH, C3D = SAMPLE_DATA / "walk.bvh", SAMPLE_DATA / "walk_markers.c3d"


# -- solvers: known answers ---------------------------------------------------------------

def _sines(T=600, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(T)
    freqs = rng.uniform(0.005, 0.03, 3)
    mix = rng.normal(size=(3, 5))
    return np.sin(2 * np.pi * freqs[None] * t[:, None] + rng.uniform(0, 6, 3)) @ mix * 10


def test_windows_and_overlap_add_are_inverse():
    X = np.arange(40.0).reshape(10, 4)
    W = ssa.windows(X, 3)
    assert W.shape == (8, 12) and np.array_equal(W[2], X[2:5].ravel())
    back = ssa.overlap_add(W, 10, 3, 4) / ssa.window_counts(10, 3)[:, None]
    assert np.allclose(back, X)
    assert list(ssa.window_counts(10, 3)) == [1, 2, 3, 3, 3, 3, 3, 3, 2, 1]


@pytest.mark.parametrize("T,m,L,K", [(50, 5, 3, 4), (200, 12, 7, 20), (30, 12, 4, 10), (23, 12, 2, 3),
                                     (1000, 12, 9, 30), (777, 5, 4, 6)])
def test_fir_projector_equals_the_window_by_window_projection(T, m, L, K):
    rng = np.random.default_rng(T)
    E = np.linalg.qr(rng.normal(size=(m * L, K)))[0]
    Z = rng.normal(size=(T, L))
    direct = ssa.overlap_add((ssa.windows(Z, m) @ E) @ E.T, T, m, L)
    assert np.allclose(ssa.projector(E, m, dtype=np.float64)(Z), direct, atol=1e-12)


def test_bases_of_three_sines_need_six_dimensions():
    """A mix of 3 sinusoids on 5 channels spans 6 dimensions of any window (sin and cos per
    frequency): 6 bases hold all the energy, 5 do not."""
    acc = ssa.LagCovariance(10, 5)
    acc.add(_sines())
    _, vals = acc.bases(k=1)
    assert ssa.unexplained_fraction(vals, 6) < 1e-10 < ssa.unexplained_fraction(vals, 5)
    E, _ = acc.bases(energy=0.999999)
    assert E.shape[1] == 6
    assert np.allclose(E.T @ E, np.eye(6), atol=1e-8)


def test_robust_reconstruction_removes_spikes_and_fills_a_gap():
    X = _sines()
    acc = ssa.LagCovariance(10, 5)
    acc.add(X)
    E, _ = acc.bases(k=6)
    Y = X + np.random.default_rng(1).normal(0, 0.3, X.shape)
    Y[100, 2] += 40.0
    Y[300:303, 0] -= 25.0
    Y[400:412, 4] = np.nan
    Z, w, _ = ssa.robust_reconstruct(Y, E, 10, lam=1.0, p=3.0, iterations=20)
    assert not np.isnan(Z).any()
    assert w[100, 2] < 0.01 and (w[300:303, 0] < 0.01).all() and (w[400:412, 4] == 0).all()
    assert abs(Z[100, 2] - X[100, 2]) < 1.0 and np.abs(Z[300:303, 0] - X[300:303, 0]).max() < 1.0
    # the 12-frame gap: better than a straight line across it (convergence across gaps is
    # slow: 20 iterations, over-relaxed)
    from mocapfix.solvers.segments import linear_bridge

    line = np.abs(linear_bridge(Y)[400:412, 4] - X[400:412, 4]).max()
    assert np.abs(Z[400:412, 4] - X[400:412, 4]).max() < 0.7 * line
    # the noise is reduced too (projection on 6 of 50 dimensions)
    assert np.sqrt(np.mean((Z - X) ** 2)) < 0.5 * 0.3


def test_sure_smooths_a_slow_channel_more_than_a_fast_one():
    T = 2000
    t = np.arange(T)
    clean = np.stack([np.sin(2 * np.pi * t / 1000), np.sin(2 * np.pi * t / 25)], axis=1) * 10
    noisy = clean + np.random.default_rng(2).normal(0, 0.5, clean.shape)
    Z, widths = sure.sure_gaussian(noisy, 0.5)
    assert widths[0] > 3 * widths[1]
    err = np.sqrt(np.mean((Z - clean) ** 2, axis=0))
    assert err[0] < 0.2 * 0.5 and err[1] < 0.8 * 0.5


@pytest.mark.parametrize("axes", ["ZYX", "XYZ", "ZXY", "YZX"])
def test_euler_quaternions_match_scipy(axes):
    from scipy.spatial.transform import Rotation

    d = np.random.default_rng(0).uniform(-180, 180, (200, 3))
    ours = rotchannels.euler_quaternions(axes, d)
    ref = Rotation.from_euler(axes, d, degrees=True).as_quat()[:, [3, 0, 1, 2]]
    assert np.allclose(np.abs(np.sum(ours * ref, axis=1)), 1.0, atol=1e-12)


def test_rotation_features_round_trip_and_are_continuous():
    m = formats.read(shared("asfamc/90_31.amc"))
    F = rotchannels.to_features(m.rig, m.channels)
    assert F.shape[1] == sum(e["size"] for e in rotchannels.layout(m.rig))
    # acrobatics: the root turns over, yet no quaternion feature jumps between frames
    nq = 4 * sum(e["kind"] == "quat" for e in rotchannels.layout(m.rig))
    assert rotchannels.layout(m.rig)[0]["kind"] == "quat"
    quat_cols = [c for c, e in enumerate(e for e in rotchannels.layout(m.rig) for _ in range(e["size"]))
                 if e["kind"] == "quat"]
    assert len(quat_cols) == nq
    assert np.abs(np.diff(F[:, quat_cols], axis=0)).max() < 60.0
    back = rotchannels.from_features(m.rig, F, m.channels)
    assert np.abs(back - m.channels).max() < 1e-9


# -- the rotations bench protocol ---------------------------------------------------------

def test_rotations_protocol_is_seeded_and_leaves_translations_alone():
    m = formats.read(shared("asfamc/13_39.amc"))
    a, mask = br.corrupt(m, "mixed", 3)
    b, _ = br.corrupt(m, "mixed", 3)
    assert np.array_equal(a.channels, b.channels) and mask.any()
    trans = m.rig.trans_columns[m.rig.trans_columns >= 0]
    assert np.array_equal(a.channels[:, trans], m.channels[:, trans])
    d = (a.channels - m.channels)[:, br.rotation_columns(m.rig)]
    assert 0.6 < np.std(d[np.abs(d) < 5]) < 0.8                 # the 0.7° jitter
    assert 9.9 < np.abs(d).max() < 45                            # 10–40° spikes on top
    clean, _ = br.corrupt(m, "clean", 0)
    scores = br.evaluate(m, clean)
    assert scores["pos_err_pct"] == 0 and scores["deg_err"] == 0


def test_equivalent_euler_solutions_are_not_errors():
    m = formats.read(shared("asfamc/13_39.amc"))
    ch = m.channels.copy()
    j = next(j for j, a in enumerate(m.rig.rot_axes) if len(a) == 3 and m.rig.parents[j] >= 0)
    a, b, c = (ch[:, k].copy() for k in m.rig.rot_columns[j])
    ch[:, m.rig.rot_columns[j]] = np.stack([a + 180, 180 - b, c + 180], axis=1)
    assert np.allclose(m.rig.positions(ch), m.positions, atol=1e-9)
    assert br.channel_errors(m.rig, ch, m.channels).max() < 1e-9


# -- cleaners on real files ---------------------------------------------------------------

def test_euler_smooth_wants_an_odd_median():
    with pytest.raises(ConfigError, match="odd"):
        build("euler_smooth", median=4)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["asfamc/90_31.amc", "bvh/cmu_cgspeed_131_01.bvh"])
def test_rotation_outliers_remove_spikes_and_keep_fast_real_motion(name):
    m = formats.read(shared(name))
    out, info = build("rotation_outliers").apply(m)
    # clean acrobatics and toes: almost nothing replaced, joints move < 0.03 % of height
    assert info["joint_frames_replaced"] < 0.006 * m.n_frames * len(rotchannels.layout(m.rig))
    assert br.evaluate(m, out)["pos_err_pct"] < 0.03
    spiked, _ = br.corrupt(m, "spikes", 1)
    cleaned, _ = build("rotation_outliers").apply(spiked)
    assert br.evaluate(m, cleaned)["pos_err_pct"] < 0.3 * br.evaluate(m, spiked)["pos_err_pct"]
    # only the re-made joint-frames change: every other channel value is kept bit for bit
    assert (cleaned.channels != spiked.channels).mean() < 0.01


def _gait_channel(T=220, period=32, seed=0):
    """A 30 Hz toe angle: a slow swing plus, once per gait cycle, a toe-off flick two
    frames wide (30 degrees), each cycle a little different; light noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(T)
    x = 20 * np.sin(2 * np.pi * t / period)
    for k, c in enumerate(range(26, T - 30, period)):
        x[c:c + 2] += 30 * (1 + 0.05 * rng.standard_normal()) * np.array([0.8, 1.0])
    return x + 0.2 * rng.standard_normal(T)


def test_a_deviation_that_recurs_every_cycle_is_motion_and_a_lone_one_a_glitch():
    x = _gait_channel()
    rng = np.random.default_rng(1)
    # an aperiodic background: a slow, smooth wander (no cycle repeats around a glitch)
    wander = np.cumsum(np.cumsum(rng.standard_normal(len(x)))) * 0.02 + 0.2 * rng.standard_normal(len(x))
    X = np.stack([x, x.copy(), wander], axis=1)
    X[101, 1] += 25.0                    # one glitch between two toe-offs
    for g in (40, 100, 160):             # three glitches alike in one channel
        X[g, 2] += 25.0
    found = glitches.glitches(X, width=7, k=16, floor=5.0)
    toe_offs = np.zeros(len(x), bool)
    for c in range(26, len(x) - 30, 32):
        toe_offs[c:c + 2] = True
    # the flicks are not flagged in any column; every glitch is, alone or alike
    assert not found[toe_offs].any()
    assert found[101, 1] and found[[40, 100, 160], 2].all()
    assert found.sum() == 4
    # without the recurrence test the flicks were flagged, and without its third part
    # (the motion around them) the three alike glitches would clear each other
    plain = glitches.confirm(X, found | toe_offs[:, None], threshold=np.full(3, 5.0),
                             max_run=3)
    assert plain[toe_offs].any()
    lenient = glitches.recurring(X, found, context=np.inf)
    assert not lenient[[40, 100, 160], 2].any()


def test_glitches_at_the_ends_are_checked_against_the_cubic_beyond_them():
    t = np.arange(120) / 30.0
    fast = np.stack([40 * np.sin(2 * np.pi * 1.5 * t)] * 2, axis=1)   # fast, smooth, real
    fast[1, 1] += 30.0                                                    # a glitch at frame 1
    found = glitches.glitches(fast, width=7, k=16, floor=5.0)
    assert not found[:, 0].any()                     # the real motion at both ends is kept
    assert found[1, 1] and not found[5:, 1].any()


def test_bandai_walk_toe_offs_are_kept_by_rotation_outliers():
    # 30 Hz walk: one of its toes was re-made at every toe-off (27 joint-frames; now 8)
    m = formats.read(shared("bvh/bandai_dataset-1_walk_normal_001.bvh"))
    out, info = build("rotation_outliers", threshold=16).apply(m)
    assert info.get("joint_frames_replaced", 0) <= 8
    # the toe-offs of the middle cycles are all kept (Toes_L at 93, 125, 157; Toes_R at
    # 76-78, 108-110, 140-142, 173-174 were re-made); near the ends of the take the
    # motion around a toe-off cannot be compared, and some are still re-made
    middle = [f for frames in info.get("replaced_frames", {}).values() for f in frames
              if 70 <= f <= 180]
    assert middle == []
    spiked, _ = br.corrupt(m, "spikes", 0)
    cleaned, _ = build("rotation_outliers", threshold=16).apply(spiked)
    assert br.evaluate(m, cleaned)["pos_err_pct"] < 0.05 * br.evaluate(m, spiked)["pos_err_pct"]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["asfamc/13_39.amc", "bvh/cmu_cgspeed_131_01.bvh",
                                  "bvh/bandai_dataset-1_walk_normal_001.bvh"])
def test_rotation_denoise_beats_the_gaussian_on_euler_curves(name):
    m = formats.read(shared(name))
    noisy, _ = br.corrupt(m, "jitter", 1)
    ours = br.evaluate(m, build("rotation_denoise").apply(noisy)[0])["pos_err_pct"]
    euler = br.evaluate(m, build("euler_smooth", sigma="2 frames").apply(noisy)[0])["pos_err_pct"]
    none = br.evaluate(m, noisy)["pos_err_pct"]
    assert ours < 0.95 * euler and ours < 0.5 * none


@pytest.mark.slow
def test_mssa_uses_the_shipped_model_on_cmu_skeletons_and_learns_otherwise():
    assert "mssa-cmu" in models.shipped()
    m = formats.read(shared("asfamc/13_39.amc"))          # not in the training corpus
    noisy, _ = br.corrupt(m, "mixed", 2)
    out, info = build("mssa").apply(noisy)
    assert info["bases"] == "mssa-cmu" and "warning" not in info
    assert br.evaluate(m, out)["pos_err_pct"] < 0.5 * br.evaluate(m, noisy)["pos_err_pct"]
    b = formats.read(shared("bvh/cmu_cgspeed_131_01.bvh"))
    noisy, _ = br.corrupt(b, "jitter", 2)
    out, info = build("mssa").apply(noisy)
    assert info["bases"] == "self" and "learned from the file itself" in info["note"]
    assert br.evaluate(b, out)["pos_err_pct"] < 0.5 * br.evaluate(b, noisy)["pos_err_pct"]


def test_mssa_fills_missing_rotation_channels():
    m = formats.read(shared("asfamc/13_39.amc"))
    ch = m.channels.copy()
    j = m.rig.names.index("lfemur")
    ch[100:140, m.rig.rot_columns[j]] = np.nan
    gappy = m.replace(channels=ch, positions=m.rig.positions(ch))
    out, info = build("mssa").apply(gappy)
    assert not np.isnan(out.channels).any()
    err = br.channel_errors(m.rig, out.channels, m.channels)
    assert err.max() < 8.0 and err[100:140].mean() < 2.0, (err.max(), err[100:140].mean())


def test_mssa_warns_on_motion_unlike_its_training():
    """Bases trained on a slow sway cannot explain an acrobatic take: the report says so."""
    m = formats.read(shared("asfamc/90_31.amc"))
    slow = m.replace(channels=np.repeat(m.channels[:1], m.n_frames, axis=0)
                     + np.sin(np.arange(m.n_frames) / 60.0)[:, None] * 5.0)
    slow = slow.replace(positions=m.rig.positions(slow.channels))
    c = build("mssa", window=8, window_step=2).fit([slow])
    _, info = c.apply(m)
    assert info["unexplained"] > 0.05 and "unlike the training set" in info["warning"], info


def test_local_quadratic_kernel_reproduces_quadratics_and_sure_prefers_it_in_a_fast_turn():
    """Known answers: each local quadratic kernel sums to 1 and has zero first and second
    moments (it passes quadratics unchanged); on a fast noisy sinusoid SURE with the
    quadratic fits beats the Gaussians alone."""
    for s in sure.QUADRATIC_WIDTHS:
        h = sure.local_quadratic_kernel(s)
        n = len(h) // 2
        u = np.arange(-n, n + 1, dtype=float)
        np.testing.assert_allclose([h.sum(), h @ u, h @ u ** 2], [1.0, 0.0, 0.0], atol=1e-9)
    # a fast sinusoid (period 40 samples) with noise: a Gaussian wide enough to average
    # the noise flattens the peaks; the quadratic fit of least risk does better
    rng = np.random.default_rng(0)
    x = 20 * np.sin(2 * np.pi * np.arange(2000) / 40.0)[:, None]
    y = x + rng.normal(0, 1.0, x.shape)
    g, _ = sure.sure_gaussian(y, 1.0)
    q, _ = sure.sure_gaussian(y, 1.0, quadratic_widths=sure.QUADRATIC_WIDTHS)
    err = lambda z: np.sqrt(np.mean((z - x) ** 2))
    assert err(q) < 0.85 * err(g) and err(q) < 0.6


def test_quaternion_noise_shape_matches_jitter_on_a_real_file():
    """0.7° jitter on every Euler channel of CMU 05_01: each quaternion feature's measured
    noise follows 0.7 · noise_shape (the w of joints near rest barely moves), and the
    level measured with the shape is near 0.7 (seeds 0–2: per-feature ratio
    measured / predicted 0.89–1.18, median 1.00–1.02; level 0.726–0.735)."""


    m = formats.read(shared("asfamc/05_01.amc"))
    F = rotchannels.to_features(m.rig, m.channels)
    shape = rotchannels.noise_shape(m.rig, F)
    for seed in range(3):
        noisy, _ = br.corrupt(m, "jitter", seed)
        G = rotchannels.to_features(m.rig, noisy.channels)
        D = G - F
        quat = np.concatenate([np.full(e["size"], e["kind"] == "quat") for e in rotchannels.layout(m.rig)])
        measured = np.sqrt(np.mean(D[:, quat] ** 2, axis=0))
        predicted = 0.7 * np.sqrt(np.mean(shape[:, quat] ** 2, axis=0))
        ratio = measured / predicted
        # Euler axes are not orthogonal away from a zero middle angle, so not exactly 1
        assert np.median(ratio) == pytest.approx(1.0, abs=0.05) and ratio.min() > 0.8 and ratio.max() < 1.3
        level = ssa.noise_level(rotchannels.to_features(m.rig, noisy.channels), shape=shape)
        assert 0.68 < level < 0.78


def test_steps_finds_a_discontinuity_and_not_fast_smooth_motion():
    rng = np.random.default_rng(0)
    t = np.arange(600)
    # group 0: a slow sine that jumps by 20 noise units at t = 300 and stays;
    # group 1: a fast, large sine (period 12 samples, amplitude 60 noise units)
    slow = np.sin(2 * np.pi * t / 300.0)[:, None] * [5.0, 3.0] + np.where(t >= 300, 20.0, 0.0)[:, None]
    fast = 60.0 * np.sin(2 * np.pi * t / 12.0)[:, None] * [1.0, 0.5]
    X = np.hstack([slow, fast]) + rng.normal(0, 1.0, (600, 4))
    mask = glitches.steps(X, 1.0, groups=np.array([0, 0, 1, 1]), threshold=6.0)
    assert mask.shape == (599, 2)
    assert np.flatnonzero(mask[:, 0]).tolist() == [299]
    assert not mask[:, 1].any()


def test_sure_piecewise_does_not_smooth_across_a_step():
    rng = np.random.default_rng(1)
    t = np.arange(400)
    x = (np.where(t >= 200, 30.0, 0.0) + np.sin(2 * np.pi * t / 400.0))[:, None]
    y = x + rng.normal(0, 1.0, x.shape)
    breaks = glitches.steps(y, 1.0, threshold=6.0)
    whole, _ = sure.sure_gaussian(y, 1.0, span=30.0)
    pieces, _ = sure.sure_piecewise(y, 1.0, breaks=breaks, span=30.0)
    err = lambda z, s: np.sqrt(np.mean((z - x)[s] ** 2))
    near = slice(170, 230)
    # smoothing across the jump (or not smoothing near it, for its large risk) costs there
    assert err(pieces, near) < 0.6 * err(whole, near) and err(pieces, slice(None)) < 0.45
    # with no breaks it is the plain smoother
    same, _ = sure.sure_piecewise(y, 1.0, breaks=np.zeros((399, 1), bool), span=30.0)
    np.testing.assert_array_equal(same, whole)


@pytest.mark.parametrize("span", [None, 12.0])
def test_sure_piecewise_gives_each_piece_its_own_smoother(span):
    """Pieces of equal length go through one call side by side; each must still come out
    as if smoothed alone (its own columns, its own risk, its own width)."""
    rng = np.random.default_rng(3)
    T, groups = 300, np.array([0, 0, 1, 2, 2, 2])
    t = np.arange(T)[:, None]
    X = np.sin(2 * np.pi * t * np.array([1, 2, 5, 9, 0.5, 3]) / T) * 10 + rng.normal(0, 1, (T, 6))
    breaks = np.zeros((T - 1, 3), bool)
    breaks[[49, 99, 149, 151, 160], 0] = True          # pieces of 50, 50, 50, 2, 9, 139
    breaks[[99, 199], 1] = True                         # 100, 100, 100
    breaks[[49, 59, 69], 2] = True                      # 50, 10, 10, 230
    noise = rng.uniform(0.5, 1.5, (T, 6))
    Z, widths = sure.sure_piecewise(X, noise, breaks=breaks, groups=groups, span=span)
    for g in range(3):
        cols = groups == g
        cuts = np.r_[0, np.flatnonzero(breaks[:, g]) + 1, T]
        chosen = []
        for a, b in zip(cuts[:-1], cuts[1:]):
            if b - a < 3:
                np.testing.assert_array_equal(Z[a:b, cols], X[a:b, cols])
                continue
            alone, w = sure.sure_gaussian(X[a:b, cols], noise[a:b, cols],
                                          groups=np.zeros(int(cols.sum()), int), span=span)
            np.testing.assert_array_equal(Z[a:b, cols], alone)
            chosen.append(np.repeat(w[:1], b - a))
        assert (widths[cols] == np.median(np.concatenate(chosen))).all()


@pytest.mark.slow
def test_sure_piecewise_with_more_pieces_of_one_length_than_one_call_takes():
    """333 pieces of 3 frames (two calls side by side): each still as if smoothed alone;
    and a one-frame channel goes through the quadratic fits (it raised once)."""
    rng = np.random.default_rng(5)
    T = 1000
    X = np.cumsum(rng.normal(size=(T, 2)), axis=0)
    breaks = np.zeros((T - 1, 1), bool)
    breaks[2::3] = True
    Z, _ = sure.sure_piecewise(X, 0.5, breaks=breaks, groups=np.zeros(2, int),
                               quadratic_widths=sure.QUADRATIC_WIDTHS)
    for a in range(0, 999, 3):
        alone, _ = sure.sure_gaussian(X[a:a + 3], 0.5, groups=np.zeros(2, int),
                                      quadratic_widths=sure.QUADRATIC_WIDTHS)
        np.testing.assert_array_equal(Z[a:a + 3], alone)
    one = X[:1]                 # nothing to average: the sample itself, to rounding
    np.testing.assert_allclose(sure.sure_gaussian(one, 0.5, quadratic_widths=sure.QUADRATIC_WIDTHS)[0],
                               one, rtol=1e-12)


def test_group_sums_add_a_group_alike_wherever_it_stands():
    def sums(R, labels):
        return sure.group_sums(R, sure.group_plan(np.asarray(labels)), int(max(labels)) + 1)

    R = np.array([[0.1, 0.2, 0.3, 1e16, 1.0, -1e16]])
    assert sums(R, [0, 0, 0, 1, 1, 1]).tolist() == [[0.6000000000000001, 0.0]]   # in order
    # the same group's columns with another group interleaved: the same sum, bit for bit
    R2 = np.array([[0.1, 5.0, 0.2, 7.0, 0.3]])
    assert sums(R2, [0, 1, 0, 1, 0])[0].tolist() == [sums(R[:, :3], [0, 0, 0])[0, 0], 12.0]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["asfamc/60_10.amc", "asfamc/05_10.amc"])
def test_rotation_denoise_does_not_smooth_across_steps_of_the_motion(name):
    """CMU 60_10 and 05_10 hold frame-to-frame jumps of 15–100° in their own data (a femur,
    foot, toes); smoothing across them, or leaving ±0.3 s around them unsmoothed for their
    risk, costs: measured 0.401 → 0.368 and 0.405 → 0.375 % of height (mean of seeds 0–2)."""
    m = formats.read(shared(name))
    for seed in (0, 1):
        noisy, _ = br.corrupt(m, "jitter", seed)
        err = {s: br.evaluate(m, build("rotation_denoise", local="0.3 s", steps=s).apply(noisy)[0])["pos_err_pct"]
               for s in (None, 6.0)}
        assert err[6.0] < 0.95 * err[None], err


def test_glitch_screen_on_a_take_of_eight_frames_warns_nothing():
    # rotation_outliers on a take of <= 8 frames printed NumPy's "RuntimeWarning: Mean of
    # empty slice" (twice, naming no file) into the terminal
    import warnings

    import numpy as np

    from mocapfix.solvers.glitches import glitches

    x = np.cumsum(np.random.default_rng(0).normal(size=(8, 6)), axis=0)
    x[4, 2] += 50.0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        found = glitches(x)
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in caught]
    assert found.shape == x.shape and found[4, 2]


def test_mssa_with_a_named_model_refuses_a_file_the_model_was_not_made_for():
    """A model named in the config is what the user asked for: on a skeleton it was not
    made for, the file is an error naming it (bases learned from the file instead left a
    line that said OK); with no model named, the file's own bases are the documented
    fallback (test above)."""
    from mocapfix.core.errors import MocapfixError
    from mocapfix.config import loads_config
    pipeline = loads_config("version: 1\npipeline:\n  - cleaner: mssa\n    model: mssa-cmu\n")
    cleaner = pipeline.steps[0].cleaner
    amc = formats.read(shared("asfamc/13_39.amc"))
    assert cleaner.apply(amc)[1]["bases"] == "mssa-cmu"
    bvh = formats.read(shared("bvh/cmu_cgspeed_131_01.bvh"))
    with pytest.raises(MocapfixError, match=r"cmu_cgspeed_131_01\.bvh.*train a model for it"):
        cleaner.apply(bvh)


def test_training_mssa_on_a_bvh_and_a_c3d_says_one_model_per_skeleton(tmp_path):
    # the first file (BVH) made the model learn rotations; the C3D has none:
    # "internal error AttributeError: 'NoneType' object has no attribute 'rot_axes'"
    out = tmp_path / "m.npz"
    r = CliRunner().invoke(main, ["train-dictionary", str(BVH), str(C3D), "--method", "mssa", "-o", str(out)])
    no_traceback(r)
    assert r.exit_code == 2, r.output
    assert f"{C3D}: has no rotation channels" in r.output and "one model per skeleton" in r.output
    assert not out.exists()


def test_recurring_looks_for_recurrences_within_its_reach_only():
    """A flick at every 32-frame cycle recurs: cleared. The same flick with its alike ones
    farther than ``reach`` frames away is not (the reach keeps the test linear in the take's
    length), and the whole-channel answer is the reach of the whole take."""
    t = np.arange(640)
    x = 10 * np.sin(2 * np.pi * t / 32.0)
    flicks = np.zeros(len(t), bool)
    for c in range(40, 600, 32):
        x[c] += 6.0
        flicks[c] = True
    X, mask = x[:, None], flicks[:, None]
    assert not glitches.recurring(X, mask).any()                  # REACH covers the take
    assert not glitches.recurring(X, mask, reach=100).any()       # three cycles each side
    one_cycle = glitches.recurring(X, mask, reach=40)             # one alike flick each side:
    assert np.flatnonzero(one_cycle[:, 0]).tolist() == [40, 584]  # the end flicks have one
    assert glitches.recurring(X, mask, reach=20)[flicks].all()    # none within reach


@pytest.mark.parametrize("path", ["c3d/hdm05_HDM_mm_01-02_03_120.c3d",
                                  "kinect/kv1_msr3d_a01_s01_e01_skeleton3D.txt"])
def test_mssa_on_a_take_with_a_point_never_seen_warns_nothing(path):
    # a marker (or joint) never seen: NumPy's "RuntimeWarning: All-NaN slice encountered"
    # from the per-channel median of the file's own bases, printed to the user
    import warnings

    from mocapfix import formats

    motion = formats.read(shared(path)).slice_frames(0, 300)
    pos = motion.positions.copy()
    pos[:, 5] = np.nan
    motion = motion.replace(positions=pos)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out, info = build("mssa").apply(motion)
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)], [str(w.message) for w in caught]
    assert "skipped" not in info
    assert np.isnan(out.positions[:, 5]).all() or np.isfinite(out.positions[:, 5]).all()
