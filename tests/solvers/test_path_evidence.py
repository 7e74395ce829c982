"""contradicted_by_path judges the runs that a cubic repairs all at once; the answers must
be those of judging each run alone (the one-run test of limb_contradicts)."""
import numpy as np

from mocapfix.core.gaps import runs
from mocapfix.solvers import glitches
from mocapfix.solvers.segments import linear_bridge


def _one_run_at_a_time(P, mask, ratio=glitches.EVIDENCE_RATIO, context=glitches.EVIDENCE_CONTEXT):
    T, J = mask.shape
    keep = mask.copy()
    X = np.where(np.repeat(keep, 3, axis=1), np.nan, P.reshape(T, 3 * J))
    seen = ~np.isnan(X[:, 0::3])
    path = np.where(keep[..., None], linear_bridge(X).reshape(T, J, 3), P)
    for j, s, n in zip(*runs(keep)):
        a, b = max(s - context, 0), min(s + n + context, T)
        before = path[a:b, j].copy()
        before[s - a:s - a + n] = P[s:s + n, j]
        if seen[:s, j].any() and seen[s + n:, j].any():
            run = glitches._cubic_across(path[:, j], s, n)
        else:
            run = glitches._extrapolated(X[:, 3 * j:3 * j + 3], s, n)
        if run is None:
            keep[s:s + n, j] = False
            continue
        after = before.copy()
        after[s - a:s - a + n] = run
        if not glitches.limb_contradicts(before[:, None], after[:, None], ratio=ratio):
            keep[s:s + n, j] = False
    return keep


def test_runs_judged_together_get_the_answers_of_runs_judged_alone():
    rng = np.random.default_rng(7)
    dropped = kept = 0
    for _ in range(200):
        T, J = int(rng.integers(5, 150)), int(rng.integers(1, 5))
        P = np.cumsum(rng.normal(size=(T, J, 3)), axis=0) * rng.choice([0.01, 1.0, 100.0])
        spikes = rng.random((T, J)) < 0.05
        P[spikes] += rng.normal(scale=20.0, size=(int(spikes.sum()), 3))
        P[rng.random((T, J)) < 0.1] = np.nan
        mask = (rng.random((T, J)) < rng.random() * 0.4) & ~np.isnan(P[..., 0])
        mask |= spikes & ~np.isnan(P[..., 0])
        got = glitches.contradicted_by_path(P, mask)
        np.testing.assert_array_equal(got, _one_run_at_a_time(P, mask))
        kept += int(got.sum())
        dropped += int((mask & ~got).sum())
    assert kept and dropped          # both answers occur

