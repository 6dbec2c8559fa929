"""Force-sensor correction: single forecasting models and their weighted SVM combination.

Tong et al. (Tong et al.) corrects the readings of a force sensor with a weighted combination
forecasting model, WCFM_SVM: single models map the sensor signal to force (a polynomial,
a back-propagation network, an SVR and a least-squares SVM); their predictions, each
multiplied by a weight from the inverse summed relative error (Eq. 1), are the inputs of an
SVR that outputs the corrected force. The baselines of Table 1 are the combinations with
equal weights (CFM_SVM, CFM_LSSVM) and the weighted LSSVM combination (WCFM_LSSVM).

Each sample (one applied force) is one example: its k readings (the paper takes five) are
the inputs of the BP network, the SVR and the LSSVM, and their mean that of the polynomial.
Hyperparameters are chosen by cross-validation on the training samples, and the combiners
are trained on the single models' out-of-fold forecasts (:func:`fit_calibrations`).

A :class:`ForceCalibration` holds one fitted model and applies it (``.correct``); it is
saved as JSON (``.save``/``.load``) with every number prediction needs (polynomial
coefficients, network weights, support vectors, dual coefficients, intercepts, kernel
widths, weights), so that the acquisition code can apply it without pickles. Prediction
from a loaded file uses only NumPy.

Calibration data (CSV, one row per sensor reading)::

    sample,force_N,signal_V

``sample`` groups the readings of one applied force (every sample needs the same number);
it is optional (each row its own sample, one reading each). The train/test split is by
sample.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

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
    "evaluate_calibrations",
    "read_calibration_csv",
    "sample_readings",
    "split_samples",
    "synthetic_sensor",
]

SINGLE_MODELS: tuple[str, ...] = ("polynomial", "bp", "svm", "lssvm")
COMBINED_MODELS: tuple[str, ...] = ("CFM_SVM", "CFM_LSSVM", "WCFM_LSSVM", "WCFM_SVM")
CALIBRATION_MODELS: tuple[str, ...] = SINGLE_MODELS + COMBINED_MODELS
"""Every model name :func:`fit_calibration` accepts (Table 1 of Tong et al.)."""

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

HYPERPARAMETER_GRIDS: dict[str, tuple[dict[str, float], ...]] = {
    "polynomial": tuple({"degree": degree} for degree in (1, 2, 3, 4, 5)),
    "bp": tuple(
        {"hidden": hidden, "alpha": alpha} for hidden in (2, 4, 8) for alpha in (1e-4, 1e-2)
    ),
    "svm": tuple(
        {"C": c, "gamma": gamma, "epsilon": epsilon}
        for c in (1.0, 1e1, 1e2, 1e3)
        for gamma in (0.03, 0.3, 3.0)
        for epsilon in (1e-4, 1e-3)
    ),
    "lssvm": tuple(
        {"regularization": regularization, "gamma": gamma}
        for regularization in (1e2, 1e3, 1e4, 1e5, 1e6)
        for gamma in (0.03, 0.3, 3.0)
    ),
}
"""Candidate hyperparameters of the single models (on min-max normalized readings and force;
an RBF ``gamma`` is divided by the number of inputs). Chosen by cross-validation on the
training samples only."""

COMBINER_GRIDS: dict[str, tuple[dict[str, float], ...]] = {
    "svm": tuple(
        {"C": c, "epsilon": epsilon}
        for c in (0.1, 1.0, 10.0, 100.0, 1e3)
        for epsilon in (1e-5, 1e-4, 1e-3)
    ),
    "lssvm": tuple({"regularization": regularization} for regularization in (1.0, 1e2, 1e4, 1e6)),
}
"""Candidate hyperparameters of the combining SVR / LSSVM (linear kernel)."""


def _fit_model(
    kind: str,
    features: np.ndarray,
    target: np.ndarray,
    params: dict[str, float],
    seed: int,
    *,
    kernel: str = "rbf",
) -> dict:
    """Fit one model on normalized features (n, d) and target (n,); return its parameters.

    ``params`` holds the kind's hyperparameters (see :data:`HYPERPARAMETER_GRIDS`);
    ``kernel`` ("rbf" or "linear") applies to the "svm" and "lssvm" kinds."""
    if kind == "polynomial":
        degree = int(params["degree"])
        coefficients = np.polynomial.polynomial.polyfit(features.mean(axis=1), target, degree)
        return {"kind": kind, "hyperparameters": params, "coefficients": coefficients}
    if kind == "bp":
        from sklearn.neural_network import MLPRegressor

        network = MLPRegressor(
            hidden_layer_sizes=(int(params["hidden"]),),
            activation="tanh",
            solver="lbfgs",
            alpha=float(params["alpha"]),
            max_iter=2000,
            tol=1e-7,
            random_state=seed,
        ).fit(features, target)
        return {
            "kind": kind,
            "hyperparameters": params,
            "activation": "tanh",
            "weights": list(network.coefs_),
            "biases": list(network.intercepts_),
        }
    gamma = float(params.get("gamma", 1.0)) / features.shape[1]
    if kind == "svm":
        from sklearn.svm import SVR

        machine = SVR(
            kernel=kernel, C=float(params["C"]), epsilon=float(params["epsilon"]), gamma=gamma
        ).fit(features, target)
        return {
            "kind": kind,
            "hyperparameters": params,
            "kernel": kernel,
            "gamma": gamma,
            "support_vectors": machine.support_vectors_,
            "dual_coef": machine.dual_coef_.ravel(),
            "intercept": float(machine.intercept_[0]),
        }
    if kind == "lssvm":
        machine = LeastSquaresSVM(
            regularization=float(params["regularization"]), gamma=gamma, kernel=kernel
        ).fit(features, target)
        return {
            "kind": kind,
            "hyperparameters": params,
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


@dataclass(frozen=True)
class _Tuned:
    """The cross-validated choice for one model: hyperparameters, the out-of-fold
    predictions they give (n,), and their cross-validated mean absolute error."""

    params: dict[str, float]
    out_of_fold: np.ndarray
    cv_mae: float


def _cross_validate(
    kind: str,
    grid: Sequence[dict[str, float]],
    features: np.ndarray,
    target: np.ndarray,
    folds: Sequence[np.ndarray],
    seed: int,
    *,
    kernel: str = "rbf",
) -> _Tuned:
    """The grid entry with the smallest k-fold mean absolute error, with its out-of-fold
    predictions (each sample predicted by the model fitted without its fold)."""
    best: _Tuned | None = None
    for params in grid:
        out_of_fold = np.empty_like(target)
        for held in folds:
            model = _fit_model(kind, features[~held], target[~held], params, seed, kernel=kernel)
            out_of_fold[held] = _predict_model(model, features[held])
        cv_mae = float(np.abs(out_of_fold - target).mean())
        if best is None or cv_mae < best.cv_mae:
            best = _Tuned(dict(params), out_of_fold, cv_mae)
    return best


def combination_weights(predictions: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Tong et al. Eq. 1: w_i = (1 / E_i) / sum_k (1 / E_k).

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
        readings: Readings per sample, k: the models' inputs are a sample's k readings.
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
    readings: int = 1
    metadata: dict[str, Any] = field(default_factory=dict)

    def _features(self, raw_signal: np.ndarray | Sequence[float]) -> np.ndarray:
        """Normalized model inputs, shape (n, k), from readings (n, k), or (n,) / a scalar
        (one reading per sample, used for all k inputs: a live reading stream)."""
        signal = np.asarray(raw_signal, dtype=np.float64)
        if signal.ndim < 2:
            signal = np.repeat(np.atleast_1d(signal)[:, None], self.readings, axis=1)
        if signal.ndim != 2 or signal.shape[1] != self.readings:
            raise InputError(
                f"raw_signal must have shape (n,) or (n, {self.readings}) (readings per sample)",
                value=signal.shape,
            )
        if not np.all(np.isfinite(signal)):
            raise InputError("raw_signal must be finite volts")
        return (signal - self.signal_offset_V) / self.signal_scale_V

    def correct(self, raw_signal: np.ndarray | Sequence[float]) -> np.ndarray:
        """Corrected force of each sample.

        Args:
            raw_signal: Sensor readings, volts: shape (n, k) (the k readings of each of n
                samples), or (n,) or a scalar (one reading per sample; it stands for all k).

        Returns:
            Force, shape (n,), newtons.

        Raises:
            InputError: Wrong shape or non-finite values.
        """
        features = self._features(raw_signal)
        normalized = np.array([_predict_model(single, features) for single in self.singles])
        if self.combiner is None:
            output = normalized[0]
        else:
            output = _predict_model(self.combiner, (normalized * self.weights[:, None]).T)
        return output * self.force_scale_N + self.force_offset_N

    def single_predictions(self, raw_signal: np.ndarray | Sequence[float]) -> np.ndarray:
        """Force predicted by each single model, shape (m, n), newtons (input as
        :meth:`correct`)."""
        features = self._features(raw_signal)
        outputs = [_predict_model(single, features) for single in self.singles]
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
                    "readings": self.readings,
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
    def polynomial(cls, coefficients: Sequence[float]) -> ForceCalibration:
        """A polynomial correction ``force_N = sum_i c_i * raw**i`` of the raw reading.

        Args:
            coefficients: c0 (N), c1 (N per raw unit), c2, ...: at least one, all finite.

        Raises:
            InputError: No coefficients, or a non-finite one.
        """
        values = np.asarray(coefficients, dtype=np.float64).ravel()
        if values.size == 0 or not np.all(np.isfinite(values)):
            raise InputError(
                "polynomial coefficients must be a non-empty list of finite numbers",
                value=[float(c) for c in values],
            )
        return cls(
            model="polynomial",
            signal_offset_V=0.0,
            signal_scale_V=1.0,
            force_offset_N=0.0,
            force_scale_N=1.0,
            singles=[{"kind": "polynomial", "coefficients": values}],
            weights=np.empty(0),
        )

    @classmethod
    def load(cls, path: str | Path) -> ForceCalibration:
        """Read a calibration written by :meth:`save`, or a hand-written polynomial file
        ``{"model": "polynomial", "coefficients": [c0, c1, ...]}`` (see :meth:`polynomial`).

        Raises:
            InputError: The file is missing, not JSON, or not a force calibration (the key
                at fault named).
        """
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except OSError as exc:
            raise InputError(f"cannot read calibration: {exc.strerror}", path=path) from None
        except json.JSONDecodeError as exc:
            raise InputError(f"not JSON: {exc.msg}", path=path, line=exc.lineno) from None
        if isinstance(data, dict) and "format" not in data and data.get("model") == "polynomial":
            return cls._load_polynomial(path, data)
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise InputError(
                f'not a force calibration: expected "format": "{FORMAT}", or '
                '"model": "polynomial" with "coefficients"',
                path=path,
            )
        if data.get("version") != FORMAT_VERSION:
            raise InputError(
                f'key "version": unsupported calibration version; this warptissue reads '
                f"{FORMAT_VERSION}",
                path=path,
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
                readings=int(data["input"].get("readings", 1)),
                metadata=dict(data.get("metadata") or {}),
            )
        except KeyError as exc:
            raise InputError(
                f"malformed calibration: key {exc.args[0]!r} missing", path=path
            ) from None
        except (TypeError, ValueError, AttributeError) as exc:
            raise InputError(f"malformed calibration: {exc}", path=path) from None

    @classmethod
    def _load_polynomial(cls, path: Path, data: dict[str, Any]) -> ForceCalibration:
        coefficients = data.get("coefficients")
        if (
            not isinstance(coefficients, list)
            or not coefficients
            or not all(
                isinstance(c, int | float) and not isinstance(c, bool) and np.isfinite(c)
                for c in coefficients
            )
        ):
            raise InputError(
                'key "coefficients": must be a non-empty list of finite numbers',
                path=path,
                value=coefficients,
            )
        return cls.polynomial(coefficients)


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
            fewer than 10 readings, or samples with unequal numbers of readings or two
            forces (file, sample).
    """
    path = Path(path)
    samples, forces, signals = [], [], []
    for line, row in read_csv_rows(path, required=("force_N", "signal_V")):
        forces.append(csv_number(path, line, row, "force_N"))
        signals.append(csv_number(path, line, row, "signal_V"))
        samples.append((row.get("sample") or str(line)).strip())
    if len(forces) < 10:
        raise InputError(f"need at least 10 readings, got {len(forces)}", path=path)
    for column, values in (("signal_V", signals), ("force_N", forces)):
        if np.ptp(values) == 0:
            raise InputError(
                f"{column} is {values[0]:g} in every reading: nothing to calibrate",
                path=path,
                column=column,
            )
    data = CalibrationData(np.array(samples), np.array(forces), np.array(signals))
    try:
        sample_readings(data)
    except InputError as exc:
        raise InputError(exc.message, path=path, column=exc.column, value=exc.value) from None
    return data


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


