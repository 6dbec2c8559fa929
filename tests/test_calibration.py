"""Force-sensor correction (seed 002, WCFM_SVM and its baselines)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from warptissue.calibration import (
    CALIBRATION_MODELS,
    ForceCalibration,
    LeastSquaresSVM,
    _fit_model,
    _predict_model,
    calibration_metrics,
    combination_weights,
    fit_calibrations,
    read_calibration_csv,
    sample_means,
    split_samples,
    synthetic_sensor,
)
from warptissue.errors import InputError
from warptissue.io import write_csv


@pytest.fixture(scope="module")
def sensor_fits():
    """The paper's set-up: 76 samples of 5 readings, 70 for training and 6 held out."""
    data = synthetic_sensor(samples=76, seed=2017)
    train, test = split_samples(data, test_samples=6, seed=0)
    return train, test, fit_calibrations(train, seed=0)


def test_lssvm_equals_kernel_ridge_with_its_bias(rng):
    from sklearn.kernel_ridge import KernelRidge

    features = rng.uniform(0.0, 1.0, (40, 2))
    target = np.sin(3.0 * features[:, 0]) + features[:, 1] ** 2 + 0.5
    machine = LeastSquaresSVM(regularization=50.0, gamma=2.0).fit(features, target)
    assert abs(machine.dual_coef.sum()) < 1e-10  # the bias row of the dual system
    ridge = KernelRidge(alpha=1.0 / 50.0, kernel="rbf", gamma=2.0)
    ridge.fit(features, target - machine.bias)
    np.testing.assert_allclose(machine.dual_coef, ridge.dual_coef_, rtol=1e-8, atol=1e-10)
    probe = rng.uniform(0.0, 1.0, (10, 2))
    np.testing.assert_allclose(
        machine.predict(probe), ridge.predict(probe) + machine.bias, rtol=1e-9, atol=1e-12
    )


def test_stored_svr_and_network_predict_like_scikit_learn(rng):
    from sklearn.neural_network import MLPRegressor
    from sklearn.svm import SVR

    features = rng.uniform(0.0, 1.0, (60, 1))
    target = np.tanh(2.0 * features[:, 0]) + 0.01 * rng.normal(size=60)
    probe = rng.uniform(0.0, 1.0, (15, 1))
    svr_dict = _fit_model("svm", features, target, 0)
    svr = SVR(kernel="rbf", C=1e3, epsilon=1e-4, gamma=svr_dict["gamma"]).fit(features, target)
    np.testing.assert_allclose(_predict_model(svr_dict, probe), svr.predict(probe), atol=1e-10)
    network_dict = _fit_model("bp", features, target, 0)
    network = MLPRegressor(
        hidden_layer_sizes=(8,),
        activation="tanh",
        solver="lbfgs",
        alpha=1e-5,
        max_iter=5000,
        tol=1e-9,
        random_state=0,
    ).fit(features, target)
    np.testing.assert_allclose(
        _predict_model(network_dict, probe), network.predict(probe), atol=1e-10
    )


def test_weights_follow_equation_1():
    target = np.array([1.0, 2.0, 4.0])
    predictions = np.array([[1.1, 2.0, 4.0], [1.0, 2.2, 4.4]])
    summed = np.array([0.1, 0.1 + 0.1])  # sum_j |X_ij - Y_j| / Y_j
    expected = (1.0 / summed) / (1.0 / summed).sum()
    np.testing.assert_allclose(combination_weights(predictions, target), expected)


def test_metrics_follow_the_paper_definitions():
    actual = np.array([10.0, 20.0, 40.0, 5.0])
    corrected = np.array([10.5, 19.0, 40.0, 5.5])
    metrics = calibration_metrics(actual, corrected)
    assert metrics["mae_N"] == pytest.approx((0.5 + 1.0 + 0.0 + 0.5) / 4)
    assert metrics["mse_paper_N"] == pytest.approx(np.sqrt(0.25 + 1.0 + 0.25) / 4)
    assert metrics["mape_percent"] == pytest.approx((0.05 + 0.05 + 0.0 + 0.1) / 4 * 100)
    assert metrics["mean_square_N2"] == pytest.approx((0.25 + 1.0 + 0.25) / 4)


