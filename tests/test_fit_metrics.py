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


def test_windowed_durbin_watson_windows_double_and_find_a_local_misfit(rng):
    """Windows: the first up to first_end_s, each next twice as long; each statistic is the
    direct formula on its samples. A misfit confined to the first second (a smooth bump)
    gives a window below the limit while the whole record's statistic is above it."""
    from warptissue.lsq.metrics import (
        DURBIN_WATSON_LIMIT,
        MIN_WINDOW_SAMPLES,
        durbin_watson,
        windowed_durbin_watson,
    )

    time_s = np.arange(0.0, 100.0, 0.01)
    residuals = rng.normal(size=time_s.size)
    windows = windowed_durbin_watson(time_s, residuals, first_end_s=1.0)
    starts = [w[0] for w in windows]
    np.testing.assert_allclose(starts[:5], [0.0, 1.01, 3.01, 7.01, 15.01], atol=1e-9)
    assert sum(w[2] for w in windows) == time_s.size
    assert all(w[2] >= MIN_WINDOW_SAMPLES for w in windows)
    kept = (time_s >= 1.005) & (time_s < 3.005)
    assert windows[1][3] == pytest.approx(
        np.sum(np.diff(residuals[kept]) ** 2) / np.sum(residuals[kept] ** 2), rel=1e-12
    )
    assert all(w[3] > DURBIN_WATSON_LIMIT for w in windows)  # independent noise
    bump = residuals + 8.0 * np.exp(-(((time_s - 0.5) / 0.2) ** 2))
    assert durbin_watson(bump) > DURBIN_WATSON_LIMIT  # diluted by the long tail
    flagged = [w for w in windowed_durbin_watson(time_s, bump, first_end_s=1.0)]
    assert flagged[0][3] < DURBIN_WATSON_LIMIT
    assert all(w[3] > DURBIN_WATSON_LIMIT for w in flagged[1:])


def test_windowed_durbin_watson_short_records_and_short_windows():
    from warptissue.lsq.metrics import MIN_WINDOW_SAMPLES, windowed_durbin_watson

    assert windowed_durbin_watson(np.array([]), np.array([]), first_end_s=1.0) == []
    time_s = np.arange(10.0)
    (only,) = windowed_durbin_watson(time_s, np.sin(time_s), first_end_s=-1.0)
    assert only[2] == 10
    time_s = np.arange(0.0, 50.0)  # a first window before the first sample: 20 samples
    windows = windowed_durbin_watson(time_s, np.cos(time_s), first_end_s=-5.0)
    assert windows[0][2] == MIN_WINDOW_SAMPLES
    assert sum(w[2] for w in windows) == 50 and all(w[2] >= MIN_WINDOW_SAMPLES for w in windows)
    with pytest.raises(InputError):
        windowed_durbin_watson(np.arange(3.0), np.arange(4.0), first_end_s=1.0)