def sample_readings(data: CalibrationData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The readings grouped by sample, in order of first appearance.

    Returns:
        Sample labels (n,), actual force (n,) in N, and readings (n, k) in V, k the readings
        per sample.

    Raises:
        InputError: Samples with different numbers of readings, or one sample with two
            different actual forces.
    """
    labels, first, inverse = np.unique(data.sample, return_index=True, return_inverse=True)
    counts = np.bincount(inverse)
    if np.any(counts != counts[0]):
        odd = str(labels[np.argmax(counts != counts[0])])
        raise InputError(
            f"every sample needs the same number of readings ({counts[0]})",
            column="sample",
            value=odd,
        )
    order = np.argsort(first)
    force = data.force_N[first]
    if np.any(data.force_N != force[inverse]):
        odd = str(data.sample[np.argmax(data.force_N != force[inverse])])
        raise InputError("one sample has two different force_N values", column="sample", value=odd)
    positions = np.argsort(inverse, kind="stable").reshape(len(labels), counts[0])
    return labels[order], force[order], data.signal_V[positions][order]


def evaluate_calibrations(
    calibrations: dict[str, ForceCalibration], data: CalibrationData
) -> dict[str, dict[str, float]]:
    """Table 1: :func:`calibration_metrics` of each calibration on ``data``'s samples (each
    sample's corrected force from its k readings)."""
    _, force, readings = sample_readings(data)
    return {
        name: calibration_metrics(force, calibration.correct(readings))
        for name, calibration in calibrations.items()
    }


def calibration_metrics(actual_N: np.ndarray, corrected_N: np.ndarray) -> dict[str, float]:
    """Tong et al.'s error measures of corrected against actual forces.

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


def _folds(count: int, folds: int, seed: int) -> list[np.ndarray]:
    """``folds`` boolean masks (count,) that partition a random permutation of the rows."""
    order = np.random.default_rng(seed).permutation(count)
    masks = []
    for k in range(folds):
        mask = np.zeros(count, dtype=bool)
        mask[order[k::folds]] = True
        masks.append(mask)
    return masks


def fit_calibrations(
    data: CalibrationData,
    *,
    models: Sequence[str] = CALIBRATION_MODELS,
    folds: int = 5,
    seed: int = 0,
    progress: bool = False,
) -> dict[str, ForceCalibration]:
    """Fit several force corrections (Tong et al., Eq. 1 and Table 1) sharing the single models.

    Each sample (one applied force, its k readings) is one training example. The single
    models (``polynomial``: a polynomial in the mean reading; ``bp``: a one-hidden-layer
    tanh network, L-BFGS; ``svm``: RBF epsilon-SVR; ``lssvm``: RBF least-squares SVM; the
    last three take the k readings as inputs) work on min-max normalized readings and force.
    Each model's hyperparameters are chosen from :data:`HYPERPARAMETER_GRIDS` by
    ``folds``-fold cross-validation on ``data`` (mean absolute error); the deployed model is
    then refitted on all of ``data``.

    A combination's inputs are the single models' forecasts, each multiplied by its weight
    (Eq. 1 for WCFM, 1/m for CFM), into a linear-kernel SVR (``*_SVM``) or LSSVM
    (``*_LSSVM``). It is trained on the out-of-fold forecasts of the chosen single models
    (each sample forecast by the models fitted without its fold), so that it learns how
    they err on data they have not seen; the weights' summed relative errors E_i use the same
    forecasts, and the combiner's own hyperparameters (:data:`COMBINER_GRIDS`) are chosen
    by cross-validation on them. Nothing outside ``data`` is used for any choice.

    Args:
        data: Training readings (every sample with the same number of readings).
        models: Names from :data:`CALIBRATION_MODELS`.
        folds: Folds of the cross-validation.
        seed: Random seed (network initialization, folds).
        progress: Show a progress bar (one step per tuned model).

    Returns:
        Model name to fitted calibration; ``metadata`` holds the chosen hyperparameters,
        the cross-validated MAE (N) and, for combinations, the Eq. 1 weights.

    Raises:
        InputError: Unknown model names, unequal readings per sample, or fewer than
            ``2 folds`` samples.
    """
    from tqdm import tqdm

    unknown = [m for m in models if m not in CALIBRATION_MODELS]
    if unknown:
        raise InputError(f"models must be among {CALIBRATION_MODELS}", value=unknown)
    _, force, readings = sample_readings(data)
    if folds < 2 or len(force) < 2 * folds:
        raise InputError(
            f"folds must be 2 or more, with at least two samples per fold ({len(force)} samples)",
            value=folds,
        )
    signal_offset = float(readings.min())
    signal_scale = float(np.ptp(readings)) or 1.0
    force_offset = float(force.min())
    force_scale = float(np.ptp(force)) or 1.0
    features = (readings - signal_offset) / signal_scale
    target = (force - force_offset) / force_scale
    fold_masks = _folds(len(target), folds, seed)
    combined = [m for m in models if m in COMBINED_MODELS]
    needed = SINGLE_MODELS if combined else tuple(m for m in SINGLE_MODELS if m in models)

    def calibration(model: str, tuned: _Tuned, **parts: Any) -> ForceCalibration:
        return ForceCalibration(
            model=model,
            signal_offset_V=signal_offset,
            signal_scale_V=signal_scale,
            force_offset_N=force_offset,
            force_scale_N=force_scale,
            readings=readings.shape[1],
            metadata={
                "software": software_versions(),
                "training_samples": len(target),
                "cv_folds": folds,
                "cv_mae_N": tuned.cv_mae * force_scale,
                "hyperparameters": tuned.params,
            },
            **parts,
        )

    # Small problems: one BLAS/OpenMP thread each is much faster than oversubscribed threads.
    bar = tqdm(
        total=len(needed) + len(combined), desc="calibration", unit="model", disable=not progress
    )
    # Load the libraries (and their BLAS) before limiting the threads: threadpoolctl limits
    # only the BLAS libraries already loaded, and an unlimited one made a first fit 6x slower.
    import sklearn.neural_network  # noqa: F401
    import sklearn.svm  # noqa: F401

    with threadpool_limits(limits=1), bar:
        tuned = {}
        for kind in needed:
            bar.set_postfix_str(kind)
            tuned[kind] = _cross_validate(
                kind, HYPERPARAMETER_GRIDS[kind], features, target, fold_masks, seed
            )
            bar.update(1)
        singles = {
            kind: _fit_model(kind, features, target, tuned[kind].params, seed) for kind in needed
        }
        fitted = {
            m: calibration(m, tuned[m], singles=[singles[m]], weights=np.zeros(0))
            for m in models
            if m in SINGLE_MODELS
        }
        if combined:
            out_of_fold = np.array([tuned[kind].out_of_fold for kind in SINGLE_MODELS])
            weighted = combination_weights(out_of_fold * force_scale + force_offset, force)
            equal = np.full(len(SINGLE_MODELS), 1.0 / len(SINGLE_MODELS))
        for m in combined:
            bar.set_postfix_str(m)
            weights = weighted if m.startswith("WCFM") else equal
            combiner_kind = "svm" if m.endswith("_SVM") else "lssvm"
            inputs = (out_of_fold * weights[:, None]).T
            chosen = _cross_validate(
                combiner_kind,
                COMBINER_GRIDS[combiner_kind],
                inputs,
                target,
                fold_masks,
                seed,
                kernel=COMBINER_KERNEL,
            )
            combiner = _fit_model(
                combiner_kind, inputs, target, chosen.params, seed, kernel=COMBINER_KERNEL
            )
            fitted[m] = calibration(
                m,
                chosen,
                singles=[singles[kind] for kind in SINGLE_MODELS],
                weights=weights,
                combiner=combiner,
            )
            fitted[m].metadata["weights"] = dict(zip(SINGLE_MODELS, weights.tolist(), strict=True))
            bar.update(1)
    return {m: fitted[m] for m in models}


def fit_calibration(
    data: CalibrationData, *, model: str = "WCFM_SVM", folds: int = 5, seed: int = 0
) -> ForceCalibration:
    """Fit one force correction; see :func:`fit_calibrations`."""
    return fit_calibrations(data, models=(model,), folds=folds, seed=seed)[model]


GRAM_FORCE_N = 9.80665e-3
"""One gram-force in newtons."""


def synthetic_sensor(
    *,
    samples: int = 76,
    readings: int = 5,
    seed: int = 2017,
    noise_V: float = 1e-3,
    emi_probability: float = 0.05,
    emi_V: float = 0.02,
    temperature_coefficient_per_K: float = 5e-4,
) -> CalibrationData:
    """A synthetic calibration session of a 3 kg load cell (Tong et al.'s set-up, simulated).

    ``samples`` weights, uniform on 2-100 % of 3000 g, are applied one after another in
    random order, 60 s each; the sensor is read ``readings`` times, 1 s apart, from 10 s after
    the load is applied. The actual force is the reference scale's reading, the true force
    rounded to its 2 g resolution. Each reading (volts) is

        V = V0 + S F_FS g(x) c(t) (1 + b dT) + a V_FS dT + n + e,    x = F / F_FS,

    quantized by a 12-bit ADC over 0-5 V, with

    - V0 = 0.5 V zero output, S F_FS = V_FS = 4 V span at F_FS = 3000 g;
    - gain nonlinearity g(x) = x - 0.06 x^2 + 0.02 x^3 (sensitivity 6 % lower at full scale,
      full-scale output 4 % below the initial tangent; a cheap load cell);
    - creep c(t) = 1 + 0.002 ln(1 + t / 2 s) with t the time under load;
    - temperature (not recorded): dT(t) = 2 K (1 - exp(-t / 20 min)) (warm-up of the
      electronics after power-on) + 1 K sin(2 pi t / 90 min + phase) (room), t the session
      time; zero coefficient a and span coefficient b, each
      ``temperature_coefficient_per_K`` (0.05 %/K: 2 mV/K of zero, about 0.015 N/K);
    - n: white noise, ``noise_V`` rms per reading (amplifier and ADC);
    - e: electromagnetic interference, a spike of ``emi_V`` rms (Gaussian) on each reading
      with probability ``emi_probability``.

    The parameters are typical data-sheet values of a low-cost load cell with an
    instrumentation amplifier, chosen before any model was fitted.

    Returns:
        Readings with labels S000, S001, ... (the session order).
    """
    rng = np.random.default_rng(seed)
    full_scale_g = 3000.0
    grams = rng.uniform(0.02, 1.0, samples) * full_scale_g
    actual_N = np.round(grams / 2.0) * 2.0 * GRAM_FORCE_N
    time_under_load_s = 10.0 + np.arange(readings, dtype=np.float64)
    session_s = 60.0 * np.arange(samples)[:, None] + time_under_load_s[None, :]
    delta_K = 2.0 * (1.0 - np.exp(-session_s / 1200.0)) + np.sin(
        2.0 * np.pi * session_s / 5400.0 + rng.uniform(0.0, 2.0 * np.pi)
    )
    x = (grams / full_scale_g)[:, None]
    span_V = 4.0
    load_V = (
        span_V * (x - 0.06 * x**2 + 0.02 * x**3) * (1.0 + 0.002 * np.log1p(time_under_load_s / 2.0))
    )
    signal = (
        0.5
        + load_V * (1.0 + temperature_coefficient_per_K * delta_K)
        + temperature_coefficient_per_K * span_V * delta_K
        + rng.normal(0.0, noise_V, (samples, readings))
        + (rng.random((samples, readings)) < emi_probability)
        * rng.normal(0.0, emi_V, (samples, readings))
    )
    lsb_V = 5.0 / 4096
    signal = np.round(signal / lsb_V) * lsb_V
    labels = np.repeat([f"S{k:03d}" for k in range(samples)], readings)
    return CalibrationData(labels, np.repeat(actual_N, readings), signal.ravel())
