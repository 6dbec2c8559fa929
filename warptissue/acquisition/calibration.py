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

The single models and their cross-validation are in
:mod:`warptissue.acquisition.forecasters`; the readings (``sample,force_N,signal_V`` files,
the split by sample, the error measures, a simulated session) in
:mod:`warptissue.acquisition.calibration_data`. Every name still imports from here.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from warptissue.acquisition.calibration_data import (
    GRAM_FORCE_N,
    CalibrationData,
    calibration_metrics,
    read_calibration_csv,
    sample_readings,
    split_samples,
    synthetic_sensor,
)
from warptissue.acquisition.forecasters import (
    COMBINER_GRIDS,
    HYPERPARAMETER_GRIDS,
    LeastSquaresSVM,
)
from warptissue.acquisition.forecasters import Tuned as _Tuned
from warptissue.acquisition.forecasters import cross_validate as _cross_validate
from warptissue.acquisition.forecasters import fit_model as _fit_model
from warptissue.acquisition.forecasters import fold_masks as _folds
from warptissue.acquisition.forecasters import predict_model as _predict_model
from warptissue.errors import InputError
from warptissue.io import atomic_path, software_versions, to_jsonable

__all__ = [
    "CALIBRATION_MODELS",
    "COMBINER_GRIDS",
    "GRAM_FORCE_N",
    "HYPERPARAMETER_GRIDS",
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
    training = _Training.normalized(force, readings, folds=folds, seed=seed)
    combined = [m for m in models if m in COMBINED_MODELS]
    needed = SINGLE_MODELS if combined else tuple(m for m in SINGLE_MODELS if m in models)
    bar = tqdm(
        total=len(needed) + len(combined), desc="calibration", unit="model", disable=not progress
    )
    # Load the libraries (and their BLAS) before limiting the threads: threadpoolctl limits
    # only the BLAS libraries already loaded, and an unlimited one made a first fit 6x slower.
    import sklearn.neural_network  # noqa: F401
    import sklearn.svm  # noqa: F401

    # Small problems: one BLAS/OpenMP thread each is much faster than oversubscribed threads.
    with threadpool_limits(limits=1), bar:
        tuned = {}
        for kind in needed:
            bar.set_postfix_str(kind)
            tuned[kind] = training.cross_validate(kind, HYPERPARAMETER_GRIDS[kind])
            bar.update(1)
        singles = {
            kind: _fit_model(kind, training.features, training.target, tuned[kind].params, seed)
            for kind in needed
        }
        fitted = {
            m: training.calibration(m, tuned[m], singles=[singles[m]], weights=np.zeros(0))
            for m in models
            if m in SINGLE_MODELS
        }
        for m in combined:
            bar.set_postfix_str(m)
            fitted[m] = _combination(m, training, tuned, singles)
            bar.update(1)
    return {m: fitted[m] for m in models}


@dataclass(frozen=True)
class _Training:
    """The training samples of :func:`fit_calibrations`, min-max normalized: readings to
    ``features`` (n, k), force to ``target`` (n,); the cross-validation's folds."""

    force_N: np.ndarray
    features: np.ndarray
    target: np.ndarray
    signal_offset_V: float
    signal_scale_V: float
    force_offset_N: float
    force_scale_N: float
    folds: int
    fold_masks: list[np.ndarray]
    seed: int

    @classmethod
    def normalized(
        cls, force_N: np.ndarray, readings_V: np.ndarray, *, folds: int, seed: int
    ) -> _Training:
        signal_offset = float(readings_V.min())
        signal_scale = float(np.ptp(readings_V)) or 1.0
        force_offset = float(force_N.min())
        force_scale = float(np.ptp(force_N)) or 1.0
        target = (force_N - force_offset) / force_scale
        return cls(
            force_N=force_N,
            features=(readings_V - signal_offset) / signal_scale,
            target=target,
            signal_offset_V=signal_offset,
            signal_scale_V=signal_scale,
            force_offset_N=force_offset,
            force_scale_N=force_scale,
            folds=folds,
            fold_masks=_folds(len(target), folds, seed),
            seed=seed,
        )

    def cross_validate(
        self,
        kind: str,
        grid: Sequence[dict[str, float]],
        inputs: np.ndarray | None = None,
        *,
        kernel: str = "rbf",
    ) -> _Tuned:
        """The grid's best entry for ``kind`` on ``inputs`` (None: the features)."""
        features = self.features if inputs is None else inputs
        return _cross_validate(
            kind, grid, features, self.target, self.fold_masks, self.seed, kernel=kernel
        )

    def calibration(self, model: str, tuned: _Tuned, **parts: Any) -> ForceCalibration:
        """The :class:`ForceCalibration` of ``model`` with this normalization and the
        cross-validation's choice in its metadata."""
        return ForceCalibration(
            model=model,
            signal_offset_V=self.signal_offset_V,
            signal_scale_V=self.signal_scale_V,
            force_offset_N=self.force_offset_N,
            force_scale_N=self.force_scale_N,
            readings=self.features.shape[1],
            metadata={
                "software": software_versions(),
                "training_samples": len(self.target),
                "cv_folds": self.folds,
                "cv_mae_N": tuned.cv_mae * self.force_scale_N,
                "hyperparameters": tuned.params,
            },
            **parts,
        )


def _combination(
    model: str, training: _Training, tuned: dict[str, _Tuned], singles: dict[str, dict]
) -> ForceCalibration:
    """A combination (``CFM_*``, ``WCFM_*``) of every single model: its weights (Eq. 1 from
    the out-of-fold forecasts for WCFM, equal for CFM) and its linear-kernel combiner, chosen
    by cross-validation on the weighted out-of-fold forecasts."""
    out_of_fold = np.array([tuned[kind].out_of_fold for kind in SINGLE_MODELS])
    if model.startswith("WCFM"):
        forecasts_N = out_of_fold * training.force_scale_N + training.force_offset_N
        weights = combination_weights(forecasts_N, training.force_N)
    else:
        weights = np.full(len(SINGLE_MODELS), 1.0 / len(SINGLE_MODELS))
    combiner_kind = "svm" if model.endswith("_SVM") else "lssvm"
    inputs = (out_of_fold * weights[:, None]).T
    chosen = training.cross_validate(
        combiner_kind, COMBINER_GRIDS[combiner_kind], inputs, kernel=COMBINER_KERNEL
    )
    combiner = _fit_model(
        combiner_kind, inputs, training.target, chosen.params, training.seed, kernel=COMBINER_KERNEL
    )
    fitted = training.calibration(
        model,
        chosen,
        singles=[singles[kind] for kind in SINGLE_MODELS],
        weights=weights,
        combiner=combiner,
    )
    fitted.metadata["weights"] = dict(zip(SINGLE_MODELS, weights.tolist(), strict=True))
    return fitted


def fit_calibration(
    data: CalibrationData, *, model: str = "WCFM_SVM", folds: int = 5, seed: int = 0
) -> ForceCalibration:
    """Fit one force correction; see :func:`fit_calibrations`."""
    return fit_calibrations(data, models=(model,), folds=folds, seed=seed)[model]
