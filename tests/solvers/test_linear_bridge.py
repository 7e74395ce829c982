"""linear_bridge: the starting point of the iterative solvers and the glitch tests."""
import numpy as np

from mocapfix.solvers.segments import linear_bridge


def test_linear_bridge_interpolates_gaps_holds_ends_and_keeps_samples():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(80, 6)) * 100.0
    x[rng.random(x.shape) < 0.3] = np.nan
    x[:5, 1] = x[-4:, 2] = np.nan
    x[:, 5] = np.nan
    out = linear_bridge(x)
    t = np.arange(len(x))
    for c in range(5):
        seen = ~np.isnan(x[:, c])
        # np.interp holds the end values outside the samples, as linear_bridge does
        np.testing.assert_allclose(out[:, c], np.interp(t, t[seen], x[seen, c]), rtol=1e-12)
        np.testing.assert_array_equal(out[seen, c], x[seen, c])
    np.testing.assert_array_equal(out[:, 5], 0.0)
    np.testing.assert_array_equal(linear_bridge(x.reshape(80, 2, 3)), out.reshape(80, 2, 3))
