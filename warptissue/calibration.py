"""Force-sensor correction: single forecasting models and their weighted SVM combination.

Seed 002 (Tong et al.) corrects the readings of a force sensor with a weighted combination
forecasting model, WCFM_SVM: single models map the sensor signal to force (a polynomial,
a back-propagation network, an SVR and a least-squares SVM); their predictions, each
multiplied by a weight from the inverse summed relative error (Eq. 1), are the inputs of an
SVR that outputs the corrected force. The baselines of Table 1 are the combinations with
equal weights (CFM_SVM, CFM_LSSVM) and the weighted LSSVM combination (WCFM_LSSVM).

A :class:`ForceCalibration` holds one fitted model and applies it (``.correct``); it is
saved as JSON (``.save``/``.load``) with every number prediction needs (polynomial
coefficients, network weights, support vectors, dual coefficients, intercepts, kernel
widths, weights), so that the acquisition code can apply it without pickles. Prediction
from a loaded file uses only NumPy.

Calibration data (CSV, one row per sensor reading)::

    sample,force_N,signal_V

``sample`` groups the repeated readings of one applied force (the paper takes five per
sample); it is optional (each row its own sample). The train/test split is by sample.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from warptissue.errors import InputError
from warptissue.io import atomic_path, csv_number, read_csv_rows, software_versions, to_jsonable

__all__ = [
    "CALIBRATION_MODELS",
    "CalibrationData",
    "ForceCalibration",
    "LeastSquaresSVM",
    "calibration_metrics",
    "combination_weights",
    "fit_calibration",
    "fit_calibrations",
    "read_calibration_csv",
    "sample_means",
    "split_samples",
    "synthetic_sensor",
]

SINGLE_MODELS: tuple[str, ...] = ("polynomial", "bp", "svm", "lssvm")
COMBINED_MODELS: tuple[str, ...] = ("CFM_SVM", "CFM_LSSVM", "WCFM_LSSVM", "WCFM_SVM")
CALIBRATION_MODELS: tuple[str, ...] = SINGLE_MODELS + COMBINED_MODELS
"""Every model name :func:`fit_calibration` accepts (Table 1 of seed 002)."""

COMBINER_KERNEL = "linear"
"""Kernel of the combining SVR/LSSVM: a weighted linear blend of the single forecasts."""

FORMAT = "warptissue.force_calibration"
FORMAT_VERSION = 1


def _kernel(a: np.ndarray, b: np.ndarray, kind: str, gamma: float) -> np.ndarray:
    """Kernel matrix, shape (len(a), len(b)): "rbf" exp(-gamma ||a_i - b_j||^2) or
    "linear" a_i . b_j."""
    if kind == "linear":
        return a @ b.T
    return _rbf(a, b, gamma)


def _rbf(a: np.ndarray, b: np.ndarray, gamma: float) -> np.ndarray:
    """Gaussian kernel exp(-gamma ||a_i - b_j||^2), shape (len(a), len(b))."""
    squared = (a**2).sum(1)[:, None] + (b**2).sum(1)[None, :] - 2.0 * a @ b.T
    return np.exp(-gamma * np.maximum(squared, 0.0))


def _scale_gamma(features: np.ndarray) -> float:
    """scikit-learn's "scale" kernel width, 1 / (n_features var(X))."""
    variance = float(features.var())
    return 1.0 / (features.shape[1] * variance) if variance > 0 else 1.0


