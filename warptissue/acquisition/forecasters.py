"""The single forecasting models of the force-sensor correction (Tong et al.): a polynomial,
a back-propagation network, an epsilon-SVR and a least-squares SVM, each fitted and applied as
a plain dict of arrays (its JSON form), and the k-fold cross-validation that chooses their
hyperparameters. :mod:`warptissue.acquisition.calibration` combines them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from warptissue.errors import InputError

__all__ = [
    "COMBINER_GRIDS",
    "HYPERPARAMETER_GRIDS",
    "LeastSquaresSVM",
    "Tuned",
    "cross_validate",
    "fit_model",
    "fold_masks",
    "predict_model",
]


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


def fit_model(
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


def predict_model(model: dict, features: np.ndarray) -> np.ndarray:
    """Predictions of a model dict (from :func:`fit_model` or a file) for features (n, d)."""
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
class Tuned:
    """The cross-validated choice for one model: hyperparameters, the out-of-fold
    predictions they give (n,), and their cross-validated mean absolute error."""

    params: dict[str, float]
    out_of_fold: np.ndarray
    cv_mae: float


def cross_validate(
    kind: str,
    grid: Sequence[dict[str, float]],
    features: np.ndarray,
    target: np.ndarray,
    folds: Sequence[np.ndarray],
    seed: int,
    *,
    kernel: str = "rbf",
) -> Tuned:
    """The grid entry with the smallest k-fold mean absolute error, with its out-of-fold
    predictions (each sample predicted by the model fitted without its fold)."""
    best: Tuned | None = None
    for params in grid:
        out_of_fold = np.empty_like(target)
        for held in folds:
            model = fit_model(kind, features[~held], target[~held], params, seed, kernel=kernel)
            out_of_fold[held] = predict_model(model, features[held])
        cv_mae = float(np.abs(out_of_fold - target).mean())
        if best is None or cv_mae < best.cv_mae:
            best = Tuned(dict(params), out_of_fold, cv_mae)
    return best


def fold_masks(count: int, folds: int, seed: int) -> list[np.ndarray]:
    """``folds`` boolean masks (count,) that partition a random permutation of the rows."""
    order = np.random.default_rng(seed).permutation(count)
    masks = []
    for k in range(folds):
        mask = np.zeros(count, dtype=bool)
        mask[order[k::folds]] = True
        masks.append(mask)
    return masks
