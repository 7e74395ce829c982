"""The model-averaging gap filler ``pma`` (Tits et al. 2018 as a baseline): exact on a
rigid body, observed samples untouched, and on a real capture with occlusion gaps better
than its own members alone and than a cubic spline."""
import sys

import numpy as np
import pytest

from mocapfix import read
from mocapfix.cleaners import build
from mocapfix.bench.corrupt import occlusion
from mocapfix.core.motion import Motion
from mocapfix.solvers import pma as kernels

from conftest import shared


def _rigid_motion(T=200, seed=0):
    rng = np.random.default_rng(seed)
    body = rng.normal(0, 100.0, size=(8, 3))
    t = np.linspace(0, 2 * np.pi, T)
    angle = 1.5 * np.sin(t)
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros((T, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1
    trans = np.stack([500 * np.sin(t), 300 * t, 50 * np.cos(3 * t)], axis=1)
    pos = np.einsum("tij,kj->tki", R, body) + trans[:, None]
    return Motion(pos, [f"m{k}" for k in range(8)], fps=100.0)


def test_rigid_body_gap_is_filled_exactly_and_observed_samples_kept():
    truth = _rigid_motion()
    pos = truth.positions.copy()
    pos[60:140, 2] = np.nan          # interior gap of 80 frames
    pos[:25, 5] = np.nan             # a start gap
    out, info = build("pma").apply(truth.replace(positions=pos))
    assert info["gaps_filled"] == 2
    err = np.linalg.norm(out.positions - truth.positions, axis=2)
    assert err.max() < 1e-3
    seen = ~np.isnan(pos).any(axis=2)
    assert np.array_equal(out.positions[seen], pos[seen])
    assert np.all(out.confidence[seen] == 1.0)
    assert np.all((out.confidence[~seen] > 0) & (out.confidence[~seen] <= 1))


def test_soft_constraint_moves_only_violations_onto_the_interval():
    others = np.zeros((2, 1, 3))
    x = np.array([[0.0, 0.0, 10.0], [0.0, 0.0, 5.2]])
    y = kernels.soft_distance_constraint(x, others, np.array([5.0]), np.array([0.5]), width=2.0)
    assert np.allclose(y[0], [0, 0, 6.0])          # pulled onto mu + 2 sd
    assert np.allclose(y[1], x[1])                 # inside: untouched


def test_meet_borders_ramp():
    fill = np.zeros((5, 3))
    data = np.full((5, 3), np.nan)
    data[0], data[-1] = 1.0, 3.0
    out = kernels.meet_borders(fill, data, True, True)
    assert np.allclose(out[:, 0], [1, 1.5, 2, 2.5, 3])


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_beats_members_and_spline_on_cmu_85_02(seed):
    truth = read(shared("c3d/cmu_85_02.c3d"))
    corrupted, mask = occlusion(truth, "gaps", seed)

    def gap_rmse(cleaner, **kw):
        out, _ = build(cleaner, **kw).apply(corrupted)
        e = np.linalg.norm(out.positions[mask] - truth.positions[mask], axis=1)
        assert not np.isnan(e).any()
        return float(np.sqrt(np.mean(e ** 2)))

    full = gap_rmse("pma")
    assert full < gap_rmse("fill", method="spline", max_gap=None)
    assert full < gap_rmse("fill_pca", fill_ends=True)
    assert full < gap_rmse("pma", members=["linear"])


@pytest.mark.slow
def test_default_fills_the_start_gap_without_a_jump():
    """c3dorg_s01_Eb015pi: PV3 misses its first 47 frames. The default's fill must not
    plateau and then jump to meet the data: no frame-to-frame step in the gap or onto its
    border larger than the largest step of the marker's own data."""
    from mocapfix.config import default_config_path, load_config

    m = read(shared("c3d/c3dorg_s01_Eb015pi.c3d"))
    j = m.index("PV3")
    gap = np.flatnonzero(m.missing[:, j])
    assert gap.tolist() == list(range(47))
    out, records = load_config(default_config_path()).run(m)
    steps = np.linalg.norm(np.diff(out.positions[:48, j], axis=0), axis=1)
    own = np.nanmax(np.linalg.norm(np.diff(m.positions[:, j], axis=0), axis=1))
    assert not np.isnan(steps).any()
    assert steps.max() < own
    # observed samples are left as measured, except those the trust step judged wrong
    seen = ~m.missing
    changed = seen & (out.positions != m.positions).any(axis=2)
    untrusted = sum(r.flagged for r in records)
    assert untrusted.sum() < 0.001 * seen.sum()
    assert not (changed & ~untrusted).any()
    # the filled samples carry a confidence below 1 that falls with the distance to the data
    conf = out.confidence[gap, j]
    assert np.all((conf > 0) & (conf < 1)) and conf[0] < conf[-1]


def test_pose_member_recovers_a_marker_that_follows_its_neighbours_pose():
    """Known answer: marker 3's place in the rigid frame of markers 0-2 is an affine
    function of where markers 4-7 (another, freely moving part) are in that frame. The
    ``pose`` members (ridge regression on the neighbours in the rigid frame) rebuild an
    80-frame gap to well under a millimetre; ``interp`` (the frame-local ramp) cannot."""
    T = 400
    t = np.linspace(0, 4 * np.pi, T)
    rng = np.random.default_rng(3)
    rigid = np.array([[0.0, 0, 0], [120, 0, 0], [0, 90, 0]])
    # four markers moving smoothly (different frequencies) in the rigid part's frame
    freq = rng.uniform(0.5, 2.0, size=(4, 3))
    phase = rng.uniform(0, 2 * np.pi, size=(4, 3))
    other = (np.array([[300.0, 0, 0], [0, 300, 0], [300, 300, 0], [150, 150, 200]])
             + 80 * np.sin(freq * t[:, None, None] + phase))
    W = rng.normal(0, 0.05, size=(12, 3))
    follower = np.array([60.0, 40, 30]) + (other - other.mean(axis=0)).reshape(T, 12) @ W
    local = np.concatenate([np.broadcast_to(rigid, (T, 3, 3)), follower[:, None], other], axis=1)
    angle = 1.2 * np.sin(0.7 * t)
    c, s = np.cos(angle), np.sin(angle)
    R = np.zeros((T, 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1
    truth = (np.einsum("tij,tkj->tki", R, local)
             + np.stack([400 * np.sin(0.3 * t), 200 * t, 30 * np.cos(t)], axis=1)[:, None])
    pos = truth.copy()
    pos[150:230, 3] = np.nan
    observed = ~np.isnan(pos).any(axis=2)
    (cand, fills), = kernels.member_fills(pos, observed, [(3, 150, 230)], {},
                                          local=("interp", "pose"), neighbours=3)
    assert set(cand[:3]) == {0, 1, 2}
    err = {k: float(np.sqrt(np.mean(np.sum((v - truth[150:230, 3]) ** 2, axis=1))))
           for k, v in fills.items()}
    assert set(err) == {"interp", "pose6"}          # 7 neighbours: one pose member
    assert err["pose6"] < 0.5, err
    assert err["interp"] > 20 * err["pose6"], err


@pytest.mark.slow
def test_refill_uses_a_missing_neighbour_once_it_is_filled():
    """PhoeniX dance (40 markers, no gaps): a 1-s gap in a marker overlaps a 1.1-s gap in
    its most rigid neighbour, for every third marker. Without ``refill`` each gap is filled
    without the other marker; with it both gaps are filled again with the other's fill
    counted as seen (and the frames where it was missing back in the training). Both gaps
    of each pair are refilled, the gap error over all pairs falls by more than 15 %, and
    observed samples stay as measured. A second round starts from the first round's fills
    of the pair (so its output differs from one round's) and is no worse."""
    m = read(shared("c3d/c3dorg_s13_Dance.c3d"))
    truth = m.positions
    _, sd = kernels.distance_stats(truth, ~m.missing)
    se = {0: 0.0, 1: 0.0, 2: 0.0}
    n, second_round_moved = 0, False
    for j in range(0, m.n_joints, 3):
        k = int(np.argmin(np.where(np.arange(m.n_joints) == j, np.inf, sd[j])))
        pos = truth.copy()
        pos[200:265, j] = np.nan
        pos[220:290, k] = np.nan
        gaps = np.isnan(pos).any(axis=2)
        n += gaps.sum()
        outs = {}
        for passes in se:
            out, info = build("fill_ensemble", refill=passes).apply(m.replace(positions=pos))
            assert info.get("refilled_gaps", 0) == (2 if passes else 0)
            assert np.array_equal(out.positions[~gaps], truth[~gaps])
            se[passes] += float(np.sum((out.positions[gaps] - truth[gaps]) ** 2))
            assert any(name.endswith("+") for name in info["weights_mean"]) == bool(passes)
            outs[passes] = out.positions
        second_round_moved |= not np.array_equal(outs[1], outs[2])
    rmse = {p: np.sqrt(v / n) for p, v in se.items()}
    assert rmse[1] < 0.85 * rmse[0], rmse
    assert rmse[2] < 0.85 * rmse[0] and rmse[2] <= 1.01 * rmse[1], rmse
    assert second_round_moved


def test_refill_leaves_gaps_whose_neighbours_are_seen_as_they_were():
    """A gap whose marker keeps its five most rigid neighbours on the gap and its borders
    is not refilled: the output is the one-pass output bit for bit."""
    truth = _rigid_motion(T=300)
    pos = truth.positions.copy()
    pos[100:160, 2] = np.nan
    pos[200:240, 6] = np.nan          # after the first gap: no overlap
    one, _ = build("fill_ensemble", refill=0).apply(truth.replace(positions=pos))
    two, info = build("fill_ensemble", refill=2).apply(truth.replace(positions=pos))
    assert info["refilled_gaps"] == 0
    assert np.array_equal(one.positions, two.positions)


@pytest.mark.slow
def test_refill_skips_edge_and_short_gaps():
    """Edge gaps are neither refilled nor lent (an extrapolated neighbour is no
    measurement), and gaps shorter than REFILL_MIN_S are left as the first pass made
    them: with such overlaps only, the refill changes nothing."""
    from mocapfix.cleaners.pma import REFILL_MIN_S

    m = read(shared("c3d/c3dorg_s13_Dance.c3d"))
    truth = m.positions
    _, sd = kernels.distance_stats(truth, ~m.missing)
    j = 6
    k = int(np.argmin(np.where(np.arange(m.n_joints) == j, np.inf, sd[j])))
    short = int(0.8 * REFILL_MIN_S * m.fps)
    cases = {"neighbour's start gap": ((100, 165), (0, 150)),
             "own start gap": ((0, 60), (30, 100)),
             "own end gap": ((430, 499), (400, 470)),
             "short overlapping gaps": ((200, 200 + short), (202, 202 + short))}
    for label, ((a, b), (c, d)) in cases.items():
        pos = truth.copy()
        pos[a:b, j] = np.nan
        pos[c:d, k] = np.nan
        one, _ = build("fill_ensemble", refill=0).apply(m.replace(positions=pos))
        two, info = build("fill_ensemble", refill=2).apply(m.replace(positions=pos))
        assert info["refilled_gaps"] == 0, label
        assert np.array_equal(one.positions, two.positions, equal_nan=True), label


def test_grnn_is_the_gaussian_weighted_mean_of_the_training_targets():
    # Specht 1991: y(x) = Σ y_i exp(−|z − z_i|² / 2s²) / Σ exp(…), z standardised by the
    # training mean and spread; written out directly here (cdist) against the in-place
    # kernel of pma._grnn (solvers), including far queries whose weights all underflow without
    # the shift by the nearest distance
    from scipy.spatial.distance import cdist

    rng = np.random.default_rng(3)
    X = rng.normal(size=(300, 9)) * rng.uniform(0.5, 50, size=9)
    Y = rng.normal(size=(300, 3))
    Xn = np.vstack([rng.normal(size=(40, 9)) * 20, X[:5] + 1e3])
    predict = kernels._grnn(X, Y)
    mx, sx = X.mean(axis=0), X.std(axis=0)
    Z, Zn = (X - mx) / sx, (Xn - mx) / sx
    d2 = cdist(Zn, Z, "sqeuclidean")
    k = np.sort(cdist(Z[np.linspace(0, 299, kernels.SPREAD_POINTS).astype(int)], Z,
                      "sqeuclidean"), axis=1)[:, 5]
    s2 = np.median(k)
    w = np.exp(-0.5 * (d2 - d2.min(axis=1, keepdims=True)) / s2)
    np.testing.assert_allclose(predict(Xn), (w @ Y) / w.sum(axis=1, keepdims=True),
                               rtol=1e-9, atol=1e-9)


def test_kth_smallest_of_each_row_counts_repeated_values_once_each():
    # the GRNN spread's 5th-neighbour distances: row [3, 1, 1, 2, 1, 0] sorted is
    # 0, 1, 1, 1, 2, 3 -> index 4 is 2 (a tie counts once per copy), in a small array (a
    # partition) and in one of 200 such rows side by side with others (struck out one at
    # a time); and on random rows with ties and a first column of zeros (a point's
    # distance to itself), small and large, what a sort gives for every k
    row = np.array([3.0, 1, 1, 2, 1, 0])
    assert kernels._kth_smallest(row[None].copy(), 4).tolist() == [2.0]
    wide = np.hstack([np.tile(row, (200, 1)), np.full((200, 60), 9.0)])
    assert wide.size >= 8000 and (kernels._kth_smallest(wide, 4) == 2.0).all()
    rng = np.random.default_rng(0)
    for shape in ((50, 30), (200, 600)):
        rows = np.round(rng.uniform(0, 4, size=shape), 0)
        rows[:, 0] = 0.0
        for k in range(8):
            np.testing.assert_array_equal(kernels._kth_smallest(rows.copy(), k),
                                          np.sort(rows, axis=1)[:, k])


@pytest.mark.slow
def test_gaps_no_other_marker_is_seen_through_get_no_members_and_a_reason(monkeypatch):
    """PhoeniX dance with interior gaps in six markers and its last 60 frames empty (every
    marker gone, as OptiTrack exports end): the empty frames are left missing, each with the
    reason in ``rejected_fills``; no member is fitted for them or for their validation
    windows (only the six 50-frame gaps' windows are predicted), and the six gaps get the same
    fills as when every gap goes through the members."""
    m = read(shared("c3d/c3dorg_s13_Dance.c3d"))
    pos = m.positions.copy()
    T = len(pos)
    for k, j in enumerate(range(0, 36, 6)):
        pos[100 + 40 * k:150 + 40 * k, j] = np.nan
    pos[T - 60:] = np.nan
    work = m.replace(positions=pos)
    predicted = []

    def counting(pos_, observed, j, windows, *args, **kw):
        predicted.extend(windows)
        return window_fills(pos_, observed, j, windows, *args, **kw)

    window_fills = kernels.window_fills
    monkeypatch.setattr(kernels, "window_fills", counting)
    out, info = build("fill_ensemble").apply(work)
    empty = np.zeros(pos.shape[:2], bool)
    empty[T - 60:] = True
    assert np.isnan(out.positions[empty]).all()
    assert not np.isnan(out.positions[~empty]).any()
    assert sorted(info["rejected_fills"]) == sorted(m.names)
    assert all(r == [[T - 60, 60, "no other marker is seen through it"]]
               for r in info["rejected_fills"].values())
    assert predicted and all(e - s == 50 for s, e in predicted)     # no 60-frame window
    # the shortcut against every gap through the members (same windows, same fills)
    cleaner = build("fill_ensemble")
    observed = ~work.missing
    mu, sd = kernels.distance_stats(pos, observed)
    gaps = kernels.gap_list(observed)
    local = tuple(cleaner["members"])
    quick = cleaner._validated_fills(work, observed, gaps, {}, local, mu, sd, skip_unsupported=True)
    full = cleaner._validated_fills(work, observed, gaps, {}, local, mu, sd)
    hopeless = [not len(kernels.candidates(observed, sd, *g)) for g in gaps]
    assert sum(hopeless) == m.n_joints and sum(not h for h in hopeless) == 6
    for h, (cand_q, fills_q), (cand_f, fills_f), err_q, err_f in zip(hopeless, quick[0], full[0],
                                                                     quick[1], full[1]):
        if h:
            assert not fills_q and not fills_f and not err_q and not len(cand_q)
        else:
            assert fills_q.keys() == fills_f.keys() and err_q == err_f
            assert all(np.array_equal(fills_q[k], fills_f[k]) for k in fills_q)


def test_fits_made_together_give_the_fills_of_the_jobs_one_after_another(monkeypatch):
    """member_fills makes the rigid fits of all its jobs together (_fit_together). On a
    real capture with many gaps (c3d.org s28: 296 frames), the real gaps and then a
    validation copy sharing their reference shapes, as the cleaner makes them: the same
    members and fills (to rounding) and the same reference shapes as when each job runs
    alone, in order; where two jobs of one round ask for one reference (the same marker
    and neighbours), the second waits for the first's instead of making it again."""
    from mocapfix.solvers import fill_error

    m = read(shared("c3d/c3dorg_s28_dynamic.C3D"))
    pos, observed = m.positions, ~m.missing
    mu, sd = kernels.distance_stats(pos, observed)
    gaps = kernels.gap_list(observed)
    cut, windows = fill_error.window_plan(observed, gaps, 1).windows[0]
    synth = [(gaps[g][0], u, v) for g, u, v in windows]
    together_fit = kernels._fit_together
    making = kernels._cached_reference
    waits = []

    def watched(cache, key, points):
        gen, sent = making(cache, key, points), None
        while True:
            try:
                asked = gen.send(sent)
            except StopIteration as done:
                return done.value
            if asked is None:
                waits.append(key)
            sent = yield asked

    monkeypatch.setattr(kernels, "_cached_reference", watched)

    def run(refs):
        real = kernels.member_fills(pos, observed, gaps, {}, neighbours=(3, 5), mu=mu, sd=sd,
                                    references=refs)
        copy = kernels.member_fills(np.where(cut[..., None], pos, np.nan), cut, synth, {},
                                    neighbours=(3, 5), mu=mu, sd=sd, references=refs)
        return real + copy

    refs_together = {}
    together = run(refs_together)
    assert waits                                  # some reference was asked for twice in a round
    monkeypatch.setattr(kernels, "_fit_together",
                        lambda jobs: [together_fit([job])[0] for job in jobs])
    refs_alone = {}
    alone = run(refs_alone)
    assert len(together) == len(alone) == len(gaps) + len(synth) and len(synth) > 10
    assert sum(len(f) for _, f in together) > 5 * len(gaps)      # the members filled them
    for (cand_t, fills_t), (cand_a, fills_a) in zip(together, alone):
        assert np.array_equal(cand_t, cand_a) and fills_t.keys() == fills_a.keys()
        for k in fills_t:
            np.testing.assert_allclose(fills_t[k], fills_a[k], rtol=0, atol=1e-6)
    assert refs_together.keys() == refs_alone.keys()
    for key in refs_together:
        np.testing.assert_allclose(refs_together[key], refs_alone[key], rtol=0, atol=1e-9)


def test_marker_groups_split_whole_markers_with_about_the_same_work():
    """Every gap in one group, a marker's gaps all in one, the groups' work (gaps and
    windows) within the largest marker's of each other; one group when one marker has
    every gap."""
    gaps = [(0, 5, 9), (1, 3, 4), (0, 20, 22), (2, 7, 8), (3, 1, 2), (1, 30, 33), (4, 9, 12)]
    copies = [(None, [(0, 40, 44), (2, 50, 52), (6, 60, 63)]), (None, [(0, 70, 74), (1, 8, 9)])]
    first, second = kernels.marker_groups(gaps, copies)
    assert sorted(first + second) == list(range(len(gaps)))
    markers = [{gaps[g][0] for g in grp} for grp in (first, second)]
    assert not markers[0] & markers[1]
    work = [len(grp) + sum(g in grp for _, w in copies for g, _, _ in w) for grp in (first, second)]
    assert abs(work[0] - work[1]) <= 6            # marker 0: 2 gaps + 3 windows, the largest
    assert kernels.marker_groups([(3, 1, 2), (3, 8, 9)], [(None, [(1, 20, 21)])]) == [[0, 1]]


def test_validated_fills_in_two_groups_are_those_of_all_the_gaps_at_once(monkeypatch, fork_calls):
    """validated_member_fills fits two groups of markers apart (the second in a child
    process where it can fork). On c3d.org s28's gaps with two validation copies: the
    same members, fills, window errors and reference shapes (to rounding) as all the gaps
    fitted as one group, whether the second group ran in a child or here."""
    from mocapfix.core import threads
    from mocapfix.solvers import fill_error

    m = read(shared("c3d/c3dorg_s28_dynamic.C3D"))
    pos, observed = m.positions, ~m.missing
    mu, sd = kernels.distance_stats(pos, observed)
    gaps = kernels.gap_list(observed)
    copies = fill_error.window_plan(observed, gaps, 2).windows
    assert len(kernels.marker_groups(gaps, copies)) == 2

    def run(**kw):
        refs = {}
        return kernels.validated_member_fills(pos, observed, gaps, copies, {}, neighbours=(3, 5),
                                              mu=mu, sd=sd, references=refs, **kw), refs

    monkeypatch.setattr(threads, "_TASK_THREADS", [2])
    split, refs_split = run()
    monkeypatch.setattr(threads, "_TASK_THREADS", [1])
    here, refs_here = run()
    monkeypatch.setattr(kernels, "marker_groups", lambda g, c: [list(range(len(g)))])
    whole, refs_whole = run()
    # on Linux the first run's second group went to a child, the second run's did not
    assert fork_calls[0] == sys.platform.startswith("linux") and not fork_calls[1]
    assert sum(len(w) for *_, w in whole) > len(gaps)                   # windows were fitted
    for rows in (split, here):
        assert len(rows) == len(whole)
        for (cand_s, fills_s, err_s, win_s), (cand_w, fills_w, err_w, win_w) in zip(rows, whole):
            assert np.array_equal(cand_s, cand_w) and fills_s.keys() == fills_w.keys()
            for k in fills_s:
                np.testing.assert_allclose(fills_s[k], fills_w[k], rtol=0, atol=1e-6)
            assert err_s.keys() == err_w.keys()
            np.testing.assert_allclose([err_s[k] for k in err_s], [err_w[k] for k in err_s],
                                       rtol=1e-9, atol=1e-9)
            assert [w[:3] for w in win_s] == [w[:3] for w in win_w]
    assert all(np.array_equal(a[1][k], b[1][k]) for a, b in zip(split, here) for k in a[1])
    for refs in (refs_split, refs_here):
        assert refs.keys() == refs_whole.keys()
        for key in refs:
            np.testing.assert_allclose(refs[key], refs_whole[key], rtol=0, atol=1e-9)