class LeastSquaresSVM:
    """Least-squares support vector regression with a Gaussian kernel (Suykens).

    Fitting solves the dual linear system

        [ 0   1^T         ] [b]     [0]
        [ 1   K + I / reg ] [a]  =  [y],     K_ij = exp(-gamma ||x_i - x_j||^2)

    and predicts f(x) = sum_i a_i k(x_i, x) + b. Every training point is a support vector.

    Args:
        regularization: reg > 0 (larger fits the data more closely).
        gamma: Kernel width, or None for 1 / (n_features var(X)).
    """

    def __init__(
        self, *, regularization: float = 1e3, gamma: float | None = None, kernel: str = "rbf"
    ) -> None:
        if not regularization > 0:
            raise InputError("LSSVM regularization must be positive", value=regularization)
        if kernel not in ("rbf", "linear"):
            raise InputError("LSSVM kernel must be 'rbf' or 'linear'", value=kernel)
        self.kernel = kernel
        self.regularization = float(regularization)
        self.gamma = gamma
        self.support_vectors: np.ndarray | None = None
        self.dual_coef: np.ndarray | None = None
        self.bias = 0.0

    def fit(self, features: np.ndarray, target: np.ndarray) -> LeastSquaresSVM:
        """Fit to ``features`` (n, d) and ``target`` (n,)."""
        features = np.asarray(features, dtype=np.float64)
        target = np.asarray(target, dtype=np.float64)
        count = len(features)
        self.gamma = _scale_gamma(features) if self.gamma is None else float(self.gamma)
        system = np.zeros((count + 1, count + 1))
        system[0, 1:] = 1.0
        system[1:, 0] = 1.0
        system[1:, 1:] = (
            _kernel(features, features, self.kernel, self.gamma)
            + np.eye(count) / self.regularization
        )
        solution = np.linalg.solve(system, np.concatenate([[0.0], target]))
        self.bias = float(solution[0])
        self.dual_coef = solution[1:]
        self.support_vectors = features.copy()
        return self

    def predict(self, features: np.ndarray) -> np.ndarray:
        """Predictions, shape (n,)."""
        kernel = _kernel(
            np.asarray(features, dtype=np.float64), self.support_vectors, self.kernel, self.gamma
        )
        return kernel @ self.dual_coef + self.bias


# Each fitted single or combining model is a plain dict of arrays (its JSON form), and
# prediction reads only that dict, so a saved file predicts exactly like the fitted model.


def _fit_model(
    kind: str, features: np.ndarray, target: np.ndarray, seed: int, *, kernel: str = "rbf"
) -> dict:
    """Fit one model on normalized features (n, d) and target (n,); return its parameters.

    ``kernel`` ("rbf" or "linear") applies to the "svm" and "lssvm" kinds."""
    if kind == "polynomial":
        coefficients = np.polynomial.polynomial.polyfit(features.mean(axis=1), target, 3)
        return {"kind": kind, "coefficients": coefficients}
    if kind == "bp":
        from sklearn.neural_network import MLPRegressor

        network = MLPRegressor(
            hidden_layer_sizes=(8,),
            activation="tanh",
            solver="lbfgs",
            alpha=1e-5,
            max_iter=5000,
            tol=1e-9,
            random_state=seed,
        ).fit(features, target)
        return {
            "kind": kind,
            "activation": "tanh",
            "weights": [w for w in network.coefs_],
            "biases": [b for b in network.intercepts_],
        }
    if kind == "svm":
        from sklearn.svm import SVR

        gamma = _scale_gamma(features)
        machine = SVR(kernel=kernel, C=1e3, epsilon=1e-4, gamma=gamma).fit(features, target)
        return {
            "kind": kind,
            "kernel": kernel,
            "gamma": gamma,
            "support_vectors": machine.support_vectors_,
            "dual_coef": machine.dual_coef_.ravel(),
            "intercept": float(machine.intercept_[0]),
        }
    if kind == "lssvm":
        machine = LeastSquaresSVM(regularization=1e3, kernel=kernel).fit(features, target)
        return {
            "kind": kind,
            "kernel": kernel,
            "gamma": machine.gamma,
            "support_vectors": machine.support_vectors,
            "dual_coef": machine.dual_coef,
            "intercept": machine.bias,
        }
    raise InputError(f"unknown model kind {kind!r}")