def test_every_model_corrects_the_nonlinear_sensor(sensor_fits):
    """On held-out samples every correction beats the straight-line calibration by 5x."""
    train, test, fits = sensor_fits
    slope, intercept = np.polyfit(train.signal_V, train.force_N, 1)
    linear = calibration_metrics(*sample_means(test, slope * test.signal_V + intercept))
    for name in CALIBRATION_MODELS:
        metrics = calibration_metrics(*sample_means(test, fits[name].correct(test.signal_V)))
        assert metrics["mae_N"] < 0.2 * linear["mae_N"], name
        assert metrics["max_abs_error_N"] < 0.15, name


def test_combinations_carry_their_weights(sensor_fits):
    _, _, fits = sensor_fits
    for name in ("CFM_SVM", "CFM_LSSVM"):
        np.testing.assert_allclose(fits[name].weights, 0.25)
    for name in ("WCFM_SVM", "WCFM_LSSVM"):
        assert fits[name].weights.sum() == pytest.approx(1.0)
        assert np.ptp(fits[name].weights) > 0.01  # Eq. 1 weights differ between models
    assert fits["polynomial"].combiner is None and len(fits["polynomial"].weights) == 0


def test_calibration_json_round_trip(tmp_path, sensor_fits):
    _, test, fits = sensor_fits
    path = fits["WCFM_SVM"].save(tmp_path / "calibration.json")
    content = json.loads(path.read_text())
    assert content["format"] == "warptissue.force_calibration" and content["model"] == "WCFM_SVM"
    loaded = ForceCalibration.load(path)
    np.testing.assert_array_equal(
        loaded.correct(test.signal_V), fits["WCFM_SVM"].correct(test.signal_V)
    )
    assert loaded.correct(1.2).shape == (1,)
    (tmp_path / "bad.json").write_text('{"format": "something else"}')
    with pytest.raises(InputError, match="not a warptissue.force_calibration"):
        ForceCalibration.load(tmp_path / "bad.json")
    with pytest.raises(InputError, match="finite"):
        loaded.correct([1.0, np.nan])


def test_calibration_csv_errors_name_line_and_column(tmp_path):
    path = tmp_path / "sensor.csv"
    path.write_text("sample,force_N,signal_V\n" + "S1,1.0,0.1\n" * 10 + "S2,x,0.2\n")
    with pytest.raises(InputError) as info:
        read_calibration_csv(path)
    assert "sensor.csv:12" in str(info.value) and "force_N" in str(info.value)


def test_cli_calibrate_sensor(tmp_path, capsys):
    from warptissue.cli import main

    data = synthetic_sensor(samples=30, readings=3, seed=5)
    csv_path = write_csv(
        tmp_path / "sensor.csv",
        {"sample": data.sample, "force_N": data.force_N, "signal_V": data.signal_V},
    )
    out = tmp_path / "out"
    assert main(["calibrate-sensor", str(csv_path), "--test-samples", "4", "--out", str(out)]) == 0
    table = json.loads((out / "calibration_metrics.json").read_text())
    assert set(table) == set(CALIBRATION_MODELS)
    assert (out / "calibration.png").stat().st_size > 0
    loaded = ForceCalibration.load(out / "calibration.json")
    assert np.all(np.isfinite(loaded.correct(data.signal_V)))
    capsys.readouterr()
    assert main(["calibrate-sensor", str(tmp_path / "missing.csv")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_recorder_loads_the_calibration_file(tmp_path, sensor_fits):
    """The acquisition recorder's loader applies our JSON exactly (CONVENTIONS.md)."""
    recorder = pytest.importorskip("warptissue.acquisition.recorder")
    _, test, fits = sensor_fits
    for name in ("polynomial", "WCFM_SVM"):
        path = fits[name].save(tmp_path / f"{name}.json")
        loaded = recorder.load_force_calibration(path)
        np.testing.assert_array_equal(
            loaded.correct(test.signal_V), fits[name].correct(test.signal_V)
        )
