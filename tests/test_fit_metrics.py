"""Tests of warptissue.lsq.metrics against direct formulas and scikit-learn."""

from __future__ import annotations

import numpy as np
import pytest
from sklearn.metrics import mean_squared_error, r2_score

from warptissue.errors import InputError
from warptissue.lsq.metrics import r_squared, rmse


def test_metrics_match_scikit_learn(rng):
    y = rng.normal(size=50)
    y_fit = y + rng.normal(scale=0.3, size=50)
    assert r_squared(y, y_fit) == pytest.approx(r2_score(y, y_fit), rel=1e-12)
    assert rmse(y, y_fit) == pytest.approx(np.sqrt(mean_squared_error(y, y_fit)), rel=1e-12)


def test_perfect_and_mean_fits():
    y = np.array([1.0, 2.0, 4.0])
    assert r_squared(y, y) == 1.0
    assert r_squared(y, np.full(3, y.mean())) == pytest.approx(0.0, abs=1e-15)
    assert rmse(y, y) == 0.0


@pytest.mark.parametrize(
    ("y", "y_fit", "match"),
    [
        ([1.0, 1.0], [1.0, 2.0], "constant"),
        ([1.0, 2.0], [1.0], "length"),
        ([], [], "no values"),
        ([1.0, np.nan], [1.0, 2.0], "finite"),
    ],
)
def test_invalid_input(y, y_fit, match):
    with pytest.raises(InputError, match=match):
        r_squared(np.array(y), np.array(y_fit))
