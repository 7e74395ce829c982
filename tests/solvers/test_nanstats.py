"""Statistics without numpy's wrappers (mocapfix.solvers.nanstats): the values numpy's
nanmedian and nanquantile give, column by column, on random columns with ties, NaN runs,
columns with one number and columns with none; and np.mean's and np.median's of short
arrays and lists."""
import warnings

import numpy as np
import pytest

from mocapfix.solvers.nanstats import mean_of, median_of, nanmedian_columns, nanquantile_columns


def _columns(seed: int):
    rng = np.random.default_rng(seed)
    for trial in range(400):
        T, J = int(rng.integers(1, 50)), int(rng.integers(1, 7))
        x = rng.normal(size=(T, J)) * 10.0 ** rng.uniform(-3, 3)
        if trial % 3 == 0:
            x = np.round(x, 1)                      # ties
        x[rng.random((T, J)) < rng.uniform(0.0, 0.95)] = np.nan
        if trial % 7 == 0:
            x[:, 0] = np.nan                        # a column with no number
        yield x


@pytest.mark.parametrize("q", [0.0, 0.1, 1 / 3, 0.5, 0.75, 0.9, 1.0])
def test_quantiles_are_numpys_bit_for_bit(q):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)       # numpy on an all-NaN column
        for x in _columns(int(q * 100)):
            np.testing.assert_array_equal(nanquantile_columns(x, q), np.nanquantile(x, q, axis=0))


def test_medians_are_numpys_bit_for_bit():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for x in _columns(7):
            np.testing.assert_array_equal(nanmedian_columns(x), np.nanmedian(x, axis=0))


def test_known_answers():
    x = np.array([[1.0, np.nan], [2.0, 5.0], [3.0, np.nan], [np.nan, np.nan], [10.0, np.nan]])
    # column 0: 1, 2, 3, 10 → the 0.9 quantile at (4 − 1) 0.9 = 2.7: 3 + 0.7 × 7 = 7.9
    np.testing.assert_allclose(nanquantile_columns(x, 0.9), [7.9, 5.0])
    np.testing.assert_array_equal(nanmedian_columns(x), [2.5, 5.0])


def test_mean_and_median_of_short_arrays_are_numpys_bit_for_bit():
    rng = np.random.default_rng(3)
    for trial in range(3000):
        n = int(rng.integers(1, 300))
        v = rng.normal(size=n) * 10.0 ** rng.uniform(-5, 5) + rng.normal() * 1e3
        if trial % 4 == 0:
            v = np.round(v, 1)                      # ties
        assert mean_of(v) == float(np.mean(v))
        assert mean_of(list(v)) == float(np.mean(list(v)))
        assert median_of(v) == float(np.median(v))
    v = np.array([3.0, np.nan, 1.0])
    assert np.isnan(median_of(v)) and np.isnan(np.median(v))
    assert median_of(np.array([4.0, 1.0, 3.0, 2.0])) == 2.5 and mean_of([1, 2, 4]) == 7 / 3