def _predict_model(model: dict, features: np.ndarray) -> np.ndarray:
    """Predictions of a model dict (from :func:`_fit_model` or a file) for features (n, d)."""
    kind = model["kind"]
    if kind == "polynomial":
        return np.polynomial.polynomial.polyval(
            features.mean(axis=1), np.asarray(model["coefficients"])
        )
    if kind == "bp":
        activation = np.asarray(features, dtype=np.float64)
        layers = list(zip(model["weights"], model["biases"], strict=True))
        for index, (weights, biases) in enumerate(layers):
            activation = activation @ np.asarray(weights) + np.asarray(biases)
            if index < len(layers) - 1:
                activation = np.tanh(activation)
        return activation.ravel()
    if kind in ("svm", "lssvm"):
        kernel = _kernel(
            features,
            np.asarray(model["support_vectors"]),
            model.get("kernel", "rbf"),
            float(model["gamma"]),
        )
        return kernel @ np.asarray(model["dual_coef"]) + float(model["intercept"])
    raise InputError(f"unknown model kind {kind!r} in calibration")


def combination_weights(predictions: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Seed 002 Eq. 1: w_i = (1 / E_i) / sum_k (1 / E_k).

    Args:
        predictions: Predictions of the m single models, shape (m, n).
        target: Actual values, shape (n,). Samples with a zero target are skipped in the
            relative error (it is undefined there).

    Returns:
        Weights, shape (m,), summing to 1. E_i is the sum over samples of
        |X_ij - Y_j| / |Y_j|.
    """
    keep = np.asarray(target) != 0
    errors = np.abs(predictions[:, keep] - target[keep]) / np.abs(target[keep])
    summed = np.maximum(errors.sum(axis=1), np.finfo(float).tiny)
    inverse = 1.0 / summed
    return inverse / inverse.sum()


@dataclass
class ForceCalibration:
    """A fitted force correction: sensor signal (V) to force (N).

    Attributes:
        model: Name from :data:`CALIBRATION_MODELS`.
        signal_offset_V, signal_scale_V: Signal normalization, x = (V - offset) / scale.
        force_offset_N, force_scale_N: Force normalization, y = (F - offset) / scale.
        singles: The single models (parameter dicts), in the order of ``weights``.
        weights: Combination weights (Eq. 1, or equal for CFM), shape (m,); empty for a
            single model.
        combiner: The combining SVR or LSSVM (parameter dict), or None for a single model.
        metadata: Free-form provenance (data file, split, metrics, software versions).
    """

    model: str
    signal_offset_V: float
    signal_scale_V: float
    force_offset_N: float
    force_scale_N: float
    singles: list[dict]
    weights: np.ndarray
    combiner: dict | None = None
    metadata: dict[str, Any] = field(default_factory=dict)

    def correct(self, raw_signal: np.ndarray | Sequence[float]) -> np.ndarray:
        """Corrected force for sensor signals.

        Args:
            raw_signal: Sensor signal, shape (n,) (or a scalar), volts.

        Returns:
            Force, shape (n,), newtons.

        Raises:
            InputError: The signal holds non-finite values.
        """
        signal = np.atleast_1d(np.asarray(raw_signal, dtype=np.float64))
        if signal.ndim != 1 or not np.all(np.isfinite(signal)):
            raise InputError("raw_signal must be a finite 1-D array of volts")
        features = ((signal - self.signal_offset_V) / self.signal_scale_V)[:, None]
        normalized = np.array([_predict_model(single, features) for single in self.singles])
        if self.combiner is None:
            output = normalized[0]
        else:
            output = _predict_model(self.combiner, (normalized * self.weights[:, None]).T)
        return output * self.force_scale_N + self.force_offset_N

    def single_predictions(self, raw_signal: np.ndarray) -> np.ndarray:
        """Force predicted by each single model, shape (m, n), newtons."""
        features = (np.asarray(raw_signal, np.float64) - self.signal_offset_V) / self.signal_scale_V
        outputs = [_predict_model(single, features[:, None]) for single in self.singles]
        return np.array(outputs) * self.force_scale_N + self.force_offset_N

    def to_dict(self) -> dict[str, Any]:
        """The JSON form (format ``warptissue.force_calibration``, version 1)."""
        return to_jsonable(
            {
                "format": FORMAT,
                "version": FORMAT_VERSION,
                "model": self.model,
                "input": {
                    "column": "signal_V",
                    "offset": self.signal_offset_V,
                    "scale": self.signal_scale_V,
                },
                "output": {
                    "column": "force_N",
                    "offset": self.force_offset_N,
                    "scale": self.force_scale_N,
                },
                "singles": self.singles,
                "weights": self.weights,
                "combiner": self.combiner,
                "metadata": self.metadata,
            }
        )

    def save(self, path: str | Path) -> Path:
        """Write the calibration as JSON, atomically."""
        with atomic_path(path) as temporary:
            temporary.write_text(json.dumps(self.to_dict(), indent=1) + "\n", encoding="utf-8")
        return Path(path)

    @classmethod
    def load(cls, path: str | Path) -> ForceCalibration:
        """Read a calibration written by :meth:`save`.

        Raises:
            InputError: The file is missing, not JSON, or not a force calibration.
        """
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise InputError(f"cannot read calibration: {exc.strerror}", path=path) from exc
        except json.JSONDecodeError as exc:
            raise InputError(f"not JSON: {exc.msg}", path=path, line=exc.lineno) from exc
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise InputError(f"not a {FORMAT} file", path=path, column="format")
        if data.get("version") != FORMAT_VERSION:
            raise InputError(
                "unsupported calibration version",
                path=path,
                column="version",
                value=data.get("version"),
            )
        try:
            return cls(
                model=str(data["model"]),
                signal_offset_V=float(data["input"]["offset"]),
                signal_scale_V=float(data["input"]["scale"]),
                force_offset_N=float(data["output"]["offset"]),
                force_scale_N=float(data["output"]["scale"]),
                singles=list(data["singles"]),
                weights=np.asarray(data["weights"], dtype=np.float64),
                combiner=data.get("combiner"),
                metadata=dict(data.get("metadata") or {}),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"malformed calibration: {exc!r}", path=path) from exc


@dataclass(frozen=True)
class CalibrationData:
    """Calibration readings.

    Attributes:
        sample: Sample label of each reading, shape (n,) (readings of one applied force).
        force_N: Actual force (reference scale), shape (n,), newtons.
        signal_V: Sensor signal, shape (n,), volts.
    """

    sample: np.ndarray
    force_N: np.ndarray
    signal_V: np.ndarray

    def subset(self, mask: np.ndarray) -> CalibrationData:
        """The readings selected by a boolean mask."""
        return CalibrationData(self.sample[mask], self.force_N[mask], self.signal_V[mask])


def read_calibration_csv(path: str | Path) -> CalibrationData:
    """Read ``sample,force_N,signal_V`` (``sample`` optional).

    Raises:
        InputError: Missing columns, non-numeric or non-finite values (file, line, column),
            or fewer than 10 readings.
    """
    path = Path(path)
    samples, forces, signals = [], [], []
    for line, row in read_csv_rows(path, required=("force_N", "signal_V")):
        forces.append(csv_number(path, line, row, "force_N"))
        signals.append(csv_number(path, line, row, "signal_V"))
        samples.append((row.get("sample") or str(line)).strip())
    if len(forces) < 10:
        raise InputError(f"need at least 10 readings, got {len(forces)}", path=path)
    return CalibrationData(np.array(samples), np.array(forces), np.array(signals))


def split_samples(
    data: CalibrationData, *, test_samples: int = 6, seed: int = 0
) -> tuple[CalibrationData, CalibrationData]:
    """Split by sample: ``test_samples`` random samples held out (the paper: 70 / 6)."""
    labels = np.unique(data.sample)
    if not 0 < test_samples < len(labels):
        raise InputError(
            f"test_samples must be between 1 and {len(labels) - 1}", value=test_samples
        )
    held = np.random.default_rng(seed).choice(labels, test_samples, replace=False)
    mask = np.isin(data.sample, held)
    return data.subset(~mask), data.subset(mask)


def sample_means(data: CalibrationData, corrected_N: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per sample: the actual force and the mean of its corrected readings (the paper's
    "corrected force" of a sample), each shape (samples,), in order of first appearance."""
    _, first, inverse = np.unique(data.sample, return_index=True, return_inverse=True)
    counts = np.bincount(inverse)
    means = np.bincount(inverse, weights=np.asarray(corrected_N, dtype=np.float64)) / counts
    order = np.argsort(first)
    return data.force_N[first][order], means[order]


def calibration_metrics(actual_N: np.ndarray, corrected_N: np.ndarray) -> dict[str, float]:
    """Seed 002's error measures of corrected against actual forces.

    e_MAE = 1/n sum |x - x^|; e_MSE = 1/n sqrt(sum (x - x^)^2) (as the paper defines it: not
    the usual mean square, which is also returned as ``mean_square_N2``); e_MAPE = 1/n sum
    |(x^ - x) / x| * 100 (zero actual forces are skipped).
    """
    actual = np.asarray(actual_N, dtype=np.float64)
    corrected = np.asarray(corrected_N, dtype=np.float64)
    count = len(actual)
    error = corrected - actual
    nonzero = actual != 0
    return {
        "mae_N": float(np.abs(error).mean()),
        "mse_paper_N": float(np.sqrt(np.sum(error**2)) / count),
        "mape_percent": float(np.mean(np.abs(error[nonzero] / actual[nonzero])) * 100.0),
        "mean_square_N2": float(np.mean(error**2)),
        "max_abs_error_N": float(np.abs(error).max()),
    }


def _group_folds(samples: np.ndarray, folds: int, seed: int) -> list[np.ndarray]:
    labels = np.unique(samples)
    order = np.random.default_rng(seed).permutation(len(labels))
    return [np.isin(samples, labels[order[k::folds]]) for k in range(folds)]


def fit_calibrations(
    data: CalibrationData,
    *,
    models: Sequence[str] = CALIBRATION_MODELS,
    folds: int = 5,
    seed: int = 0,
) -> dict[str, ForceCalibration]:
    """Fit several force corrections (seed 002, Eq. 1 and Table 1) sharing the single models.

    Single models (``polynomial``: cubic in the signal; ``bp``: an 8-neuron tanh network,
    L-BFGS; ``svm``: RBF epsilon-SVR; ``lssvm``: RBF least-squares SVM) are fitted on the
    normalized signal and force. For a combination, the inputs of the combining SVR/LSSVM are
    the single models' predictions, each multiplied by its weight (Eq. 1 for WCFM, 1/m for
    CFM). Those training inputs are out-of-fold predictions (``folds`` folds by sample), so
    that the combiner learns how the single models err on data they have not seen; the
    weights' summed relative errors E_i use the same out-of-fold predictions. The deployed
    single models are fitted on all the training data.

    Args:
        data: Training readings.
        models: Names from :data:`CALIBRATION_MODELS`.
        folds: Folds for the out-of-fold predictions.
        seed: Random seed (network initialization, folds).

    Returns:
        Model name to fitted calibration.
    """
    unknown = [m for m in models if m not in CALIBRATION_MODELS]
    if unknown:
        raise InputError(f"models must be among {CALIBRATION_MODELS}", value=unknown)
    if len(np.unique(data.sample)) < folds:
        raise InputError(f"need at least {folds} samples to fit", value=len(data.sample))
    signal_offset = float(data.signal_V.min())
    signal_scale = float(np.ptp(data.signal_V)) or 1.0
    force_offset = float(data.force_N.min())
    force_scale = float(np.ptp(data.force_N)) or 1.0
    features = ((data.signal_V - signal_offset) / signal_scale)[:, None]
    target = (data.force_N - force_offset) / force_scale
    singles = {kind: _fit_model(kind, features, target, seed) for kind in SINGLE_MODELS}

    def calibration(model: str, **parts: Any) -> ForceCalibration:
        return ForceCalibration(
            model=model,
            signal_offset_V=signal_offset,
            signal_scale_V=signal_scale,
            force_offset_N=force_offset,
            force_scale_N=force_scale,
            metadata={"software": software_versions(), "training_readings": len(target)},
            **parts,
        )

    fitted = {
        m: calibration(m, singles=[singles[m]], weights=np.zeros(0))
        for m in models
        if m in SINGLE_MODELS
    }
    combined = [m for m in models if m in COMBINED_MODELS]
    if not combined:
        return fitted
    out_of_fold = np.zeros((len(SINGLE_MODELS), len(target)))
    for held in _group_folds(data.sample, folds, seed):
        for index, kind in enumerate(SINGLE_MODELS):
            fold_model = _fit_model(kind, features[~held], target[~held], seed)
            out_of_fold[index, held] = _predict_model(fold_model, features[held])
    weighted = combination_weights(out_of_fold * force_scale + force_offset, data.force_N)
    equal = np.full(len(SINGLE_MODELS), 1.0 / len(SINGLE_MODELS))
    for m in combined:
        weights = weighted if m.startswith("WCFM") else equal
        combiner_kind = "svm" if m.endswith("_SVM") else "lssvm"
        combiner = _fit_model(
            combiner_kind, (out_of_fold * weights[:, None]).T, target, seed, kernel=COMBINER_KERNEL
        )
        fitted[m] = calibration(
            m,
            singles=[singles[kind] for kind in SINGLE_MODELS],
            weights=weights,
            combiner=combiner,
        )
    return {m: fitted[m] for m in models}


def fit_calibration(
    data: CalibrationData, *, model: str = "WCFM_SVM", folds: int = 5, seed: int = 0
) -> ForceCalibration:
    """Fit one force correction; see :func:`fit_calibrations`."""
    return fit_calibrations(data, models=(model,), folds=folds, seed=seed)[model]


def synthetic_sensor(
    *,
    samples: int = 76,
    readings: int = 5,
    max_force_N: float = 3.0 * 9.80665,
    noise_V: float = 1e-3,
    drift_V_per_K: float = 1e-3,
    seed: int = 2017,
) -> CalibrationData:
    """A synthetic miniature force sensor (nonlinear gain, temperature drift, noise).

    The applied forces are uniform on (2%, 100%] of ``max_force_N`` (the paper: 0-3000 g on a
    2 g scale), applied in random order during one session. The signal of a reading is

        V = 2.5 tanh(F / F_s) + 0.15 (F / F_max)^2 + k_T T(t) (1 + F / F_max) + n

    with F_s = 1.2 F_max (a saturating gain with a quadratic term), a room temperature that
    swings T(t) = 2 K sin(2 pi t / t_session + phase) over the session and shifts offset
    and gain by ``drift_V_per_K`` per kelvin (not recorded, so it acts as a slow disturbance),
    and white noise n of ``noise_V`` per reading.
    """
    rng = np.random.default_rng(seed)
    force = rng.uniform(0.02, 1.0, samples) * max_force_N
    time_fraction = (np.arange(samples)[:, None] * readings + np.arange(readings)) / (
        samples * readings
    )
    temperature_K = 2.0 * np.sin(2.0 * np.pi * time_fraction + rng.uniform(0, 2 * np.pi))
    relative = (force / max_force_N)[:, None]
    clean = 2.5 * np.tanh(relative / 1.2) + 0.15 * relative**2
    signal = (
        clean
        + drift_V_per_K * temperature_K * (1.0 + relative)
        + rng.normal(0.0, noise_V, (samples, readings))
    )
    labels = np.repeat([f"S{k:03d}" for k in range(samples)], readings)
    return CalibrationData(labels, np.repeat(force, readings), signal.ravel())
